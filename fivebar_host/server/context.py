"""What the routes share, as a FastAPI dependency: the `Context` and its parameter type `Ctx`.

`create_app` (server.app) builds one `Context` per application — the job store, the handle
to the machine thread, the compiled jobs, the profile, the compilation slots and compiler,
the event hub — and keeps it in `app.state.context`. A route asks for it with a parameter
`ctx: Ctx` (`Depends(context)`), so the routers (server.routes) close over nothing and
import nothing from the application; tests and other applications can build a `Context` of
their own.
"""

from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass, field
from typing import Annotated

from fastapi import Depends, Request

from fivebar_host.config import Profile
from fivebar_host.server import store as st_
from fivebar_host.server.compiler import Compiler
from fivebar_host.server.events import Compiling, EventHub
from fivebar_host.server.jobs import CompiledCache
from fivebar_host.server.models import ApiError, shown
from fivebar_host.server.requests import WorkerHandle
from fivebar_host.server.state import LiveView
from fivebar_host.server.store import JobRecord, JobStore
from fivebar_host.server.stored import StoredJobs


@dataclass
class Cached:
    """An answer built once and reused for a while (`GET /api/status`)."""

    at: float = -1.0  # when it was built, monotonic s
    body: bytes = b""


@dataclass(frozen=True)
class Context:
    """What the route handlers share (module docstring)."""

    store: JobStore
    worker: WorkerHandle
    jobs: StoredJobs
    profile: Profile
    stopping: threading.Event
    slots: asyncio.Semaphore  # the compilation slots
    started: float  # monotonic s
    compiler: Compiler
    events: EventHub
    status: Cached = field(default_factory=Cached)

    @property
    def cache(self) -> CompiledCache:
        """The compiled jobs kept for the machine thread."""
        return self.jobs.cache

    @property
    def compiling(self) -> dict[int, Compiling]:
        """The compilations under way (submissions, dry runs), shown as `compiling`."""
        return self.events.compiling

    def live(self) -> LiveView | None:
        """The running job's live progress as the machine thread last published it."""
        return self.worker.snapshot().live

    def get_rec(self, job_id: int) -> JobRecord:
        """A job, or the 404 answer (also for numbers no job can have: negative, or beyond
        SQLite's 64-bit integers, which it could not even look up)."""
        if not st_.valid_job_id(job_id):
            raise ApiError(404, "not_found", f"no job {shown(str(job_id))}: job ids are "
                           f"{st_.MIN_JOB_ID}..{st_.MAX_JOB_ID}")
        rec = self.store.get(job_id)
        if rec is None:
            raise ApiError(404, "not_found", f"no job {job_id}")
        return rec


async def context(request: Request) -> Context:
    """The application's `Context` (async: resolved on the event loop, no thread taken)."""
    ctx: Context = request.app.state.context
    return ctx


#: A route's parameter for the application's `Context`.
Ctx = Annotated[Context, Depends(context)]
