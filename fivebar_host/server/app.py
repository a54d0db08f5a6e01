"""The daemon's HTTP + JSON API (FastAPI): routes, response models, error format.

FastAPI derives the OpenAPI description (`GET /openapi.json`) from the route signatures and
the models below; docs/serve.md explains the API in prose. Every error answers with
`{"error": <stable key>, "message": <what and why>}` (plus details for refused drawings),
whatever produced it: a refused drawing, a bad option, an unknown job, a state conflict, a
missing token, an oversized body, a malformed query string or a full daemon (the last four
come from `security.Guard`). Every path and query value is checked before it reaches the
database: a job id is an integer (else 422), and one no job can have — negative, or beyond
SQLite's 64-bit range — is simply not found (404); a parameter that takes one value is
refused when repeated.

Submissions wait for one of `compile_slots` compilation slots on the event loop (they do
not occupy a thread while waiting, so reads stay quick under a burst of uploads); how many
may wait at once is the Guard's limit. A submission that waited `SUBMIT_WAIT_S` without a
slot, or whose client has gone, is not queued.

Handlers never touch the serial port: they read the database and the worker's snapshot, and
hand pause/resume/cancel/home to the machine thread.
"""

from __future__ import annotations

import asyncio
import math
import re
import threading
import time
import types
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Literal, TypeVar, Union, get_args, get_origin

from fastapi import Depends, FastAPI, Path, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, BeforeValidator, Field, create_model
from starlette.exceptions import HTTPException as StarletteHTTPException

from fivebar_host import __version__
from fivebar_host.config import Profile
from fivebar_host.errors import FivebarError, OptionError
from fivebar_host.options import JOB_OPTIONS, Option, parse_query, unknown_option
from fivebar_host.run.stops import planned_time_s
from fivebar_host.server import store as st_
from fivebar_host.server.compiler import Compiler
from fivebar_host.server.jobs import (
    Compiled,
    CompiledCache,
    JobOptions,
    SubmitError,
    compile_upload,
)
from fivebar_host.server.requests import WorkerHandle
from fivebar_host.server.security import RETRY_AFTER_S
from fivebar_host.server.state import ActionError, JobStateError, LiveView, machine_view
from fivebar_host.server.store import JobRecord, JobStore
from fivebar_host.server.stored import StoredJobs

T = TypeVar("T")

#: Content types a web page can send without a CORS preflight; uploads must not use them.
SIMPLE_CONTENT_TYPES = frozenset({"application/x-www-form-urlencoded", "multipart/form-data",
                                  "text/plain"})


#: How long a built status answer is reused, s.
STATUS_CACHE_S = 0.05
#: Longest a submission waits for a compilation slot before it is refused as busy, s.
SUBMIT_WAIT_S = 120.0
#: Longest parameter name echoed back in an error message, characters.
MAX_ECHO = 64
#: What a job id in a path may look like: decimal digits, optionally negative (a number no
#: job has is "not found"; anything else — `5_0`, `+5`, ` 5`, `0x5` — is not an id).
_ID_TEXT = re.compile(r"-?[0-9]+")


def _id_digits(value: Any) -> Any:
    """Refuse a path job id that is not plain decimal digits before pydantic's lax int
    parsing would read `1_0` as job 10."""
    if isinstance(value, str) and not _ID_TEXT.fullmatch(value):
        raise ValueError("a job id is a whole number in decimal digits")
    return value


#: A job id in a path (out-of-range numbers are answered 404 by `_Ctx.get_rec`).
JobId = Annotated[int, BeforeValidator(_id_digits),
                  Path(description="The job's id (a positive integer).")]


class ApiError(FivebarError):
    """An error answer: HTTP status, stable key, message, optional details and headers."""

    def __init__(self, status: int, error: str, message: str,
                 detail: dict[str, Any] | None = None,
                 headers: dict[str, str] | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.error = error
        self.message = message
        self.detail = detail or {}
        self.headers = headers


def busy(message: str, retry_after_s: float = RETRY_AFTER_S) -> ApiError:
    """The 503 answer of a daemon that cannot take more work now (with Retry-After)."""
    return ApiError(503, "busy", message,
                    headers={"Retry-After": str(max(1, math.ceil(retry_after_s)))})


# ---------------------------------------------------------------------------- models
class ErrorOut(BaseModel):
    """Every error response."""

    error: str = Field(description="Stable key: input_error, job_error, bad_option, "
                       "not_found, conflict, unauthorized, too_large, ...")
    message: str = Field(description="What went wrong, where, and what to do.")
    reason: str | None = Field(None, description="job_error only: reach, joint_limit, "
                               "type1_margin, type2_margin, mode_change, does_not_fit, ...")
    where: dict[str, Any] | None = Field(None, description="job_error only: path and point.")


def _option_out(o: Option) -> tuple[Any, Any]:
    """A job option as a field of `OptionsOut`: its stored JSON type, its default and help."""
    kinds: dict[str, Any] = {"bool": bool, "float": float, "int": int, "choice": str,
                             "xy": list[float], "text": str}
    kind = list[str] if o.repeat else kinds[o.kind]
    default = [] if o.repeat else o.default
    return (kind if default is not None else kind | None,
            Field(default, description=o.describe()))


#: The plot options a job was submitted with: every job option, generated from its one
#: definition (`fivebar_host.options`), as the submission stored it.
_OPTION_FIELDS: dict[str, Any] = {o.name: _option_out(o) for o in JOB_OPTIONS}
OptionsOut = create_model("OptionsOut", __doc__="The plot options a job was submitted with.",
                          **_OPTION_FIELDS)


class ResumeOut(BaseModel):
    """Where an interrupted job continues."""

    next_segment: int = Field(description="First job segment not known to be finished.")
    position: list[int] | None = Field(description="Firmware steps [A, B] where the machine "
                                       "stopped; null when unknown (home before resuming).")
    reason: str
    copy_number: int = Field(1, description="The copy (`copies` option, 1-based) it "
                             "continues in.")


class OverridesOut(BaseModel):
    """The running job's live overrides (POST /api/jobs/{id}/overrides)."""

    feed_pct: int = Field(description="Feed, % of the planned speed (10..100, slower only).")
    power_pct: int = Field(description="Laser power, % of the planned power (0..100).")


class JobOut(BaseModel):
    """A job in the queue or in the history."""

    id: int
    name: str
    state: Literal["queued", "running", "paused", "held", "done", "failed", "cancelled"]
    message: str = Field(description="What happened last (fault, interruption, result).")
    question: str | None = Field(description="held: what the daemon needs a person to "
                                 "confirm (resume with confirm=true once it is so).")
    submitted_at: float = Field(description="Unix time.")
    started_at: float | None
    finished_at: float | None
    options: OptionsOut  # type: ignore[valid-type]  # a model made from the options
    mode: str = Field(description="Working mode the job was compiled in.")
    max_dev_mm: float | None = Field(description="Largest deviation from the drawing, mm.")
    segments_total: int
    segments_done: int = Field(description="Segments finished of the copy being drawn.")
    copy_number: int = Field(1, description="The copy being drawn (or last drawn), "
                             "1-based; options.copies is how many the job draws.")
    progress: float = Field(description="segments_done / segments_total.")
    estimated_s: float = Field(description="Planned duration of the whole job, s.")
    remaining_s: float | None = Field(description="Planned time left, s.")
    elapsed_s: float = Field(description="Time spent running (all runs of it), s.")
    underruns: int | None = Field(description="done: times the firmware queue ran empty "
                                  "mid-job (0 is the goal); null if unknown.")
    resume: ResumeOut | None
    overrides: OverridesOut | None = Field(None, description="Running or paused: the live "
                                           "feed and laser-power overrides; else null.")


class MachineOut(BaseModel):
    """The machine as last reported (no request reaches the serial port)."""

    connected: bool
    port: str
    error: str | None
    firmware: dict[str, Any] | None = Field(description="version, protocol, rx_bytes, "
                                            "queue_blocks, line_bytes from the banner.")
    state: str | None = Field(description="Idle, Run, Hold, Home or Alarm.")
    detail: int | None = Field(description="Hold reason or alarm code.")
    position: dict[str, int] | None = Field(description="Firmware steps {a, b}.")
    position_mm: dict[str, float] | None = Field(None, description="The pen {x, y} in machine "
                                                 "mm (forward kinematics), when pose_known.")
    laser: int | None = Field(description="Laser output now (0 = off).")
    queued_blocks: int | None = Field(description="Blocks waiting in the firmware queue.")
    done_line: int | None
    accepted_line: int | None
    underruns: int | None = Field(description="Times the queue ran empty since reset (U:).")
    pose_known: bool = Field(description="The daemon trusts the firmware's position.")
    motors_off: bool = Field(False, description="The motors were switched off (M18); the "
                             "next motion switches them on (M17).")
    alarm: str | None = Field(None, description="Alarm: its code and reason in words.")
    status_age_s: float | None = Field(description="Age of the last status report, s.")


class StatusOut(BaseModel):
    """Daemon, machine and queue at a glance."""

    version: str
    uptime_s: float
    stopping: bool
    machine: MachineOut
    jobs: dict[str, int] = Field(description="Number of jobs per state.")
    current_job: int | None
    blocked_by: int | None = Field(description="A paused or held job that keeps the queue "
                                   "from moving (resume or cancel it).")


# ---------------------------------------------------------------------------- helpers
def job_out(rec: JobRecord, live: LiveView | None) -> JobOut:
    """The API view of a job, with live progress for the running one (`live`: the
    machine thread's last published progress)."""
    done, remaining, elapsed = rec.segments_done, rec.remaining_s, rec.run_s
    copy = rec.resume.copy if rec.resume is not None else rec.copy
    ov = None
    if live is not None and live.job_id == rec.id:
        done, remaining, elapsed = live.segments_done, live.remaining_s, live.elapsed_s
        copy = live.copy
        if rec.state in (st_.RUNNING, st_.PAUSED):
            ov = OverridesOut(feed_pct=live.feed_pct, power_pct=live.power_pct)
    if rec.state == st_.QUEUED and rec.resume is None:
        remaining = rec.estimated_s
    o = JobOptions.from_json(rec.options).to_json()
    return JobOut(
        id=rec.id, name=rec.name, state=rec.state,  # type: ignore[arg-type]
        message=rec.message, question=rec.question, submitted_at=rec.submitted_at,
        started_at=rec.started_at, finished_at=rec.finished_at, options=OptionsOut(**o),
        mode=rec.mode, max_dev_mm=rec.max_dev_mm, segments_total=rec.segments_total,
        segments_done=done, copy_number=copy,
        progress=round(done / rec.segments_total, 6) if rec.segments_total else 1.0,
        estimated_s=rec.estimated_s, remaining_s=remaining, elapsed_s=round(elapsed, 3),
        underruns=rec.underruns, overrides=ov,
        resume=None if rec.resume is None else ResumeOut(
            next_segment=rec.resume.next_segment,
            position=list(rec.resume.position) if rec.resume.position else None,
            reason=rec.resume.reason, copy_number=rec.resume.copy))


def _error_response(status: int, error: str, message: str,
                    detail: dict[str, Any] | None = None,
                    headers: dict[str, str] | None = None) -> JSONResponse:
    body: dict[str, Any] = {"error": error, "message": message}
    body.update(detail or {})
    return JSONResponse(body, status_code=status, headers=headers)


_ERRORS: dict[int | str, dict[str, Any]] = {
    404: {"model": ErrorOut, "description": "No such job."},
    409: {"model": ErrorOut, "description": "The job's state does not allow this."},
}


@dataclass(frozen=True)
class _Ctx:
    """What the route handlers share."""

    store: JobStore
    worker: WorkerHandle
    jobs: StoredJobs
    cache: CompiledCache
    profile: Profile
    stopping: threading.Event
    slots: asyncio.Semaphore
    started: float
    compiler: Compiler

    def get_rec(self, job_id: int) -> JobRecord:
        """A job, or the 404 answer (also for numbers no job can have: negative, or beyond
        SQLite's 64-bit integers, which it could not even look up)."""
        if not st_.valid_job_id(job_id):
            raise ApiError(404, "not_found", f"no job {_shown(str(job_id))}: job ids are "
                           f"{st_.MIN_JOB_ID}..{st_.MAX_JOB_ID}")
        rec = self.store.get(job_id)
        if rec is None:
            raise ApiError(404, "not_found", f"no job {job_id}")
        return rec


def _repeatable(annotation: Any) -> bool:
    """Whether a parameter's type takes several values (`list[str] | None` does)."""
    origin = get_origin(annotation)
    if origin is Annotated:
        return _repeatable(get_args(annotation)[0])
    if origin is Union or origin is types.UnionType:
        return any(_repeatable(a) for a in get_args(annotation))
    return origin in (list, tuple, set, frozenset) or annotation in (list, tuple, set)


def _known_query(request: Request) -> tuple[set[str], set[str]]:
    """The query parameters the matched route declares (its signature and its OpenAPI
    extra parameters, which is where the job options are declared), and those of its
    signature that take one value only (the job options check their own repetition)."""
    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    params = list(getattr(dependant, "query_params", ()))
    names = {p.alias for p in params}
    single = {p.alias for p in params if not _repeatable(p.field_info.annotation)}
    extra = getattr(route, "openapi_extra", None) or {}
    names |= {p["name"] for p in extra.get("parameters", ())}
    return names, single


def _shown(key: str) -> str:
    """A client's parameter name as echoed in a message (long ones cut)."""
    return key if len(key) <= MAX_ECHO else key[:MAX_ECHO - 3] + "..."


async def reject_unknown_query(request: Request) -> None:
    """Every route: a query parameter it does not know is an error (`scael=2` must not be
    queued with the scale left at its default), and so is a second value for one that takes
    one (`limit=1&limit=1000` must not silently mean either)."""
    if getattr(request.scope.get("route"), "dependant", None) is None:
        return  # no route matched: the 404 answer follows
    known, single = _known_query(request)
    seen: set[str] = set()
    for key, _ in request.query_params.multi_items():
        if key not in known:
            raise unknown_option(_shown(key), known)
        if key in single and key in seen:
            raise OptionError(key, "given more than once")
        seen.add(key)


def create_app(*, store: JobStore, worker: WorkerHandle, jobs: StoredJobs, profile: Profile,
               stopping: threading.Event, compiler: Compiler,
               compile_slots: int = 2) -> FastAPI:
    """The FastAPI application over a store and a running worker; submissions compile with
    `compiler` (the daemon closes it)."""
    app = FastAPI(
        title="fivebar daemon", version=__version__,
        description="Queue, run and follow plot jobs on a five-bar plotter or laser "
        "(docs/serve.md). Uploads are the drawing's bytes as the request body "
        "(Content-Type image/svg+xml or text/x-gcode) with the plot options as query "
        "parameters. With a token configured, every request needs "
        "'Authorization: Bearer <token>'.",
        docs_url=None, redoc_url=None, dependencies=[Depends(reject_unknown_query)])
    ctx = _Ctx(store, worker, jobs, jobs.cache, profile, stopping,
               asyncio.Semaphore(compile_slots), time.monotonic(), compiler)
    _error_handlers(app)
    _status_routes(app, ctx)
    _job_routes(app, ctx)
    _submit_route(app, ctx)
    _machine_routes(app, ctx)
    from fivebar_host.server.web import add_web_routes  # web imports this module

    add_web_routes(app, ctx)
    return app


def _error_handlers(app: FastAPI) -> None:
    """Every error answers in the documented JSON format."""

    @app.exception_handler(ApiError)
    async def api_error(request: Request, exc: ApiError) -> JSONResponse:
        return _error_response(exc.status, exc.error, exc.message, exc.detail, exc.headers)

    @app.exception_handler(OptionError)
    async def option_error(request: Request, exc: OptionError) -> JSONResponse:
        return _error_response(422, "bad_option", str(exc))

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        parts = []
        for err in exc.errors():
            loc = ".".join(str(x) for x in err.get("loc", ()) if x not in ("query", "path"))
            msg = str(err.get("msg", "invalid")).removeprefix("Value error, ")
            parts.append(f"{loc}: {msg}")
        return _error_response(422, "bad_option", "; ".join(parts) or "invalid request")

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        key = {404: "not_found", 405: "method_not_allowed"}.get(exc.status_code, "http_error")
        return _error_response(exc.status_code, key, str(exc.detail),
                               headers=getattr(exc, "headers", None))


def _status_routes(app: FastAPI, ctx: _Ctx) -> None:
    status_cache: dict[str, Any] = {"at": -1.0, "body": b""}

    @app.get("/api/status", response_model=StatusOut, tags=["machine"])
    async def status() -> Response:
        """Daemon, machine (last status report) and queue counts (at most 50 ms old)."""
        # Built at most 20 times a second and answered from the event loop: clients that
        # poll hard cost the machine thread (which must keep the serial link busy) little.
        now = time.monotonic()
        if now - status_cache["at"] > STATUS_CACHE_S:
            blk = ctx.store.blocking()
            snap = ctx.worker.snapshot()
            out = StatusOut(
                version=__version__, uptime_s=round(now - ctx.started, 3),
                stopping=ctx.stopping.is_set(),
                machine=MachineOut(**machine_view(snap, ctx.profile)),
                jobs=ctx.store.counts(), current_job=snap.current,
                blocked_by=blk.id if blk is not None and blk.id != snap.current else None)
            status_cache["body"] = out.model_dump_json().encode()
            status_cache["at"] = now
        return Response(status_cache["body"], media_type="application/json")


_SUBMIT_RESPONSES: dict[int | str, dict[str, Any]] = {
    413: {"model": ErrorOut, "description": "Upload over the size limit."},
    415: {"model": ErrorOut, "description": "Wrong Content-Type."},
    422: {"model": ErrorOut, "description": "The drawing cannot be read, an option is out "
          "of range or unknown, or the job cannot run (the CLI's message); nothing was "
          "queued."},
    400: {"model": ErrorOut, "description": "Empty upload or bad name."},
    503: {"model": ErrorOut, "description": "The daemon is stopping (`stopping`), or too "
          "many submissions wait for a compilation slot (`busy`, with Retry-After); nothing "
          "was queued."}}
#: The request body and the job options (generated from their one definition).
_SUBMIT_EXTRA: dict[str, Any] = {
    "requestBody": {"required": True, "description": "The drawing's bytes.", "content": {
        "image/svg+xml": {"schema": {"type": "string"}},
        "text/x-gcode": {"schema": {"type": "string"}},
        "application/octet-stream": {"schema": {"type": "string", "format": "binary"}}}},
    "parameters": [o.openapi() for o in JOB_OPTIONS]}


def _submit_route(app: FastAPI, ctx: _Ctx) -> None:
    @app.post("/api/jobs", response_model=JobOut, status_code=201, tags=["jobs"],
              responses=_SUBMIT_RESPONSES, openapi_extra=_SUBMIT_EXTRA)
    async def submit(
        request: Request,
        name: str = Query(..., description="File name of the drawing (a label; its suffix "
                          "tells SVG from G-code). No directories."),
    ) -> JobOut:
        """Compile and check a drawing, then queue it; a job that cannot run is refused.

        The job options are the query parameters declared in `fivebar_host.options` (the
        same definitions as `fivebar plot`'s options); an unknown one is refused."""
        opts, body, compiled = await compile_request(ctx, request, name)
        if await request.is_disconnected():
            # Nobody would learn the job's id: queueing it would start a drawing nobody
            # knows was accepted (the client reports a failure).
            raise ApiError(499, "client_gone", "the client went away; nothing was queued")
        return _queue(ctx, name, opts, body, compiled)


async def compile_request(ctx: _Ctx, request: Request, name: str
                          ) -> tuple[JobOptions, bytes, Compiled]:
    """A submission's options, bytes and compiled job (the submit route): see
    `read_submission` and `run_in_slot`."""
    opts, body = await read_submission(ctx, request, name)
    compiled = await run_in_slot(ctx, request, compile_upload, body, name, opts, ctx.profile)
    return opts, body, compiled


async def read_submission(ctx: _Ctx, request: Request, name: str
                          ) -> tuple[JobOptions, bytes]:
    """A submission's options (parsed from their definitions) and bytes, content type
    checked; `ApiError` when the daemon is stopping or the request is malformed."""
    if ctx.stopping.is_set():
        raise ApiError(503, "stopping", "the daemon is stopping; submit again after it "
                       "restarts", headers={"Retry-After": "10"})
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype in SIMPLE_CONTENT_TYPES or not ctype:
        raise ApiError(415, "bad_content_type", f"send the drawing's bytes as the body "
                       f"with Content-Type image/svg+xml, text/x-gcode or "
                       f"application/octet-stream (got {ctype or 'none'!r})")
    opts = JobOptions(**parse_query(request.query_params.multi_items(), extra=("name",)))
    return opts, await request.body()


async def run_in_slot(ctx: _Ctx, request: Request, fn: Callable[..., T], *args: Any) -> T:
    """`fn(*args)` (a compilation: `compile_upload` or the dry run's) in one of the
    compilation slots, in a compiling process (`server.compiler`); `ApiError` with the
    CLI's message when it cannot run, `busy` when no slot comes free in time."""
    # Wait on the event loop (no thread held) for a compilation slot.
    try:
        await asyncio.wait_for(ctx.slots.acquire(), SUBMIT_WAIT_S)
    except TimeoutError:
        raise busy(f"no compilation slot came free within {SUBMIT_WAIT_S:.0f} s; "
                   "nothing was queued, submit again later") from None
    try:
        if await request.is_disconnected():
            raise ApiError(499, "client_gone", "the client went away; nothing was queued")
        return await ctx.compiler.run(fn, *args)
    except SubmitError as e:
        raise ApiError(e.status, e.code, str(e), e.detail) from e
    finally:
        ctx.slots.release()


def _queue(ctx: _Ctx, name: str, opts: JobOptions, body: bytes, compiled: Compiled) -> JobOut:
    """Store a compiled submission and wake the machine thread."""
    job = compiled.job
    rec = ctx.store.add_job(name=name, options=opts.to_json(), upload=body,
                            upload_sha256=compiled.upload_sha256,
                            fingerprint=compiled.fingerprint, mode=job.mode,
                            max_dev_mm=None if job.max_dev_mm != job.max_dev_mm
                            else float(job.max_dev_mm),
                            segments_total=job.n_segments,
                            estimated_s=planned_time_s(job, opts.copies_plan()))
    ctx.cache.put(rec.id, job)
    ctx.worker.notify()
    return job_out(rec, ctx.worker.snapshot().live)


def _job_routes(app: FastAPI, ctx: _Ctx) -> None:
    store, worker = ctx.store, ctx.worker

    @app.get("/api/jobs", response_model=list[JobOut], tags=["jobs"])
    def list_jobs(state: Annotated[list[str] | None, Query(
                      description="Only these states (repeatable).")] = None,
                  limit: int = Query(200, ge=1, le=1000)) -> list[JobOut]:
        """Jobs, oldest first (the most recent `limit`)."""
        state = state or []
        bad = [s for s in state if s not in st_.STATES]
        if bad:
            raise ApiError(422, "bad_option", f"unknown state(s) {bad}; states are "
                           f"{', '.join(st_.STATES)}")
        live = worker.snapshot().live
        return [job_out(r, live) for r in store.list(tuple(state) or None, limit)]

    @app.get("/api/jobs/{job_id}", response_model=JobOut, tags=["jobs"], responses=_ERRORS)
    def get_job(job_id: JobId) -> JobOut:
        """One job, with live progress while it runs."""
        return job_out(ctx.get_rec(job_id), worker.snapshot().live)

    def act(job_id: int, fn: Any) -> JobOut:
        ctx.get_rec(job_id)
        try:
            fn()
        except JobStateError as e:
            raise ApiError(409, "conflict", str(e)) from e
        except KeyError:
            raise ApiError(404, "not_found", f"no job {job_id}") from None
        return job_out(ctx.get_rec(job_id), worker.snapshot().live)

    @app.post("/api/jobs/{job_id}/pause", response_model=JobOut, status_code=202,
              tags=["jobs"], responses=_ERRORS)
    def pause(job_id: JobId) -> JobOut:
        """Hold the running job at once (laser off); it stays on the machine, paused."""
        return act(job_id, lambda: worker.pause(job_id))

    @app.post("/api/jobs/{job_id}/resume", response_model=JobOut, status_code=202,
              tags=["jobs"], responses=_ERRORS)
    def resume(job_id: JobId, confirm: bool = Query(
            False, description="Answer yes to the job's question (held jobs).")) -> JobOut:
        """Continue a paused job, or a held one from its resume point."""
        return act(job_id, lambda: worker.resume(job_id, confirm))

    @app.post("/api/jobs/{job_id}/cancel", response_model=JobOut, status_code=202,
              tags=["jobs"], responses=_ERRORS)
    def cancel(job_id: JobId) -> JobOut:
        """Cancel a job: a running one stops at once (laser off, firmware queue cleared)."""
        return act(job_id, lambda: worker.cancel(job_id))

    @app.delete("/api/jobs/{job_id}", status_code=204, tags=["jobs"], responses=_ERRORS)
    def delete(job_id: JobId) -> Response:
        """Forget a finished job (done, failed or cancelled)."""
        rec = ctx.get_rec(job_id)
        if not store.delete(job_id):
            raise ApiError(409, "conflict", f"job {job_id} is {rec.state}; only finished "
                           "jobs can be deleted (cancel it first)")
        return Response(status_code=204)


def machine_action(ctx: _Ctx, fn: Any) -> MachineOut:
    """Run a manual machine action on the machine thread; its outcome as the API answers
    it: the machine afterwards, or 409 (not now: a job runs, alarm, unknown pose, unsafe),
    504 (did not finish in time) or 502 (a link fault, whose message says what happened)."""
    try:
        fn()
    except ActionError as e:
        raise ApiError(409, "conflict", str(e)) from e
    except TimeoutError as e:
        raise ApiError(504, "timeout", "the machine did not finish in time") from e
    except Exception as e:  # a link fault: the message says what happened
        raise ApiError(502, "machine_error", str(e)) from e
    return MachineOut(**machine_view(ctx.worker.snapshot(), ctx.profile))


def _machine_routes(app: FastAPI, ctx: _Ctx) -> None:
    worker = ctx.worker

    @app.post("/api/machine/home", response_model=MachineOut, tags=["machine"],
              responses={409: {"model": ErrorOut, "description": "A job runs, or the arms' "
                               "position must be confirmed."}})
    def home(at_home: bool = Query(False, description="Without endstops: the person "
                                   "confirms the arms are at the profile's home pose.")
             ) -> MachineOut:
        """Home: `$H` with endstops, else set the position to the home pose (G92 A0 B0)."""
        return machine_action(ctx, lambda: worker.home(at_home))
