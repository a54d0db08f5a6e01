"""Job pipeline benchmark: time and peak memory from a large SVG to steps, and the tolerance
against segment count and measured deviation.

1. An SVG of 10^4 paths / 10^5 segments (7 lines and 3 quadratic curves per path, random
   "handwriting" strokes on an 80 × 36 mm page, fixed seed) → read, place, flatten, order,
   inverse kinematics + checks, joint-space segmentation, travel, steps, plan. Target ≤ 2 s.
   Wall time (best and median of --repeat runs) and peak Python memory (tracemalloc, one
   separate run, since tracing slows numpy-heavy code down). Validation (forward kinematics of
   the quantised steps against the requested curves) is timed on its own.
2. For tolerances 0.5, 0.1, 0.05, 0.01 mm on the bundled text example (examples/
   fivebar_text.svg, fitted to the safe rectangle): segments produced and the max deviation
   measured with 16 samples per segment, on the ideal joint targets (the tolerance bound) and
   on the quantised steps (tolerance + one step quantum).
3. Dense input: the text example's curves sampled every 0.05 mm into straight lines (what
   `vpype read -q 0.05mm` writes), once as SVG polylines and once as G-code G1 moves at the
   machine coordinates the SVG was drawn at (what vpype-gcode writes): planned plot time
   and segments against the source curves, with the line simplification off
   (`--no-simplify`) and on (`toolpath.simplify`), and the validated max deviation from the
   original dense lines. Target: the dense copy within ~10 % of the source's plan time.

4. Peak memory per input byte: drawings of 2, 20 and 200 MB of the same kind (`write_svg`,
   in a temporary folder) compiled and validated as `fivebar convert` does, each in a fresh
   process; the process's real peak (RSS high-water mark, VmHWM: `ru_maxrss` can include
   the parent's peak), in MiB per MB of SVG, and the time; also the peak above the process
   after its imports (~36 MiB, measured in the same process before the file is read).
   Target ≤ 30 bytes per input byte (total) on large drawings. `--max-segments` is raised
   for these runs (the 200 MB drawing has 8.6 million path segments).

5. `--against TREE_OR_COMMIT`: section 1's "SVG → steps" timed for this tree and another
   (a source folder, or a commit of this repository, exported to a temporary folder),
   interleaved in one run: every run a fresh process with the tree alone on PYTHONPATH,
   the compile's CPU time (`time.process_time`: the machine's other load does not count)
   without the imports; medians over `--against-runs` runs of each and their ratio. Only
   `compile_job` and `CompileOptions` are called, from `fivebar_host.compile` or, in trees
   older than that package, `fivebar_host.job`. Target: this tree ≤ 1.0× the other and
   ≤ 1.5 s. With this option only this table is printed.

Run: python benchmarks/pipeline.py [--repeat 3] [--paths 10000] [--dense-only]
     [--memory-mb 2,20,200] [--against 71543b2 [--against-runs 7]]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

# Run as a script, this folder comes first on sys.path and benchmarks/kinematics.py would
# shadow the `kinematics` package: drop the folder before importing the project.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
from fivebar_host.compile import (  # noqa: E402
    CompileOptions,
    compile_job,
    deviations,
    read_drawing,
    validate,
)
from fivebar_host.config import Profile, load_profile  # noqa: E402
from fivebar_host.toolpath.geometry import Drawing, evaluate  # noqa: E402
from kinematics.arrays import FloatArray  # noqa: E402

ROOT = _HERE.parent


def make_svg(n_paths: int = 10_000, segs: int = 10, seed: int = 0, w: float = 80.0,
             h: float = 36.0) -> str:
    """Random pen strokes: every third segment a quadratic Bézier, the rest lines."""
    rng = np.random.default_rng(seed)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" '
           f'viewBox="0 0 {w} {h}">']
    cx = rng.uniform(3, w - 3, n_paths)
    cy = rng.uniform(3, h - 3, n_paths)
    for i in range(n_paths):
        ang = np.cumsum(rng.normal(0, 0.9, segs + 1))
        st = rng.uniform(0.3, 1.2, segs + 1)
        x = np.clip(cx[i] + np.cumsum(st * np.cos(ang)), 0.5, w - 0.5)
        y = np.clip(cy[i] + np.cumsum(st * np.sin(ang)), 0.5, h - 0.5)
        d = [f"M{x[0]:.3f} {y[0]:.3f}"]
        for k in range(1, segs + 1):
            if k % 3 == 0:
                d.append(f"Q{(x[k - 1] + x[k]) / 2 + 0.3:.3f} {(y[k - 1] + y[k]) / 2 - 0.3:.3f} "
                         f"{x[k]:.3f} {y[k]:.3f}")
            else:
                d.append(f"L{x[k]:.3f} {y[k]:.3f}")
        out.append(f'<path d="{"".join(d)}" stroke="black" fill="none"/>')
    out.append("</svg>")
    return "\n".join(out)


def dense_points(drawing: Drawing, step_mm: float) -> list[FloatArray]:
    """Every stroke of `drawing` sampled at most `step_mm` apart along its curves (the
    points lie on the curves, as a resampling tool writes them), in the drawing frame."""
    out = []
    for s in range(drawing.n_strokes):
        pieces = []
        for i in np.flatnonzero(drawing.stroke == s):
            k, p = drawing.kind[i:i + 1], drawing.params[i:i + 1]
            probe = evaluate(np.repeat(k, 257), np.repeat(p, 257, 0), np.linspace(0, 1, 257))
            n = max(1, int(np.ceil(np.hypot(*np.diff(probe, axis=0).T).sum() / step_mm)))
            q = evaluate(np.repeat(k, n + 1), np.repeat(p, n + 1, 0), np.linspace(0, 1, n + 1))
            pieces.append(q if not pieces else q[1:])
        out.append(np.concatenate(pieces))
    return out


def dense_svg(drawing: Drawing, polylines: list[FloatArray]) -> str:
    """The polylines as an SVG page of the drawing's size (page frame: y down)."""
    assert drawing.page_size_mm is not None
    w, h = drawing.page_size_mm
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" '
           f'viewBox="0 0 {w} {h}">']
    for q in polylines:
        f = drawing.to_file_frame(q)
        pts = " ".join(f"{x:.4f},{y:.4f}" for x, y in f)
        out.append(f'<polyline points="{pts}" stroke="black" fill="none"/>')
    return "\n".join([*out, "</svg>"])


def dense_gcode(polylines: list[FloatArray]) -> str:
    """The polylines as pen-plotter G-code (G0 to each start, G1 along it), coordinates as
    given (machine mm: drawn where it says)."""
    out = ["G21", "G90"]
    for q in polylines:
        out.append(f"G0 X{q[0, 0]:.4f} Y{q[0, 1]:.4f}")
        out += [f"G1 X{x:.4f} Y{y:.4f}" for x, y in q[1:]]
    return "\n".join(out) + "\n"


def dense_section(prof: Profile, tmp: Path, step_mm: float = 0.05) -> None:
    """Section 3 of the module doc: plan time of dense copies vs the source curves."""
    text = ROOT / "examples" / "fivebar_text.svg"
    src = compile_job(text, prof)
    d = read_drawing(text)
    lines = dense_points(d, step_mm)
    svg = tmp / "dense.svg"
    svg.write_text(dense_svg(d, lines))
    gc = tmp / "dense.gcode"
    gc.write_text(dense_gcode([src.placement.to_machine(q) for q in lines]))
    n_lines = sum(q.shape[0] - 1 for q in lines)
    print(f"dense input ({text.name}, {d.kind.shape[0]} curves; dense copies: {n_lines} "
          f"lines {step_mm:g} mm long; default placement, tolerance {src.tolerance_mm:g} mm):")
    print(f"  {'input':<34} {'plan s':>7} {'vs src':>7} {'segments':>9} {'max dev':>8} "
          f"{'bound':>7} {'compile s':>9}")
    rows = [("source curves (SVG)", text, False), ("SVG polylines, --no-simplify", svg, True),
            ("SVG polylines, simplified", svg, False),
            ("G-code G1 moves, --no-simplify", gc, True),
            ("G-code G1 moves, simplified", gc, False)]
    for name, path, off in rows:
        t0 = time.perf_counter()
        j = compile_job(path, prof, CompileOptions(no_simplify=off))
        dt = time.perf_counter() - t0
        bound = j.tolerance_mm + j.step_quantum_mm
        print(f"  {name:<34} {j.total_time_s:>7.2f} {j.total_time_s / src.total_time_s:>6.0%} "
              f"{j.n_segments:>9d} {j.max_dev_mm:>8.4f} {bound:>7.4f} {dt:>9.3f}"
              f"  {'ok' if j.max_dev_mm <= bound else 'EXCEEDED'}")
def write_svg(path: Path, size_bytes: int, seed: int = 0, w: float = 80.0,
              h: float = 36.0, chunk: int = 20_000) -> int:
    """Write `make_svg`'s kind of drawing (10 segments per path, every third a quadratic) of
    about `size_bytes` to `path`, generated in vectorised chunks so a 200 MB file takes
    seconds; returns the number of paths."""
    rng = np.random.default_rng(seed)
    segs = 10
    written = 0
    n_paths = 0
    with path.open("w") as f:
        head = (f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" '
                f'viewBox="0 0 {w} {h}">\n')
        f.write(head)
        written += len(head)
        while written < size_bytes:
            cx = rng.uniform(3, w - 3, (chunk, 1))
            cy = rng.uniform(3, h - 3, (chunk, 1))
            ang = np.cumsum(rng.normal(0, 0.9, (chunk, segs + 1)), axis=1)
            st = rng.uniform(0.3, 1.2, (chunk, segs + 1))
            x = np.clip(cx + np.cumsum(st * np.cos(ang), axis=1), 0.5, w - 0.5)
            y = np.clip(cy + np.cumsum(st * np.sin(ang), axis=1), 0.5, h - 0.5)
            qx = (x[:, :-1] + x[:, 1:]) / 2 + 0.3
            qy = (y[:, :-1] + y[:, 1:]) / 2 - 0.3
            lines = []
            for i in range(chunk):
                xi, yi, qxi, qyi = x[i].tolist(), y[i].tolist(), qx[i].tolist(), qy[i].tolist()
                d = [f"M{xi[0]:.3f} {yi[0]:.3f}"]
                for k in range(1, segs + 1):
                    if k % 3 == 0:
                        d.append(f"Q{qxi[k - 1]:.3f} {qyi[k - 1]:.3f} {xi[k]:.3f} {yi[k]:.3f}")
                    else:
                        d.append(f"L{xi[k]:.3f} {yi[k]:.3f}")
                lines.append(f'<path d="{"".join(d)}" stroke="black" fill="none"/>\n')
                n_paths += 1
                written += len(lines[-1])
                if written >= size_bytes:
                    break
            f.write("".join(lines))
        f.write("</svg>\n")
    return n_paths


_PEAK_RUN = """
import json, resource, sys, time
from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile

def peak():
    # this process's own high-water mark: VmHWM (Linux); ru_maxrss can carry the parent's
    # peak over (a forked child's copy of its memory counts before exec)
    try:
        with open("/proc/self/status") as f:
            return next(int(x.split()[1]) * 1024 for x in f if x.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

profile = load_profile()
base = peak()
t0 = time.perf_counter()
job = compile_job(sys.argv[1], profile, CompileOptions(max_segments=1e9))
print(json.dumps({"s": time.perf_counter() - t0, "segments": job.n_segments, "base": base,
                  "peak": peak()}))
"""


def peak_memory(sizes_mb: list[float]) -> None:
    """Section 4 (module doc): peak RSS per input MB, one fresh process per size; also the
    peak above the interpreter with numpy and the project imported (measured in the same
    process before the file is read: "base"), since the target is on the total."""
    print("peak memory per input byte (compile + validate, fresh process per size, "
          "VmHWM; 'above base': the peak less the process after its imports):")
    print(f"  {'SVG MB':>7} {'paths':>8} {'segments':>10} {'peak MiB':>9} {'MiB/MB':>7} "
          f"{'B/B':>6} {'base MiB':>9} {'above B/B':>10} {'time s':>7}")
    for mb in sizes_mb:
        with tempfile.TemporaryDirectory() as tmp:
            svg = Path(tmp) / "drawing.svg"
            n = write_svg(svg, int(mb * 1e6))
            size = svg.stat().st_size
            out = subprocess.run([sys.executable, "-c", _PEAK_RUN, str(svg)], check=True,
                                 capture_output=True, text=True, cwd=ROOT).stdout
        r = json.loads(out)
        peak, base = r["peak"], r["base"]
        print(f"  {size / 1e6:>7.0f} {n:>8d} {r['segments']:>10d} {peak / 2**20:>9.0f} "
              f"{peak / 2**20 / (size / 1e6):>7.1f} {peak / size:>6.1f} {base / 2**20:>9.0f} "
              f"{(peak - base) / size:>10.1f} {r['s']:>7.1f}  "
              f"{'MET' if peak / size <= 30 else 'NOT MET'} (≤ 30 B/B total)")


_CPU_RUN = """
import json, sys, time
try:
    from fivebar_host.compile import CompileOptions, compile_job
except ImportError:  # trees before the fivebar_host.compile package
    from fivebar_host.job import CompileOptions, compile_job
from fivebar_host.config import load_profile

profile = load_profile()
t0 = time.process_time()
job = compile_job(sys.argv[1], profile, CompileOptions(validate=False))
print(json.dumps({"cpu": time.process_time() - t0, "segments": int(job.n_segments)}))
"""


def tree_of(spec: str, tmp: Path) -> Path:
    """The source folder `spec` names: a folder as given, else a commit of this repository
    exported (`git archive`) into `tmp`."""
    if Path(spec).is_dir():
        return Path(spec).resolve()
    out = tmp / "tree"
    out.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", spec], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(out)], input=archive, check=True)
    return out


def compile_cpu(tree: Path, svg: Path) -> tuple[float, int]:
    """CPU seconds of one `compile_job` of `svg` in a fresh process importing only from
    `tree` (alone on PYTHONPATH, so an installed copy of the project does not answer), and
    the job's segment count."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", _CPU_RUN, str(svg)], check=True, cwd=tree,
                         env=env, capture_output=True, text=True).stdout
    r = json.loads(out)
    return float(r["cpu"]), int(r["segments"])


def against(spec: str, n_paths: int, runs: int) -> None:
    """Section 5 (module doc): this tree against `spec`, runs interleaved (this, other,
    this, …) so drifts in the machine's load fall on both alike."""
    with tempfile.TemporaryDirectory() as tmp:
        other = tree_of(spec, Path(tmp))
        svg = Path(tmp) / "big.svg"
        svg.write_text(make_svg(n_paths))
        trees = {"this tree": ROOT, spec: other}
        cpu: dict[str, list[float]] = {name: [] for name in trees}
        segs: dict[str, int] = {}
        for _ in range(runs):
            for name, tree in trees.items():
                s, segs[name] = compile_cpu(tree, svg)
                cpu[name].append(s)
    print(f"SVG → steps, {n_paths} paths / {n_paths * 10} segments: CPU s of one compile per "
          f"fresh process, {runs} runs of each interleaved")
    print(f"  {'tree':<24} {'median':>7} {'min':>7} {'max':>7} {'segments':>9}")
    for name in trees:
        print(f"  {name:<24} {statistics.median(cpu[name]):>7.3f} {min(cpu[name]):>7.3f} "
              f"{max(cpu[name]):>7.3f} {segs[name]:>9d}")
    ratio = statistics.median(cpu["this tree"]) / statistics.median(cpu[spec])
    ours = statistics.median(cpu["this tree"])
    print(f"  ratio this/{spec}: {ratio:.3f}× (target ≤ 1.0×: "
          f"{'MET' if ratio <= 1.0 else 'NOT MET'}); this tree {ours:.3f} s (target ≤ 1.5 s: "
          f"{'MET' if ours <= 1.5 else 'NOT MET'})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--paths", type=int, default=10_000)
    ap.add_argument("--dense-only", action="store_true", help="only section 3 (dense input)")
    ap.add_argument("--memory-mb", default="2,20,200",
                    help="SVG sizes (MB) for the peak-memory figure; empty: skip")
    ap.add_argument("--against", metavar="TREE_OR_COMMIT",
                    help="only section 5: CPU time to steps against another source tree")
    ap.add_argument("--against-runs", type=int, default=7,
                    help="runs of each tree for --against")
    args = ap.parse_args()
    if args.against:
        against(args.against, args.paths, args.against_runs)
        return
    prof = load_profile()
    if args.dense_only:
        with tempfile.TemporaryDirectory() as tmp:
            dense_section(prof, Path(tmp))
        return
    with tempfile.TemporaryDirectory() as tmp:
        svg = Path(tmp) / "big.svg"
        svg.write_text(make_svg(args.paths))
        opts = CompileOptions(validate=False)
        times = []
        job = None
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            job = compile_job(svg, prof, opts)
            times.append(time.perf_counter() - t0)
        assert job is not None
        tracemalloc.start()
        compile_job(svg, prof, opts)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        t0 = time.perf_counter()
        vjob = validate(job, prof)
        t_val = time.perf_counter() - t0
    n_in = args.paths * 10
    print(f"pipeline: SVG of {args.paths} paths / {n_in} segments → steps "
          f"({job.n_segments} segments out: {int(job.draw.sum())} drawing, "
          f"{int((~job.draw).sum())} travel; {job.n_paths} paths after joining)")
    print(f"  time to steps   best {min(times):.3f} s, median {statistics.median(times):.3f} s "
          f"over {args.repeat} runs (target ≤ 2 s) — "
          f"{'MET' if min(times) <= 2.0 else 'NOT MET'}")
    print(f"  peak memory     {peak / 2**20:.1f} MiB (tracemalloc, Python allocations)")
    print(f"  validation      {t_val:.3f} s (4 samples per segment from the quantised steps): "
          f"max deviation {vjob.max_dev_mm:.4f} mm, mean {vjob.mean_dev_mm:.4f} mm, "
          f"step quantum {vjob.step_quantum_mm:.4f} mm")
    print(f"  travel          {job.travel_before_mm:.0f} mm in file order → "
          f"{job.travel_after_mm:.0f} mm after ordering (pen-up straight lines); "
          f"plot time {job.total_time_s / 60:.1f} min")
    print()
    text = ROOT / "examples" / "fivebar_text.svg"
    print(f"tolerance vs segments and measured deviation ({text.name}, --fit, 16 samples per "
          "segment):")
    print(f"  {'tol mm':>7} {'segments':>9} {'drawing':>8} {'ideal max':>10} {'quantised max':>14} "
          f"{'quantum':>8} {'bound':>8} {'compile s':>9}")
    for tol in (0.5, 0.1, 0.05, 0.01):
        t0 = time.perf_counter()
        j = compile_job(text, prof, CompileOptions(tolerance_mm=tol, fit=True, validate=False))
        dt = time.perf_counter() - t0
        ideal, _ = deviations(j, prof, samples=16, quantised=False)
        quant, _ = deviations(j, prof, samples=16, quantised=True)
        ok = ideal.max() <= tol and quant.max() <= tol + j.step_quantum_mm
        print(f"  {tol:>7g} {j.n_segments:>9d} {int(j.draw.sum()):>8d} {ideal.max():>10.4f} "
              f"{quant.max():>14.4f} {j.step_quantum_mm:>8.4f} "
              f"{tol + j.step_quantum_mm:>8.4f} {dt:>9.3f}  {'ok' if ok else 'EXCEEDED'}")
    print()
    with tempfile.TemporaryDirectory() as tmp:
        dense_section(prof, Path(tmp))
    if args.memory_mb:
        print()
        peak_memory([float(x) for x in args.memory_mb.split(",")])


if __name__ == "__main__":
    main()
