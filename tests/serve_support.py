"""Helpers of the daemon tests that send requests the client library never would: in-process
daemons on 127.0.0.1 with the mock machine, and raw HTTP requests that keep the status,
headers and body exactly as answered."""

from __future__ import annotations

import http.client
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fivebar_host.devices import mock
from fivebar_host.server.daemon import Daemon, ServeConfig


@contextmanager
def running_daemon(state_dir: Path, machine: str, speed: float = 10.0,
                   **kw: Any) -> Iterator[Daemon]:
    """A daemon on 127.0.0.1 (OS-chosen port) over the mock machine `machine` running
    `speed` times real time; stopped and the mock forgotten afterwards."""
    kw.setdefault("banner_timeout_s", 1.0)
    d = Daemon(ServeConfig(port_url=f"fivebar-mock://?speed={speed:g}&machine={machine}",
                           listen="127.0.0.1:0", state_dir=state_dir, **kw))
    d.start()
    try:
        yield d
    finally:
        d.stop(hurry=True, timeout_s=15.0)
        mock.forget_machines()


@dataclass(frozen=True)
class Raw:
    """An answer as received."""

    status: int
    headers: dict[str, str]  # lower-case names
    body: bytes


def send(url: str, method: str, target: str, body: bytes | None = None,
         headers: dict[str, str] | None = None, timeout_s: float = 30.0) -> Raw:
    """One request with the request target sent verbatim (no quoting, no normalising)."""
    host, port = url.removeprefix("http://").rsplit(":", 1)
    conn = http.client.HTTPConnection(host.strip("[]"), int(port), timeout=timeout_s)
    try:
        conn.putrequest(method, target, skip_accept_encoding=True)
        for k, v in (headers or {}).items():
            conn.putheader(k, v)
        if body is not None or method in ("POST", "PUT"):
            conn.putheader("Content-Length", str(len(body or b"")))
        conn.endheaders(body)
        resp = conn.getresponse()
        return Raw(resp.status, {k.lower(): v for k, v in resp.getheaders()}, resp.read())
    finally:
        conn.close()


def wait_for(pred: Callable[[], Any], timeout_s: float = 20.0, what: str = "") -> Any:
    """Poll `pred` until it returns something true (returned), or fail after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what or pred}")
