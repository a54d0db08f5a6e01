"""The dry-run preview picture of a compiled job (`fivebar plot --dry-run --preview`).

The picture (matplotlib, Agg backend — no display needed) shows, in machine millimetres:
the singularity-safe region of the job's working mode and assembly (shaded), the reach
circles (type-1 singularity loci) and the type-2 singularity curves, the requested path
(black), the executed path computed from the *quantised* steps through forward kinematics
including the joint-space interpolation (red), pen-up travel (grey, dashed), and the linkage
drawn at a few poses (home, first, middle and last target). A job that changes working mode
(`--mode auto`, thesis Sec. 7.2) shows the safe region of every mode it draws in and marks
each change: the pen-up move (orange, dash-dot), where the pen lifts (▲, numbered "n: from →
to") and lands (▼), and where an arm passes its type-1 singularity (✕).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch
from numpy.typing import NDArray

from fivebar_host.compile import Job
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.report.text.dryrun import format_duration, mode_sequence
from fivebar_host.toolpath.geometry import flatten
from kinematics.arrays import FloatArray
from kinematics.fivebar import FiveBar
from kinematics.workspace import safe_mask, type2_traces

Box = tuple[float, float, float, float]  # x0, x1, y0, y1 of the view, mm
Handles = list[Line2D | Patch]
#: (fill, edge) colours of the safe regions of the working modes a job draws in.
_REGION_COLOURS = (("#d9f2d9", "#5aa05a"), ("#dde8fb", "#4a78c2"), ("#fbe3d0", "#c27a3a"),
                   ("#eadcf5", "#8a5cb0"))
_CHANGE = "#ff7f0e"  # working-mode changes


def _nan_join(pts: FloatArray, starts: NDArray[np.int64], ends: NDArray[np.int64]) -> FloatArray:
    """Concatenate pts[starts[i]:ends[i]] runs separated by NaN rows (one Line2D for all)."""
    if starts.size == 0:
        return np.zeros((0, 2))
    lens = ends - starts
    total = int(lens.sum()) + starts.size
    out = np.full((total, 2), np.nan)
    pos = np.cumsum(lens + 1) - (lens + 1)
    idx = np.repeat(starts, lens) + (np.arange(int(lens.sum()))
                                     - np.repeat(np.cumsum(lens) - lens, lens))
    dst = np.repeat(pos, lens) + (np.arange(int(lens.sum()))
                                  - np.repeat(np.cumsum(lens) - lens, lens))
    out[dst] = pts[idx]
    return out


def _runs(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Start and end (exclusive) indices of the True runs of a boolean array."""
    m = np.concatenate(([False], mask, [False])).astype(np.int8)
    d = np.diff(m)
    return np.flatnonzero(d == 1).astype(np.int64), np.flatnonzero(d == -1).astype(np.int64)


def _assembly(job: Job) -> str:
    return "+" if job.assembly > 0 else "-"


def _pose_indices(job: Job) -> list[int]:
    """Targets at which the linkage is drawn: home, first, middle and last drawing target."""
    draw_targets = np.flatnonzero(np.concatenate(([False], job.draw)))
    poses = [0]
    if draw_targets.size:
        poses += [int(draw_targets[0]), int(draw_targets[draw_targets.size // 2]),
                  int(draw_targets[-1])]
    return list(dict.fromkeys(poses))


def _extent(job: Job, fb: FiveBar, th: FloatArray, pose_pts: FloatArray) -> Box:
    """The drawing, the motors and the linkage at the poses shown (angles th), with room."""
    e1, e2 = fb.elbows(th)
    pts = np.concatenate((job.points_mm, e1, e2, pose_pts, [[0.0, 0.0], [fb.w, 0.0]]))
    lo = pts.min(axis=0)
    hi = pts.max(axis=0)
    pad = 0.08 * float(max(hi - lo))
    return lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad


def _safe_regions(ax: Axes, job: Job, profile: Profile, used: list[str], box: Box) -> Handles:
    """Safe region of each working mode the job draws in (and the machine's assembly)."""
    fb = profile.geometry
    kin = profile.kinematics
    x0, x1, y0, y1 = box
    res = max((x1 - x0), (y1 - y0)) / 300.0
    xs = np.arange(x0, x1 + res, res)
    ys = np.arange(y0, y1 + res, res)
    handles: Handles = []
    for k, m in enumerate(used):
        mask = safe_mask(fb, m, xs, ys, kin.min_type1_margin_rad, kin.min_type2_margin_rad,
                         profile.motors.limits_rad, assembly=_assembly(job))
        fill, edge = _REGION_COLOURS[k % len(_REGION_COLOURS)]
        ax.contourf(xs, ys, mask.astype(float), levels=[0.5, 1.5], colors=[fill], zorder=0,
                    alpha=1.0 if len(used) == 1 else 0.55)
        ax.contour(xs, ys, mask.astype(float), levels=[0.5], colors=[edge], linewidths=0.8,
                   zorder=1)
        handles.append(Patch(facecolor=fill, edgecolor=edge, label=f"safe region, mode {m}"))
    return handles


def _singularities(ax: Axes, fb: FiveBar, used: list[str]) -> Handles:
    """Type-1 loci (reach circles about the motors) and the type-2 curves in the modes used."""
    for (lo_r, hi_r), cx in zip(fb.reach, (0.0, fb.w), strict=True):
        for r in (lo_r, hi_r):
            if r > 0:
                ax.add_patch(Circle((cx, 0.0), r, fill=False, ls=":", lw=0.9,
                                    color="#9467bd", zorder=1))
    handles: Handles = [Line2D([], [], ls=":", color="#9467bd",
                               label="type-1 singularity (reach)")]
    drew_t2 = False
    for tr in type2_traces(fb):
        for line in [ln for m in used for ln in tr.polylines(m)]:
            ax.plot(line[:, 0], line[:, 1], "-", color="#d62728", lw=1.0, alpha=0.7, zorder=1)
            drew_t2 = True
    if drew_t2:
        handles.append(Line2D([], [], color="#d62728", alpha=0.7, label="type-2 singularity"))
    return handles


def _requested(ax: Axes, job: Job) -> Handles:
    """Requested path: the placed drawing flattened finely."""
    poly = flatten(job.drawing, max(job.tolerance_mm / 4, 1e-3))
    hatch = np.array([s.role == "hatch" for s in job.drawing.sources], dtype=bool)
    is_h = hatch[job.drawing.stroke_source[poly.stroke]] if hatch.size else \
        np.zeros(poly.stroke.shape[0], bool)
    for sel, colour, lw in ((~is_h, "black", 2.2), (is_h, "#3a3a8a", 1.2)):
        if sel.any():
            req = _nan_join(poly.points, poly.offsets[:-1][sel], poly.offsets[1:][sel])
            ax.plot(req[:, 0], req[:, 1], "-", color=colour, lw=lw, zorder=3)
    return [Line2D([], [], color="black", lw=2.2, label="requested path")]


def _hidden(ax: Axes, job: Job) -> Handles:
    """What `--hiding` left out (faint, dotted), and the hatch lines in their own colour."""
    from matplotlib.collections import LineCollection

    f = job.drawing.fill
    out: Handles = []
    if f is not None and f.hidden.shape[0]:
        ax.add_collection(LineCollection(list(f.hidden), colors="#9a9a9a", linewidths=0.8,
                                         linestyles=":", zorder=2))
        out.append(Line2D([], [], color="#9a9a9a", lw=0.8, ls=":",
                          label="hidden (--hiding): not drawn"))
    if f is not None and f.hatch:
        out.append(Line2D([], [], color="#3a3a8a", lw=1.2, label="hatch (--hatch)"))
    return out


def _executed_points(fb: FiveBar, th: FloatArray, assembly: str, samples: int) -> FloatArray:
    """Pen points (T, samples + 1, 2) along each segment's joint-space interpolation of the
    quantised step angles th (T + 1, 2), by forward kinematics."""
    s = np.arange(samples + 1) / samples
    dth = np.diff(th, axis=0)
    q = (th[:-1, None, :] + s[None, :, None] * dth[:, None, :])  # (T, S+1, 2)
    fk = fb.forward_batch(q.reshape(-1, 2), assembly).points
    return fk.reshape(-1, samples + 1, 2)


def _executed(ax: Axes, job: Job, fk: FloatArray) -> Handles:
    """Executed path from the quantised steps (draw segments) and the pen-up travel."""
    per = fk.shape[1]
    ex_pts = fk.reshape(-1, 2)
    d0, d1 = _runs(job.draw)
    exe = _nan_join(ex_pts, d0 * per, d1 * per)
    ax.plot(exe[:, 0], exe[:, 1], "-", color="#ff3b30", lw=0.7, zorder=4)
    t0, t1 = _runs(~job.draw)
    trv = _nan_join(ex_pts, t0 * per, t1 * per)
    ax.plot(trv[:, 0], trv[:, 1], "--", color="#7f7f7f", lw=0.7, zorder=2)
    return [Line2D([], [], color="#ff3b30", lw=0.7, label="executed path (quantised steps)"),
            Line2D([], [], ls="--", color="#7f7f7f", label="pen-up travel")]


def _mode_changes(ax: Axes, job: Job, fk: FloatArray) -> Handles:
    """Working-mode changes: the executed pen-up move, where the pen lifts and lands, and
    where an arm passes its type-1 singularity."""
    for n, mc in enumerate(job.mode_changes, start=1):
        seg = fk[mc.first_seg:mc.end_seg].reshape(-1, 2)
        ax.plot(seg[:, 0], seg[:, 1], "-.", color=_CHANGE, lw=1.3, zorder=4)
        ax.plot(*mc.lift_mm, marker="^", color=_CHANGE, ms=9, mec="black", zorder=7)
        ax.plot(*mc.land_mm, marker="v", color=_CHANGE, ms=9, mec="black", zorder=7)
        for _, _, cx, cy in mc.crossings:
            ax.plot(cx, cy, marker="X", color=_CHANGE, ms=9, mec="black", zorder=7)
        ax.annotate(f"{n}: {mc.from_mode} → {mc.to_mode}", mc.lift_mm,
                    textcoords="offset points", xytext=(6, 6), fontsize=9, color="#a34a00",
                    fontweight="bold", zorder=8)
    if not job.mode_changes:
        return []
    return [Line2D([], [], ls="-.", color=_CHANGE, lw=1.3, label="working-mode change (pen up)"),
            Line2D([], [], ls="", marker="^", color=_CHANGE, mec="black",
                   label="mode change: pen lifts (n: from → to)"),
            Line2D([], [], ls="", marker="v", color=_CHANGE, mec="black",
                   label="mode change: pen lands"),
            Line2D([], [], ls="", marker="X", color=_CHANGE, mec="black",
                   label="arm passes its type-1 singularity")]


def _linkages(ax: Axes, fb: FiveBar, th: FloatArray, pose_pts: FloatArray) -> Handles:
    """The linkage at the poses shown (angles th (K, 2), pen points pose_pts), home bold."""
    for k in range(th.shape[0]):
        r1, r2 = fb.elbows(th[k].reshape(1, 2))
        p = pose_pts[k]
        j = fb.joint_from_pen(r1, p.reshape(1, 2))[0]  # the pen unless it is off the joint
        xs = [0.0, r1[0, 0], j[0], r2[0, 0], fb.w]
        ys = [0.0, r1[0, 1], j[1], r2[0, 1], 0.0]
        if not np.array_equal(j, p):  # the extension of link 1 to the pen
            xs[3:3], ys[3:3] = [p[0], r1[0, 0], j[0]], [p[1], r1[0, 1], j[1]]
        ax.plot(xs, ys, "-o", color="#1f77b4", lw=2.0, ms=3.5,
                alpha=0.9 if k == 0 else 0.45, label=None, zorder=5)
    return [Line2D([], [], color="#1f77b4", marker="o", lw=2.0, ms=3.5,
                   label="linkage (home, first, middle, last)")]


def _finish(ax: Axes, job: Job, fb: FiveBar, box: Box, handles: Handles) -> None:
    """Motors, limits, axes, the title with the job's figures, and the legend."""
    ax.plot([0.0, fb.w], [0.0, 0.0], "s", color="black", ms=7, zorder=6)
    ax.annotate("M1", (0.0, 0.0), textcoords="offset points", xytext=(-14, -12), fontsize=9)
    ax.annotate("M2", (fb.w, 0.0), textcoords="offset points", xytext=(4, -12), fontsize=9)
    x0, x1, y0, y1 = box
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_xlabel("x, mm (machine frame, motor M1 at the origin)")
    ax.set_ylabel("y, mm")
    ax.set_title(f"{Path(job.file).name}: mode {mode_sequence(job)}, {job.n_paths} paths, "
                 f"{job.n_segments} segments, ≈ {format_duration(job.total_time_s)}\n"
                 f"max deviation {job.max_dev_mm:.4f} mm (tolerance {job.tolerance_mm:g} mm "
                 f"+ step quantum {job.step_quantum_mm:.4f} mm)", fontsize=10)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              framealpha=0.9)


def _save_atomic(fig: Figure, out: str | Path, dpi: int) -> Path:
    """Write the PNG to a temporary file next to `out`, then rename it into place."""
    out = Path(out)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".png",
                               dir=str(out.parent if str(out.parent) else "."))
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=dpi, format="png", bbox_inches="tight")
        os.replace(tmp, out)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.unlink(tmp)
    return out


def draw_preview(job: Job, profile: Profile, out: str | Path, samples: int = 4,
                 dpi: int = 130) -> Path:
    """Write the preview PNG (see module doc) atomically; returns the path."""
    fb = profile.geometry
    fig, ax = plt.subplots(figsize=(11.0, 8.0))
    th = step_angles(job.joint_steps, job.home_rad, job.steps_per_rev)
    sel = _pose_indices(job)
    pose_pts = fb.forward_batch(th[sel], _assembly(job)).points
    box = _extent(job, fb, th[sel], pose_pts)
    used = list(dict.fromkeys(job.path_modes or (job.mode,)))
    handles = _safe_regions(ax, job, profile, used, box)
    handles += _singularities(ax, fb, used)
    handles += _requested(ax, job)
    handles += _hidden(ax, job)
    fk = _executed_points(fb, th, _assembly(job), samples)
    handles += _executed(ax, job, fk)
    handles += _mode_changes(ax, job, fk)
    handles += _linkages(ax, fb, th[sel], pose_pts)
    _finish(ax, job, fb, box, handles)
    fig.tight_layout()
    return _save_atomic(fig, out, dpi)
