"""Uploads compiled while a job streams: does the running job's queue ever run empty?

Starts `fivebar serve` as its own process on 127.0.0.1 over the firmware in simavr throttled
to real time (`fivebar-sim://?realtime=1`), submits a link-heavy job (5 passes of a wobbly
100 mm line in 0.1 mm moves at 100 mm/s: ~330 segments/s), and while it streams sends
`--uploads` dry runs of a large SVG (`--svg-mb`, the pipeline benchmark's generated drawing)
one after the other. Prints each compile's time and the job's mid-path underruns (the
daemon's `underruns`: every one stops the arms dead mid-path). Run once with the daemon's
compilations in child processes (the default) and once in threads of the daemon
(`--threads`, how it compiled before `server.compiler`), or both (`--both`).

Bounded: one daemon at a time, a fixed number of uploads, every wait has a deadline; only
loopback.

Run: python benchmarks/serve_uploads.py [--svg-mb 3] [--uploads 5] [--threads | --both]
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.pipeline import write_svg  # noqa: E402
from benchmarks.serve_load import stop_daemon, wait_over  # noqa: E402
from fivebar_host.devices import sim  # noqa: E402
from fivebar_host.server.client import ServerClient, plot_options  # noqa: E402

#: The daemon in threads mode: `Daemon` with compile_processes=False, run as a script.
_THREADS_DAEMON = """
import sys
from pathlib import Path
from fivebar_host.server.daemon import Daemon, ServeConfig, setup_logging
setup_logging()
d = Daemon(ServeConfig(port_url="fivebar-sim://?realtime=1", listen="127.0.0.1:0",
                       state_dir=Path(sys.argv[1]), ready_file=Path(sys.argv[2]),
                       compile_processes=False))
d.start()
import signal, threading
done = threading.Event()
signal.signal(signal.SIGTERM, lambda *a: done.set())
done.wait()
d.stop(hurry=True)
"""


def dense_gcode(passes: int = 5) -> bytes:
    """Passes of a 100 mm line in 0.1 mm moves, each point off the line by up to 0.03 mm."""
    x0, y0 = -40.0, 101.6
    moves = []
    for r in range(passes):
        for k in range(1, 1001):
            x = x0 + 0.1 * k if r % 2 == 0 else x0 + 100.0 - 0.1 * k
            moves.append(f"G1 X{x + 0.03 * math.sin(k):.3f} "
                         f"Y{y0 + 0.5 * r + 0.03 * math.cos(0.7 * k):.3f}")
    return ("\n".join(["G21", "G90", f"G0 X{x0} Y{y0}", "M3 S255", *moves, "M5"])
            + "\n").encode()


def start_daemon(tmp: Path, threads: bool) -> tuple[subprocess.Popen[bytes], str]:
    """The daemon process and its URL (once it is ready)."""
    ready = tmp / "ready"
    state = tmp / "state"
    if threads:
        cmd = [sys.executable, "-c", _THREADS_DAEMON, str(state), str(ready)]
    else:
        cmd = [sys.executable, "-c", "from fivebar_host.cli import main; main()", "serve",
               "--port", "fivebar-sim://?realtime=1", "--listen", "127.0.0.1:0",
               "--state-dir", str(state), "--ready-file", str(ready)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not ready.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise SystemExit("the daemon did not start")
        time.sleep(0.05)
    return proc, ready.read_text().strip()


def one_run(svg: bytes, uploads: int, threads: bool) -> None:
    """Stream the dense job, compile `uploads` dry runs meanwhile, print the underruns."""
    with tempfile.TemporaryDirectory(prefix="fivebar-serve-uploads-") as tmp:
        proc, url = start_daemon(Path(tmp), threads)
        try:
            c = ServerClient(url)
            jid = int(c.submit(dense_gcode(), "dense.gcode", plot_options(
                confirm=True, no_simplify=True, draw_feed_mm_s=100.0))["id"])
            deadline = time.monotonic() + 60
            while c.job(jid)["segments_done"] < 1:
                if time.monotonic() > deadline:
                    raise SystemExit("the job did not start")
                time.sleep(0.05)
            times = []
            for _ in range(uploads):
                t0 = time.monotonic()
                c.request("POST", "/api/dryrun", query={"name": "big.svg"}, body=svg,
                          content_type="image/svg+xml", timeout_s=300.0)
                times.append(time.monotonic() - t0)
            job = wait_over(c, jid, 120.0)
            if job["state"] in ("queued", "running"):
                raise SystemExit("the job did not finish")
        finally:
            stop_daemon(proc)
    where = "threads of the daemon" if threads else "child processes"
    print(f"compiling in {where}: {uploads} dry runs of {len(svg) / 1e6:.1f} MB, "
          f"{', '.join(f'{t:.1f}' for t in times)} s each; job {job['state']}, "
          f"{job['segments_done']} segments, mid-path underruns {job['underruns']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--svg-mb", type=float, default=3.0)
    ap.add_argument("--uploads", type=int, default=5)
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--threads", action="store_true", help="compile in daemon threads")
    mode.add_argument("--both", action="store_true", help="child processes, then threads")
    args = ap.parse_args()
    why = sim.toolchain_missing()
    if why:
        raise SystemExit(f"emulator unavailable: {why}")
    sim.ensure_built()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.svg"
        write_svg(path, int(args.svg_mb * 1e6))
        svg = path.read_bytes()
    for threads in ([False, True] if args.both else [args.threads]):
        one_run(svg, args.uploads, threads)


if __name__ == "__main__":
    main()
