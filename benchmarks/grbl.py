"""Throughput of `fivebar bridge` beside `fivebar plot`, on the same drawing, on the emulated
firmware in real time (`fivebar-sim://?realtime=1`: simavr throttled to wall-clock speed, so
the 115200-baud UART binds as on hardware).

1. bridge: a GRBL sender streams `tests/grbl/drawing.nc` (258 G-code lines: a rounded frame
   of arcs, a 240-segment sine wave, a circle) by character counting against GRBL's 128-byte
   receive buffer over TCP; the bridge compiles online and drives the firmware. Reported:
   G-code lines/s until every line is answered, and until the machine is idle again.
2. plot: `fivebar plot` of the same file with the same origin, tolerance and laser, timed
   from start to finish (compile included), as G-code lines/s of the same file.

Run: python benchmarks/grbl.py [--repeat 1]
"""

from __future__ import annotations

import argparse
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# Run as a script, this folder comes first on sys.path and benchmarks/kinematics.py would
# shadow the package of that name.
sys.path[:] = [str(ROOT)] + [p for p in sys.path
                             if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

from fivebar_host.bridge.controller import Bridge  # noqa: E402
from fivebar_host.bridge.serve import Server  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from fivebar_host.controllers.fivebar.link import Link  # noqa: E402
from fivebar_host.devices import register  # noqa: E402
from fivebar_host.devices.sim import toolchain_missing  # noqa: E402

DRAWING = ROOT / "tests" / "grbl" / "drawing.nc"
ORIGIN = (5.0, 95.0)
RX = 128


class Sender:
    """A minimal character-counting GRBL sender over TCP."""

    def __init__(self, address: tuple[str, int]) -> None:
        self.sock = socket.create_connection(address, timeout=10)
        self.buf = b""
        self.wait(lambda s: s.startswith("Grbl"))

    def lines(self) -> list[str]:
        chunk = self.sock.recv(4096)
        self.buf += chunk
        out = []
        while b"\n" in self.buf:
            line, self.buf = self.buf.split(b"\n", 1)
            out.append(line.decode().strip())
        return out

    def wait(self, pred: object, timeout: float = 600.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for s in self.lines():
                if pred(s):  # type: ignore[operator]
                    return s
        raise TimeoutError("no answer")

    def stream(self, lines: list[str]) -> None:
        inflight: list[int] = []
        i = acked = 0
        while acked < len(lines):
            while i < len(lines) and sum(inflight) + len(lines[i]) + 1 <= RX:
                self.sock.sendall(lines[i].encode() + b"\n")
                inflight.append(len(lines[i]) + 1)
                i += 1
            for s in self.lines():
                if s == "ok" or s.startswith("error:"):
                    if s != "ok":
                        raise RuntimeError(f"line {acked + 1}: {s}")
                    acked += 1
                    inflight.pop(0)

    def wait_idle(self) -> None:
        while True:
            self.sock.sendall(b"?")
            st = self.wait(lambda s: s.startswith("<"))
            if st.startswith("<Idle"):
                return
            time.sleep(0.02)


def bridge_run(lines: list[str]) -> tuple[float, float]:
    """(seconds until the last ok, seconds until idle) for the bridge."""
    link = Link.open("fivebar-sim://?realtime=1")
    core = Bridge(link, load_profile(), laser=True, tolerance_mm=0.05, origin_mm=ORIGIN)
    server = Server(core, None, ("127.0.0.1", 0))
    core.start()
    server.start()
    try:
        assert server.address is not None
        s = Sender(server.address)
        s.sock.sendall(b"$X\n")
        s.wait(lambda x: x == "ok")
        t0 = time.monotonic()
        s.stream(lines)
        t_ok = time.monotonic() - t0
        s.wait_idle()
        t_idle = time.monotonic() - t0
        s.sock.close()
    finally:
        server.stop()
        core.close()
        link.close()
    return t_ok, t_idle


def plot_run() -> float:
    """Seconds for `fivebar plot` of the same drawing on the real-time emulator."""
    with tempfile.TemporaryDirectory() as tmp:
        drawing = Path(tmp) / DRAWING.name
        drawing.write_bytes(DRAWING.read_bytes())
        cmd = [sys.executable, "-c", "from fivebar_host.cli import main; main()", "plot",
               str(drawing), "--port", "fivebar-sim://?realtime=1", "--origin",
               f"{ORIGIN[0]},{ORIGIN[1]}", "--laser", "--yes", "--keep-order"]
        t0 = time.monotonic()
        subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
        return time.monotonic() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    register()  # the emulator's URL scheme
    reason = toolchain_missing()
    if reason is not None:
        print(f"emulator unavailable: {reason}")
        return 1
    lines = [s for s in DRAWING.read_text().splitlines() if s]
    n = len(lines)
    oks, idles, plots = [], [], []
    for _ in range(args.repeat):
        t_ok, t_idle = bridge_run(lines)
        oks.append(t_ok)
        idles.append(t_idle)
        plots.append(plot_run())
    t_ok, t_idle, t_plot = (statistics.median(v) for v in (oks, idles, plots))
    print(f"drawing: {DRAWING.relative_to(ROOT)}, {n} G-code lines, emulator in real time "
          "(115200 baud)")
    print(f"bridge (character counting, 128 B): {n / t_ok:7.1f} lines/s accepted "
          f"({t_ok:.2f} s), {n / t_idle:7.1f} lines/s to idle ({t_idle:.2f} s)")
    print(f"fivebar plot (compile + run):       {n / t_plot:7.1f} lines/s "
          f"({t_plot:.2f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
