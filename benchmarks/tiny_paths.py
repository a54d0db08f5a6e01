"""A million tiny paths: how long the compile takes, stage by stage, and its peak memory.

Writes an SVG of `--paths` tiny separate paths (`<path d="M x y h.2"/>`, 0.1 mm long, at
random places on a 50 mm page: about 36 bytes a path, 1 M paths ≈ 36 MB, under the reader's
2 M-segment cap) and compiles it as `fivebar convert` does, with the terminal's progress
lines, timing each stage (`fivebar_host.progress` reports) and reading the process's peak
resident memory. `--tolerance 0.01` keeps nearly every path separate (paths closer than the
tolerance are joined). Prints the stages, the total, the estimate the compile told before
starting (`compile.budget`) and the peak memory: the figures behind `compile/budget.py`.

Run: python benchmarks/tiny_paths.py [--paths 1000000] [--tolerance 0.01]
"""

from __future__ import annotations

import argparse
import random
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # before benchmarks/ itself (its kinematics.py shadows the package)

from fivebar_host import progress  # noqa: E402
from fivebar_host.compile import CompileOptions, compile_job  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402


def write_drawing(path: Path, n: int, seed: int = 37) -> int:
    """`n` tiny paths at random places on a 50 mm page; the file's size in bytes."""
    rnd = random.Random(seed)
    with path.open("w", encoding="ascii") as f:
        f.write('<svg xmlns="http://www.w3.org/2000/svg" width="50mm" height="50mm" '
                'viewBox="0 0 100 100">\n')
        for _ in range(n):
            f.write(f'<path d="M {rnd.uniform(0, 99.7):.3f} {rnd.uniform(0, 99.7):.3f} h.2"/>\n')
        f.write("</svg>\n")
    return path.stat().st_size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--paths", type=int, default=1_000_000)
    ap.add_argument("--tolerance", type=float, default=0.01, help="mm (default 0.01)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        svg = Path(tmp) / "tiny.svg"
        size = write_drawing(svg, a.paths)
        print(f"{a.paths:,} tiny paths: {svg.name}, {size / 1e6:.1f} MB", flush=True)
        stages: dict[str, float] = {}
        notes: list[str] = []
        t0 = time.monotonic()
        last = [t0, ""]

        def hear(ev: progress.Event) -> None:
            if ev.note is not None:
                notes.append(ev.note)
                print(f"  estimate: {ev.note}", flush=True)
                return
            now = time.monotonic()
            if ev.stage != last[1]:
                if last[1]:
                    stages[str(last[1])] = now - float(last[0])
                last[:] = [now, ev.stage]

        with progress.listening_with(hear):
            job = compile_job(svg, load_profile(None), CompileOptions(tolerance_mm=a.tolerance))
        end = time.monotonic()
        stages[str(last[1])] = end - float(last[0])
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    for name, s in stages.items():
        print(f"  {name:16s} {s:7.1f} s")
    print(f"compiled in {end - t0:.1f} s: {job.n_paths:,} paths after joining, "
          f"{job.n_segments:,} segments; peak memory {peak:.0f} MB")


if __name__ == "__main__":
    main()
