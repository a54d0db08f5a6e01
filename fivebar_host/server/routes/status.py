"""`GET /api/status`: daemon, machine and queue at a glance, cheap under hard polling.

The answer is built at most every `STATUS_CACHE_S` on the event loop from the machine
thread's published snapshot and two quick database reads; clients that poll hard cost the
machine thread (which must keep the serial link busy) little, and never reach the port.
"""

from __future__ import annotations

import time

from fastapi import APIRouter
from fastapi.responses import Response

from fivebar_host import __version__
from fivebar_host.server.context import Ctx
from fivebar_host.server.models import CompilingOut, MachineOut, StatusOut
from fivebar_host.server.state import machine_view

#: How long a built status answer is reused, s.
STATUS_CACHE_S = 0.05

router = APIRouter()


@router.get("/api/status", response_model=StatusOut, tags=["machine"])
async def status(ctx: Ctx) -> Response:
    """Daemon, machine (last status report) and queue counts (at most 50 ms old)."""
    now = time.monotonic()
    cached = ctx.status
    if now - cached.at > STATUS_CACHE_S:
        blk = ctx.store.blocking()
        snap = ctx.worker.snapshot()
        out = StatusOut(
            version=__version__, uptime_s=round(now - ctx.started, 3),
            stopping=ctx.stopping.is_set(),
            machine=MachineOut(**machine_view(snap, ctx.profile)),
            jobs=ctx.store.counts(), current_job=snap.current,
            blocked_by=blk.id if blk is not None and blk.id != snap.current else None,
            compiling=[CompilingOut(name=c.name, stage=c.stage, progress=c.fraction,
                                    elapsed_s=round(now - c.started, 1), note=c.note)
                       for c in list(ctx.compiling.values())])
        cached.body = out.model_dump_json().encode()
        cached.at = now
    return Response(cached.body, media_type="application/json")
