"""The full workspace report of one machine: what `fivebar workspace` prints and draws.

The page rectangle of every working mode, then for one mode the grid maps of transmission
angle, step quantum, ±δ displacement, sensitivity and condition number, the type-2 traces and
the figures over the page. Numbers only; the text and the picture are made by
`fivebar_host.report.text.workspace` and `fivebar_host.report.workspace`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kinematics.arrays import BoolArray, FloatArray
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace.measures import (
    PageStats,
    measures,
    page_stats,
    perturbation_displacements,
)
from kinematics.workspace.rectangles import PageFit, Rect, find_page_rectangle
from kinematics.workspace.region import Limits, NoSafeRegionError, assembly_sign
from kinematics.workspace.singularities import SingularityTrace, type2_traces

__all__ = ["WorkspaceReport", "workspace_report"]


@dataclass(frozen=True)
class WorkspaceReport:
    """Everything `fivebar workspace` shows for one machine.

    fits: the page search per working mode (None where nothing fits); mode: the mode analysed
    in detail (the configured one, or the one with the largest page if "auto"); fit, stats:
    its page rectangle and figures over it; xs, ys (nx,), (ny,) the grid; reach (ny, nx): both
    arms reach; safe (ny, nx): safe in `mode` and the page's assembly; mu (ny, nx, 2)
    transmission angles; step (ny, nx, 2) and delta (ny, nx, 2): the larger end-effector
    displacement of −/+ one step and of −/+ δ at motor i (exact forward kinematics, thesis
    Sec. 4.1); sens (ny, nx, 2) |∂P/∂θ_i| mm/rad; cond (ny, nx); all NaN outside reach.
    page: the asked page placed inside the safe region (None if not asked or it does not fit).
    """

    mode: str
    fits: dict[str, PageFit | None]
    fit: PageFit
    stats: PageStats
    xs: FloatArray
    ys: FloatArray
    reach: BoolArray
    safe: BoolArray
    mu: FloatArray
    step: FloatArray
    delta: FloatArray
    sens: FloatArray
    cond: FloatArray
    traces: list[SingularityTrace]
    delta_rad: float
    rad_per_step: float
    page_asked: tuple[float, float] | None
    page: Rect | None


def _max_disp(d: FloatArray) -> FloatArray:
    """Per motor, the larger |displacement| of the −/+ perturbations: (N, 2, 2, 2) → (N, 2)."""
    with np.errstate(invalid="ignore"):
        mag = np.sqrt((d ** 2).sum(axis=-1))
    return np.asarray(np.max(mag, axis=2), dtype=np.float64)


def _analysed(fits: dict[str, PageFit | None], mode: str, assembly: str | None,
              min1: float, min2: float) -> tuple[str, PageFit]:
    """The mode to analyse in detail ("auto": the one with the largest page) and its page
    fit; `NoSafeRegionError` if it has none."""
    if mode == "auto":
        ranked = [m for m in WORKING_MODES if fits[m] is not None]
        if not ranked:
            asm = "" if assembly is None else f" in assembly {assembly}"
            raise NoSafeRegionError(f"no working mode has a safe region{asm} with these margins")
        mode = max(ranked, key=lambda m: fits[m].rect.area)  # type: ignore[union-attr]
    fit = fits.get(mode)
    if fit is None:
        raise NoSafeRegionError(
            f"working mode {mode} has no safe region"
            f"{'' if assembly is None else f' in assembly {assembly}'} (margins type 1 ≥ "
            f"{math.degrees(min1):g}°, type 2 ≥ {math.degrees(min2):g}°)")
    return mode, fit


def _place_page(fb: FiveBar, mode: str, assembly: str, page: tuple[float, float], min1: float,
                min2: float, limits: Limits | None, resolution_mm: float | None) -> Rect | None:
    """A page of size `page` = (width, height) mm centred in the largest safe rectangle of its
    aspect, or None if that rectangle is smaller than the page."""
    pw, ph = page
    try:
        pf = find_page_rectangle(fb, mode, min1, min2, limits, aspect=pw / ph,
                                 resolution_mm=resolution_mm, assembly=assembly)
    except NoSafeRegionError:
        return None
    if pf.rect.height < ph * (1.0 - 1e-9):
        return None
    cx, cy = pf.rect.center
    return Rect(cx - 0.5 * pw, cy - 0.5 * ph, pw, ph)


def workspace_report(fb: FiveBar, mode: str, min_type1_rad: float, min_type2_rad: float,
                     limits_rad: Limits | None, rad_per_step: float, *,
                     delta_rad: float = math.radians(5.0), resolution_mm: float | None = None,
                     page: tuple[float, float] | None = None,
                     assembly: str | None = None) -> WorkspaceReport:
    """Analyse a machine: page rectangle per working mode, then for `mode` ("auto": the mode
    with the largest rectangle) the maps of transmission angle, step and ±δ displacement,
    sensitivity and condition number, the type-2 traces, and the figures over the page.
    With `page` = (width, height) mm, also place a page of that size (fixed aspect search).
    `assembly` ("+"/"-") is the assembly mode the machine is built in: the page rectangles
    are searched in it only (None: in both, the larger wins — for a machine not yet built)."""
    assembly_sign(assembly)
    fits: dict[str, PageFit | None] = {}
    for m in WORKING_MODES:
        try:
            fits[m] = find_page_rectangle(fb, m, min_type1_rad, min_type2_rad, limits_rad,
                                          resolution_mm=resolution_mm, assembly=assembly)
        except NoSafeRegionError:
            fits[m] = None
    mode, fit = _analysed(fits, mode, assembly, min_type1_rad, min_type2_rad)
    stats = page_stats(fb, mode, fit.rect, rad_per_step)
    xs, ys = fit.xs, fit.ys
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack((gx.ravel(), gy.ravel()), axis=1)
    pm = measures(fb, mode, pts)
    shape = gx.shape
    step = _max_disp(perturbation_displacements(fb, mode, pts, rad_per_step))
    delta = _max_disp(perturbation_displacements(fb, mode, pts, delta_rad))
    placed = None if page is None else _place_page(
        fb, mode, fit.assembly, page, min_type1_rad, min_type2_rad, limits_rad, resolution_mm)
    return WorkspaceReport(
        mode=mode, fits=fits, fit=fit, stats=stats, xs=xs, ys=ys,
        reach=pm.valid.reshape(shape), safe=fit.mask,
        mu=pm.mu.reshape(*shape, 2), step=step.reshape(*shape, 2),
        delta=delta.reshape(*shape, 2), sens=pm.sens.reshape(*shape, 2),
        cond=pm.cond.reshape(shape), traces=type2_traces(fb), delta_rad=delta_rad,
        rad_per_step=rad_per_step, page_asked=page, page=placed)
