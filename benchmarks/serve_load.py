"""Load test of `fivebar serve` on loopback while a job streams to the emulated firmware.

Starts the daemon as its own process on 127.0.0.1 (an OS-chosen port) with the firmware in
simavr throttled to real time (`fivebar-sim://?realtime=1`), submits a link-heavy drawing (a
dense spiral: ~240 numbered, checksummed lines per second at 115200 baud) and, while it
streams, sends GET /api/status at a fixed rate (default 200 requests/s for 30 s) from a few
keep-alive connections. Prints:

- requests sent, failed (non-200 or no answer), achieved rate, latency percentiles;
- the job's result and whether the firmware queue ever ran empty mid-job: the firmware's
  `U:` counter of queue underruns over the job (the daemon reports `underruns`, which
  excludes the one stop at the job's end) and the smallest queue depth seen in the status
  reports while the job ran (first and last 2 s excluded).

Bounded: one daemon, a fixed number of requests, every wait has a deadline; only loopback.

Run: python benchmarks/serve_load.py [--duration 30] [--rate 200] [--connections 4]
"""

from __future__ import annotations

import argparse
import http.client
import json
import math
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fivebar_host.compile import CompileOptions, compile_drawing  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from fivebar_host.devices import sim  # noqa: E402
from fivebar_host.server.client import ServerClient, plot_options  # noqa: E402
from fivebar_host.server.security import is_loopback  # noqa: E402
from fivebar_host.toolpath.svg import read_svg  # noqa: E402


def spiral_svg(turns: float, step_mm: float, size_mm: float = 60.0) -> bytes:
    """A dense Archimedean spiral of equal `step_mm` chords: many short segments of about
    the same duration, so the serial link carries a steady, high line rate."""
    c = size_mm / 2
    r0, r1 = 2.0, 23.0
    a_end = 2 * math.pi * turns
    pts = []
    a = 0.0
    while a <= a_end:
        r = r0 + (r1 - r0) * a / a_end
        pts.append(f"{c + r * math.cos(a):.4f},{c + r * math.sin(a):.4f}")
        a += step_mm / math.hypot(r, (r1 - r0) / a_end)
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{size_mm}mm" height="{size_mm}mm"'
            f' viewBox="0 0 {size_mm} {size_mm}"><path d="M {" L ".join(pts)}" fill="none" '
            'stroke="black"/></svg>').encode()


def drawing_for(duration_s: float, step_mm: float) -> tuple[bytes, Any]:
    """A spiral whose job lasts a little longer than the load (compiled to check)."""
    prof = load_profile(None)
    turns = 4.0
    for _ in range(8):
        data = spiral_svg(turns, step_mm)
        job = compile_drawing(read_svg(data, None, file="spiral.svg"), prof, CompileOptions())
        if job.total_time_s >= duration_s + 4.0:
            return data, job
        turns *= (duration_s + 6.0) / max(job.total_time_s, 1.0)
    raise SystemExit("could not make a long enough drawing")


@dataclass
class Load:
    """What the load generator saw."""

    latencies: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    statuses: list[tuple[float, dict[str, Any]]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)


def worker(url: str, start: float, rate: float, index: int, stride: int, total: int,
           load: Load) -> None:
    """Send requests index, index+stride, ... each at start + i/rate, on one connection."""
    parts = urllib.parse.urlsplit(url)
    assert parts.hostname is not None and parts.port is not None
    conn: http.client.HTTPConnection | None = None
    for i in range(index, total, stride):
        due = start + i / rate
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        t0 = time.monotonic()
        try:
            if conn is None:
                conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=5)
            conn.request("GET", "/api/status")
            resp = conn.getresponse()
            body = resp.read()
            dt = time.monotonic() - t0
            if resp.status != 200:
                raise RuntimeError(f"HTTP {resp.status}: {body[:100]!r}")
            doc = json.loads(body)
            with load.lock:
                load.latencies.append(dt)
                load.statuses.append((t0, doc))
        except Exception as e:
            with load.lock:
                load.failures.append(f"request {i}: {e}")
            if conn is not None:
                conn.close()
            conn = None
    if conn is not None:
        conn.close()


def pct(values: list[float], q: float) -> float:
    """The q-th percentile (nearest rank) of `values`."""
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q / 100 * len(s)) - 1))]


def wait_over(client: ServerClient, job_id: int, timeout_s: float) -> dict[str, Any]:
    """The job once it is no longer queued or running, or as it is after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while (job := client.job(job_id))["state"] in ("queued", "running"):
        if time.monotonic() > deadline:
            break
        time.sleep(0.25)
    return job


def stop_daemon(proc: subprocess.Popen[Any]) -> None:
    """SIGTERM (the daemon stops its job and exits), killed after 60 s."""
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(60)
    except subprocess.TimeoutExpired:
        proc.kill()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=30.0, help="seconds of load (30)")
    ap.add_argument("--rate", type=float, default=200.0, help="status requests/s (200)")
    ap.add_argument("--connections", type=int, default=4, help="keep-alive connections (4)")
    ap.add_argument("--step-mm", type=float, default=0.1,
                    help="spiral chord length: shorter means more lines/s on the link (0.1)")
    args = ap.parse_args(argv)
    if not 0 < args.duration <= 600 or not 0 < args.rate <= 2000:
        ap.error("--duration must be in (0, 600] s and --rate in (0, 2000] per s")
    reason = sim.toolchain_missing()
    if reason is not None:
        print(f"emulator unavailable: {reason}")
        return 2
    sim.ensure_built()
    data, job = drawing_for(args.duration, args.step_mm)
    print(f"job: spiral, {job.n_segments} segments, {job.total_time_s:.1f} s planned, "
          f"{job.n_segments / job.total_time_s:.0f} lines/s on the link")
    with tempfile.TemporaryDirectory(prefix="fivebar-serve-load-") as tmp:
        ready = Path(tmp) / "ready"
        log = (Path(tmp) / "daemon.log").open("w")
        proc = subprocess.Popen(
            [sys.executable, "-c", "from fivebar_host.cli import main; main()", "serve",
             "--port", "fivebar-sim://?realtime=1", "--listen", "127.0.0.1:0",
             "--state-dir", str(Path(tmp) / "state"), "--ready-file", str(ready)],
            stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
        try:
            deadline = time.monotonic() + 60
            while not ready.exists():
                if proc.poll() is not None or time.monotonic() > deadline:
                    log.flush()
                    print((Path(tmp) / "daemon.log").read_text())
                    return 1
                time.sleep(0.05)
            url = ready.read_text().strip()
            host = urllib.parse.urlsplit(url).hostname or ""
            if not is_loopback(host):  # never load anything but this machine
                raise SystemExit(f"refusing to load a non-loopback address {host!r}")
            client = ServerClient(url)
            sub = client.submit(data, "spiral.svg", plot_options(confirm=True))
            jid = int(sub["id"])
            deadline = time.monotonic() + 60
            while client.job(jid)["segments_done"] < 1:
                if time.monotonic() > deadline:
                    raise SystemExit("the job did not start")
                time.sleep(0.05)
            total = int(args.duration * args.rate)
            load = Load()
            start = time.monotonic() + 0.1
            threads = [threading.Thread(target=worker, args=(url, start, args.rate, k,
                                                              args.connections, total, load))
                       for k in range(args.connections)]
            for t in threads:
                t.start()
            for t in threads:
                t.join(args.duration + 60)
            wall = time.monotonic() - start
            final = wait_over(client, jid, job.total_time_s + 60)
        finally:
            stop_daemon(proc)
            log.close()
    lat_ms = [x * 1000 for x in load.latencies]
    print(f"load: {total} GET /api/status over {wall:.1f} s ({len(load.latencies) / wall:.1f}/s "
          f"answered), {args.connections} keep-alive connections")
    print(f"failed requests: {len(load.failures)}")
    for f in load.failures[:5]:
        print(f"  {f}")
    if lat_ms:
        print(f"latency ms: p50 {statistics.median(lat_ms):.2f}, p90 {pct(lat_ms, 90):.2f}, "
              f"p99 {pct(lat_ms, 99):.2f}, max {max(lat_ms):.2f}")
    # Queue depth while the job ran, away from its start and end.
    running = [(t, d["machine"]) for t, d in load.statuses
               if d["current_job"] == jid and d["machine"]["state"] == "Run"]
    if running:
        t_lo, t_hi = running[0][0] + 2.0, running[-1][0] - 2.0
        mid = [m for t, m in running if t_lo <= t <= t_hi and m["queued_blocks"] is not None]
        depths = [int(m["queued_blocks"]) for m in mid]
        us = [int(m["underruns"]) for m in mid]
        if depths:
            print(f"firmware queue during the job: min {min(depths)} / median "
                  f"{statistics.median(depths):.0f} blocks queued over {len(depths)} reports; "
                  f"U: counter {us[0]} -> {us[-1]}")
    print(f"job {final['state']}: {final['message'].removeprefix('done: ')}")
    ran_empty = final.get("underruns")
    print("firmware queue ran empty mid-job: "
          + ("unknown" if ran_empty is None else ("never" if ran_empty == 0
                                                  else f"{ran_empty} times")))
    ok = not load.failures and final["state"] == "done" and ran_empty == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
