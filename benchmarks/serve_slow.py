"""Slow clients against `fivebar serve`: uploads that dribble their bodies, connections that
dribble their headers (slowloris), and one legitimate submission in the middle of them.

Starts an in-process daemon on 127.0.0.1 (an OS-chosen port) with the mock machine, opens
`--dribblers` uploads (`POST /api/jobs`, Content-Length 1000) that send one body byte every
`--every` seconds and `--slowloris` connections that send one header line every `--every`
seconds, from `--from` (another loopback address, 127.0.0.2 by default: another client; give
127.0.0.1 for the same one), waits until the daemon holds every upload, then submits a small
G-code drawing from 127.0.0.1 and times its answer. Prints the legitimate answer and its
time, and for each kind of slow client how it ended (408 `timeout`, 503 `busy`, closed),
when (median and max), and how many were still open at the end.

Bounded: one daemon, a fixed number of connections, every wait has a deadline; only loopback.

Run: python benchmarks/serve_slow.py [--dribblers 300] [--slowloris 600] [--every 5]
"""

from __future__ import annotations

import argparse
import asyncio
import http.client
import statistics
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # before benchmarks/ itself (its kinematics.py shadows the package)

from fivebar_host.devices import mock  # noqa: E402
from fivebar_host.server.daemon import Daemon, ServeConfig  # noqa: E402

#: A small drawing in reach of the default profile (a 5 mm L).
SMALL_GCODE = b"G21\nG90\nG0 X10 Y100\nG1 X15 Y100\nG1 X15 Y105\n"


@dataclass
class Ends:
    """How the slow clients of one kind ended: status (or "closed"/"open") and when, s."""

    outcome: Counter[str] = field(default_factory=Counter)
    times: list[float] = field(default_factory=list)
    connected: int = 0

    def line(self, what: str) -> str:
        t = sorted(self.times)
        when = (f", ended after median {statistics.median(t):.1f} s, max {t[-1]:.1f} s"
                if t else "")
        return (f"{what}: {self.connected} connected; "
                + ", ".join(f"{k} {v}" for k, v in sorted(self.outcome.items())) + when)


def _status(data: bytes) -> str:
    head = data.split(b"\r\n", 1)[0].split()
    return head[1].decode() if len(head) > 1 and head[0].startswith(b"HTTP/") else "closed"


async def _slow(host: str, port: int, src: str, head: bytes, trickle: bytes, every_s: float,
                max_s: float, ends: Ends) -> None:
    """One slow client: send `head`, then `trickle` every `every_s` until an answer or EOF."""
    reader, writer = await asyncio.open_connection(host, port, local_addr=(src, 0))
    ends.connected += 1
    t0 = time.monotonic()
    outcome = "open"
    try:
        writer.write(head)
        await writer.drain()
        while time.monotonic() - t0 < max_s:
            try:
                data = await asyncio.wait_for(reader.read(4096), every_s)
            except TimeoutError:
                writer.write(trickle)
                await writer.drain()
                continue
            outcome = _status(data)
            break
    except (ConnectionError, OSError):
        outcome = "closed"
    finally:
        writer.close()
    ends.outcome[outcome] += 1
    if outcome != "open":
        ends.times.append(time.monotonic() - t0)


def legit_submit(host: str, port: int, timeout_s: float = 120.0) -> tuple[int, float]:
    """One ordinary submission from 127.0.0.1: (status, seconds)."""
    t0 = time.monotonic()
    conn = http.client.HTTPConnection(host, port, timeout=timeout_s,
                                      source_address=("127.0.0.1", 0))
    try:
        conn.request("POST", "/api/jobs?name=legit.gcode", body=SMALL_GCODE,
                     headers={"Content-Type": "text/x-gcode"})
        resp = conn.getresponse()
        resp.read()
        return resp.status, time.monotonic() - t0
    finally:
        conn.close()


@dataclass
class Result:
    """What one run measured."""

    legit_status: int
    legit_s: float
    dribblers: Ends
    slowloris: Ends
    jobs: int


async def attack(d: Daemon, dribblers: int, slowloris: int, src: str, every_s: float,
                 max_s: float) -> Result:
    """The run of the module doc against a started daemon `d`."""
    assert d.guard is not None and d.store is not None
    host, port_text = d.url.removeprefix("http://").rsplit(":", 1)
    port = int(port_text)
    body_head = (f"POST /api/jobs?name=slow.gcode HTTP/1.1\r\nHost: {host}:{port}\r\n"
                 "Content-Type: text/x-gcode\r\nContent-Length: 1000\r\n\r\n").encode()
    loris_head = f"GET /api/status HTTP/1.1\r\nHost: {host}:{port}\r\n".encode()
    up, loris = Ends(), Ends()
    tasks = [asyncio.create_task(_slow(host, port, src, body_head, b"G", every_s, max_s, up))
             for _ in range(dribblers)]
    tasks += [asyncio.create_task(_slow(host, port, src, loris_head, b"X-a: b\r\n", every_s,
                                        max_s, loris)) for _ in range(slowloris)]
    deadline = time.monotonic() + 60
    while d.guard.in_flight < dribblers and time.monotonic() < deadline:
        await asyncio.sleep(0.01)  # every upload's headers are in: the daemon holds them
    status, took = await asyncio.to_thread(legit_submit, host, port)
    await asyncio.gather(*tasks)
    return Result(status, took, up, loris, sum(d.store.counts().values()))


def run(dribblers: int, slowloris: int, src: str, every_s: float, max_s: float,
        state_dir: Path, **cfg: float) -> Result:
    """Start a daemon over the mock machine, run `attack`, stop it."""
    d = Daemon(ServeConfig(port_url="fivebar-mock://?speed=10&machine=slow",
                           listen="127.0.0.1:0", state_dir=state_dir, banner_timeout_s=1.0,
                           compile_processes=False, **cfg))  # type: ignore[arg-type]
    d.start()
    try:
        return asyncio.run(attack(d, dribblers, slowloris, src, every_s, max_s))
    finally:
        d.stop(hurry=True, timeout_s=15.0)
        mock.forget_machines()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dribblers", type=int, default=300)
    ap.add_argument("--slowloris", type=int, default=600)
    ap.add_argument("--every", type=float, default=5.0, help="s between two slow pieces")
    ap.add_argument("--from", dest="src", default="127.0.0.2",
                    help="the slow clients' address (127.0.0.1: the same as the legitimate)")
    ap.add_argument("--max-s", type=float, default=90.0, help="give up on a client after")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        r = run(a.dribblers, a.slowloris, a.src, a.every, a.max_s, Path(tmp))
    print(f"legitimate submission from 127.0.0.1 while {a.dribblers} uploads dribbled from "
          f"{a.src}: {r.legit_status} in {r.legit_s:.2f} s")
    print(r.dribblers.line(f"dribbling uploads (1 byte every {a.every:g} s)"))
    print(r.slowloris.line(f"slowloris connections (1 header line every {a.every:g} s)"))
    print(f"jobs in the store: {r.jobs}")


if __name__ == "__main__":
    main()
