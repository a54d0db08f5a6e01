"""Burst of simultaneous submissions to `fivebar serve` on loopback: how many are accepted,
how many refused (and how), how long it takes, and whether the queue holds exactly the
accepted ones.

Starts an in-process daemon on 127.0.0.1 (an OS-chosen port) with the mock machine, queues one
job first (held: it asks whether the arms are at the home pose, so nothing moves and the queue
stays put), then opens `--clients` connections, waits until all are open and sends one small
G-code drawing on each at the same moment. Prints accepted (201), refused (503 `busy` JSON
with Retry-After), anything else, the wall time, and the jobs in the store against the
accepted ones plus the first job. The daemon and the client threads share one process (and
its GIL), so the time is an upper bound of what a separate daemon needs.

Bounded: one daemon, a fixed number of requests, every wait has a deadline; only loopback.

Run: python benchmarks/serve_burst.py [--clients 200] [--max-uploads 256]
"""

from __future__ import annotations

import argparse
import http.client
import json
import sys
import tempfile
import threading
import time
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # before benchmarks/ itself (its kinematics.py shadows the package)

from fivebar_host.devices import mock  # noqa: E402
from fivebar_host.server.daemon import Daemon, ServeConfig  # noqa: E402
from fivebar_host.server.security import MAX_UPLOADS, is_loopback  # noqa: E402

#: A small drawing in reach of the default profile (a 5 mm L: 33 segments).
SMALL_GCODE = b"G21\nG90\nG0 X10 Y100\nG1 X15 Y100\nG1 X15 Y105\n"  # machine mm


@dataclass(frozen=True)
class Answer:
    """One response as received: status, headers (lower-case names), raw body."""

    status: int
    headers: dict[str, str]
    body: bytes

    def json(self) -> dict[str, object] | None:
        """The body as a JSON object, or None when it is not one (e.g. plain text)."""
        try:
            doc = json.loads(self.body)
        except ValueError:
            return None
        return doc if isinstance(doc, dict) else None

    def is_busy(self) -> bool:
        """The documented refusal: 503, JSON `busy` with a message, and Retry-After."""
        doc = self.json()
        return (self.status == 503 and doc is not None and doc.get("error") == "busy"
                and isinstance(doc.get("message"), str)
                and self.headers.get("content-type", "").startswith("application/json")
                and self.headers.get("retry-after", "").isdigit())


@dataclass
class BurstResult:
    """What a burst of submissions got back."""

    accepted: list[Answer] = field(default_factory=list)
    refused: list[Answer] = field(default_factory=list)
    other: list[Answer | str] = field(default_factory=list)
    seconds: float = 0.0


def burst(url: str, n: int, data: bytes, name: str = "small.gcode",
          content_type: str = "text/x-gcode", timeout_s: float = 180.0) -> BurstResult:
    """Open `n` connections to `url` (loopback only), then send one submission on each at
    the same moment (a barrier); classify the answers. Bounded by `timeout_s`."""
    parts = urllib.parse.urlsplit(url)
    host, port = parts.hostname or "", parts.port or 80
    if not is_loopback(host):  # never load anything but this machine
        raise ValueError(f"refusing to load a non-loopback address {host!r}")
    result = BurstResult()
    lock = threading.Lock()
    barrier = threading.Barrier(n + 1)
    path = f"/api/jobs?name={urllib.parse.quote(name)}"

    def one() -> None:
        conn = http.client.HTTPConnection(host, port, timeout=timeout_s)
        try:
            conn.connect()
            barrier.wait(60)
            conn.request("POST", path, body=data, headers={"Content-Type": content_type})
            resp = conn.getresponse()
            ans = Answer(resp.status, {k.lower(): v for k, v in resp.getheaders()},
                         resp.read())
        except Exception as e:  # reported, not raised: the caller counts them
            with lock:
                result.other.append(f"{type(e).__name__}: {e}")
            return
        finally:
            conn.close()
        with lock:
            if ans.status == 201 and ans.json() is not None:
                result.accepted.append(ans)
            elif ans.is_busy():
                result.refused.append(ans)
            else:
                result.other.append(ans)

    threads = [threading.Thread(target=one, daemon=True) for _ in range(n)]
    for t in threads:
        t.start()
    barrier.wait(60)
    t0 = time.monotonic()
    deadline = t0 + timeout_s + 10
    for t in threads:
        t.join(max(0.0, deadline - time.monotonic()))
    result.seconds = time.monotonic() - t0
    if any(t.is_alive() for t in threads):
        result.other.append("some requests did not finish in time")
    return result


def main(argv: list[str] | None = None) -> int:
    """Run one burst and print the figures; exit 0 when every answer was an accepted job or
    the documented refusal and the store holds exactly the accepted jobs."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=200, help="simultaneous submissions (200)")
    ap.add_argument("--max-uploads", type=int, default=MAX_UPLOADS,
                    help=f"the daemon's limit of uploads in progress ({MAX_UPLOADS})")
    args = ap.parse_args(argv)
    if not 1 <= args.clients <= 2000 or args.max_uploads < 1:
        ap.error("--clients must be 1..2000 and --max-uploads at least 1")
    with tempfile.TemporaryDirectory(prefix="fivebar-serve-burst-") as tmp:
        d = Daemon(ServeConfig(port_url="fivebar-mock://?speed=10&machine=burst",
                               listen="127.0.0.1:0", state_dir=Path(tmp),
                               banner_timeout_s=1.0, max_uploads=args.max_uploads))
        d.start()
        try:
            assert d.store is not None
            first = burst(d.url, 1, SMALL_GCODE)  # held: asks for the home pose
            r = burst(d.url, args.clients, SMALL_GCODE)
            counts = d.store.counts()
            ledger = len(mock.machine("burst").ledger)
        finally:
            d.stop(hurry=True, timeout_s=15.0)
            mock.forget_machines()
    stored = sum(counts.values())
    print(f"{args.clients} simultaneous submissions (max_uploads {args.max_uploads}): "
          f"{len(r.accepted)} accepted (201), {len(r.refused)} refused (503 busy JSON with "
          f"Retry-After), {len(r.other)} other, in {r.seconds:.2f} s")
    for o in r.other[:5]:
        print(f"  other: {o}")
    print(f"store: {stored} jobs = {len(first.accepted)} queued before + {len(r.accepted)} "
          f"accepted ({counts}); mock machine ledger: {ledger} blocks")
    ok = not r.other and stored == len(first.accepted) + len(r.accepted) and ledger == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
