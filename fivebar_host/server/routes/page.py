"""The web page's routes: the page itself, its files, the job options' definitions and the
event stream.

The page (`GET /`, `GET /static/…`) is plain HTML, CSS and JavaScript shipped in the package
(`fivebar_host/server/static/`, package data; found through `importlib.resources`, so it
works from a checkout and from an installed wheel alike). It loads nothing from elsewhere;
its Content-Security-Policy says so. These files hold nothing secret and are served without
the token (`security.Policy.public_paths`): the page asks for the token and sends it in the
`Authorization` header of every API request, never in a URL.

The page builds its upload form from `GET /api/options` — the job options' one definition in
`fivebar_host.options`, the same that makes the CLI's flags and the API's query parameters —
and checks a drawing with `POST /api/dryrun` (server.routes.submit) before queueing it.
Live progress comes as server-sent events (`GET /api/events`, server.events); the rest of
what the page does is the API's (server.routes.jobs, server.routes.machine).
"""

from __future__ import annotations

import functools
import importlib.resources
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import Response, StreamingResponse

from fivebar_host.config import Profile
from fivebar_host.options import JOB_OPTIONS, Option
from fivebar_host.server.context import Ctx
from fivebar_host.server.events import JOBS_SENT
from fivebar_host.server.models import ApiError, job_out
from fivebar_host.server.requests import WorkerHandle
from fivebar_host.server.store import JobStore

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

router = APIRouter()


@functools.cache
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
            "label": o.label or o.query, "page_help": o.web_help or o.help,
            "example": o.example, "units": o.unit in ("mm", "mm/s") or o.percent,
            "description": o.describe(), "unit": o.unit, "default": o.default,
            "min": o.lo, "max": o.hi, "min_exclusive": o.lo_open, "range": o.range_text(),
            "choices": list(o.choices), "repeat": o.repeat, "flag": o.flag}


def features(profile: Profile) -> dict[str, bool]:
    """What the machine has, so the page shows only the controls that work.

    `pen`: a pen servo (pen up/down); shown once the profile describes one (a `pen`
    section) — the page's pen controls call `POST /api/machine/pen`."""
    return {"endstops": bool(profile.motors.endstops),
            "pen": getattr(profile, "pen", None) is not None, "motors_off": True, "jog": True}


def jobs_event(store: JobStore, worker: WorkerHandle) -> dict[str, Any]:
    """The `jobs` event: recent jobs (oldest first) and the queue's run order."""
    recs = store.list(None, JOBS_SENT)
    live = worker.snapshot().live
    return {"queue": store.queue_order(),
            "jobs": [job_out(r, live).model_dump() for r in recs]}


@router.get("/", include_in_schema=False)
def page() -> Response:
    """The web page."""
    body, media = static_files()["index.html"]
    return Response(body, media_type=media, headers=PAGE_HEADERS)


@router.get("/static/{name}", include_in_schema=False)
def static(name: str) -> Response:
    """One of the page's files (scripts, style sheet, pictures); only those shipped."""
    files = static_files()
    if name not in files:
        raise ApiError(404, "not_found", f"no file {name[:64]!r}")
    body, media = files[name]
    return Response(body, media_type=media, headers=PAGE_HEADERS)


@router.get("/api/options", tags=["web"])
def options(ctx: Ctx) -> dict[str, Any]:
    """The job options' definitions (name, type, unit, range, help) and what the
    machine has: the web page builds its upload form from them."""
    geo = ctx.profile.geometry
    return {"options": [option_schema(o) for o in JOB_OPTIONS],
            "features": features(ctx.profile),
            "geometry": {"a1": geo.a1, "b1": geo.b1, "a2": geo.a2, "b2": geo.b2,
                         "w": geo.w}}


@router.get("/api/events", tags=["web"], response_class=StreamingResponse)
async def events(ctx: Ctx, request: Request) -> StreamingResponse:
    """Server-sent events (`text/event-stream`): `status` (machine, pose, live
    progress), `trail` (the running job's drawn path) and `jobs` (queue and history),
    pushed when they change (docs/serve.md)."""
    return StreamingResponse(ctx.events.stream(request.is_disconnected),
                             media_type="text/event-stream",
                             headers={"Cache-Control": "no-store",
                                      "X-Accel-Buffering": "no"})
