"""Submissions and the dry run: a drawing compiled and checked before it is queued (or only
reported on).

Submissions wait for one of the compilation slots on the event loop (they do not occupy a
thread while waiting, so reads stay quick under a burst of uploads); how many may wait at
once is the Guard's limit (server.security). A submission that waited `SUBMIT_WAIT_S`
without a slot, or whose client has gone, is not queued. Each compilation runs in a
compiling process (server.compiler), never in the daemon that streams.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Any, TypeVar

from fastapi import APIRouter, Query, Request

from fivebar_host.options import JOB_OPTIONS, parse_query
from fivebar_host.run.stops import planned_time_s
from fivebar_host.server.context import Context, Ctx
from fivebar_host.server.dryrun import DryRunOut, dry_run_upload
from fivebar_host.server.events import Compiling
from fivebar_host.server.jobs import (
    NAME_PATTERN,
    Compiled,
    JobOptions,
    SubmitError,
    compile_upload,
)
from fivebar_host.server.models import ApiError, ErrorOut, JobOut, busy, job_out

T = TypeVar("T")

#: Content types a web page can send without a CORS preflight; uploads must not use them.
SIMPLE_CONTENT_TYPES = frozenset({"application/x-www-form-urlencoded", "multipart/form-data",
                                  "text/plain"})
#: Longest a submission waits for a compilation slot before it is refused as busy, s.
SUBMIT_WAIT_S = 120.0

#: The error answers of a submission (and of a dry run).
SUBMIT_RESPONSES: dict[int | str, dict[str, Any]] = {
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
SUBMIT_EXTRA: dict[str, Any] = {
    "requestBody": {"required": True, "description": "The drawing's bytes.", "content": {
        "image/svg+xml": {"schema": {"type": "string", "minLength": 1}},
        "text/x-gcode": {"schema": {"type": "string", "minLength": 1}},
        "application/octet-stream": {"schema": {"type": "string", "format": "binary",
                                                "minLength": 1}}}},
    "parameters": [o.openapi() for o in JOB_OPTIONS]}

#: The `name` parameter's schema: the pattern the daemon checks (`jobs.NAME_PATTERN`).
NAME_SCHEMA: dict[str, Any] = {"pattern": NAME_PATTERN, "minLength": 1, "maxLength": 128}

router = APIRouter()


@router.post("/api/jobs", response_model=JobOut, status_code=201, tags=["jobs"],
             responses=SUBMIT_RESPONSES, openapi_extra=SUBMIT_EXTRA)
async def submit(
    ctx: Ctx,
    request: Request,
    name: str = Query(..., description="File name of the drawing (a label; its suffix "
                      "tells SVG from G-code). No directories, no leading dot, no control "
                      "or bidi characters; else 400 bad_name.",
                      json_schema_extra=NAME_SCHEMA),
) -> JobOut:
    """Compile and check a drawing, then queue it; a job that cannot run is refused.

    The job options are the query parameters declared in `fivebar_host.options` (the
    same definitions as `fivebar plot`'s options); an unknown one is refused."""
    opts, body = await read_submission(ctx, request, name)
    compiled = await run_in_slot(ctx, request, name, compile_upload, body, name, opts,
                                 ctx.profile)
    if await request.is_disconnected():
        # Nobody would learn the job's id: queueing it would start a drawing nobody
        # knows was accepted (the client reports a failure).
        raise ApiError(499, "client_gone", "the client went away; nothing was queued")
    return queue_job(ctx, name, opts, body, compiled)


@router.post("/api/dryrun", response_model=DryRunOut, tags=["jobs"],
             responses=SUBMIT_RESPONSES, openapi_extra=SUBMIT_EXTRA)
async def dryrun(ctx: Ctx, request: Request, name: str = Query(
        ..., description="File name of the drawing (as for a submission).",
        json_schema_extra=NAME_SCHEMA)) -> DryRunOut:
    """Compile and check a drawing exactly as a submission would, and answer the dry
    run (report, estimate, deviation, warnings, preview picture); nothing is queued.
    A job that cannot run is refused as a submission is (422 with the CLI's message)."""
    opts, body = await read_submission(ctx, request, name)
    return await run_in_slot(ctx, request, name, dry_run_upload, body, name, opts,
                             ctx.profile)


async def read_submission(ctx: Context, request: Request, name: str
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


async def run_in_slot(ctx: Context, request: Request, name: str, fn: Callable[..., T],
                      *args: Any) -> T:
    """`fn(*args)` (a compilation of the drawing `name`: `compile_upload` or the dry
    run's) in one of the compilation slots, in a compiling process (`server.compiler`),
    shown as `compiling` with its progress (`GET /api/status`) meanwhile; `ApiError` with
    the CLI's message when it cannot run, `busy` when no slot comes free in time."""
    entry = Compiling(name, time.monotonic(), ctx.events.poke)
    ctx.compiling[id(entry)] = entry
    ctx.events.poke()
    try:
        # Wait on the event loop (no thread held) for a compilation slot.
        try:
            await asyncio.wait_for(ctx.slots.acquire(), SUBMIT_WAIT_S)
        except TimeoutError:
            raise busy(f"no compilation slot came free within {SUBMIT_WAIT_S:.0f} s; "
                       "nothing was queued, submit again later") from None
        try:
            if await request.is_disconnected():
                raise ApiError(499, "client_gone", "the client went away; nothing was "
                               "queued")
            entry.stage = "reading"
            return await ctx.compiler.run(fn, *args, on_progress=entry.heard)
        except SubmitError as e:
            raise ApiError(e.status, e.code, str(e), e.detail) from e
        finally:
            ctx.slots.release()
    finally:
        ctx.compiling.pop(id(entry), None)
        ctx.events.poke()


def queue_job(ctx: Context, name: str, opts: JobOptions, body: bytes,
              compiled: Compiled) -> JobOut:
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
    return job_out(rec, ctx.live())
