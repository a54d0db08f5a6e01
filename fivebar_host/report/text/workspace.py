"""Workspace and design reports as text and files: the summary `fivebar workspace` prints,
its CSV/JSON numbers, and the profile and table written by `fivebar design`. The math lives in
`kinematics.workspace` and `kinematics.design`; the picture in `fivebar_host.report.workspace`
(kept apart so that these commands' text and files load no plotting library).
"""

from __future__ import annotations

import csv
import json
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host.config import ConfigError, parse_profile
from kinematics.design import DesignCandidate, DesignResult
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace import Rect, WorkspaceReport


# ----------------------------------------------------------------------------- text
def summary_lines(rep: WorkspaceReport, fb: FiveBar) -> list[str]:
    """The figures `fivebar workspace` prints."""
    st = rep.stats
    r = rep.fit.rect
    ext = getattr(fb, "extension", 0.0)
    pen = (f" extension={ext:g} mm at {math.degrees(getattr(fb, 'extension_angle', 0.0)):g}°"
           if ext else "")
    lines = [f"geometry a1={fb.a1:g} b1={fb.b1:g} a2={fb.a2:g} b2={fb.b2:g} w={fb.w:g} mm"
             f"{pen}; grid {rep.fit.resolution_mm:.3g} mm"]
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
        "geometry": {"a1": fb.a1, "b1": fb.b1, "a2": fb.a2, "b2": fb.b2, "w": fb.w,
                     "extension": getattr(fb, "extension", 0.0),
                     "extension_angle_deg": math.degrees(getattr(fb, "extension_angle", 0.0))},
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
