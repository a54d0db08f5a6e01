"""Slow clients cannot deny service: uploads that dribble their bodies and connections that
dribble their headers are cut (408) or refused (503 busy), and a legitimate submission gets
its 201 while they are connected (`server.security.Guard`, `server.connections`).

The deadlines are shortened here (1.5 s instead of 10 s) so that the test is quick; the
figures at the daemon's own settings come from `python benchmarks/serve_slow.py`. Nothing
here is timed: every wait has a generous deadline.
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
from serve_support import running_daemon, send

from benchmarks.serve_slow import run

QUICK = {"header_timeout_s": 1.5, "body_grace_s": 1.5, "body_idle_s": 1.5}


def read_all(s: socket.socket) -> bytes:
    """Everything the daemon sends until it closes the connection."""
    out = b""
    while chunk := s.recv(4096):
        out += chunk
    return out


@pytest.mark.parametrize("src, dribblers, slowloris", [("127.0.0.2", 300, 100),
                                                       ("127.0.0.1", 60, 20)])
def test_a_legitimate_upload_gets_201_while_slow_clients_are_connected(
        tmp_path: Path, src: str, dribblers: int, slowloris: int) -> None:
    r = run(dribblers, slowloris, src, 0.5, 60.0, tmp_path, **QUICK)
    assert r.legit_status == 201
    assert r.dribblers.connected == dribblers and r.slowloris.connected == slowloris
    # every dribbler was cut or refused, none is left open and none was queued
    assert set(r.dribblers.outcome) <= {"408", "503"}, r.dribblers.outcome
    assert r.dribblers.outcome["408"] >= 1
    assert r.slowloris.outcome == {"408": slowloris}
    assert r.jobs == 1


def test_headers_and_bodies_have_deadlines_and_answers_say_nosniff(tmp_path: Path) -> None:
    with running_daemon(tmp_path, "deadlines", **QUICK) as d:
        host, port = d.url.removeprefix("http://").rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=30) as s:
            s.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # never ends
            answer = read_all(s)
        assert answer.startswith(b"HTTP/1.1 408 ") and b'"error": "timeout"' in answer
        assert b"x-content-type-options: nosniff" in answer.lower()
        with socket.create_connection((host, int(port)), timeout=30) as s:
            s.sendall(b"POST /api/jobs?name=a.gcode HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                      b"Content-Type: text/x-gcode\r\nContent-Length: 100\r\n\r\nG1")
            answer = read_all(s)
        assert answer.startswith(b"HTTP/1.1 408 ") and b"came too slowly" in answer
        for method, target in (("GET", "/api/status"), ("GET", "/"), ("GET", "/nowhere"),
                               ("POST", "/api/jobs?name=x.svg")):
            raw = send(d.url, method, target)
            assert raw.headers.get("x-content-type-options") == "nosniff", (target, raw)
        assert d.guard is not None and d.guard.slow == {} and d.guard.upload_bytes == 0
