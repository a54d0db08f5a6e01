"""A small HTTP client of the daemon's API (stdlib `urllib`), for `fivebar plot --server`.

`ServerClient` wraps each endpoint and turns error answers into `ServerError` carrying the
daemon's `error` key and message (the same message the CLI prints for a refused drawing).
`follow()` polls a job until it is over or needs a person, calling back on every change.
"""

from __future__ import annotations

import json
import os
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fivebar_host.errors import FivebarError
from fivebar_host.options import to_query

#: Job states after which nothing more happens without a person.
END_STATES = frozenset({"done", "failed", "cancelled", "held"})


class ServerError(FivebarError, RuntimeError):
    """An error answer of the daemon (or no answer): HTTP status, key and message."""

    def __init__(self, message: str, status: int = 0, error: str = "unreachable",
                 body: dict[str, Any] | None = None,
                 retry_after_s: float | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.error = error
        self.body = body or {}
        #: The answer's Retry-After (busy, stopping), s; None without one.
        self.retry_after_s = retry_after_s


#: How often `ServerClient.submit` tries again after a `busy` refusal, and the longest wait
#: between tries it accepts from Retry-After, s.
BUSY_RETRIES = 5
BUSY_WAIT_MAX_S = 30.0


def _retry_after(value: str | None) -> float | None:
    """A Retry-After header in seconds (the HTTP-date form is not used by the daemon)."""
    try:
        return max(0.0, float(value)) if value is not None else None
    except ValueError:
        return None


def default_token(state_dir: Path | None = None) -> str | None:
    """`$FIVEBAR_TOKEN`, else the local daemon's token file when readable, else None."""
    env = os.environ.get("FIVEBAR_TOKEN")
    if env:
        return env.strip()
    from fivebar_host.server.security import default_state_dir

    path = (state_dir or default_state_dir()) / "token"
    try:
        return path.read_text(encoding="ascii").strip() or None
    except (OSError, UnicodeDecodeError):
        return None


class ServerClient:
    """The daemon at `base_url` (http://host:port)."""

    def __init__(self, base_url: str, token: str | None = None, timeout_s: float = 30.0) -> None:
        parts = urllib.parse.urlsplit(base_url)
        if parts.scheme != "http" or not parts.netloc:
            raise ServerError(f"--server must be an http://HOST:PORT URL; got {base_url!r}")
        self.base = f"{parts.scheme}://{parts.netloc}{parts.path.rstrip('/')}"
        self.token = token
        self.timeout_s = timeout_s

    def request(self, method: str, path: str, *, query: dict[str, Any] | None = None,
                body: bytes | None = None, content_type: str | None = None,
                timeout_s: float | None = None) -> Any:
        """One request; the decoded JSON answer (None for 204), or ServerError."""
        url = self.base + path
        if query:
            pairs: list[tuple[str, str]] = []
            for k, v in query.items():
                if v is None:
                    continue
                for item in v if isinstance(v, list | tuple) else [v]:
                    pairs.append((k, str(item).lower() if isinstance(item, bool) else
                                  str(item)))
            if pairs:
                url += "?" + urllib.parse.urlencode(pairs)
        req = urllib.request.Request(url, data=body, method=method)
        req.add_header("Accept", "application/json")
        if content_type is not None:
            req.add_header("Content-Type", content_type)
        if self.token:
            req.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(req, timeout=timeout_s or self.timeout_s) as resp:
                data = resp.read()
        except urllib.error.HTTPError as e:
            raw = e.read()
            try:
                doc = json.loads(raw)
            except ValueError:
                doc = {}
            msg = doc.get("message") if isinstance(doc, dict) else None
            raise ServerError(msg or f"{self.base}: HTTP {e.code} {e.reason}", e.code,
                              str(doc.get("error", "http_error")) if isinstance(doc, dict)
                              else "http_error", doc if isinstance(doc, dict) else {},
                              _retry_after(e.headers.get("Retry-After"))) from None
        except (urllib.error.URLError, OSError) as e:
            reason = getattr(e, "reason", e)
            raise ServerError(f"{self.base}: no answer from the daemon ({reason}); is "
                              "`fivebar serve` running there?") from None
        return json.loads(data) if data else None

    # ------------------------------------------------------------------ endpoints
    def status(self) -> dict[str, Any]:
        """GET /api/status."""
        out: dict[str, Any] = self.request("GET", "/api/status")
        return out

    def submit(self, data: bytes, name: str, options: dict[str, Any],
               busy_retries: int = BUSY_RETRIES) -> dict[str, Any]:
        """POST /api/jobs: queue a drawing (bytes) with plot options (query parameters).

        A `busy` refusal (the daemon's upload limits; it queued nothing, so trying again
        cannot queue the drawing twice) is retried up to `busy_retries` times after the
        answer's Retry-After."""
        ctype = "image/svg+xml" if name.lower().endswith(".svg") else "text/x-gcode"
        attempt = 0
        while True:
            try:
                out: dict[str, Any] = self.request(
                    "POST", "/api/jobs", query={"name": name, **options}, body=data,
                    content_type=ctype, timeout_s=300.0)
                return out
            except ServerError as e:
                if e.error != "busy" or attempt >= busy_retries:
                    raise
                attempt += 1
                time.sleep(min(BUSY_WAIT_MAX_S, e.retry_after_s or 1.0))

    def job(self, job_id: int) -> dict[str, Any]:
        """GET /api/jobs/{id}."""
        out: dict[str, Any] = self.request("GET", f"/api/jobs/{job_id}")
        return out

    def jobs(self) -> list[dict[str, Any]]:
        """GET /api/jobs."""
        out: list[dict[str, Any]] = self.request("GET", "/api/jobs")
        return out

    def pause(self, job_id: int) -> dict[str, Any]:
        """POST /api/jobs/{id}/pause."""
        out: dict[str, Any] = self.request("POST", f"/api/jobs/{job_id}/pause")
        return out

    def resume(self, job_id: int, confirm: bool = False) -> dict[str, Any]:
        """POST /api/jobs/{id}/resume."""
        out: dict[str, Any] = self.request("POST", f"/api/jobs/{job_id}/resume",
                                           query={"confirm": confirm})
        return out

    def cancel(self, job_id: int) -> dict[str, Any]:
        """POST /api/jobs/{id}/cancel."""
        out: dict[str, Any] = self.request("POST", f"/api/jobs/{job_id}/cancel")
        return out

    def home(self, at_home: bool = False) -> dict[str, Any]:
        """POST /api/machine/home."""
        out: dict[str, Any] = self.request("POST", "/api/machine/home",
                                           query={"at_home": at_home}, timeout_s=200.0)
        return out


def plot_options(**values: Any) -> dict[str, Any]:
    """The query parameters of a submission from job option values keyed by their field
    names (`laser=True`, `tolerance_mm=0.1`, `origin_mm=(10, 95)`, …), generated from their
    one definition in `fivebar_host.options`; an unknown name or a value out of range is an
    OptionError before anything is sent."""
    return dict(to_query(values))


def follow(client: ServerClient, job_id: int, on_update: Callable[[dict[str, Any]], None],
           *, poll_s: float = 0.25, should_stop: Callable[[], bool] | None = None,
           max_s: float | None = None) -> dict[str, Any]:
    """Poll a job until it is done, failed, cancelled or held (or `should_stop()`).

    Calls `on_update(job)` after every poll; returns the last job seen. Transient errors
    (the daemon restarting) are retried for up to 30 s.
    """
    t0 = time.monotonic()
    failing_since: float | None = None
    last: dict[str, Any] = {}
    while True:
        try:
            last = client.job(job_id)
            failing_since = None
        except ServerError as e:
            if e.status not in (0, 502, 503, 504):
                raise
            failing_since = failing_since or time.monotonic()
            if time.monotonic() - failing_since > 30.0:
                raise
            time.sleep(1.0)
            continue
        on_update(last)
        if last.get("state") in END_STATES:
            return last
        if should_stop is not None and should_stop():
            return last
        if max_s is not None and time.monotonic() - t0 > max_s:
            return last
        time.sleep(poll_s)
