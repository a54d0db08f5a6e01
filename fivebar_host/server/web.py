"""The web page's routes: the page itself, option definitions, dry run, events, queue order,
the running job's live overrides, and the machine panel's actions (jog, motors off, clear
alarm).

The page (`GET /`, `GET /static/…`) is plain HTML, CSS and JavaScript shipped in the package
(`fivebar_host/server/static/`, package data; found through `importlib.resources`, so it
works from a checkout and from an installed wheel alike). It loads nothing from elsewhere;
its Content-Security-Policy says so. These files hold nothing secret and are served without
the token (`security.Policy.public_paths`): the page asks for the token and sends it in the
`Authorization` header of every API request, never in a URL.

The page builds its upload form from `GET /api/options` — the job options' one definition in
`fivebar_host.options`, the same that makes the CLI's flags and the API's query parameters —
and checks a drawing with `POST /api/dryrun` before queueing it: the same compilation as a
submission, then the CLI's dry-run report lines (`dryrun.report_lines`) and preview picture
(`report.preview.draw_preview`, PNG), nothing queued. Live progress comes as server-sent
events (`GET /api/events`, server.events).
"""

from __future__ import annotations

import base64
import importlib.resources
import tempfile
import threading
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Query, Request
from fastapi.responses import Response, StreamingResponse
from pydantic import BaseModel, Field

from fivebar_host.compile import Job, nbar_opinion
from fivebar_host.config import Profile
from fivebar_host.options import JOB_OPTIONS, Option
from fivebar_host.report.text.dryrun import format_duration, report_lines
from fivebar_host.run.overrides import FEED_MAX_PCT, FEED_MIN_PCT, POWER_MAX_PCT, POWER_MIN_PCT
from fivebar_host.run.stops import Copies, planned_time_s
from fivebar_host.server import store as st_
from fivebar_host.server.app import (
    _SUBMIT_EXTRA,
    _SUBMIT_RESPONSES,
    ApiError,
    ErrorOut,
    JobId,
    JobOut,
    MachineOut,
    _Ctx,
    job_out,
    machine_action,
    read_submission,
    run_in_slot,
)
from fivebar_host.server.events import JOBS_SENT, EventHub
from fivebar_host.server.jobs import JobOptions, SubmitError, compile_upload
from fivebar_host.server.state import JobStateError

#: The page's files: name → media type. Only these are served.
STATIC_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
                ".css": "text/css; charset=utf-8", ".svg": "image/svg+xml"}
#: Where they are, inside the package.
STATIC_PACKAGE = "fivebar_host.server"
#: What the page may load and where it may connect: only this daemon.
PAGE_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; "
    "style-src 'self'; script-src 'self'; connect-src 'self'; frame-ancestors 'none'; "
    "base-uri 'none'; form-action 'none'",
    "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-cache"}
#: Resolution of the dry run's preview picture (the CLI's file is 130 dpi).
PREVIEW_DPI = 80
#: Longest planned path sent to the page's live view, points.
PATH_POINTS = 4000
#: Largest jog: pen move per axis, mm; motor move, steps.
MAX_JOG_MM = 100.0
MAX_JOG_STEPS = 20000

#: matplotlib's pyplot keeps global state: one preview is drawn at a time.
_PREVIEW_LOCK = threading.Lock()


def static_files() -> dict[str, tuple[bytes, str]]:
    """The page's files (name → bytes, media type), read once from the package."""
    root = importlib.resources.files(STATIC_PACKAGE).joinpath("static")
    out: dict[str, tuple[bytes, str]] = {}
    for entry in root.iterdir():
        suffix = Path(entry.name).suffix
        if entry.is_file() and suffix in STATIC_TYPES:
            out[entry.name] = (entry.read_bytes(), STATIC_TYPES[suffix])
    return out


def option_schema(o: Option) -> dict[str, Any]:
    """One job option as the page needs it to build and check its form field."""
    return {"name": o.name, "query": o.query, "kind": o.kind, "help": o.help,
            "description": o.describe(), "unit": o.unit, "default": o.default,
            "min": o.lo, "max": o.hi, "min_exclusive": o.lo_open, "range": o.range_text(),
            "choices": list(o.choices), "repeat": o.repeat, "flag": o.flag}


def features(profile: Profile) -> dict[str, bool]:
    """What the machine has, so the page shows only the controls that work.

    `pen`: a pen servo (pen up/down); shown once the profile describes one (a `pen`
    section) — the page's pen controls call `POST /api/machine/pen`."""
    return {"endstops": bool(profile.motors.endstops),
            "pen": getattr(profile, "pen", None) is not None, "motors_off": True, "jog": True}


class DryRunOut(BaseModel):
    """A checked drawing, not queued."""

    name: str
    report: list[str] = Field(description="The dry-run report, line for line as "
                              "`fivebar plot --dry-run` prints it.")
    estimated_s: float
    estimate: str = Field(description="The estimate for people (\"4 min 5 s\").")
    max_dev_mm: float | None
    tolerance_mm: float
    segments: int
    paths: int
    mode: str
    warnings: list[str] = Field(description="The report's notes.")
    preview_png: str = Field(description="The preview picture, PNG, base64.")


def _dry_run(job: Job, profile: Profile, laser: bool,
             copies: Copies | None = None) -> tuple[list[str], bytes]:
    """The CLI's report lines and preview picture (PNG bytes) of a compiled job (`copies`:
    the run's copies and page delay, in the time line)."""
    from fivebar_host.report.preview import draw_preview  # matplotlib only in report/

    lines = report_lines(job, nbar_opinion(job, profile), laser=laser, profile=profile,
                         copies=copies)
    with tempfile.TemporaryDirectory(prefix="fivebar-preview-") as d, _PREVIEW_LOCK:
        out = draw_preview(job, profile, Path(d) / "preview.png", dpi=PREVIEW_DPI)
        return lines, out.read_bytes()


def dry_run_upload(data: bytes, name: str, opts: JobOptions, profile: Profile) -> DryRunOut:
    """Compile a submission as `compile_upload` does and answer its dry run; all of it in
    one compiling process (`server.compiler`), so neither the job nor the preview's
    drawing runs in the daemon that streams."""
    job = compile_upload(data, name, opts, profile).job
    copies = opts.copies_plan()
    lines, png = _dry_run(job, profile, opts.laser, copies)
    dev = None if job.max_dev_mm != job.max_dev_mm else float(job.max_dev_mm)
    total_s = planned_time_s(job, copies)
    return DryRunOut(name=name, report=lines, estimated_s=round(total_s, 3),
                     estimate=format_duration(total_s), max_dev_mm=dev,
                     tolerance_mm=job.tolerance_mm, segments=job.n_segments,
                     paths=job.n_paths, mode=job.mode, warnings=list(job.notes),
                     preview_png=base64.b64encode(png).decode("ascii"))


def add_web_routes(app: FastAPI, ctx: _Ctx) -> None:
    """Add the page, the dry run, events, queue order and the machine panel's actions."""
    _page_routes(app, ctx)
    _dryrun_route(app, ctx)
    _queue_routes(app, ctx)
    _override_route(app, ctx)
    _manual_routes(app, ctx)


def _page_routes(app: FastAPI, ctx: _Ctx) -> None:
    files = static_files()

    @app.get("/", include_in_schema=False)
    def page() -> Response:
        body, media = files["index.html"]
        return Response(body, media_type=media, headers=PAGE_HEADERS)

    @app.get("/static/{name}", include_in_schema=False)
    def static(name: str) -> Response:
        if name not in files:
            raise ApiError(404, "not_found", f"no file {name[:64]!r}")
        body, media = files[name]
        return Response(body, media_type=media, headers=PAGE_HEADERS)

    @app.get("/api/options", tags=["web"])
    def options() -> dict[str, Any]:
        """The job options' definitions (name, type, unit, range, help) and what the
        machine has: the web page builds its upload form from them."""
        geo = ctx.profile.geometry
        return {"options": [option_schema(o) for o in JOB_OPTIONS],
                "features": features(ctx.profile),
                "geometry": {"a1": geo.a1, "b1": geo.b1, "a2": geo.a2, "b2": geo.b2,
                             "w": geo.w}}


def _dryrun_route(app: FastAPI, ctx: _Ctx) -> None:
    @app.post("/api/dryrun", response_model=DryRunOut, tags=["jobs"],
              responses=_SUBMIT_RESPONSES, openapi_extra=_SUBMIT_EXTRA)
    async def dryrun(request: Request, name: str = Query(
            ..., description="File name of the drawing (as for a submission).")) -> DryRunOut:
        """Compile and check a drawing exactly as a submission would, and answer the dry
        run (report, estimate, deviation, warnings, preview picture); nothing is queued.
        A job that cannot run is refused as a submission is (422 with the CLI's message)."""
        opts, body = await read_submission(ctx, request, name)
        return await run_in_slot(ctx, request, dry_run_upload, body, name, opts, ctx.profile)


def _jobs_view(ctx: _Ctx) -> dict[str, Any]:
    """The `jobs` event: recent jobs (oldest first) and the queue's run order."""
    recs = ctx.store.list(None, JOBS_SENT)
    live = ctx.worker.snapshot().live
    return {"queue": ctx.store.queue_order(),
            "jobs": [job_out(r, live).model_dump() for r in recs]}


def _queue_routes(app: FastAPI, ctx: _Ctx) -> None:
    hub = EventHub(ctx.worker, ctx.store, ctx.cache, ctx.profile, ctx.stopping,
                   lambda: _jobs_view(ctx))

    @app.get("/api/events", tags=["web"], response_class=StreamingResponse)
    async def events(request: Request) -> StreamingResponse:
        """Server-sent events (`text/event-stream`): `status` (machine, pose, live
        progress), `trail` (the running job's drawn path) and `jobs` (queue and history),
        pushed when they change (docs/serve.md)."""
        return StreamingResponse(hub.stream(request.is_disconnected),
                                 media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store",
                                          "X-Accel-Buffering": "no"})

    @app.post("/api/jobs/{job_id}/move", tags=["jobs"],
              responses={404: {"model": ErrorOut}, 409: {"model": ErrorOut}})
    def move(job_id: JobId, index: int = Query(
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

    @app.get("/api/jobs/{job_id}/path", tags=["jobs"],
              responses={404: {"model": ErrorOut}, 409: {"model": ErrorOut}})
    async def path(job_id: JobId, request: Request) -> dict[str, Any]:
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
                compiled = await run_in_slot(ctx, request, compile_upload,
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


def _override_route(app: FastAPI, ctx: _Ctx) -> None:
    @app.post("/api/jobs/{job_id}/overrides", response_model=JobOut, tags=["jobs"],
              responses={404: {"model": ErrorOut, "description": "No such job."},
                         409: {"model": ErrorOut, "description": "The job is not running."}})
    def overrides(job_id: JobId,
                  feed: int | None = Query(None, ge=FEED_MIN_PCT, le=FEED_MAX_PCT,
                                           description="Feed, % of the planned speed "
                                           "(slower only)."),
                  power: int | None = Query(None, ge=POWER_MIN_PCT, le=POWER_MAX_PCT,
                                            description="Laser power, % of the planned "
                                            "power.")) -> JobOut:
        """Set the running (or paused) job's live feed and/or laser-power override; the job
        with the overrides now in force. Lines already written to the controller (about 15
        segments) keep their values; a power change applies from the next line written, a
        feed change from the next point where the plan comes to rest (docs/serve.md)."""
        if feed is None and power is None:
            raise ApiError(422, "bad_option", "give feed and/or power (percent)")
        rec = ctx.get_rec(job_id)
        try:
            ctx.worker.set_overrides(job_id, feed, power)
        except JobStateError as e:
            raise ApiError(409, "conflict", f"job {job_id} is {rec.state}: overrides apply "
                           "to the running job only") from e
        return job_out(ctx.get_rec(job_id), ctx.worker.snapshot().live)


def _manual_routes(app: FastAPI, ctx: _Ctx) -> None:
    worker = ctx.worker
    responses: dict[int | str, dict[str, Any]] = {
        409: {"model": ErrorOut, "description": "A job runs, the machine is not connected "
              "or in alarm, the position is unknown, or the move is not safe."}}

    def done(fn: Any) -> MachineOut:
        return machine_action(ctx, fn)

    @app.post("/api/machine/jog", response_model=MachineOut, tags=["machine"],
              responses=responses)
    def jog(motor: str | None = Query(None, pattern="^[AB]$", description="Motor A or B "
                                      "(with steps); else the pen moves by dx, dy."),
            steps: int = Query(0, ge=-MAX_JOG_STEPS, le=MAX_JOG_STEPS,
                               description="Motor steps (with motor)."),
            dx: float = Query(0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, description="Pen move, mm."),
            dy: float = Query(0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, description="Pen move, mm.")
            ) -> MachineOut:
        """Jog as `fivebar jog` (laser off): a motor by steps, or the pen by dx, dy mm (the
        pen move is checked and needs a known position)."""
        if motor is not None and (dx or dy):
            raise ApiError(422, "bad_option", "give motor with steps, or dx/dy, not both")
        return done(lambda: worker.jog(motor=motor, steps=steps) if motor is not None
                    else worker.jog(dxy_mm=(dx, dy)))

    @app.post("/api/machine/motors_off", response_model=MachineOut, tags=["machine"],
              responses=responses)
    def motors_off() -> MachineOut:
        """Switch the motors off (M18): the arms move by hand; home before the next job."""
        return done(worker.motors_off)

    @app.post("/api/machine/pen", response_model=MachineOut, tags=["machine"],
              responses=responses)
    def pen(down: bool = Query(..., description="true: lower the pen; false: raise it.")
            ) -> MachineOut:
        """Lower or raise the servo pen (pen machines only; the machine must be idle)."""
        return done(lambda: worker.pen(down))

    @app.post("/api/machine/clear_alarm", response_model=MachineOut, tags=["machine"],
              responses=responses)
    def clear_alarm() -> MachineOut:
        """Clear the machine's alarm (`$X`, position kept)."""
        return done(worker.clear_alarm)
