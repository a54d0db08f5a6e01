"""The firmware's deepest stack on every kind of job, in the emulator (exact, cycle by cycle).

The Uno's static RAM (.data + .bss + .noinit) is 1,737 of its 2,048 bytes; the stack grows
down towards it and nothing stops it there (an overflow silently corrupts .bss).  Each job
below runs the real firmware in simavr with the harness's profile on (fbsim -P: the lowest
stack pointer of the run, `fivebar-sim://?stack=FILE`) and prints the headroom at the
deepest point: the lowest stack pointer less avr-nm's `_end` (devices/simstack.py), and the
function whose instruction reached it.

- g6: benchmarks/segcost.py's job (1–2-step G6 segments, P = 250 µs) at 1,000,000 baud, the
  emulator in real time (the link at its real rate against the step interrupt);
- raster-default / raster-fast: an 8×30 grey patch with a darker band (power changes in
  every line) engraved on configs/default.toml (its G7 blocks on the step interrupt's C path,
  where the pixel interrupt nests) and on configs/raster-fast.toml (the fast path);
- pen-servo: examples/simple.svg on configs/pen-servo.toml (the pen servo's Timer0 compare);
- servo-build: examples/simple.svg on configs/plotclock.toml (`make SERVO=1`, the arm servos);
- raster-noise: raster-default with line noise (`corrupt=0.003`): damaged G7 lines refused and
  resent.

With --chain, each job's line is followed by the functions its deepest point's return
addresses go back to (devices/simstack.py `return_chain`: the calls and interrupts on top
of each other there, deepest first).

Run: python benchmarks/stack.py [--jobs g6,raster-default,...] [--segments 1000] [--chain]
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from click.testing import CliRunner
from PIL import Image

_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
from fivebar_host.cli import main as cli_main  # noqa: E402
from fivebar_host.devices.sim import Emulator, boot, ensure_built, firmware_dir  # noqa: E402
from fivebar_host.devices.simstack import StackDepth, read_stack  # noqa: E402

ROOT = _HERE.parent
#: The headroom the tests ask of every job (tests/firmware/test_stack_depth.py says why).
MIN_HEADROOM = 32


def g6_job(tmp: Path, segments: int = 1000) -> tuple[StackDepth, str]:
    """segcost.py's G6 job at 1 Mbaud, the emulator in real time, on the normal build."""
    from benchmarks import segcost

    build = ensure_built()
    prof = tmp / "g6.stack"
    lines = segcost.packed_lines(segcost.issue_job(segments, 250), 4)
    emu = Emulator(build.elf, build.harness, tmp / "g6.trace", realtime=True,
                   extra=["-P", str(prof)])
    dev = boot(emu, tmp / "g6.trace", 20.0)
    try:
        final = segcost.stream(dev.session, dev.port, lines, 1_000_000)
    finally:
        dev.close()
    return read_stack(prof, build.elf), f"{segments} segments, {final.underruns - 1} underruns"


def grey_patch(path: Path) -> Path:
    """An 8×30 grey patch with a darker band: power changes inside every line."""
    a = np.full((8, 30), 128, dtype=np.uint8)
    a[:, 10:20] = 64
    Image.fromarray(a).save(path)
    return path


def plot_job(tmp: Path, name: str, args: list[str], query: str = "",
             servo: bool = False) -> tuple[StackDepth, str]:
    """`fivebar plot ARGS --port fivebar-sim://?stack=...`; the run's deepest stack and its
    `done:` line's counts.  SystemExit when the plot fails (the figure would mean nothing)."""
    prof = tmp / f"{name}.stack"
    res = CliRunner().invoke(cli_main, [
        "plot", *args, "--yes", "--preview", str(tmp / f"{name}.png"), "--port",
        f"fivebar-sim://?state=off&stack={prof}{query}"])
    done = re.search(r"^done: (\d+) segments.*?(\d+) resends", res.output, re.MULTILINE)
    if res.exit_code != 0 or done is None:
        raise SystemExit(f"{name}: plot failed ({res.exit_code}):\n{res.output}")
    elf = firmware_dir() / "build" / ("servo" if servo else "") / "fivebar.elf"
    return read_stack(prof, elf), f"{done[1]} segments, {done[2]} resends"


def _raster(config: str, query: str = "") -> Callable[[Path], tuple[StackDepth, str]]:
    def run(tmp: Path) -> tuple[StackDepth, str]:
        img = grey_patch(tmp / "grey.png")
        name = Path(config).stem + ("-noise" if query else "")
        return plot_job(tmp, name, [str(img), "--laser", "--width", "6mm", "--config",
                                    str(ROOT / "configs" / config)], query)
    return run


def _drawing(config: str, servo: bool = False) -> Callable[[Path], tuple[StackDepth, str]]:
    def run(tmp: Path) -> tuple[StackDepth, str]:
        return plot_job(tmp, Path(config).stem, [
            str(ROOT / "examples" / "simple.svg"), "--config", str(ROOT / "configs" / config),
            *(["--fit"] if servo else [])], servo=servo)
    return run


#: Every job, by name (the g6 job takes its segment count separately).
JOBS: dict[str, Callable[[Path], tuple[StackDepth, str]]] = {
    "raster-default": _raster("default.toml"),
    "raster-fast": _raster("raster-fast.toml"),
    "pen-servo": _drawing("pen-servo.toml"),
    "servo-build": _drawing("plotclock.toml", servo=True),
    "raster-noise": _raster("default.toml", "&corrupt=0.003&seed=3"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--jobs", default=",".join(["g6", *JOBS]))
    ap.add_argument("--segments", type=int, default=1000, help="the g6 job's segments")
    ap.add_argument("--chain", action="store_true",
                    help="also print the calls and interrupts on the stack at its deepest")
    args = ap.parse_args()
    print(f"{'job':16s} {'headroom':>8s}  lowest SP  deepest near          what")
    for name in args.jobs.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            depth, what = (g6_job(Path(tmp), args.segments) if name == "g6"
                           else JOBS[name](Path(tmp)))
        print(f"{name:16s} {depth.headroom:6d} B  {depth.min_sp:#06x}     "
              f"{depth.function:20s}  {what}", flush=True)
        if args.chain:
            print(f"{'':16s} under it: {' < '.join(depth.chain)}")


if __name__ == "__main__":
    main()
