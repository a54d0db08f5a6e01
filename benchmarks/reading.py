"""SVG reading against vpype's reader (issue 39), side by side in one run.

1. Read time: `fivebar_host.toolpath.svg.read_svg` (exact primitives) against
   `vpype.read_multilayer_svg` at `vpype read`'s default quantization (0.1 mm), on real
   drawings (benchmarks/drawings; no `<text>`, which vpype does not draw) and generated
   files: line-heavy (`<path>` polylines of `L` commands, `<polyline>` points, `<line>`
   elements) and curve-heavy (cubic `C` commands, `A` arcs). CPU seconds
   (`time.process_time`: the machine's other load does not count), the median of `--runs`
   reads of each, the two readers interleaved; the ratio fivebar / vpype and µs per
   primitive read. Targets: line-heavy files ≤ 1.0× vpype; curve-heavy files keep their
   advantage (< 1.0×).
2. Memory per input byte: generated line-heavy drawings of 2, 20 and 200 MB (`--memory-mb`)
   read in a fresh process each; the peak resident memory (VmHWM) above the process after
   its imports, per input byte. Target ≤ 30 B/B.

Run: python benchmarks/reading.py [--runs 5] [--memory-mb 2,20,200] [--no-memory]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
ROOT = _HERE.parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(ROOT))  # this tree, not an installed copy
from fivebar_host.toolpath.svg import read_svg  # noqa: E402

HEAD = ('<svg xmlns="http://www.w3.org/2000/svg" width="300mm" height="200mm" '
        'viewBox="0 0 300 200">\n')


def _walks(rng: np.random.Generator, n: int, pts: int) -> np.ndarray:
    """`n` random walks of `pts` points on the page, (n, pts, 2)."""
    start = rng.uniform(20, 180, (n, 1, 2))
    return np.clip(start + np.cumsum(rng.normal(0, 1.5, (n, pts, 2)), axis=1), 1, 199)


def _fmt(a: np.ndarray) -> list[str]:
    """Coordinates as SVG numbers (3 decimals)."""
    return [f"{x:.3f}" for x in a.ravel().tolist()]


def write_lines(path: Path, size: int, kind: str, seed: int = 0) -> None:
    """A line-heavy file of about `size` bytes: `path` (M + 19 L per element), `polyline`
    (20 points) or `line` elements."""
    rng = np.random.default_rng(seed)
    with path.open("w") as f:
        f.write(HEAD)
        written = len(HEAD)
        while written < size:
            w = _walks(rng, 2000, 20)
            out = []
            for k in range(w.shape[0]):
                v = _fmt(w[k])
                if kind == "path":
                    pairs = [f"{v[2 * i]} {v[2 * i + 1]}" for i in range(20)]
                    out.append(f'<path d="M{pairs[0]} L{" L".join(pairs[1:])}" '
                               f'fill="none" stroke="black"/>\n')
                elif kind == "polyline":
                    out.append(f'<polyline points="{" ".join(v)}" fill="none" '
                               f'stroke="black"/>\n')
                else:
                    out.extend(f'<line x1="{v[2 * i]}" y1="{v[2 * i + 1]}" x2="{v[2 * i + 2]}" '
                               f'y2="{v[2 * i + 3]}" stroke="black"/>\n' for i in range(19))
            s = "".join(out)
            f.write(s)
            written += len(s)
        f.write("</svg>\n")


def write_curves(path: Path, size: int, kind: str, seed: int = 1) -> None:
    """A curve-heavy file: paths of 10 cubic `C` commands, or of 10 elliptical arcs."""
    rng = np.random.default_rng(seed)
    with path.open("w") as f:
        f.write(HEAD)
        written = len(HEAD)
        while written < size:
            w = _walks(rng, 2000, 31)
            out = []
            for k in range(w.shape[0]):
                v = _fmt(w[k])
                p = [f"{v[2 * i]} {v[2 * i + 1]}" for i in range(31)]
                if kind == "cubic":
                    d = "M" + p[0] + "".join(f" C{p[3 * i + 1]} {p[3 * i + 2]} {p[3 * i + 3]}"
                                             for i in range(10))
                else:
                    d = "M" + p[0] + "".join(f" A3 2 15 0 1 {p[i + 1]}" for i in range(10))
                out.append(f'<path d="{d}" fill="none" stroke="black"/>\n')
            s = "".join(out)
            f.write(s)
            written += len(s)
        f.write("</svg>\n")


def cpu(fn: Callable[[], object]) -> float:
    """CPU seconds of one call."""
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def read_times(files: list[tuple[str, str, Path]], runs: int) -> None:
    """Section 1 (module doc)."""
    import vpype as vp

    q = vp.convert_length("0.1mm")
    print(f"read time: CPU s, median of {runs} runs each (interleaved); fivebar read_svg "
          f"(exact primitives) against vpype read_multilayer_svg (-q 0.1mm)")
    print(f"  {'file':<26} {'kind':<6} {'KB':>7} {'prims':>8} {'fivebar s':>9} {'vpype s':>8} "
          f"{'ratio':>6} {'µs/prim':>8}")
    ratios: dict[str, list[float]] = {}
    for name, kind, path in files:
        data = path.read_bytes()
        prims = read_svg(data, None, file=path.name).kind.shape[0]
        mine: list[float] = []
        ref: list[float] = []
        for _ in range(runs):
            mine.append(cpu(partial(_fivebar_read, path)))
            ref.append(cpu(partial(vp.read_multilayer_svg, str(path), q)))
        m, r = statistics.median(mine), statistics.median(ref)
        ratios.setdefault(kind, []).append(m / r)
        print(f"  {name:<26} {kind:<6} {len(data) / 1e3:>7.0f} {prims:>8d} {m:>9.3f} {r:>8.3f} "
              f"{m / r:>6.2f} {m / max(prims, 1) * 1e6:>8.1f}")
    for kind, rs in ratios.items():
        print(f"  {kind}: fivebar / vpype from {min(rs):.2f} to {max(rs):.2f}× over {len(rs)} "
              f"files" + (f" (target ≤ 1.0×: {'MET' if max(rs) <= 1.0 else 'NOT MET'})"
                          if kind == "lines" else ""))


def _fivebar_read(path: Path) -> object:
    """fivebar's read of a file, as `fivebar` reads it (bytes, then the reader)."""
    return read_svg(path.read_bytes(), None, file=path.name)


_PEAK_RUN = """
import json, resource, sys, time
sys.path.insert(0, sys.argv[2])
from fivebar_host.toolpath.svg import read_svg

def peak():
    try:
        with open("/proc/self/status") as f:
            return next(int(x.split()[1]) * 1024 for x in f if x.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

base = peak()
t0 = time.process_time()
d = read_svg(sys.argv[1], max_segments=None)
print(json.dumps({"s": time.process_time() - t0, "prims": int(d.kind.shape[0]),
                  "base": base, "peak": peak()}))
"""


def memory(sizes_mb: list[float]) -> None:
    """Section 2 (module doc)."""
    print("memory of reading a line-heavy SVG (<path> of M + 19 L), fresh process per size: "
          "peak RSS (VmHWM) above the process after its imports, per input byte")
    print(f"  {'SVG MB':>7} {'prims':>10} {'base MiB':>9} {'peak MiB':>9} {'above B/B':>10} "
          f"{'CPU s':>7}")
    for mb in sizes_mb:
        with tempfile.TemporaryDirectory() as tmp:
            svg = Path(tmp) / "lines.svg"
            write_lines(svg, int(mb * 1e6), "path")
            size = svg.stat().st_size
            out = subprocess.run([sys.executable, "-c", _PEAK_RUN, str(svg), str(ROOT)],
                                 check=True, capture_output=True, text=True).stdout
        r = json.loads(out)
        above = (r["peak"] - r["base"]) / size
        print(f"  {size / 1e6:>7.0f} {r['prims']:>10d} {r['base'] / 2**20:>9.0f} "
              f"{r['peak'] / 2**20:>9.0f} {above:>10.1f} {r['s']:>7.1f}  "
              f"{'MET' if above <= 30 else 'NOT MET'} (≤ 30 B/B)")


def main() -> None:
    """Both sections (module doc)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--memory-mb", default="2,20,200")
    ap.add_argument("--no-memory", action="store_true")
    args = ap.parse_args()
    drawings = _HERE / "drawings"
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        gen: list[tuple[str, str, Path]] = []
        for kind in ("path", "polyline", "line"):
            write_lines(t / f"{kind}.svg", 2_000_000, kind)
            gen.append((f"generated <{kind}> 2 MB", "lines", t / f"{kind}.svg"))
        for kind in ("cubic", "arc"):
            write_curves(t / f"{kind}.svg", 1_000_000, kind)
            gen.append((f"generated {kind} 1 MB", "curves", t / f"{kind}.svg"))
        real = [(p.name, "lines", drawings / p.name) for p in
                (Path("multi_skull.svg"), Path("plotter.svg"), Path("voronoi.svg"),
                 Path("a49n.svg"), Path("circlelines_2.svg"))]
        real.append(("halftone.svg", "curves", drawings / "halftone.svg"))
        read_times(real + gen, args.runs)
    if not args.no_memory:
        memory([float(x) for x in args.memory_mb.split(",")])


if __name__ == "__main__":
    main()
