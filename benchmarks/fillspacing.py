"""The hatch spacing at the paper from an emulator run, and docs/fill.md's pictures
(`benchmarks/fill.py --spacing`, `--pictures`).

Spacing: the job is compiled again with the run's options (compiling is deterministic), the
executed pen points of the run's CSV (forward kinematics of the step pulses the emulated
firmware sent, `fivebar_host.report.text.executed`) are assigned to their job segments, and
the segments that draw a hatch line (their requested chord lies on a grid line of the hatch)
group the points by line. Each line's executed offset is the mean of its points' distance
across the hatch direction; the spacing is the difference of neighbouring lines' offsets,
against the nominal spacing. Outside: executed points of hatch segments farther outside
their element's fill region (built again from the file, exact fill rule) than the job's
tolerance + step quantum.
"""

from __future__ import annotations

import math
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import shapely

ROOT = Path(__file__).resolve().parent.parent


def run_on_emulator(file: Path, args: list[str], profile: Path, out_dir: Path) -> Path:
    """`fivebar plot FILE ARGS --port fivebar-sim:// --preview …` → the executed CSV."""
    preview = out_dir / "run.png"
    cmd = [sys.executable, "-c", "from fivebar_host.cli import main; main()", "plot",
           str(file), *args, "--config", str(profile), "--port", "fivebar-sim://",
           "--preview", str(preview), "--yes"]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    print(r.stdout.strip())
    if r.returncode:
        raise SystemExit(f"the emulator run failed ({r.returncode}): {r.stderr.strip()}")
    return preview.with_name("run.executed.csv")


def _job_args(rest: list[str]) -> tuple[Path, Path, dict[str, object]]:
    """--file F, --config P and job options (their CLI flags) from the command line."""
    from fivebar_host.options import JOB_OPTIONS, defaults

    by_flag = {o.flag: o for o in JOB_OPTIONS}
    values = defaults()
    file, profile = ROOT / "examples" / "fill_logo.svg", ROOT / "configs" / "pen-servo.toml"
    i = 0
    while i < len(rest):
        a = rest[i]
        if a in ("--file", "--config"):
            file, profile = (Path(rest[i + 1]), profile) if a == "--file" else \
                (file, Path(rest[i + 1]))
            i += 2
            continue
        o = by_flag[a]
        if o.kind == "bool":
            values[o.name] = True
            i += 1
        else:
            values[o.name] = o.parse(rest[i + 1])
            i += 2
    return file, profile, values


def spacing_report(csv: Path | None, rest: list[str]) -> None:
    """Print the spacing and outside figures (module doc). `rest`: --file F, --config P and
    the plot options of the run (with no CSV given, the run is made here)."""
    from fivebar_host.compile import CompileOptions
    from fivebar_host.config import load_profile
    from fivebar_host.options import compile_values

    file, profile_path, values = _job_args(rest)
    prof = load_profile(profile_path)
    opts = CompileOptions(**compile_values(values))
    if csv is None or not csv.exists():
        tmp = Path(tempfile.mkdtemp())
        plot_args = [a for a in rest if a not in ("--file", str(file), "--config",
                                                  str(profile_path))]
        csv = run_on_emulator(file, plot_args, profile_path, tmp)
    sf = spacing_figures(csv, file, opts, prof)
    rel = sf.gaps / sf.nominal - 1.0
    print(f"hatch spacing at the paper (executed steps → forward kinematics), nominal "
          f"{sf.nominal:g} mm, {sf.gaps.size} pairs of neighbouring lines, {sf.points} points:")
    print(f"  mean {np.mean(sf.gaps):.5f} mm ({100 * np.mean(rel):+.3f} %), median "
          f"{np.median(sf.gaps):.5f} mm ({100 * np.median(rel):+.3f} %); 5–95 %: "
          f"{100 * np.percentile(rel, 5):+.2f} % … {100 * np.percentile(rel, 95):+.2f} %; "
          f"worst pair {100 * np.abs(rel).max():.2f} % (goal: mean within ±1 %)")
    print(f"  executed hatch segments outside their region by more than {sf.bound:.4f} mm "
          f"(tolerance + step quantum): {sf.outside} of {sf.segments}")


@dataclass(frozen=True)
class SpacingFigures:
    """The nominal spacing, the executed gaps between neighbouring hatch lines (mm), the
    points they come from, and the executed hatch segments farther outside their region
    than `bound` (of `segments`)."""

    nominal: float
    gaps: np.ndarray
    points: int
    bound: float
    outside: int
    segments: int


def spacing_figures(csv: Path, file: Path, opts: Any, prof: Any) -> SpacingFigures:
    """`SpacingFigures` of an emulator run's executed CSV (module doc)."""
    from fivebar_host.compile import compile_job, read_drawing
    from fivebar_host.compile.fill import FINE
    from fivebar_host.toolpath.fill.regions import fill_regions

    job = compile_job(file, prof, opts)
    f = job.drawing.fill
    assert f is not None and f.hatch, "the job has no hatch"
    rows = np.genfromtxt(csv, delimiter=",", names=True)
    pts = np.stack((rows["x_mm"], rows["y_mm"]), axis=1)
    seg = rows["segment"].astype(np.int64)
    s = opts.hatch_mm or 0.0
    if s == 0.0:
        s = prof.pen.width_mm if prof.pen is not None else prof.laser.spot_mm
    a = job.placement.matrix @ np.array([math.cos(math.radians(opts.hatch_angle_deg)),
                                         math.sin(math.radians(opts.hatch_angle_deg))])
    d = a / np.hypot(*a)
    n = np.array([-d[1], d[0]])
    p0, p1 = job.points_mm[:-1], job.points_mm[1:]
    hatch_src = np.zeros(len(job.drawing.sources) + 1, bool)
    hatch_src[list(f.hatch_of)] = True
    src = np.where(job.source >= 0, job.source, len(job.drawing.sources))
    is_h = job.draw & hatch_src[src]
    # the rotated frame's offset of the requested ends: (k + ½)·s on a hatch line
    u0, u1 = p0 @ n, p1 @ n
    k0, k1 = u0 / s - 0.5, u1 / s - 0.5
    on_line = is_h & (np.abs(k0 - np.rint(k0)) < 1e-6) & (np.abs(k1 - np.rint(k1)) < 1e-6) \
        & (np.rint(k0) == np.rint(k1)) & (np.hypot(*(p1 - p0).T) > 0)
    ok = (seg >= 0) & (seg < job.n_segments)
    sel = ok.copy()
    sel[ok] = on_line[seg[ok]]
    key_src = job.source[seg[sel]].astype(np.int64)
    key_k = np.rint(k0[seg[sel]]).astype(np.int64)
    u = pts[sel] @ n
    keys = key_src * (1 << 32) + (key_k + (1 << 31))
    uk, inv = np.unique(keys, return_inverse=True)
    mean = np.bincount(inv, weights=u) / np.bincount(inv)
    ksrc, kk = uk >> 32, (uk & ((1 << 32) - 1)) - (1 << 31)
    nxt = (ksrc[1:] == ksrc[:-1]) & (kk[1:] == kk[:-1] + 1)
    gaps = (mean[1:] - mean[:-1])[nxt]
    # outside: executed points of hatch segments against their element's fill region
    d0 = read_drawing(file, opts.layers, None, prof)
    md = d0.transformed(job.placement.matrix, job.placement.offset)
    regions = fill_regions(md, job.tolerance_mm * FINE)
    bound = job.tolerance_mm + job.step_quantum_mm
    hs = np.zeros(seg.shape[0], bool)
    hs[ok] = is_h[seg[ok]]
    far_segs: set[int] = set()
    for h, el in f.hatch_of.items():
        m = hs.copy()
        m[ok] &= job.source[seg[ok]] == h
        if not m.any():
            continue
        g = regions[el]
        dist = shapely.distance(g, shapely.points(pts[m]))
        far_segs.update(seg[m][dist > bound].tolist())
    return SpacingFigures(s, gaps, int(sel.sum()), bound, len(far_segs),
                          int(np.unique(seg[hs]).size))




def pictures(out_dir: Path) -> None:
    """docs/fill.png: the example logo as outlines, hatched, and hatched with hidden lines
    (the requested paths of the three compiled jobs on the machine's paper)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    from fivebar_host.compile import CompileOptions, compile_job
    from fivebar_host.config import load_profile
    from fivebar_host.toolpath.geometry import flatten

    prof = load_profile(ROOT / "configs" / "pen-servo.toml")
    file = ROOT / "examples" / "fill_logo.svg"
    cases = [("outline only (fivebar before)", CompileOptions()),
             ("--hatch 0.4mm", CompileOptions(hatch_mm=0.4)),
             ("--hatch 0.4mm --hiding", CompileOptions(hatch_mm=0.4, hiding=True))]
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.4))
    for ax, (title, o) in zip(axes, cases, strict=True):
        job = compile_job(file, prof, o)
        d = job.drawing
        poly = flatten(d, 0.01)
        hatch = np.array([s.role == "hatch" for s in d.sources], dtype=bool)
        is_h = hatch[d.stroke_source[poly.stroke]]
        for sel, colour, lw in ((~is_h, "black", 1.4), (is_h, "#2b2b7a", 0.6)):
            segs = [poly.points[a:b] for a, b, k in zip(poly.offsets[:-1], poly.offsets[1:],
                                                        sel, strict=True) if k]
            ax.add_collection(LineCollection(segs, colors=colour, linewidths=lw))
        if d.fill is not None and d.fill.hidden.shape[0]:
            ax.add_collection(LineCollection(list(d.fill.hidden), colors="#e07a5f",
                                             linewidths=0.9, linestyles=":"))
        ax.autoscale()
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        extra = "; hidden parts dotted red" if o.hiding else ""
        ax.set_title(f"{title}\n{job.draw_length_mm / 1000:.2f} m drawn, {job.pen_downs} pen "
                     f"lifts{extra}", fontsize=10)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.97))
    out = out_dir / "fill.png"
    fig.savefig(out, dpi=110)
    print(f"pictures: {out}")
