"""A small sender-side client for the GRBL contract suite: talks to the bridge over TCP or
its pty as a GRBL sender would (banner, `ok`/`error:`, real-time bytes, character-counting
streaming against the 128-byte receive buffer)."""

from __future__ import annotations

import os
import re
import socket
import time
from pathlib import Path

RX = 128
STATUS = re.compile(r"<([A-Za-z]+)(?::(\d))?\|MPos:([-\d.]+),([-\d.]+),([-\d.]+)")


class GrblClient:
    """One sender connection (TCP, or a pty path)."""

    def __init__(self, tcp: tuple[str, int] | None = None, pty: Path | None = None) -> None:
        self.sock: socket.socket | None = None
        self.fd: int | None = None
        if tcp is not None:
            self.sock = socket.create_connection(tcp, timeout=5)
            self.sock.settimeout(0.02)
        else:
            assert pty is not None
            self.fd = os.open(str(pty), os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.buf = b""
        self.lines: list[str] = []  # every line received, in order

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
        if self.fd is not None:
            os.close(self.fd)

    def write(self, data: bytes) -> None:
        if self.sock is not None:
            self.sock.sendall(data)
        else:
            assert self.fd is not None
            os.write(self.fd, data)

    def _read(self) -> None:
        try:
            if self.sock is not None:
                chunk = self.sock.recv(4096)
            else:
                assert self.fd is not None
                chunk = os.read(self.fd, 4096)
        except (TimeoutError, BlockingIOError):
            time.sleep(0.005)
            return
        self.buf += chunk
        while b"\n" in self.buf:
            line, self.buf = self.buf.split(b"\n", 1)
            text = line.decode("ascii", "replace").strip()
            if text:
                self.lines.append(text)

    def wait_for(self, pred, timeout: float = 10.0, start: int = 0) -> str:  # type: ignore[no-untyped-def]
        """The first line from index `start` on that satisfies `pred`."""
        deadline = time.monotonic() + timeout
        i = start
        while time.monotonic() < deadline:
            while i < len(self.lines):
                if pred(self.lines[i]):
                    return self.lines[i]
                i += 1
            self._read()
        raise TimeoutError(f"no matching line; got {self.lines[start:][-10:]}")

    def command(self, line: str, timeout: float = 10.0) -> tuple[list[str], str]:
        """Send one line, wait for its reply: (lines before the reply, the reply)."""
        start = len(self.lines)
        self.write(line.encode() + b"\n")
        reply = self.wait_for(lambda s: s == "ok" or s.startswith("error:"), timeout, start)
        idx = self.lines.index(reply, start)
        return [s for s in self.lines[start:idx] if not s.startswith("<")], reply

    def status(self, timeout: float = 5.0) -> str:
        start = len(self.lines)
        self.write(b"?")
        return self.wait_for(lambda s: s.startswith("<"), timeout, start)

    def wait_state(self, state: str, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            st = self.status()
            if st[1:].startswith(state):
                return st
            time.sleep(0.05)
        raise TimeoutError(f"state never {state}; last {st}")

    def stream(self, lines: list[str], timeout: float = 300.0) -> list[str]:
        """Character counting against the 128-byte buffer: replies, one per line."""
        replies: list[str] = []
        inflight: list[int] = []
        i = 0
        start = len(self.lines)
        deadline = time.monotonic() + timeout
        while len(replies) < len(lines):
            while i < len(lines) and sum(inflight) + len(lines[i]) + 1 <= RX:
                self.write(lines[i].encode() + b"\n")
                inflight.append(len(lines[i]) + 1)
                i += 1
            self._read()
            while start < len(self.lines):
                s = self.lines[start]
                start += 1
                if s == "ok" or s.startswith("error:"):
                    replies.append(s)
                    inflight.pop(0)
            if time.monotonic() > deadline:
                raise TimeoutError(f"{len(replies)} of {len(lines)} replies")
        return replies


def mpos(report: str) -> tuple[float, float, float]:
    m = STATUS.match(report)
    assert m is not None, report
    return float(m.group(3)), float(m.group(4)), float(m.group(5))
