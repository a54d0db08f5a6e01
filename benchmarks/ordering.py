"""Pen-up travel of fivebar's path ordering against vpype's `linesort` (issue 39), side by
side in one run, on real line drawings:

- benchmarks/drawings/*.svg: 16 plotter drawings from vpype's test data, examples and
  documentation figures (benchmarks/drawings/SOURCES.md), examples/birthday_card.svg,
  and tests/gcode_corpus/mrbeam-heart.gco (a real laser job).

Each drawing is read and flattened as `fivebar` does (0.05 mm), and the same polylines go
to both orderers: `toolpath.order.order_paths` and vpype's `linesort` and `linesort
--two-opt` (through `vpype_cli.execute` on a one-layer document of those polylines). vpype
counts the pen-up distance between consecutive lines (`LineCollection.pen_up_length`) and
its two-opt may put any line first; fivebar's tour is given no start and no park position
(`order_paths(starts, ends, None, None)`), so both figures are the pen-up length between
consecutive paths of a route through every path that begins and ends anywhere. Times are
wall seconds of the ordering alone (best of `--repeat` runs; vpype's two-opt once unless
`--repeat-vpype`). Target (issue 39): fivebar ≤ 0.95× `linesort --two-opt` on at least 5
drawings, in no more time than vpype's on each of them; every drawing is printed, the
ones it is not met on too. Layers are not separated here (both sides get the same one
set of polylines).

Run: python benchmarks/ordering.py [--repeat 3] [--repeat-vpype 1] [FILES...]
"""

from __future__ import annotations

import argparse
import itertools
import logging
import statistics
import sys
import time
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
ROOT = _HERE.parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(ROOT))  # this tree, not an installed copy
from fivebar_host.compile import read_drawing  # noqa: E402
from fivebar_host.toolpath.geometry import flatten  # noqa: E402
from fivebar_host.toolpath.order import order_paths  # noqa: E402
from kinematics.arrays import FloatArray  # noqa: E402

DEFAULT = [*sorted((_HERE / "drawings").glob("*.svg")), ROOT / "examples" / "birthday_card.svg",
           ROOT / "tests" / "gcode_corpus" / "mrbeam-heart.gco"]


def polylines(path: Path) -> list[FloatArray]:
    """The drawing's flattened strokes (mm), as `fivebar` orders them."""
    poly = flatten(read_drawing(path), 0.05)
    offs = poly.offsets.tolist()
    return [poly.points[a:b] for a, b in itertools.pairwise(offs)]


def vpype_sort(lines: list[FloatArray], two_opt: bool) -> tuple[float, float]:
    """vpype's `linesort` (`--two-opt`) on these lines: (pen-up mm, seconds)."""
    import vpype as vp
    import vpype_cli

    doc = vp.Document(vp.LineCollection([q[:, 0] + 1j * q[:, 1] for q in lines]))
    t0 = time.perf_counter()
    out = vpype_cli.execute("linesort --two-opt" if two_opt else "linesort", doc)
    dt = time.perf_counter() - t0
    return float(out.pen_up_length()), dt


def fivebar_sort(lines: list[FloatArray]) -> tuple[float, float]:
    """fivebar's `order_paths` with free ends, as vpype's tour: (pen-up mm, s)."""
    starts = np.array([q[0] for q in lines])
    ends = np.array([q[-1] for q in lines])
    t0 = time.perf_counter()
    od = order_paths(starts, ends, None, None)
    dt = time.perf_counter() - t0
    return od.travel_after_mm, dt


def main() -> None:
    """The table (module doc)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="*", type=Path, default=DEFAULT)
    ap.add_argument("--repeat", type=int, default=3, help="runs of fivebar and vpype linesort")
    ap.add_argument("--repeat-vpype", type=int, default=1, help="runs of linesort --two-opt")
    args = ap.parse_args()
    logging.getLogger().setLevel(logging.WARNING)
    print("pen-up travel (mm) and ordering time (s, best of runs): fivebar against vpype "
          "linesort / linesort --two-opt on the same flattened polylines")
    print(f"  {'drawing':<22} {'paths':>6} {'fivebar':>9} {'linesort':>9} {'2-opt':>9} "
          f"{'ratio':>6} {'fivebar s':>9} {'2-opt s':>8} {'linesort s':>10}")
    ratios: list[float] = []
    slower = ok_fast = 0
    for f in args.files:
        lines = polylines(f)
        fb = [fivebar_sort(lines) for _ in range(args.repeat)]
        ls = [vpype_sort(lines, False) for _ in range(args.repeat)]
        lt = [vpype_sort(lines, True) for _ in range(args.repeat_vpype)]
        mine, t_mine = fb[0][0], min(t for _, t in fb)
        ref, t_ref = lt[0][0], min(t for _, t in lt)
        ratio = mine / ref if ref > 0 else 1.0
        ratios.append(ratio)
        slower += t_mine > t_ref
        ok_fast += ratio <= 0.95 and t_mine <= t_ref
        print(f"  {f.name:<22} {len(lines):>6d} {mine:>9.1f} {ls[0][0]:>9.1f} {ref:>9.1f} "
              f"{ratio:>6.3f} {t_mine:>9.3f} {t_ref:>8.3f} {min(t for _, t in ls):>10.3f}")
    ok = sum(r <= 0.95 for r in ratios)
    print(f"  ratio fivebar / linesort --two-opt: median {statistics.median(ratios):.3f}, "
          f"max {max(ratios):.3f}; {ok} of {len(ratios)} drawings ≤ 0.95, {ok_fast} of them "
          f"in no more time than --two-opt (target ≥ 5: {'MET' if ok_fast >= 5 else 'NOT MET'})"
          f"; fivebar slower than --two-opt on {slower} of {len(ratios)}")


if __name__ == "__main__":
    main()
