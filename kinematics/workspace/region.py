"""The safe region of the five-bar robot: which end-effector points the pen may visit.

A point is *safe* in a working mode if the inverse kinematics (Eqs. 16–22) exist there, the
motor angles lie within the joint limits and both singularity margins clear the configured
minima. Across the type-2 curve the assembly mode flips, which the motors cannot control, so a
safe region is also tied to one assembly sign ("+" iff P lies left of R1→R2). Every other part
of the workspace analysis (page rectangles, design search, mode planning) builds on
`point_safety`, so the definition lives here once.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from kinematics.arrays import BoolArray
from kinematics.errors import FivebarError
from kinematics.fivebar import WORKING_MODES, FiveBar

Limits = Sequence[Sequence[float]]  # ((lo1, hi1), (lo2, hi2)) in rad

__all__ = [
    "Limits",
    "NoSafeRegionError",
    "angles_within_limits",
    "assembly_sign",
    "connected_component",
    "default_resolution",
    "point_safety",
    "safe_mask",
    "workspace_bounds",
]


class NoSafeRegionError(FivebarError, ValueError):
    """No point of the searched area is safe (or no rectangle of the asked shape fits)."""


def angles_within_limits(angles: ArrayLike, limits_rad: Limits) -> BoolArray:
    """True where both motor angles (N, 2) lie in their limit intervals, modulo 2π.

    The inverse kinematics return angles in (−π, π]; a limit such as [−200°, −10°] is
    honoured by testing whether some θ + 2πk falls in [lo, hi].
    """
    th = np.asarray(angles, dtype=np.float64).reshape(-1, 2)
    ok = np.ones(th.shape[0], dtype=bool)
    for i in range(2):
        lo, hi = float(limits_rad[i][0]), float(limits_rad[i][1])
        t = lo + np.mod(th[:, i] - lo, 2.0 * math.pi)
        # mod can return exactly 2π for θ − lo = −tiny; that is θ ≈ lo, inside.
        t = np.where(t - lo >= 2.0 * math.pi - 1e-12, lo, t)
        ok &= t <= hi + 1e-12
    return ok


def assembly_sign(assembly: str | None) -> float:
    """+1.0 / −1.0 for assembly "+" / "-", 0.0 for None (either sign); else ValueError."""
    if assembly is None:
        return 0.0
    if assembly not in ("+", "-"):
        raise ValueError(f"assembly must be '+', '-' or None; got {assembly!r}")
    return 1.0 if assembly == "+" else -1.0


def point_safety(fb: FiveBar, mode: str, points: ArrayLike, min_type1_rad: float,
                 min_type2_rad: float, limits_rad: Limits | None = None, *,
                 assembly: str | None = None) -> BoolArray:
    """Safety (N,) of end-effector points in working mode `mode`.

    Safe means: the inverse kinematics exist in that mode (reach annuli, Eqs. 16–22), the
    motor angles are within `limits_rad` (if given), the type-1 margin of each arm (angle
    between a_i and b_i lines, signed by the arm's mode) is ≥ `min_type1_rad`, and the type-2
    margin (angle between b1 and b2) is ≥ `min_type2_rad` in magnitude — or, with `assembly`
    "+"/"-", with that sign, so the point is on the given side of the type-2 curve.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    sign = assembly_sign(assembly)
    if mode not in WORKING_MODES:
        raise ValueError(f"working mode must be one of {', '.join(WORKING_MODES)}; got {mode!r}")
    s = np.array([1.0 if mode[0] == "+" else -1.0, 1.0 if mode[1] == "+" else -1.0])
    inv = fb.inverse_batch(pts, mode)
    ok = inv.valid.copy()
    if not ok.any():
        return ok
    m = fb.singularity_margins(inv.angles, pts)
    ok &= (m[:, 0] * s[0] >= min_type1_rad) & (m[:, 1] * s[1] >= min_type1_rad)
    t2 = np.abs(m[:, 2]) if sign == 0.0 else m[:, 2] * sign
    ok &= t2 >= min_type2_rad
    if limits_rad is not None:
        ok &= angles_within_limits(inv.angles, limits_rad)
    return ok


def safe_mask(fb: FiveBar, mode: str, xs: ArrayLike, ys: ArrayLike, min_type1_rad: float,
              min_type2_rad: float, limits_rad: Limits | None = None, *,
              assembly: str | None = None) -> BoolArray:
    """Boolean grid of the safe region (see `point_safety`).

    With 1-D `xs` (nx,) and `ys` (ny,) the result has shape (ny, nx) and element [j, i] is
    the point (xs[i], ys[j]) — the layout of `np.meshgrid(xs, ys)` and of images (row = y).
    Arrays of any other (broadcastable) shapes give a result of their broadcast shape.
    """
    x = np.asarray(xs, dtype=np.float64)
    y = np.asarray(ys, dtype=np.float64)
    if x.ndim == 1 and y.ndim == 1:
        x, y = np.meshgrid(x, y)
    x, y = np.broadcast_arrays(x, y)
    pts = np.stack((x.ravel(), y.ravel()), axis=1)
    ok = point_safety(fb, mode, pts, min_type1_rad, min_type2_rad, limits_rad,
                      assembly=assembly)
    return ok.reshape(x.shape)


def workspace_bounds(fb: FiveBar) -> tuple[float, float, float, float]:
    """Box (x_min, x_max, y_min, y_max) mm that contains every reachable point: the union
    of the two outer reach circles |P − M_i| ≤ a_i + b_i (their intersection is smaller;
    `FiveBar.reach`, which widens them for a pen off the joint)."""
    r1, r2 = fb.reach[0][1], fb.reach[1][1]
    x_min = max(-r1, fb.w - r2)
    x_max = min(r1, fb.w + r2)
    r = min(r1, r2)
    return (x_min, x_max, -r, r)


def default_resolution(fb: FiveBar) -> float:
    """Grid pitch, mm, that puts about 400 cells across the workspace box."""
    x_min, x_max, y_min, y_max = workspace_bounds(fb)
    return max(x_max - x_min, y_max - y_min) / 400.0


def connected_component(mask: BoolArray, seed: tuple[int, int]) -> BoolArray:
    """The 4-connected component of `mask` (ny, nx) containing node `seed` = (j, i), by
    repeated masked dilation (numpy only; a few hundred sweeps at most on our grids)."""
    comp = np.zeros_like(mask, dtype=bool)
    if not mask[seed]:
        return comp
    comp[seed] = True
    while True:
        grown = comp.copy()
        grown[1:, :] |= comp[:-1, :]
        grown[:-1, :] |= comp[1:, :]
        grown[:, 1:] |= comp[:, :-1]
        grown[:, :-1] |= comp[:, 1:]
        grown &= mask
        if np.array_equal(grown, comp):
            return comp
        comp = grown
