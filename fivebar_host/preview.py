"""Dry-run output: the preview picture and the text report of a compiled job.

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

import math
import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch
from numpy.typing import NDArray

from fivebar_host.compile import Job, NbarOpinion
from fivebar_host.config import Profile
from fivebar_host.steps import step_angles
from fivebar_host.toolpath.geometry import flatten
from kinematics import analysis
from kinematics.fivebar import FiveBar

FloatArray = NDArray[np.float64]
#: (fill, edge) colours of the safe regions of the working modes a job draws in.
_REGION_COLOURS = (("#d9f2d9", "#5aa05a"), ("#dde8fb", "#4a78c2"), ("#fbe3d0", "#c27a3a"),
                   ("#eadcf5", "#8a5cb0"))


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


def _linkage(ax: Axes, fb: FiveBar, th: FloatArray, p: FloatArray, label: str | None,
             alpha: float) -> None:
    r1, r2 = fb.elbows(th.reshape(1, 2))
    xs = [0.0, r1[0, 0], p[0], r2[0, 0], fb.w]
    ys = [0.0, r1[0, 1], p[1], r2[0, 1], 0.0]
    ax.plot(xs, ys, "-o", color="#1f77b4", lw=2.0, ms=3.5, alpha=alpha, label=label,
            zorder=5)


def draw_preview(job: Job, profile: Profile, out: str | Path, samples: int = 4,
                 dpi: int = 130) -> Path:
    """Write the preview PNG (see module doc) atomically; returns the path."""
    fb = profile.geometry
    kin = profile.kinematics
    fig, ax = plt.subplots(figsize=(11.0, 8.0))
    th = step_angles(job.steps, job.home_rad, job.steps_per_rev)
    draw_targets = np.flatnonzero(np.concatenate(([False], job.draw)))
    poses = [0]
    if draw_targets.size:
        poses += [int(draw_targets[0]), int(draw_targets[draw_targets.size // 2]),
                  int(draw_targets[-1])]
    sel = list(dict.fromkeys(poses))
    pose_pts = fb.forward_batch(th[sel], "+" if job.assembly > 0 else "-").points
    # Extent: the drawing, the motors and the linkage at the poses shown, with some room.
    e1, e2 = fb.elbows(th[sel])
    pts = np.concatenate((job.points_mm, e1, e2, pose_pts, [[0.0, 0.0], [fb.w, 0.0]]))
    lo = pts.min(axis=0)
    hi = pts.max(axis=0)
    pad = 0.08 * float(max(hi - lo))
    x0, x1, y0, y1 = lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad
    # Safe region of each working mode the job draws in (and the machine's assembly).
    res = max((x1 - x0), (y1 - y0)) / 300.0
    xs = np.arange(x0, x1 + res, res)
    ys = np.arange(y0, y1 + res, res)
    used = list(dict.fromkeys(job.path_modes or (job.mode,)))
    handles: list[Line2D | Patch] = []
    for k, m in enumerate(used):
        mask = analysis.safe_mask(fb, m, xs, ys, kin.min_type1_margin_rad,
                                  kin.min_type2_margin_rad, profile.motors.limits_rad,
                                  assembly="+" if job.assembly > 0 else "-")
        fill, edge = _REGION_COLOURS[k % len(_REGION_COLOURS)]
        ax.contourf(xs, ys, mask.astype(float), levels=[0.5, 1.5], colors=[fill], zorder=0,
                    alpha=1.0 if len(used) == 1 else 0.55)
        ax.contour(xs, ys, mask.astype(float), levels=[0.5], colors=[edge], linewidths=0.8,
                   zorder=1)
        handles.append(Patch(facecolor=fill, edgecolor=edge, label=f"safe region, mode {m}"))
    # Type-1 loci: reach circles about the motors.
    for (lo_r, hi_r), cx in zip(fb.reach, (0.0, fb.w), strict=True):
        for r in (lo_r, hi_r):
            if r > 0:
                ax.add_patch(Circle((cx, 0.0), r, fill=False, ls=":", lw=0.9,
                                    color="#9467bd", zorder=1))
    handles.append(Line2D([], [], ls=":", color="#9467bd", label="type-1 singularity (reach)"))
    traces = getattr(analysis, "type2_traces", None)
    drew_t2 = False
    if traces is not None:
        for tr in traces(fb):
            for line in [ln for m in used for ln in tr.polylines(m)]:
                ax.plot(line[:, 0], line[:, 1], "-", color="#d62728", lw=1.0, alpha=0.7,
                        zorder=1)
                drew_t2 = True
    else:  # the zero level of the type-2 margin over the grid
        gx, gy = np.meshgrid(xs, ys)
        g = np.stack((gx.ravel(), gy.ravel()), axis=1)
        inv = fb.inverse_batch(g, used[0])
        marg = fb.singularity_margins(inv.angles, g)[:, 2]
        marg[~inv.valid] = np.nan
        ax.contour(xs, ys, marg.reshape(gx.shape), levels=[0.0], colors=["#d62728"],
                   linewidths=1.0)
        drew_t2 = True
    if drew_t2:
        handles.append(Line2D([], [], color="#d62728", alpha=0.7,
                              label="type-2 singularity"))
    # Requested path: the placed drawing flattened finely.
    poly = flatten(job.drawing, max(job.tolerance_mm / 4, 1e-3))
    req = _nan_join(poly.points, poly.offsets[:-1], poly.offsets[1:])
    ax.plot(req[:, 0], req[:, 1], "-", color="black", lw=2.2, zorder=3)
    handles.append(Line2D([], [], color="black", lw=2.2, label="requested path"))
    # Executed path from the quantised steps (draw segments), samples per segment.
    s = np.arange(samples + 1) / samples
    dth = np.diff(th, axis=0)
    q = (th[:-1, None, :] + s[None, :, None] * dth[:, None, :])  # (T, S+1, 2)
    fk = fb.forward_batch(q.reshape(-1, 2), "+" if job.assembly > 0 else "-").points
    fk = fk.reshape(-1, samples + 1, 2)
    d0, d1 = _runs(job.draw)
    ex_pts = fk.reshape(-1, 2)
    per = samples + 1
    exe = _nan_join(ex_pts, d0 * per, d1 * per)
    ax.plot(exe[:, 0], exe[:, 1], "-", color="#ff3b30", lw=0.7, zorder=4)
    handles.append(Line2D([], [], color="#ff3b30", lw=0.7,
                          label="executed path (quantised steps)"))
    t0, t1 = _runs(~job.draw)
    trv = _nan_join(ex_pts, t0 * per, t1 * per)
    ax.plot(trv[:, 0], trv[:, 1], "--", color="#7f7f7f", lw=0.7, zorder=2)
    handles.append(Line2D([], [], ls="--", color="#7f7f7f", label="pen-up travel"))
    # Working-mode changes: the executed pen-up move, where the pen lifts and lands, and
    # where an arm passes its type-1 singularity.
    for n, mc in enumerate(job.mode_changes, start=1):
        seg = fk[mc.first_seg:mc.end_seg].reshape(-1, 2)
        ax.plot(seg[:, 0], seg[:, 1], "-.", color="#ff7f0e", lw=1.3, zorder=4)
        ax.plot(*mc.lift_mm, marker="^", color="#ff7f0e", ms=9, mec="black", zorder=7)
        ax.plot(*mc.land_mm, marker="v", color="#ff7f0e", ms=9, mec="black", zorder=7)
        for _, _, cx, cy in mc.crossings:
            ax.plot(cx, cy, marker="X", color="#ff7f0e", ms=9, mec="black", zorder=7)
        ax.annotate(f"{n}: {mc.from_mode} → {mc.to_mode}", mc.lift_mm,
                    textcoords="offset points", xytext=(6, 6), fontsize=9, color="#a34a00",
                    fontweight="bold", zorder=8)
    if job.mode_changes:
        handles += [Line2D([], [], ls="-.", color="#ff7f0e", lw=1.3,
                           label="working-mode change (pen up)"),
                    Line2D([], [], ls="", marker="^", color="#ff7f0e", mec="black",
                           label="mode change: pen lifts (n: from → to)"),
                    Line2D([], [], ls="", marker="v", color="#ff7f0e", mec="black",
                           label="mode change: pen lands"),
                    Line2D([], [], ls="", marker="X", color="#ff7f0e", mec="black",
                           label="arm passes its type-1 singularity")]
    # Linkage at a few poses.
    for k, i in enumerate(sel):
        _linkage(ax, fb, th[i], pose_pts[k], None, 0.9 if k == 0 else 0.45)
    handles.append(Line2D([], [], color="#1f77b4", marker="o", lw=2.0, ms=3.5,
                          label="linkage (home, first, middle, last)"))
    ax.plot([0.0, fb.w], [0.0, 0.0], "s", color="black", ms=7, zorder=6)
    ax.annotate("M1", (0.0, 0.0), textcoords="offset points", xytext=(-14, -12), fontsize=9)
    ax.annotate("M2", (fb.w, 0.0), textcoords="offset points", xytext=(4, -12), fontsize=9)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_xlabel("x, mm (machine frame, motor M1 at the origin)")
    ax.set_ylabel("y, mm")
    ax.set_title(f"{Path(job.file).name}: mode {_mode_sequence(job)}, {job.n_paths} paths, "
                 f"{job.n_segments} segments, ≈ {_fmt_time(job.total_time_s)}\n"
                 f"max deviation {job.max_dev_mm:.4f} mm (tolerance {job.tolerance_mm:g} mm "
                 f"+ step quantum {job.step_quantum_mm:.4f} mm)", fontsize=10)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              framealpha=0.9)
    fig.tight_layout()
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


def _mode_sequence(job: Job) -> str:
    """"+-" for a one-mode job; "++ (#0–#1) → +- (#2–#3)" for the paths' working modes."""
    modes = job.path_modes or (job.mode,)
    if len(set(modes)) == 1:
        return modes[0]
    runs: list[tuple[str, int, int]] = []
    for i, m in enumerate(modes):
        if runs and runs[-1][0] == m:
            runs[-1] = (m, runs[-1][1], i)
        else:
            runs.append((m, i, i))
    return " → ".join(f"{m} (#{a})" if a == b else f"{m} (#{a}–#{b})" for m, a, b in runs)


def _fmt_time(t: float) -> str:
    if t < 60:
        return f"{t:.1f} s"
    m, s = divmod(t, 60.0)
    if m < 60:
        return f"{int(m)} min {s:.0f} s"
    h, m = divmod(m, 60.0)
    return f"{int(h)} h {int(m)} min"


def report_lines(job: Job, nbar: NbarOpinion | None = None, laser: bool = False) -> list[str]:
    """The dry-run report: paths, segments, lengths, time, deviation, margins, mode, tool (pen,
    or laser with `laser`: the power the job would send) and the n-bar solver's second
    opinion on the deviation when given."""
    deg = math.degrees
    mm = job.min_margin_rad
    pl = job.placement
    w, h = pl.size_mm
    bx = pl.machine_bbox
    worst = int(np.nanargmax(job.paths.max_dev_mm)) if np.isfinite(
        job.paths.max_dev_mm).any() else -1
    lines = [
        f"file          {job.file}",
        f"working mode  {_mode_sequence(job)} (assembly {'+' if job.assembly > 0 else '-'}"
        + (f"; {len(job.mode_changes)} pen-up working-mode change(s), listed below; the "
           f"homed pose is in {job.home_mode})" if job.mode_changes else ")"),
        f"placement     {pl.how}: scale {pl.scale:.4g}, rotation {pl.rotate_deg:g}°, "
        f"{w:.1f} × {h:.1f} mm at ({bx[0]:.1f}, {bx[1]:.1f})–({bx[2]:.1f}, {bx[3]:.1f}) mm",
        ("tool          laser: S up to "
         f"{int(job.power.max(initial=0))} while drawing, S0 on travel (--laser)" if laser
         else "tool          pen: S0 on every line (no laser power without --laser); pen "
              "down/up = M3/M5 around drawing strokes"),
        f"paths         {job.n_paths} ({job.joined} joined across gaps < tolerance)",
        f"segments      {job.n_segments} ({int(job.draw.sum())} drawing, "
        f"{int((~job.draw).sum())} travel)",
        f"drawing       {job.draw_length_mm:.1f} mm",
        f"travel        {job.travel_length_mm:.1f} mm (pen-up straight-line estimate "
        f"{job.travel_before_mm:.1f} mm in file order → {job.travel_after_mm:.1f} mm "
        "reordered)",
        f"time          ≈ {_fmt_time(job.total_time_s)} (planned durations)",
        f"tolerance     {job.tolerance_mm:g} mm (curves flattened to "
        f"{job.flatten_tol_mm:g} mm, the rest for joint-space interpolation)",
        f"deviation     max {job.max_dev_mm:.4f} mm, mean {job.mean_dev_mm:.4f} mm "
        f"(from the quantised steps; bound {job.tolerance_mm:g} + step quantum "
        f"{job.step_quantum_mm:.4f} = {job.tolerance_mm + job.step_quantum_mm:.4f} mm)",
    ]
    if nbar is not None:
        lines.append(f"2nd opinion   {nbar.describe()}")
    if worst >= 0 and job.n_paths > 1:
        lines.append(f"worst path    #{worst} (source element "
                     f"#{int(job.paths.source[worst])}): max "
                     f"{job.paths.max_dev_mm[worst]:.4f} mm")
    lines.append(f"margins       smallest type 1: {deg(min(mm[0], mm[1])):.1f}° "
                 f"(arm 1 {deg(mm[0]):.1f}°, arm 2 {deg(mm[1]):.1f}°), type 2: "
                 f"{deg(mm[2]):.1f}°")
    lines.extend(f"mode change {k:<2d}{mc.describe(job.n_paths)}"
                 for k, mc in enumerate(job.mode_changes, start=1))
    lines.extend(f"note          {n}" for n in job.notes)
    return lines
