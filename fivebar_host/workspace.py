"""Workspace and design reports: summary text, CSV/JSON numbers, the workspace picture and the
profile written by `fivebar design`. The math lives in `kinematics.workspace`; this module only
formats and draws (matplotlib, Agg backend, so it runs without a display).
"""

from __future__ import annotations

import csv
import json
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Rectangle

from fivebar_host.config import ConfigError, parse_profile
from kinematics.design import DesignCandidate, DesignResult
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace import (
    Rect,
    WorkspaceReport,
    perturbation_displacements,
    type1_circles,
)

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


# ----------------------------------------------------------------------------- text
def summary_lines(rep: WorkspaceReport, fb: FiveBar) -> list[str]:
    """The figures `fivebar workspace` prints."""
    st = rep.stats
    r = rep.fit.rect
    lines = [f"geometry a1={fb.a1:g} b1={fb.b1:g} a2={fb.a2:g} b2={fb.b2:g} w={fb.w:g} mm; "
             f"grid {rep.fit.resolution_mm:.3g} mm"]
    for m in WORKING_MODES:
        f = rep.fits[m]
        mark = "*" if m == rep.mode else " "
        if f is None:
            lines.append(f"{mark} mode {m}: no safe region")
        else:
            lines.append(f"{mark} mode {m}: usable area {f.usable_area_mm2:.0f} mm² (assembly "
                         f"{f.assembly}), largest page {f.rect.width:.1f} x {f.rect.height:.1f}"
                         f" mm")
    lines += [
        f"working mode {rep.mode}, assembly {rep.fit.assembly}",
        f"usable area: {rep.fit.usable_area_mm2:.0f} mm²",
        f"largest page rectangle: {r.width:.1f} x {r.height:.1f} mm at x = {r.x0:.1f} .. "
        f"{r.x1:.1f}, y = {r.y0:.1f} .. {r.y1:.1f} mm (area {r.area:.0f} mm²)",
        f"step quantum in the page: worst {st.worst_step_mm * 1000:.1f} µm, median "
        f"{st.median_step_mm * 1000:.1f} µm per motor step "
        f"({math.degrees(rep.rad_per_step):.4f}° per step)",
        f"±{math.degrees(rep.delta_rad):g}° motor error in the page: worst "
        f"{_page_max(rep, rep.delta):.2f} mm; sensitivity worst "
        f"{st.worst_sens_mm_per_rad:.1f} mm/rad, median {st.median_sens_mm_per_rad:.1f} mm/rad",
        f"transmission angle in the page: worst |μ − 90°| = "
        f"{math.degrees(st.worst_mu_dev_rad):.1f}° (thesis: keep within 50°)",
        f"Jacobian condition number in the page: worst {st.worst_cond:.2f}",
        f"singularity margins in the page: type 1 ≥ {math.degrees(st.min_type1_rad):.1f}°, "
        f"type 2 ≥ {math.degrees(st.min_type2_rad):.1f}°",
    ]
    if rep.page_asked is not None:
        pw, ph = rep.page_asked
        if rep.page is None:
            lines.append(f"page {pw:g} x {ph:g} mm: does NOT fit")
        else:
            p = rep.page
            lines.append(f"page {pw:g} x {ph:g} mm: fits at x = {p.x0:.1f} .. {p.x1:.1f}, "
                         f"y = {p.y0:.1f} .. {p.y1:.1f} mm")
    return lines


def _page_max(rep: WorkspaceReport, field: np.ndarray) -> float:
    """Max of a per-motor grid field (ny, nx, 2) over the grid nodes inside the page."""
    r = rep.fit.rect
    gx, gy = np.meshgrid(rep.xs, rep.ys)
    inside = (gx >= r.x0) & (gx <= r.x1) & (gy >= r.y0) & (gy <= r.y1)
    if not inside.any():
        return float("nan")
    return float(np.nanmax(field[inside]))


def _rect_dict(r: Rect | None) -> dict[str, float] | None:
    if r is None:
        return None
    return {"x0_mm": r.x0, "y0_mm": r.y0, "width_mm": r.width, "height_mm": r.height}


def summary_dict(rep: WorkspaceReport, fb: FiveBar) -> dict[str, Any]:
    """The printed figures as a JSON-ready dict (lengths mm, areas mm², angles deg)."""
    st = rep.stats
    return {
        "geometry": {"a1": fb.a1, "b1": fb.b1, "a2": fb.a2, "b2": fb.b2, "w": fb.w},
        "working_mode": rep.mode,
        "assembly": rep.fit.assembly,
        "grid_mm": rep.fit.resolution_mm,
        "usable_area_mm2": rep.fit.usable_area_mm2,
        "page_rectangle": _rect_dict(rep.fit.rect),
        "modes": {m: (None if f is None else {
            "usable_area_mm2": f.usable_area_mm2, "assembly": f.assembly,
            "page_rectangle": _rect_dict(f.rect)}) for m, f in rep.fits.items()},
        "step_quantum_um": {"worst": st.worst_step_mm * 1000, "median": st.median_step_mm * 1000},
        "deg_per_step": math.degrees(rep.rad_per_step),
        "delta_deg": math.degrees(rep.delta_rad),
        "delta_displacement_worst_mm": _page_max(rep, rep.delta),
        "sensitivity_mm_per_rad": {"worst": st.worst_sens_mm_per_rad,
                                   "median": st.median_sens_mm_per_rad},
        "transmission_worst_dev_deg": math.degrees(st.worst_mu_dev_rad),
        "condition_number_worst": st.worst_cond,
        "margins_min_deg": {"type1": math.degrees(st.min_type1_rad),
                            "type2": math.degrees(st.min_type2_rad)},
        "page_asked": (None if rep.page_asked is None
                       else {"width_mm": rep.page_asked[0], "height_mm": rep.page_asked[1]}),
        "page_fits": None if rep.page_asked is None else rep.page is not None,
        "page": _rect_dict(rep.page),
    }


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write a summary dict as indented JSON."""
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def write_csv(path: Path, rep: WorkspaceReport) -> int:
    """One row per reachable grid node of the analysed mode; returns the row count.

    Columns: x_mm, y_mm, safe (0/1), mu1_deg, mu2_deg, step1_um, step2_um (larger pen
    displacement of −/+ one step of motor i), delta1_mm, delta2_mm (same for ±δ),
    sens1_mm_per_rad, sens2_mm_per_rad, cond."""
    gx, gy = np.meshgrid(rep.xs, rep.ys)
    sel = rep.reach
    cols = [gx[sel], gy[sel], rep.safe[sel].astype(int),
            np.degrees(rep.mu[sel][:, 0]), np.degrees(rep.mu[sel][:, 1]),
            rep.step[sel][:, 0] * 1000, rep.step[sel][:, 1] * 1000,
            rep.delta[sel][:, 0], rep.delta[sel][:, 1],
            rep.sens[sel][:, 0], rep.sens[sel][:, 1], rep.cond[sel]]
    head = ["x_mm", "y_mm", "safe", "mu1_deg", "mu2_deg", "step1_um", "step2_um",
            "delta1_mm", "delta2_mm", "sens1_mm_per_rad", "sens2_mm_per_rad", "cond"]
    with path.open("w", newline="", encoding="utf-8") as fh:
        wr = csv.writer(fh)
        wr.writerow(head)
        for row in zip(*cols, strict=True):
            wr.writerow([f"{v:.6g}" if isinstance(v, float | np.floating) else int(v)
                         for v in row])
    return int(sel.sum())


# ----------------------------------------------------------------------------- picture
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


def _frame(ax: Axes, x0: float, x1: float, y0: float, y1: float) -> None:
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


def plot_workspace(rep: WorkspaceReport, fb: FiveBar, path: Path, title: str = "") -> None:
    """Draw the workspace report to a PNG: one panel per working mode (reach, safe region,
    singularity curves, page) and, for the analysed mode, the transmission-angle, step-
    quantum (with the thesis' ±δ traces) and condition-number maps."""
    fig = plt.figure(figsize=(21, 14), dpi=100, layout="constrained")
    subs = np.asarray(fig.subfigures(2, 1, height_ratios=[1.0, 1.0])).ravel()
    top, bottom = subs[0], subs[1]
    top_axes = top.subplots(1, 4)
    low_axes = bottom.subplots(1, 3)
    x_min, x_max = float(rep.xs[0]), float(rep.xs[-1])
    y_min, y_max = float(rep.ys[0]), float(rep.ys[-1])
    reach = rep.reach.astype(float)
    trace_kinds: set[str] = set()
    for k, m in enumerate(WORKING_MODES):
        ax = top_axes[k]
        ax.contourf(rep.xs, rep.ys, reach, levels=[0.5, 1.5], colors=["0.88"])
        f = rep.fits[m]
        head = f"mode {m}" + (" (analysed)" if m == rep.mode else "")
        if f is not None:
            islands = f.mask & ~f.region
            if islands.any():
                ax.contourf(f.xs, f.ys, islands.astype(float), levels=[0.5, 1.5],
                            colors=["#d4f0cc"], hatches=["//"])
            ax.contourf(f.xs, f.ys, f.region.astype(float), levels=[0.5, 1.5],
                        colors=["#98df8a"])
            _rect(ax, f.rect)
            if m == rep.mode and rep.page is not None:
                _rect(ax, rep.page, PAGE_COLOR, "--")
            head += (f"\nusable {f.usable_area_mm2:.0f} mm², page "
                     f"{f.rect.width:.0f} x {f.rect.height:.0f} mm")
        else:
            head += "\nno safe region"
        trace_kinds |= _traces(ax, rep, m)
        _base(ax, fb)
        _frame(ax, x_min, x_max, y_min, y_max)
        ax.set_title(head, fontsize=11)
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
    fig.legend(handles=handles, loc="outside lower center", ncol=4, fontsize=10,
               frameon=False)

    # Detail maps of the analysed mode, zoomed on its safe region.
    gx, gy = np.meshgrid(rep.xs, rep.ys)
    region = rep.fit.region
    sx, sy = gx[region], gy[region]
    pad = 0.15 * max(float(sx.max() - sx.min()), float(sy.max() - sy.min()), 1.0)
    zx0, zx1 = float(sx.min()) - pad, float(sx.max()) + pad
    zy0, zy1 = float(sy.min()) - pad, float(sy.max()) + pad
    inside_safe = region

    ax = low_axes[0]
    dev = np.degrees(np.fmax(np.abs(rep.mu[..., 0] - 0.5 * math.pi),
                             np.abs(rep.mu[..., 1] - 0.5 * math.pi)))
    im = ax.pcolormesh(rep.xs, rep.ys, np.ma.masked_invalid(dev), cmap="viridis_r",
                       vmin=0, vmax=90, shading="nearest")
    cs = ax.contour(rep.xs, rep.ys, np.nan_to_num(dev, nan=90.0), levels=[50.0],
                    colors="w", linewidths=1.2, linestyles="--")
    ax.clabel(cs, fmt="%g°", fontsize=9)
    bottom.colorbar(im, ax=ax, shrink=0.7, label="worst arm |μ − 90°| (deg)")
    _safe_outline(ax, rep)
    _rect(ax, rep.fit.rect)
    _base(ax, fb)
    _frame(ax, zx0, zx1, zy0, zy1)
    ax.set_title(f"transmission angle (Eq. 23), mode {rep.mode}\nwhite dashed: 50° from 90° "
                 "(thesis limit); black: safe region", fontsize=11)

    ax = low_axes[1]
    q = np.fmax(rep.step[..., 0], rep.step[..., 1]) * 1000.0
    qs = q[inside_safe]
    vmin = float(np.nanpercentile(qs, 0.5)) if qs.size else 0.0
    vmax = float(np.nanpercentile(qs, 99.5)) if qs.size else float(np.nanmax(q))
    im = ax.pcolormesh(rep.xs, rep.ys, np.ma.masked_invalid(q), cmap="YlOrRd",
                       vmin=vmin, vmax=max(vmax, vmin * 1.01 + 1e-9), shading="nearest")
    bottom.colorbar(im, ax=ax, shrink=0.7, label="pen displacement per motor step (µm)")
    _traces_delta(ax, rep, fb, zx0, zx1, zy0, zy1)
    _safe_outline(ax, rep)
    _rect(ax, rep.fit.rect)
    _base(ax, fb)
    _frame(ax, zx0, zx1, zy0, zy1)
    ax.set_title(f"error sensitivity: step quantum ({math.degrees(rep.rad_per_step):.4f}°/step)"
                 f"\nwith ±{math.degrees(rep.delta_rad):g}° traces per motor (thesis Sec. 4.1)",
                 fontsize=11)
    ax.legend(handles=[Line2D([], [], color=MOTOR_COLORS[0], lw=1.5, label="motor 1 turned ±δ"),
                       Line2D([], [], color=MOTOR_COLORS[1], lw=1.5, label="motor 2 turned ±δ")],
              loc="lower right", fontsize=9)

    ax = low_axes[2]
    c = np.where(np.isfinite(rep.cond), rep.cond, np.nan)
    cs_vals = c[inside_safe]
    cmax = float(np.nanpercentile(cs_vals, 99)) if cs_vals.size else 100.0
    im = ax.pcolormesh(rep.xs, rep.ys, np.ma.masked_invalid(c), cmap="cividis",
                       vmin=1.0, vmax=min(max(cmax, 2.0), 50.0), shading="nearest")
    bottom.colorbar(im, ax=ax, shrink=0.7, label="condition number of J (1 = isotropic)")
    _safe_outline(ax, rep)
    _rect(ax, rep.fit.rect)
    _base(ax, fb)
    _frame(ax, zx0, zx1, zy0, zy1)
    ax.set_title(f"Jacobian condition number σmax/σmin, mode {rep.mode}\n"
                 "(colour clipped at the safe region's 99th percentile)", fontsize=11)

    fig.suptitle((title or "fivebar workspace") + f" — working modes (top), detail of mode "
                 f"{rep.mode} (bottom)", fontsize=14)
    fig.savefig(path)
    plt.close(fig)


def _traces_delta(ax: Axes, rep: WorkspaceReport, fb: FiveBar, x0: float, x1: float,
                  y0: float, y1: float) -> None:
    """The thesis' skewed-x traces (Sec. 4.1, Fig. 18): at sample points ~1/12 of the view
    apart inside the safe region, the pen path while motor i alone turns through −δ … +δ
    (exact forward kinematics, 9 samples per trace)."""
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


# ----------------------------------------------------------------------------- design output
def _set_toml_value(text: str, table: str, key: str, literal: str, source: str) -> str:
    """Replace the value of `key` in `[table]` of a TOML text, keeping its comment."""
    m = re.search(rf"(?m)^\[{re.escape(table)}\]\s*$", text)
    if m is None:
        raise ConfigError(f"{source}: no [{table}] table to update")
    nxt = re.search(r"(?m)^\[", text[m.end():])
    end = m.end() + (nxt.start() if nxt else len(text) - m.end())
    body = text[m.end():end]
    pat = re.compile(rf"(?m)^(\s*{re.escape(key)}\s*=\s*)([^#\n]*?)(\s*(#.*)?)$")
    km = pat.search(body)
    if km is None:
        raise ConfigError(f"{source}: [{table}] has no key {key} to update")
    body = body[:km.start(2)] + literal + body[km.end(2):]
    return text[:m.end()] + body + text[end:]


def design_profile_text(base_text: str, base_source: str, cand: DesignCandidate,
                        min_type1_rad: float, min_type2_rad: float) -> str:
    """The base profile's TOML with the candidate's geometry, working mode, assembly mode
    (the one the page was found in: build the machine that way), margins and a home pose at
    the page centre (motor angles in that mode, rounded to 0.1°, within
    limits), validated by the profile parser."""
    fb = cand.geometry
    text = base_text
    for key in ("a1", "b1", "a2", "b2", "w"):
        text = _set_toml_value(text, "geometry", key, f"{getattr(fb, key):.1f}", base_source)
    text = _set_toml_value(text, "kinematics", "working_mode", f'"{cand.mode}"', base_source)
    text = _set_toml_value(text, "kinematics", "assembly", f'"{cand.stats.assembly}"',
                           base_source)
    text = _set_toml_value(text, "kinematics", "min_type1_margin_deg",
                           f"{math.degrees(min_type1_rad):.6g}", base_source)
    text = _set_toml_value(text, "kinematics", "min_type2_margin_deg",
                           f"{math.degrees(min_type2_rad):.6g}", base_source)
    doc = tomllib.loads(text)
    lims = doc["motors"]["limits_deg"]
    rounded = FiveBar(*(round(getattr(fb, k), 1) for k in ("a1", "b1", "a2", "b2", "w")))
    th = np.degrees(np.asarray(rounded.inverse(cand.page.center, cand.mode), dtype=np.float64))
    home = []
    for i in range(2):
        lo, hi = float(lims[i][0]), float(lims[i][1])
        t = lo + (th[i] - lo) % 360.0
        home.append(min(max(round(t, 1), lo), hi))
    text = _set_toml_value(text, "motors", "home_deg", f"[{home[0]:.1f}, {home[1]:.1f}]",
                           base_source)
    header = (f"# Designed by `fivebar design` for a {cand.page.width:g} x {cand.page.height:g} mm "
              f"page at x = {cand.page.x0:.1f}, y = {cand.page.y0:.1f} mm (lower-left corner).\n"
              f"# home_deg is the pose with the pen at the page centre.\n")
    text = header + text
    parse_profile(tomllib.loads(text), "<designed profile>")
    return text


def design_lines(res: DesignResult, seconds: float) -> list[str]:
    """Table of the best candidates for the terminal."""
    lines = [f"evaluated {res.evaluated} candidate designs in {seconds:.2f} s: "
             f"{res.feasible} fit the page in the screen, {res.verified} verified densely"]
    if not res.candidates:
        return lines
    lines.append("rank    a1     b1     a2     b2      w   page x0,y0 (mm)   |μ−90°|max  "
                 "sens max (mm/rad)  step max/med (µm)  cond max  score")
    for k, c in enumerate(res.candidates, start=1):
        g, st, p = c.geometry, c.stats, c.page
        lines.append(
            f"{k:>4} {g.a1:6.1f} {g.b1:6.1f} {g.a2:6.1f} {g.b2:6.1f} {g.w:6.1f}   "
            f"{p.x0:7.1f},{p.y0:7.1f}   {math.degrees(st.worst_mu_dev_rad):9.1f}°  "
            f"{st.worst_sens_mm_per_rad:17.1f}  {st.worst_step_mm * 1000:8.1f}/"
            f"{st.median_step_mm * 1000:<8.1f}  {st.worst_cond:8.2f}  {c.score:.3f}")
    return lines
