"""Per-point measures of the five-bar robot and their figures of merit over a page.

Transmission angles (Eq. 23), singularity margins, the Jacobian, per-motor sensitivity and
condition number (thesis Sec. 2.2.2, 4.1, 4.2), and the end-effector displacement caused by
a motor error or one motor step by exact forward kinematics (thesis Fig. 18). `page_stats`
condenses them over a rectangle; the workspace maps and the design search both use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.arrays import BoolArray, FloatArray
from kinematics.fivebar import FiveBar
from kinematics.workspace.rectangles import Rect
from kinematics.workspace.region import NoSafeRegionError

__all__ = [
    "PageStats",
    "PointMeasures",
    "condition_numbers",
    "measures",
    "page_stats",
    "perturbation_displacements",
    "step_quantum",
]


@dataclass(frozen=True)
class PointMeasures:
    """Per-point measures (N rows) in one working mode; NaN where the point is unreachable.

    angles (N, 2) rad; mu (N, 2) transmission angles μ_i = ∠M_i R_i P (Eq. 23) rad; margins
    (N, 3) rad (type 1 arm 1, type 1 arm 2, type 2, signed as `FiveBar.singularity_margins`);
    jac (N, 2, 2) mm/rad; sens (N, 2) mm/rad = |∂P/∂θ_i|, the end-effector speed per unit
    speed of motor i alone; cond (N,) the condition number σ_max/σ_min of J; assembly (N,) ±1.
    """

    points: FloatArray
    valid: BoolArray
    angles: FloatArray
    mu: FloatArray
    margins: FloatArray
    jac: FloatArray
    sens: FloatArray
    cond: FloatArray
    assembly: NDArray[np.int8]


def condition_numbers(jac: FloatArray) -> FloatArray:
    """σ_max/σ_min of each 2×2 matrix (N, 2, 2), closed form from the Frobenius norm F and
    determinant D: σ² = (F² ± √(F⁴ − 4D²))/2. inf where J is singular or not finite."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        f2 = np.einsum("nij,nij->n", jac, jac)
        det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
        disc = np.sqrt(np.maximum(f2 * f2 - 4.0 * det * det, 0.0))
        smax = np.sqrt(0.5 * (f2 + disc))
        # σ_min from |D| = σ_max·σ_min: (F² − √…)/2 would lose digits by cancellation.
        smin = np.where(smax > 0, np.abs(det) / smax, 0.0)
        cond = np.where(smin > 0, smax / smin, np.inf)
    cond[~np.isfinite(f2)] = np.inf
    return np.asarray(cond, dtype=np.float64)


def measures(fb: FiveBar, mode: str, points: ArrayLike) -> PointMeasures:
    """Transmission angles, singularity margins, Jacobian, per-motor sensitivity and condition
    number at end-effector points in working mode `mode` (thesis Sec. 2.2.2, 4.1, 4.2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    inv = fb.inverse_batch(pts, mode)
    th = inv.angles
    mu = fb.transmission_angles(th, pts)
    mar = fb.singularity_margins(th, pts)
    jac = fb.jacobian(th, pts)
    sens = np.sqrt(jac[:, 0, :] ** 2 + jac[:, 1, :] ** 2)
    cond = condition_numbers(jac)
    asm = fb.assembly_of(th, pts)
    v = inv.valid
    nan = np.nan
    return PointMeasures(
        pts, v, np.where(v[:, None], th, nan), np.where(v[:, None], mu, nan),
        np.where(v[:, None], mar, nan), np.where(v[:, None, None], jac, nan),
        np.where(v[:, None], sens, nan), np.where(v, cond, nan),
        np.where(v, asm, 0).astype(np.int8))


def perturbation_displacements(fb: FiveBar, mode: str, points: ArrayLike,
                               delta_rad: float) -> FloatArray:
    """End-effector displacement vectors (N, 2, 2, 2) mm for motor errors of ±δ, by exact
    forward kinematics, as in thesis Sec. 4.1 (Fig. 18): index [n, i, k] is motor i (other
    motor fixed) turned by −δ (k = 0) or +δ (k = 1), last axis (dx, dy). The two traces per
    point form the thesis' skewed "x". NaN where the perturbed pose has no forward solution in
    the point's own assembly mode (the perturbation crosses a singularity)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    inv = fb.inverse_batch(pts, mode)
    asm = fb.assembly_of(inv.angles, pts).astype(np.float64)
    asm[asm == 0] = 1.0
    out = np.full((pts.shape[0], 2, 2, 2), np.nan)
    for i in range(2):
        for k, sgn in enumerate((-1.0, 1.0)):
            th = inv.angles.copy()
            th[:, i] += sgn * delta_rad
            fw = fb.forward_batch(th, asm)
            good = fw.valid & inv.valid
            out[good, i, k] = fw.points[good] - pts[good]
    return out


def step_quantum(fb: FiveBar, mode: str, points: ArrayLike, rad_per_step: float) -> FloatArray:
    """Largest end-effector displacement (N,) mm caused by one motor step (either motor,
    either direction), by exact forward kinematics of θ ± one step. NaN if unreachable."""
    d = perturbation_displacements(fb, mode, points, rad_per_step)
    with np.errstate(invalid="ignore"):
        mag = np.sqrt((d ** 2).sum(axis=-1)).reshape(d.shape[0], 4)
    bad = np.isnan(mag).any(axis=1)
    q = np.where(bad, np.nan, np.nanmax(np.where(np.isnan(mag), 0.0, mag), axis=1))
    return np.asarray(q, dtype=np.float64)


@dataclass(frozen=True)
class PageStats:
    """Figures of merit of a machine over a page (rectangle) in one working mode.

    worst_mu_dev_rad: max over the page and both arms of |μ_i − 90°| (thesis Sec. 2.2.2:
    keep within ±50°); worst_sens_mm_per_rad / median_sens_mm_per_rad: max / median over the
    page of max_i |∂P/∂θ_i|; worst_cond: max condition number of J; min_type1_rad /
    min_type2_rad: the smallest singularity margins met; worst_step_mm / median_step_mm: the
    largest pen displacement from one motor step (exact forward kinematics), max and median
    over the page; assembly: the one assembly sign of the page ("+" or "-")."""

    worst_mu_dev_rad: float
    worst_sens_mm_per_rad: float
    median_sens_mm_per_rad: float
    worst_cond: float
    min_type1_rad: float
    min_type2_rad: float
    worst_step_mm: float
    median_step_mm: float
    assembly: str
    samples: int


def page_stats(fb: FiveBar, mode: str, rect: Rect, rad_per_step: float,
               spacing_mm: float | None = None) -> PageStats:
    """Evaluate `PageStats` on a grid over `rect` (default pitch: 1/40 of its diagonal).
    Raises `NoSafeRegionError` if some sample is unreachable or the page straddles the type-2
    curve (both assembly signs occur)."""
    sp = spacing_mm if spacing_mm is not None else math.hypot(rect.width, rect.height) / 40.0
    pts = rect.sample(sp, sp)
    pm = measures(fb, mode, pts)
    if not pm.valid.all():
        raise NoSafeRegionError(f"page {rect} is not reachable everywhere in mode {mode}")
    signs = set(np.unique(pm.assembly).tolist())
    if len(signs) != 1 or 0 in signs:
        raise NoSafeRegionError(f"page {rect} straddles the type-2 singularity in mode {mode}")
    q = step_quantum(fb, mode, pts, rad_per_step)
    sens = pm.sens.max(axis=1)
    return PageStats(
        worst_mu_dev_rad=float(np.abs(pm.mu - 0.5 * math.pi).max()),
        worst_sens_mm_per_rad=float(sens.max()),
        median_sens_mm_per_rad=float(np.median(sens)),
        worst_cond=float(pm.cond.max()),
        min_type1_rad=float(np.abs(pm.margins[:, :2]).min()),
        min_type2_rad=float(np.abs(pm.margins[:, 2]).min()),
        worst_step_mm=float(np.nanmax(q)),
        median_step_mm=float(np.nanmedian(q)),
        assembly="+" if signs == {1} else "-",
        samples=int(pts.shape[0]))
