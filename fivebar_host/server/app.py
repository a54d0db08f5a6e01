"""The daemon's HTTP + JSON API (FastAPI): the application, its error format, its checks.

`create_app` builds the application over the daemon's services: one `Context`
(server.context), kept in `app.state` and handed to every route as the dependency
`ctx: Ctx`, and the routers of server.routes (status, jobs, submissions, machine, web page).
FastAPI derives the OpenAPI description (`GET /openapi.json`) from the routes' signatures and
the models (server.models); docs/serve.md explains the API in prose.

Every error answers with `{"error": <stable key>, "message": <what and why>}` (plus details
for refused drawings), whatever produced it: a refused drawing, a bad option, an unknown
job, a state conflict, a missing token, an oversized body, a malformed query string or a
full daemon (the last four come from `security.Guard`). Every path and query value is
checked before it reaches the database: a job id is an integer (else 422), and one no job
can have — negative, or beyond SQLite's 64-bit range — is simply not found (404); a
parameter that takes one value is refused when repeated, and one the route does not know is
refused (`reject_unknown_query`).

Handlers never touch the serial port: they read the database and the machine thread's
published snapshot, and hand pause/resume/cancel/home and the other actions to the machine
thread as requests (server.requests).
"""

from __future__ import annotations

import asyncio
import functools
import threading
import time
import types
from collections.abc import Iterable, Iterator
from typing import Annotated, Any, Union, get_args, get_origin

from fastapi import Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from fivebar_host import __version__
from fivebar_host.config import Profile
from fivebar_host.errors import OptionError, bounded
from fivebar_host.options import unknown_option
from fivebar_host.server.compiler import Compiler
from fivebar_host.server.context import Context
from fivebar_host.server.events import EventHub
from fivebar_host.server.models import ApiError, shown
from fivebar_host.server.requests import WorkerHandle
from fivebar_host.server.routes import jobs as job_routes
from fivebar_host.server.routes import machine, page, status, submit
from fivebar_host.server.store import JobStore
from fivebar_host.server.stored import StoredJobs


def _error_response(status: int, error: str, message: str,
                    detail: dict[str, Any] | None = None,
                    headers: dict[str, str] | None = None) -> JSONResponse:
    body: dict[str, Any] = {"error": error, "message": bounded(message)}
    body.update(detail or {})
    return JSONResponse(body, status_code=status, headers=headers)


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
            raise unknown_option(shown(key), known)
        if key in single and key in seen:
            raise OptionError(key, "given more than once")
        seen.add(key)


def create_app(*, store: JobStore, worker: WorkerHandle, jobs: StoredJobs, profile: Profile,
               stopping: threading.Event, compiler: Compiler,
               compile_slots: int = 2) -> FastAPI:
    """The FastAPI application over a store and a running machine thread's handle;
    submissions compile with `compiler` (the daemon closes it)."""
    app = FastAPI(
        title="fivebar daemon", version=__version__,
        description="Queue, run and follow plot jobs on a five-bar plotter or laser "
        "(docs/serve.md). Uploads are the drawing's bytes as the request body "
        "(Content-Type image/svg+xml or text/x-gcode) with the plot options as query "
        "parameters. With a token configured, every request needs "
        "'Authorization: Bearer <token>'.",
        docs_url=None, redoc_url=None, dependencies=[Depends(reject_unknown_query)])
    hub = EventHub(worker, store, jobs.cache, profile, stopping,
                   functools.partial(page.jobs_event, store, worker))
    app.state.context = Context(store, worker, jobs, profile, stopping,
                                asyncio.Semaphore(compile_slots), time.monotonic(), compiler,
                                hub)
    _error_handlers(app)
    for module in (status, job_routes, submit, machine, page):
        app.include_router(module.router)
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
        headers = getattr(exc, "headers", None)
        if exc.status_code == 405:
            headers = {**(headers or {}), "Allow": ", ".join(allowed_methods(request))}
        return _error_response(exc.status_code, key, str(exc.detail), headers=headers)


def allowed_methods(request: Request) -> list[str]:
    """Every method some route takes at this path (Starlette's 405 names only the first
    matching route's: `Allow: GET` for a path that also takes DELETE)."""
    path = request.scope.get("path", "")
    methods: set[str] = set()
    for route in _all_routes(request.app.routes):
        regex = getattr(route, "path_regex", None)
        if regex is not None and regex.match(path):
            methods |= set(getattr(route, "methods", None) or ())
    return sorted(methods)


def _all_routes(routes: Iterable[Any]) -> Iterator[Any]:
    """The routes, those of included routers too (FastAPI may wrap an included router)."""
    for route in routes:
        inner = getattr(getattr(route, "original_router", None), "routes", None)
        if inner is not None:
            yield from _all_routes(inner)
        else:
            yield route
