"""Shared pieces of the approximate five-bar kinematics: the `Approximation` result, the
cheap reach tests every map refuses by, the thesis' angle convention, the regular grid that
tiles and tables are laid on, and the closed-form references they are built and scored
against (pen error in mm).

Kept apart from the maps themselves (`benchmarks.approx.linear`, `benchmarks.approx.table`)
because both families build on exactly these helpers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from kinematics.arrays import BoolArray, FloatArray, IndexArray
from kinematics.fivebar import WORKING_MODES, FiveBar

Box = tuple[float, float, float, float]  # (u_min, u_max, v_min, v_max)
Form = Literal["similarity", "affine"]
Kind = Literal["inverse", "forward"]
Order = Literal["linear", "cubic"]


@dataclass(frozen=True)
class Approximation:
    """Result of an approximate map: values (N, 2) (rad for inverse, mm for forward) and a
    `valid` mask (N,); rows that are not valid hold 0.0."""

    values: FloatArray
    valid: BoolArray


# ----------------------------------------------------------------------------- helpers
def as_rows(values: ArrayLike, what: str) -> FloatArray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape == (2,):
        arr = arr.reshape(1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{what} must have shape (2,) or (N, 2); got {arr.shape}")
    return arr


def check_box(box: Box) -> Box:
    u0, u1, v0, v1 = (float(b) for b in box)
    if not (math.isfinite(u0 + u1 + v0 + v1) and u1 > u0 and v1 > v0):
        raise ValueError(f"box must be finite (u_min, u_max, v_min, v_max) with max > min; "
                         f"got {box!r}")
    return (u0, u1, v0, v1)


def in_box(q: FloatArray, box: Box) -> BoolArray:
    u0, u1, v0, v1 = box
    return np.asarray((q[:, 0] >= u0) & (q[:, 0] <= u1) & (q[:, 1] >= v0) & (q[:, 1] <= v1),
                      dtype=bool)


def reachable(fb: FiveBar, points: FloatArray) -> BoolArray:
    """True where both reach annuli contain the point: the closed form's inverse exists in
    every working mode (boundary included). Two squared distances, no square root."""
    x, y = points[:, 0], points[:, 1]
    c1 = x * x + y * y
    c2 = (x - fb.w) ** 2 + y * y
    (lo1, hi1), (lo2, hi2) = fb.reach
    ok = (c1 <= hi1 * hi1) & (c1 >= lo1 * lo1) & (c2 <= hi2 * hi2) & (c2 >= lo2 * lo2)
    return np.asarray(ok & np.isfinite(c1 + c2), dtype=bool)


def assemblable(fb: FiveBar, angles: FloatArray) -> BoolArray:
    """True where the floating links can meet: |b1 − b2| ≤ |R1 − R2| ≤ b1 + b2 (the closed
    form's forward kinematics exist, in both assemblies)."""
    dx = fb.w + fb.a2 * np.cos(angles[:, 1]) - fb.a1 * np.cos(angles[:, 0])
    dy = fb.a2 * np.sin(angles[:, 1]) - fb.a1 * np.sin(angles[:, 0])
    lsq = dx * dx + dy * dy
    hi = fb.b1 + fb.b2
    lo = fb.b1 - fb.b2
    ok = (lsq <= hi * hi) & (lsq >= lo * lo) & (lsq > 0.0)
    return np.asarray(ok & np.isfinite(lsq), dtype=bool)


def to_thesis(angles: FloatArray) -> FloatArray:
    """Motor angles in the thesis' convention: θ1 unchanged, θ2' = π − θ2 (the interior
    angle at M2 measured from M2→M1, Sec. 2). The map is its own inverse."""
    out = np.array(angles, dtype=np.float64, copy=True)
    out[..., 1] = math.pi - out[..., 1]
    return out


def unwrap_about(theta: FloatArray, ref: FloatArray) -> FloatArray:
    """Angles shifted by multiples of 2π into (ref − π, ref + π], per column."""
    return np.asarray(ref + np.mod(theta - ref + math.pi, 2.0 * math.pi) - math.pi,
                      dtype=np.float64)


def closed_inverse(fb: FiveBar, mode: str, pts: FloatArray) -> tuple[FloatArray, BoolArray]:
    res = fb.inverse_batch(pts, mode)
    return np.asarray(res.angles), np.asarray(res.valid)


def closed_forward(fb: FiveBar, assembly: str, th: FloatArray) -> tuple[FloatArray, BoolArray]:
    res = fb.forward_batch(th, assembly)
    return np.asarray(res.points), np.asarray(res.valid)


def same_branch_inverse(fb: FiveBar, mode: str, assembly: str | None, pts: FloatArray,
                         th: FloatArray) -> BoolArray:
    """True where the exact pose (pts, th) has the assembly sign `assembly` (None: any)."""
    if assembly is None:
        return np.ones(pts.shape[0], dtype=bool)
    sign = 1 if assembly == "+" else -1
    return np.asarray(fb.assembly_of(th, pts) == sign, dtype=bool)


def check_mode(mode: str) -> None:
    if mode not in WORKING_MODES:
        raise ValueError(f"working mode must be one of {', '.join(WORKING_MODES)}; got {mode!r}")


def check_assembly(assembly: str) -> None:
    if assembly not in ("+", "-"):
        raise ValueError(f"assembly must be '+' or '-'; got {assembly!r}")


def check_inverse_args(mode: str, assembly: str | None) -> None:
    """The working mode and the optional assembly of an inverse approximation's build."""
    check_mode(mode)
    if assembly is not None:
        check_assembly(assembly)




# ----------------------------------------------------------------------------- grids
@dataclass(frozen=True)
class Grid:
    """A regular grid of nx × ny nodes over a box (node (j, i) at (u0 + i·hu, v0 + j·hv))."""

    box: Box
    nx: int
    ny: int

    @property
    def hu(self) -> float:
        return (self.box[1] - self.box[0]) / (self.nx - 1)

    @property
    def hv(self) -> float:
        return (self.box[3] - self.box[2]) / (self.ny - 1)

    def nodes(self) -> FloatArray:
        u = np.linspace(self.box[0], self.box[1], self.nx)
        v = np.linspace(self.box[2], self.box[3], self.ny)
        uu, vv = np.meshgrid(u, v)
        return np.stack((uu.ravel(), vv.ravel()), axis=1)

    def locate(self, q: FloatArray, ncu: int, ncv: int
               ) -> tuple[IndexArray, IndexArray, FloatArray, FloatArray, BoolArray]:
        """Cell indices (i, j) in [0, ncu) × [0, ncv), local coordinates (fu, fv) and the
        inside-the-box mask for query points q (N, 2)."""
        fu = (q[:, 0] - self.box[0]) * (1.0 / self.hu)
        fv = (q[:, 1] - self.box[2]) * (1.0 / self.hv)
        inside = (fu >= 0.0) & (fu <= self.nx - 1) & (fv >= 0.0) & (fv <= self.ny - 1)
        with np.errstate(invalid="ignore"):
            i = np.clip(np.floor(fu), 0, ncu - 1).astype(np.intp)
            j = np.clip(np.floor(fv), 0, ncv - 1).astype(np.intp)
        i[~inside] = 0
        j[~inside] = 0
        return i, j, fu - i, fv - j, np.asarray(inside, dtype=bool)


def exact_values(fb: FiveBar, kind: Kind, mode_or_asm: str, q: FloatArray,
           page_assembly: str | None, min_margins: tuple[float, float] = (0.0, 0.0)
           ) -> tuple[FloatArray, BoolArray]:
    """Closed-form values at q for building/checking an approximation: inverse (angles of
    points, restricted to one assembly if given) or forward (points of angles). With
    `min_margins` = (type 1, type 2) in rad, poses closer than that to a singularity
    (`FiveBar.singularity_margins`, magnitudes) count as having no value."""
    if kind == "inverse":
        th, ok = closed_inverse(fb, mode_or_asm, q)
        ok &= same_branch_inverse(fb, mode_or_asm, page_assembly, q, th)
        vals, pts, ang = th, q, th
    else:
        vals, ok = closed_forward(fb, mode_or_asm, q)
        pts, ang = vals, q
    m1, m2 = min_margins
    if (m1 > 0.0 or m2 > 0.0) and ok.any():
        m = np.abs(fb.singularity_margins(ang, pts))
        ok &= (m[:, 0] >= m1) & (m[:, 1] >= m1) & (m[:, 2] >= m2)
    return vals, ok


def pen_error(fb: FiveBar, kind: Kind, q: FloatArray, approx: FloatArray,
               exact: FloatArray) -> FloatArray:
    """Pen error (mm) of approximate answers at inputs q: for forward maps the distance to the
    exact point; for inverse maps the distance from q to where the approximate angles put the
    pen (closed-form forward kinematics in the exact pose's own assembly), inf if they put it
    nowhere. Angle errors are thereby weighed by the machine's sensitivity, which is what a
    tolerance in mm needs (near a type-2 singularity a tiny angle error moves the pen far)."""
    if kind == "forward":
        return np.asarray(np.hypot(*(approx - exact).T), dtype=np.float64)
    asm = fb.assembly_of(exact, q).astype(np.float64)
    asm[asm == 0] = 1.0
    fw = fb.forward_batch(approx, asm)
    e = np.hypot(*(np.asarray(fw.points) - q).T)
    return np.asarray(np.where(fw.valid, e, np.inf), dtype=np.float64)

