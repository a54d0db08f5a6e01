"""The queue and history: list, one job, pause, resume, cancel, delete, reorder, the planned
path and the live overrides.

Reads come from the database and the machine thread's published live progress; pause,
resume, cancel and overrides are requests to the machine thread (server.requests), which
answers once it has carried them out, or refuses (409 conflict, 404 for a job it does not
know).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

from fivebar_host.run.overrides import FEED_MAX_PCT, FEED_MIN_PCT, POWER_MAX_PCT, POWER_MIN_PCT
from fivebar_host.server import store as st_
from fivebar_host.server.context import Context, Ctx
from fivebar_host.server.jobs import JobOptions, SubmitError, compile_upload
from fivebar_host.server.models import ApiError, ErrorOut, JobId, JobOut, job_out
from fivebar_host.server.routes.submit import run_in_slot
from fivebar_host.server.state import JobStateError

#: Longest planned path sent to the page's live view, points.
PATH_POINTS = 4000

#: The error answers of a route about one job.
JOB_ERRORS: dict[int | str, dict[str, Any]] = {
    404: {"model": ErrorOut, "description": "No such job."},
    409: {"model": ErrorOut, "description": "The job's state does not allow this."},
}

router = APIRouter()


@router.get("/api/jobs", response_model=list[JobOut], tags=["jobs"])
def list_jobs(ctx: Ctx,
              state: Annotated[list[str] | None, Query(
                  description="Only these states (repeatable).",
                  json_schema_extra={"items": {"type": "string",
                                               "enum": list(st_.STATES)}})] = None,
              limit: int = Query(200, ge=1, le=1000)) -> list[JobOut]:
    """Jobs, oldest first (the most recent `limit`)."""
    state = state or []
    bad = [s for s in state if s not in st_.STATES]
    if bad:
        raise ApiError(422, "bad_option", f"unknown state(s) {bad}; states are "
                       f"{', '.join(st_.STATES)}")
    live = ctx.live()
    return [job_out(r, live) for r in ctx.store.list(tuple(state) or None, limit)]


@router.get("/api/jobs/{job_id}", response_model=JobOut, tags=["jobs"],
            responses=JOB_ERRORS)
def get_job(ctx: Ctx, job_id: JobId) -> JobOut:
    """One job, with live progress while it runs."""
    return job_out(ctx.get_rec(job_id), ctx.live())


def _request(ctx: Context, job_id: int, ask: Callable[[], Any]) -> JobOut:
    """Ask the machine thread about a job; the job afterwards, or the error answer."""
    ctx.get_rec(job_id)
    try:
        ask()
    except JobStateError as e:
        raise ApiError(409, "conflict", str(e)) from e
    except KeyError:
        raise ApiError(404, "not_found", f"no job {job_id}") from None
    except TimeoutError as e:
        raise ApiError(504, "timeout", "the machine thread did not answer in time") from e
    return job_out(ctx.get_rec(job_id), ctx.live())


@router.post("/api/jobs/{job_id}/pause", response_model=JobOut, status_code=202,
             tags=["jobs"], responses=JOB_ERRORS)
def pause(ctx: Ctx, job_id: JobId) -> JobOut:
    """Hold the running job at once (laser off); it stays on the machine, paused."""
    return _request(ctx, job_id, lambda: ctx.worker.pause(job_id))


@router.post("/api/jobs/{job_id}/resume", response_model=JobOut, status_code=202,
             tags=["jobs"], responses=JOB_ERRORS)
def resume(ctx: Ctx, job_id: JobId, confirm: bool = Query(
        False, description="Answer yes to the job's question (held jobs).")) -> JobOut:
    """Continue a paused job, or a held one from its resume point."""
    return _request(ctx, job_id, lambda: ctx.worker.resume(job_id, confirm))


@router.post("/api/jobs/{job_id}/cancel", response_model=JobOut, status_code=202,
             tags=["jobs"], responses=JOB_ERRORS)
def cancel(ctx: Ctx, job_id: JobId) -> JobOut:
    """Cancel a job: a running one stops at once (laser off, firmware queue cleared)."""
    return _request(ctx, job_id, lambda: ctx.worker.cancel(job_id))


@router.delete("/api/jobs/{job_id}", status_code=204, tags=["jobs"], responses=JOB_ERRORS)
def delete(ctx: Ctx, job_id: JobId) -> Response:
    """Forget a finished job (done, failed or cancelled)."""
    rec = ctx.get_rec(job_id)
    if not ctx.store.delete(job_id):
        raise ApiError(409, "conflict", f"job {job_id} is {rec.state}; only finished "
                       "jobs can be deleted (cancel it first)")
    return Response(status_code=204)


@router.post("/api/jobs/{job_id}/move", tags=["jobs"],
             responses={404: {"model": ErrorOut}, 409: {"model": ErrorOut}})
def move(ctx: Ctx, job_id: JobId, index: int = Query(
        ..., ge=0, le=1_000_000, description="New place among the waiting jobs "
        "(0 = next to run).")) -> dict[str, list[int]]:
    """Reorder the queue: move a queued job that has not started yet; the new order."""
    rec = ctx.get_rec(job_id)
    order = ctx.store.move(job_id, index)
    if order is None:
        raise ApiError(409, "conflict", f"job {job_id} is {rec.state}"
                       + (" and has started before" if rec.state == st_.QUEUED else "")
                       + ": only a waiting job can be moved")
    ctx.worker.notify()
    return {"queue": order}


@router.get("/api/jobs/{job_id}/path", tags=["jobs"],
            responses={404: {"model": ErrorOut}, 409: {"model": ErrorOut}})
async def path(ctx: Ctx, job_id: JobId, request: Request) -> dict[str, Any]:
    """The planned path of a job that is not over (machine mm, at most 4000 points,
    each with whether the segment ending there draws): the live view's background.
    A job not in the cache (after a restart) is compiled again as a submission is, in
    a compilation slot and a compiling process: never in the daemon that streams."""
    rec = ctx.get_rec(job_id)
    if rec.state in st_.FINAL_STATES:
        raise ApiError(409, "conflict", f"job {job_id} is {rec.state}: its drawing is "
                       "no longer stored")
    job = ctx.cache.get(rec.id)
    try:
        if job is None:
            compiled = await run_in_slot(ctx, request, rec.name, compile_upload,
                                         ctx.jobs.upload(rec), rec.name,
                                         JobOptions.from_json(rec.options), ctx.profile)
            job = ctx.jobs.adopt(rec, compiled)
    except SubmitError as e:
        raise ApiError(409, "conflict", str(e)) from e
    step = max(1, -(-job.n_segments // PATH_POINTS))
    pts = job.points_mm[::step]
    draw = [True, *(bool(d) for d in job.draw[step - 1::step])]
    return {"job_id": job_id, "points": [[round(float(x), 2), round(float(y), 2), int(d)]
                                         for (x, y), d in zip(pts, draw, strict=False)]}


@router.post("/api/jobs/{job_id}/overrides", response_model=JobOut, tags=["jobs"],
             responses={404: {"model": ErrorOut, "description": "No such job."},
                        409: {"model": ErrorOut, "description": "The job is not running."}})
def overrides(ctx: Ctx, job_id: JobId,
              feed: int | None = Query(None, ge=FEED_MIN_PCT, le=FEED_MAX_PCT,
                                       description="Feed, % of the planned speed "
                                       "(slower only)."),
              power: int | None = Query(None, ge=POWER_MIN_PCT, le=POWER_MAX_PCT,
                                        description="Laser power, % of the planned "
                                        "power.")) -> JobOut:
    """Set the running (or paused) job's live feed and/or laser-power override; the job
    with the overrides now in force (with neither, nothing changes). Lines already written
    to the controller (about 15 segments) keep their values; a power change applies from
    the next line written, a feed change from the next point where the plan comes to rest
    (docs/serve.md)."""
    rec = ctx.get_rec(job_id)
    try:
        ctx.worker.set_overrides(job_id, feed, power)
    except JobStateError as e:
        raise ApiError(409, "conflict", f"job {job_id} is {rec.state}: overrides apply "
                       "to the running job only") from e
    except TimeoutError as e:
        raise ApiError(504, "timeout", "the machine thread did not answer in time") from e
    return job_out(ctx.get_rec(job_id), ctx.live())
