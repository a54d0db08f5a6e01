"""Figures of issue 33 (filled shapes and hidden lines), printed side by side:

* `--corpus`: fill rules against headless Chromium — per file of tests/svg_fills/ the area
  the hatch covers (length × spacing) against the browser's inked area, and hatch points
  off the ink (`benchmarks/fillcorpus.py`);
* `--lifts`: pen-down runs per simple region (one ring, no hole) on the corpus and the
  example logo;
* `--speed`: CPU time (process time, median of `--runs`) to hatch 1,000 filled shapes
  (regions, hatch lines, links and the rebuilt drawing; reading excluded);
* `--occult`: hidden-line removal on 5,000 overlapping filled, stroked rectangles, fivebar
  (`--hiding`) against vpype-occult on the same file in the same run (medians), and the
  visible line length of both (the `bench` extra installs vpype-occult);
* `--spacing CSV`: the hatch spacing at the paper from an emulator run's executed path
  (`fivebar plot FILE --hatch … --port fivebar-sim:// --preview P.png` writes
  P.executed.csv): the executed points of every hatch line (forward kinematics of the
  recorded step pulses), each line's mean offset across the hatch direction, and the
  distance between neighbouring lines against the nominal spacing; plus the executed
  hatch points outside the region by more than the tolerance + step quantum;
* `--scan`: the laser scan fill (`--fill scan`) against headless Chromium — per corpus file
  the area its scan grid burns (0.1 mm cells, lit where the centre is inside the painted
  region) against the browser's inked area;
* `--pictures DIR`: docs/fill.md's pictures (outline only, hatched, hidden lines).

Run: python benchmarks/fill.py [--corpus] [--scan] [--lifts] [--speed] [--occult] [--spacing CSV
--file F --hatch 0.4mm ...] [--pictures docs]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.fillcorpus import CORPUS, MM_PER_PX, SPACING, hatched, measure  # noqa: E402
from fivebar_host.compile.fill import Hatch, fill_drawing  # noqa: E402
from fivebar_host.toolpath.svg import read_svg  # noqa: E402


def median_cpu(fn: Callable[[], Any], runs: int) -> tuple[float, Any]:
    """Median process (CPU) time of `runs` calls, and the last result."""
    times, out = [], None
    for _ in range(runs):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return statistics.median(times), out


# ------------------------------------------------------------------ corpus and lifts
def corpus() -> None:
    sys.path.insert(0, str(ROOT / "tests"))
    from web_support import browser_missing, chromium

    why = browser_missing()
    if why:
        print(f"corpus: skipped ({why})")
        return
    print(f"fill rule against headless Chromium (hatch {SPACING} mm, hidden lines on):")
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp, chromium(Path(tmp)) as driver:
        for path in sorted(CORPUS.glob("*.svg")):
            f = measure(driver, path)
            worst = max(worst, abs(f.error))
            print(f"  {f.name:18s} browser {f.browser_mm2:9.1f} mm²  hatch "
                  f"{f.hatch_mm2:9.1f} mm²  {100 * f.error:+7.3f} %  off the ink: "
                  f"{f.far_points}")
    print(f"  worst area difference {100 * worst:.3f} % (goal 1 %)")


def scan_corpus() -> None:
    sys.path.insert(0, str(ROOT / "tests"))
    from web_support import browser_missing, chromium

    from benchmarks.fillcorpus import render, scan_area

    why = browser_missing()
    if why:
        print(f"scan: skipped ({why})")
        return
    print("laser scan fill (0.1 mm cells) against headless Chromium:")
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp, chromium(Path(tmp)) as driver:
        for path in sorted(CORPUS.glob("*.svg")):
            browser = float(render(driver, path.read_text()).sum()) * MM_PER_PX ** 2
            burned, exact = scan_area(path)
            err = (burned - browser) / browser
            worst = max(worst, abs(err))
            print(f"  {path.stem:18s} browser {browser:9.1f} mm²  scan {burned:9.1f} mm²  "
                  f"{100 * err:+7.3f} %  (exact region {exact:9.1f} mm²)")
    print(f"  worst area difference {100 * worst:.3f} %")


def lifts() -> None:
    files = [*sorted(CORPUS.glob("*.svg")), ROOT / "examples" / "fill_logo.svg"]
    print("pen-down runs per simple region (hatch 0.4 mm at 45°, hidden lines on):")
    regions = runs = 0
    for path in files:
        d = hatched(path, 0.4)
        assert d.fill is not None
        regions += d.fill.simple_regions
        runs += d.fill.hatch_runs_simple
        print(f"  {path.stem:18s} {d.fill.simple_regions:3d} simple regions, "
              f"{d.fill.hatch_runs_simple:3d} runs; {d.fill.regions - d.fill.simple_regions}"
              f" with holes, {d.fill.hatch_runs - d.fill.hatch_runs_simple} runs")
    print(f"  total {runs} runs for {regions} simple regions: "
          f"{runs / max(regions, 1):.2f} pen lifts per simple region (goal ≤ 1)")


# ------------------------------------------------------------------ speed
def shapes_svg(n: int, seed: int = 33) -> bytes:
    """`n` filled shapes: stars (both rules), discs, rectangles with holes, 4–12 mm."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n)))
    out = []
    for i in range(n):
        cx, cy = 14 * (i % side) + 7, 14 * (i // side) + 7
        r = rng.uniform(2, 6)
        k = i % 4
        if k == 0:
            a = np.pi / 2 + np.arange(5) * 4 * np.pi / 5
            pts = " ".join(f"{cx + r * np.cos(t):.3f},{cy - r * np.sin(t):.3f}" for t in a)
            rule = "evenodd" if i % 8 == 0 else "nonzero"
            out.append(f'<polygon points="{pts}" fill="black" fill-rule="{rule}"/>')
        elif k == 1:
            out.append(f'<circle cx="{cx}" cy="{cy}" r="{r:.3f}" fill="black"/>')
        elif k == 2:
            h = r / 2
            out.append(f'<path d="M{cx - r:.3f} {cy - r:.3f} h{2 * r:.3f} v{2 * r:.3f} '
                       f'h{-2 * r:.3f} Z M{cx - h:.3f} {cy - h:.3f} v{r:.3f} h{r:.3f} '
                       f'v{-r:.3f} Z" fill="black"/>')
        else:
            out.append(f'<ellipse cx="{cx}" cy="{cy}" rx="{r:.3f}" ry="{r / 2:.3f}" '
                       f'transform="rotate({rng.uniform(0, 180):.1f} {cx} {cy})" '
                       'fill="black"/>')
    size = 14 * side
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}mm" height="{size}mm" '
            f'viewBox="0 0 {size} {size}">' + "".join(out) + "</svg>").encode()


def speed(runs: int) -> None:
    d = read_svg(shapes_svg(1000))
    h = Hatch(0.5, 45.0, False, 0.0)
    t, out = median_cpu(lambda: fill_drawing(d, h, False, 0.05), runs)
    print(f"hatch 1,000 filled shapes (4–12 mm, 0.5 mm spacing, tolerance 0.05 mm): "
          f"{t:.2f} s CPU (median of {runs}; goal ≤ 2 s), {out.fill.regions} regions, "
          f"{out.fill.hatch_mm / 1000:.1f} m of hatch")


# ------------------------------------------------------------------ occult
def rects_svg(n: int, seed: int = 5000) -> bytes:
    """`n` overlapping rectangles, filled white and stroked black, in paint order."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, 180, n), rng.uniform(0, 180, n)
    w, h = rng.uniform(3, 20, n), rng.uniform(3, 20, n)
    body = "".join(f'<rect x="{a:.3f}" y="{b:.3f}" width="{c:.3f}" height="{e:.3f}" '
                   'fill="white" stroke="black"/>' for a, b, c, e in zip(x, y, w, h,
                                                                         strict=True))
    return ('<svg xmlns="http://www.w3.org/2000/svg" width="200mm" height="200mm" '
            f'viewBox="0 0 200 200">{body}</svg>').encode()


def occult_bench(runs: int) -> None:
    try:
        import vpype as vp
        from occult.occult import _occult_layer
    except ImportError:
        print("occult: skipped (pip install vpype-occult, or the `bench` extra)")
        return
    data = rects_svg(5000)
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "rects.svg"
        f.write_bytes(data)
        lc = vp.read_svg(str(f), quantization=0.01)[0]
        d = read_svg(f)
    px = 96 / 25.4  # vpype works in CSS px
    h = Hatch(0.0, 0.0, False, 0.0)
    for _ in range(1):  # warm both (imports, caches)
        fill_drawing(d, h, True, 0.05, hatching=False)
    t_fb, out = median_cpu(lambda: fill_drawing(d, h, True, 0.05, hatching=False), runs)
    t_oc, res = median_cpu(lambda: _occult_layer({1: lc}, 0.01 * px), runs)
    fb_len = _drawn_length(out)
    oc_len = float(res[0][1].length()) / px
    print("hidden-line removal, 5,000 overlapping filled and stroked rectangles "
          f"(median of {runs} runs, CPU):")
    print(f"  fivebar --hiding  {t_fb:7.2f} s   visible {fb_len:10.1f} mm")
    print(f"  vpype-occult      {t_oc:7.2f} s   visible {oc_len:10.1f} mm")
    print(f"  fivebar is {t_oc / t_fb:.1f}× faster (goal ≥ 2×); visible length differs by "
          f"{100 * (fb_len - oc_len) / oc_len:+.3f} % (goal within 0.5 %)")


def _drawn_length(d: Any) -> float:
    from fivebar_host.toolpath.geometry import flatten

    p = flatten(d, 0.001)
    seg = np.hypot(*np.diff(p.points, axis=0).T)
    start = np.zeros(p.points.shape[0] - 1, bool)
    start[p.offsets[1:-1] - 1] = True  # the step from one stroke's end to the next's start
    return float(seg[~start].sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", action="store_true")
    ap.add_argument("--scan", action="store_true")
    ap.add_argument("--lifts", action="store_true")
    ap.add_argument("--speed", action="store_true")
    ap.add_argument("--occult", action="store_true")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--spacing", nargs="?", const=Path("-"), type=Path, metavar="CSV",
                    help="an emulator run's executed CSV; without one the run is made")
    ap.add_argument("--pictures", type=Path, metavar="DIR")
    a, rest = ap.parse_known_args()
    everything = not (a.corpus or a.scan or a.lifts or a.speed or a.occult or a.spacing
                      or a.pictures)
    if a.corpus or everything:
        corpus()
    if a.scan or everything:
        scan_corpus()
    if a.lifts or everything:
        lifts()
    if a.speed or everything:
        speed(a.runs)
    if a.occult or everything:
        occult_bench(a.runs)
    if a.spacing:
        from benchmarks.fillspacing import spacing_report

        spacing_report(None if str(a.spacing) == "-" else a.spacing, rest)
    if a.pictures:
        from benchmarks.fillspacing import pictures

        pictures(a.pictures)


if __name__ == "__main__":
    main()
