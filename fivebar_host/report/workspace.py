"""The workspace picture of `fivebar workspace` (matplotlib, Agg backend: no display needed).

Top row, one panel per working mode: reachable area, safe region (connected to the page, and
safe islands apart from it), singularity curves and the largest page. Bottom row, for the
analysed mode and zoomed on its safe region: the transmission-angle map (Eq. 23), the step
quantum with the thesis' ±δ traces (Sec. 4.1, Fig. 18) and the Jacobian condition number.
The numbers come from `kinematics.workspace.workspace_report`; the text and files from
`fivebar_host.report.text.workspace`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import FigureBase
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Rectangle

from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace import Rect, WorkspaceReport, perturbation_displacements, type1_circles

Box = tuple[float, float, float, float]  # x0, x1, y0, y1 of a view, mm
PAGE_COLOR = "#17becf"
MOTOR_COLORS = ("#0000cd", "#000000")
TRACE_STYLE: dict[str, dict[str, Any]] = {
    "1a": {"color": "#d62728", "lw": 2.0, "ls": "-",
           "label": "type-2 singularity, Mode 1a (b1, b2 stretched in line)"},
    "1b-II": {"color": "#ff7f0e", "lw": 2.0, "ls": "-",
              "label": "type-2 singularity, Mode 1b class II (b1, b2 folded)"},
    "1b-I": {"color": "#9467bd", "lw": 2.0, "ls": "--",
             "label": "type-2 singularity, Mode 1b class I circle (R1 = R2, b1 = b2)"},
}


# ----------------------------------------------------------------------------- pieces
def _base(ax: Axes, fb: FiveBar) -> None:
    """Motors, the base link and the type-1 circles (reach boundaries)."""
    for _arm, kind, (cx, cy), rad in type1_circles(fb):
        ax.add_patch(Circle((cx, cy), rad, fill=False, lw=0.8, color="0.35",
                            ls=":" if kind == "folded" else "-."))
    ax.plot([0, fb.w], [0, 0], color="k", lw=3, solid_capstyle="round")
    ax.plot([0, fb.w], [0, 0], "ko", ms=6)
    ax.annotate("M1", (0, 0), textcoords="offset points", xytext=(-14, -12), fontsize=9)
    ax.annotate("M2", (fb.w, 0), textcoords="offset points", xytext=(4, -12), fontsize=9)


def _traces(ax: Axes, rep: WorkspaceReport, mode: str) -> set[str]:
    """The type-2 curves in working mode `mode`; returns the kinds drawn."""
    kinds: set[str] = set()
    for tr in rep.traces:
        st = TRACE_STYLE[tr.kind]
        for line in tr.polylines(mode):
            ax.plot(line[:, 0], line[:, 1], color=st["color"], lw=st["lw"], ls=st["ls"])
            kinds.add(tr.kind)
    return kinds


def _rect(ax: Axes, r: Rect, color: str = "#1f77b4", ls: str = "-") -> None:
    ax.add_patch(Rectangle((r.x0, r.y0), r.width, r.height, fill=False, lw=2.2, ec=color,
                           ls=ls))


def _frame(ax: Axes, box: Box) -> None:
    x0, x1, y0, y1 = box
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.grid(True, lw=0.3, alpha=0.5)


def _safe_outline(ax: Axes, rep: WorkspaceReport) -> None:
    ax.contour(rep.xs, rep.ys, rep.fit.region.astype(float), levels=[0.5], colors="k",
               linewidths=1.4)
    if rep.page is not None:
        _rect(ax, rep.page, PAGE_COLOR, "--")


# ----------------------------------------------------------------------------- top row
def _mode_panel(ax: Axes, rep: WorkspaceReport, fb: FiveBar, m: str, box: Box) -> set[str]:
    """Reach, safe region (and islands), page and singularity curves of working mode `m`;
    returns the type-2 kinds drawn."""
    ax.contourf(rep.xs, rep.ys, rep.reach.astype(float), levels=[0.5, 1.5], colors=["0.88"])
    f = rep.fits[m]
    head = f"mode {m}" + (" (analysed)" if m == rep.mode else "")
    if f is not None:
        islands = f.mask & ~f.region
        if islands.any():
            ax.contourf(f.xs, f.ys, islands.astype(float), levels=[0.5, 1.5],
                        colors=["#d4f0cc"], hatches=["//"])
        ax.contourf(f.xs, f.ys, f.region.astype(float), levels=[0.5, 1.5], colors=["#98df8a"])
        _rect(ax, f.rect)
        if m == rep.mode and rep.page is not None:
            _rect(ax, rep.page, PAGE_COLOR, "--")
        head += (f"\nusable {f.usable_area_mm2:.0f} mm², page "
                 f"{f.rect.width:.0f} x {f.rect.height:.0f} mm")
    else:
        head += "\nno safe region"
    kinds = _traces(ax, rep, m)
    _base(ax, fb)
    _frame(ax, box)
    ax.set_title(head, fontsize=11)
    return kinds


def _legend_handles(rep: WorkspaceReport, trace_kinds: set[str]) -> list[Any]:
    """The shared legend of the mode panels."""
    handles: list[Any] = [
        Patch(color="0.88", label="reachable (both arms)"),
        Patch(color="#98df8a", label="safe (margins, joint limits), connected to the page"),
        Patch(facecolor="#d4f0cc", hatch="//", label="safe island not connected to it"),
        Line2D([], [], color="#1f77b4", lw=2.2, label="largest page rectangle"),
        Line2D([], [], color="0.35", lw=0.8, ls="-.",
               label="type-1 singularity: arm stretched (reach circle)"),
        Line2D([], [], color="0.35", lw=0.8, ls=":",
               label="type-1 singularity: arm folded (dead-zone circle)"),
    ]
    for kind in ("1a", "1b-II", "1b-I"):
        if kind in trace_kinds:
            st = TRACE_STYLE[kind]
            handles.append(Line2D([], [], color=st["color"], lw=st["lw"], ls=st["ls"],
                                  label=st["label"]))
    if rep.page is not None:
        handles.append(Line2D([], [], color=PAGE_COLOR, lw=2.2, ls="--",
                              label=f"asked page {rep.page.width:g} x {rep.page.height:g} mm"))
    return handles


# ----------------------------------------------------------------------------- bottom row
def _zoom(rep: WorkspaceReport) -> Box:
    """The view of the detail maps: the analysed mode's safe region with 15 % room."""
    gx, gy = np.meshgrid(rep.xs, rep.ys)
    sx, sy = gx[rep.fit.region], gy[rep.fit.region]
    pad = 0.15 * max(float(sx.max() - sx.min()), float(sy.max() - sy.min()), 1.0)
    return (float(sx.min()) - pad, float(sx.max()) + pad,
            float(sy.min()) - pad, float(sy.max()) + pad)


def _overlay(ax: Axes, rep: WorkspaceReport, fb: FiveBar, zoom: Box) -> None:
    """Safe-region outline, page rectangle, base and frame over a detail map."""
    _safe_outline(ax, rep)
    _rect(ax, rep.fit.rect)
    _base(ax, fb)
    _frame(ax, zoom)


def _transmission_panel(ax: Axes, sub: FigureBase, rep: WorkspaceReport, fb: FiveBar,
                        zoom: Box) -> None:
    """Worst arm |μ − 90°| (Eq. 23) with the thesis' 50° limit dashed."""
    dev = np.degrees(np.fmax(np.abs(rep.mu[..., 0] - 0.5 * math.pi),
                             np.abs(rep.mu[..., 1] - 0.5 * math.pi)))
    im = ax.pcolormesh(rep.xs, rep.ys, np.ma.masked_invalid(dev), cmap="viridis_r",
                       vmin=0, vmax=90, shading="nearest")
    cs = ax.contour(rep.xs, rep.ys, np.nan_to_num(dev, nan=90.0), levels=[50.0],
                    colors="w", linewidths=1.2, linestyles="--")
    ax.clabel(cs, fmt="%g°", fontsize=9)
    sub.colorbar(im, ax=ax, shrink=0.7, label="worst arm |μ − 90°| (deg)")
    _overlay(ax, rep, fb, zoom)
    ax.set_title(f"transmission angle (Eq. 23), mode {rep.mode}\nwhite dashed: 50° from 90° "
                 "(thesis limit); black: safe region", fontsize=11)


def _step_panel(ax: Axes, sub: FigureBase, rep: WorkspaceReport, fb: FiveBar,
                zoom: Box) -> None:
    """Pen displacement per motor step, colour clipped to the safe region's 0.5–99.5 %, with
    the ±δ traces per motor."""
    q = np.fmax(rep.step[..., 0], rep.step[..., 1]) * 1000.0
    qs = q[rep.fit.region]
    vmin = float(np.nanpercentile(qs, 0.5)) if qs.size else 0.0
    vmax = float(np.nanpercentile(qs, 99.5)) if qs.size else float(np.nanmax(q))
    im = ax.pcolormesh(rep.xs, rep.ys, np.ma.masked_invalid(q), cmap="YlOrRd",
                       vmin=vmin, vmax=max(vmax, vmin * 1.01 + 1e-9), shading="nearest")
    sub.colorbar(im, ax=ax, shrink=0.7, label="pen displacement per motor step (µm)")
    _traces_delta(ax, rep, fb, zoom)
    _overlay(ax, rep, fb, zoom)
    ax.set_title(f"error sensitivity: step quantum ({math.degrees(rep.rad_per_step):.4f}°/step)"
                 f"\nwith ±{math.degrees(rep.delta_rad):g}° traces per motor (thesis Sec. 4.1)",
                 fontsize=11)
    ax.legend(handles=[Line2D([], [], color=MOTOR_COLORS[0], lw=1.5, label="motor 1 turned ±δ"),
                       Line2D([], [], color=MOTOR_COLORS[1], lw=1.5, label="motor 2 turned ±δ")],
              loc="lower right", fontsize=9)


def _condition_panel(ax: Axes, sub: FigureBase, rep: WorkspaceReport, fb: FiveBar,
                     zoom: Box) -> None:
    """Jacobian condition number, colour clipped at the safe region's 99th percentile."""
    c = np.where(np.isfinite(rep.cond), rep.cond, np.nan)
    cs_vals = c[rep.fit.region]
    cmax = float(np.nanpercentile(cs_vals, 99)) if cs_vals.size else 100.0
    im = ax.pcolormesh(rep.xs, rep.ys, np.ma.masked_invalid(c), cmap="cividis",
                       vmin=1.0, vmax=min(max(cmax, 2.0), 50.0), shading="nearest")
    sub.colorbar(im, ax=ax, shrink=0.7, label="condition number of J (1 = isotropic)")
    _overlay(ax, rep, fb, zoom)
    ax.set_title(f"Jacobian condition number σmax/σmin, mode {rep.mode}\n"
                 "(colour clipped at the safe region's 99th percentile)", fontsize=11)


def _traces_delta(ax: Axes, rep: WorkspaceReport, fb: FiveBar, box: Box) -> None:
    """The thesis' skewed-x traces (Sec. 4.1, Fig. 18): at sample points ~1/12 of the view
    apart inside the safe region, the pen path while motor i alone turns through −δ … +δ
    (exact forward kinematics, 9 samples per trace)."""
    x0, x1, y0, y1 = box
    step = max((x1 - x0), (y1 - y0)) / 12.0
    px, py = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    pts = np.stack((px.ravel(), py.ravel()), axis=1)
    res = rep.fit.resolution_mm
    ix = np.clip(np.rint((pts[:, 0] - rep.xs[0]) / res).astype(int), 0, rep.xs.size - 1)
    iy = np.clip(np.rint((pts[:, 1] - rep.ys[0]) / res).astype(int), 0, rep.ys.size - 1)
    pts = pts[rep.fit.region[iy, ix]]
    if pts.shape[0] == 0:
        return
    fracs = np.linspace(-1.0, 1.0, 9)
    for i, color in ((0, MOTOR_COLORS[0]), (1, MOTOR_COLORS[1])):
        legs = []
        for t in fracs:
            if t == 0.0:
                legs.append(pts)
                continue
            d = perturbation_displacements(fb, rep.mode, pts, abs(t) * rep.delta_rad)
            legs.append(pts + d[:, i, 1 if t > 0 else 0])
        path = np.stack(legs, axis=1)
        for line in path:
            ax.plot(line[:, 0], line[:, 1], color=color, lw=1.3)


# ----------------------------------------------------------------------------- figure
def plot_workspace(rep: WorkspaceReport, fb: FiveBar, path: Path, title: str = "") -> None:
    """Draw the workspace report to a PNG: one panel per working mode (reach, safe region,
    singularity curves, page) and, for the analysed mode, the transmission-angle, step-
    quantum (with the thesis' ±δ traces) and condition-number maps."""
    fig = plt.figure(figsize=(21, 14), dpi=100, layout="constrained")
    subs = np.asarray(fig.subfigures(2, 1, height_ratios=[1.0, 1.0])).ravel()
    top, bottom = subs[0], subs[1]
    top_axes = top.subplots(1, 4)
    low_axes = bottom.subplots(1, 3)
    box = (float(rep.xs[0]), float(rep.xs[-1]), float(rep.ys[0]), float(rep.ys[-1]))
    trace_kinds: set[str] = set()
    for k, m in enumerate(WORKING_MODES):
        trace_kinds |= _mode_panel(top_axes[k], rep, fb, m, box)
    fig.legend(handles=_legend_handles(rep, trace_kinds), loc="outside lower center", ncol=4,
               fontsize=10, frameon=False)
    # Detail maps of the analysed mode, zoomed on its safe region.
    zoom = _zoom(rep)
    _transmission_panel(low_axes[0], bottom, rep, fb, zoom)
    _step_panel(low_axes[1], bottom, rep, fb, zoom)
    _condition_panel(low_axes[2], bottom, rep, fb, zoom)
    fig.suptitle((title or "fivebar workspace") + f" — working modes (top), detail of mode "
                 f"{rep.mode} (bottom)", fontsize=14)
    fig.savefig(path)
    plt.close(fig)
