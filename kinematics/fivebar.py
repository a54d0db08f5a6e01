"""Closed-form kinematics of the five-bar robot (parallel SCARA).

Frame and conventions (ARCHITECTURE.md): motor M1 at (0, 0), motor M2 at (w, 0), y up, mm.
Motor angles θ_i are measured from +x, counter-clockwise, in radians, for *both* motors (the
thesis measures θ2 from M2→M1; we do not). R_i = M_i + a_i·(cos θ_i, sin θ_i) is the elbow,
|P − R_i| = b_i closes the loop at the end-effector P.

Working mode "s1s2": s_i = "+" iff the elbow R_i lies left of the directed chord M_i→P,
i.e. cross(P − M_i, R_i − M_i) > 0. Assembly mode: "+" iff P lies left of R1→R2.

Every formula avoids the thesis' divisions by quantities that vanish inside the workspace
(Eqs. 9–15 divide by x_R2 − x_R1; Eqs. 21–22 assume P above the base). Reach is decided on the
factored discriminant (Heron's form), so points exactly on the boundary are exact and points
1e-12 beyond are refused, never clamped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.arrays import FloatArray
from kinematics.errors import FivebarError

ModeStr = Literal["++", "+-", "-+", "--"]
WORKING_MODES: tuple[ModeStr, ...] = ("++", "+-", "-+", "--")


class Reason(IntEnum):
    """Why a point (inverse) or a pair of motor angles (forward) has no valid answer.

    OK means valid. The codes are stable: they are stored in job reports.
    """

    OK = 0
    NOT_FINITE = 1  # a coordinate or angle is NaN or infinite
    BEYOND_REACH_1 = 2  # |P − M1| > a1 + b1 (arm 1 cannot stretch that far)
    INSIDE_REACH_1 = 3  # |P − M1| < |a1 − b1| (inside arm 1's dead zone)
    BEYOND_REACH_2 = 4  # |P − M2| > a2 + b2
    INSIDE_REACH_2 = 5  # |P − M2| < |a2 − b2|
    AT_MOTOR_1 = 6  # P = M1 with a1 = b1: θ1 is undetermined (the arm folds onto itself)
    AT_MOTOR_2 = 7  # P = M2 with a2 = b2
    ELBOWS_TOO_FAR = 8  # forward: |R1 − R2| > b1 + b2, the floating links cannot meet
    ELBOWS_TOO_CLOSE = 9  # forward: |R1 − R2| < |b1 − b2|
    ELBOWS_COINCIDENT = 10  # forward: R1 = R2 with b1 = b2, P free on a circle (Mode 1b I)


class KinematicsError(FivebarError, ValueError):
    """A pose that has no unique answer; carries where (point/angles) and why (reason)."""

    def __init__(self, message: str, reason: Reason, where: tuple[float, float],
                 excess_mm: float = 0.0) -> None:
        super().__init__(message)
        self.reason = reason
        self.where = where
        self.excess_mm = excess_mm


class UnreachableError(KinematicsError):
    """The point (or the motor angles) cannot be reached; `excess_mm` says by how much."""


class DegenerateError(KinematicsError):
    """The pose is reachable but the answer is not unique (a free degree of freedom)."""


def mode_signs(mode: str, kind: str) -> tuple[float, float]:
    """Parse a working mode "s1s2" into two ±1 floats, with a clear error."""
    if mode not in WORKING_MODES:
        raise ValueError(f"{kind} must be one of {', '.join(WORKING_MODES)}; got {mode!r}")
    return (1.0 if mode[0] == "+" else -1.0, 1.0 if mode[1] == "+" else -1.0)


def as_points(values: ArrayLike, what: str) -> tuple[FloatArray, bool]:
    """Return an (N, 2) float array and whether the input was a single (2,) row."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape == (2,):
        return arr.reshape(1, 2), True
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{what} must have shape (2,) or (N, 2); got {arr.shape}")
    return arr, False


def _heron(a: float, b: float, c: FloatArray) -> FloatArray:
    """(a+b+c)(a+b−c)(a−b+c)(−a+b+c): 16·area² of the triangle with sides a, b, c.

    Negative iff no such triangle exists; factored so that it is exact to rounding when c
    sits on a reach boundary (a + b or |a − b|), unlike (2ac)² − (a² + c² − b²)².
    """
    return (a + b + c) * (a + b - c) * (a - b + c) * (b - a + c)


@dataclass(frozen=True)
class InverseResult:
    """Batch inverse kinematics: angles (N, 2) rad, `valid` mask and a `Reason` per point.

    Rows that are not valid hold 0.0 (never NaN, never a clamped answer): read `valid`.
    """

    angles: FloatArray
    valid: NDArray[np.bool_]
    reason: NDArray[np.int8]

    def require(self, points: ArrayLike | None = None) -> FloatArray:
        """Return the angles, or raise for the first invalid row naming its index."""
        bad = np.flatnonzero(~self.valid)
        if bad.size:
            i = int(bad[0])
            where = ""
            if points is not None:
                p = np.asarray(points, dtype=np.float64).reshape(-1, 2)[i]
                where = f" at ({p[0]:.6g}, {p[1]:.6g}) mm"
            raise UnreachableError(
                f"point {i}{where}: {Reason(int(self.reason[i])).name} "
                f"({bad.size} invalid point(s) in all)",
                Reason(int(self.reason[i])), (float("nan"), float("nan")))
        return self.angles


@dataclass(frozen=True)
class ForwardResult:
    """Batch forward kinematics: points (N, 2) mm, `valid` mask and a `Reason` per row."""

    points: FloatArray
    valid: NDArray[np.bool_]
    reason: NDArray[np.int8]


@dataclass(frozen=True)
class Pose:
    """A full pose: motor angles, elbows R1, R2 and end-effector P (all (N, 2))."""

    angles: FloatArray
    r1: FloatArray
    r2: FloatArray
    p: FloatArray


@dataclass(frozen=True)
class FiveBar:
    """An immutable five-bar geometry: driving links a1, a2, floating links b1, b2, motor
    spacing w, all in mm. Validated on construction (positive, finite, loop can close)."""

    a1: float
    b1: float
    a2: float
    b2: float
    w: float

    def __post_init__(self) -> None:
        for name in ("a1", "b1", "a2", "b2", "w"):
            v = getattr(self, name)
            if not isinstance(v, int | float) or isinstance(v, bool):
                raise TypeError(f"{name} must be a number; got {type(v).__name__}")
            if not math.isfinite(v) or v <= 0.0:
                raise ValueError(f"{name} must be a positive finite length in mm; got {v!r}")
            object.__setattr__(self, name, float(v))
        # The annuli |P−M1| ∈ [lo1, hi1] and |P−M2| ∈ [lo2, hi2] must intersect. Points at
        # distance r from M1 lie at distances [|w − r|, w + r] from M2; over r ∈ [lo1, hi1]
        # the union of those intervals is [dmin, w + hi1] (each one contains w).
        lo1, hi1 = abs(self.a1 - self.b1), self.a1 + self.b1
        lo2, hi2 = abs(self.a2 - self.b2), self.a2 + self.b2
        dmin = 0.0 if lo1 <= self.w <= hi1 else min(abs(self.w - lo1), abs(self.w - hi1))
        if dmin > hi2:
            raise ValueError(
                f"w = {self.w} mm: the arms can never meet; need w ≤ a1+b1+a2+b2 = "
                f"{hi1 + hi2} mm and the reach annuli to overlap (gap {dmin - hi2:.6g} mm)")
        if self.w + hi1 < lo2:
            raise ValueError(
                f"arm 2's dead zone |a2 − b2| = {lo2} mm swallows arm 1's reach "
                f"(w + a1 + b1 = {self.w + hi1} mm): the loop can never close")

    # ----------------------------------------------------------------- inverse kinematics
    def inverse(self, points: ArrayLike, mode: str) -> FloatArray | InverseResult:
        """Motor angles for end-effector points in working mode `mode`.

        A single (2,) point returns a (2,) array or raises `UnreachableError` /
        `DegenerateError` naming the point, the limit and by how much. An (N, 2) batch
        returns an `InverseResult` with a validity mask and a reason per point.
        """
        pts, single = as_points(points, "points")
        res = self._inverse_batch(pts, mode)
        if single:
            if not res.valid[0]:
                self._raise_inverse(pts[0], Reason(int(res.reason[0])))
            out: FloatArray = res.angles[0]
            return out
        return res

    def inverse_batch(self, points: ArrayLike, mode: str) -> InverseResult:
        """Like `inverse` for an (N, 2) batch, typed to always return an `InverseResult`."""
        pts, _ = as_points(points, "points")
        return self._inverse_batch(pts, mode)

    def _inverse_batch(self, pts: FloatArray, mode: str) -> InverseResult:
        s1, s2 = mode_signs(mode, "working mode")
        x = pts[:, 0]
        y = pts[:, 1]
        th1, k1, c1sq = arm_inverse(x, y, self.a1, self.b1, s1)
        x2 = x - self.w
        th2, k2, c2sq = arm_inverse(x2, y, self.a2, self.b2, s2)
        valid = (k1 >= 0.0) & (k2 >= 0.0) & (c1sq > 0.0) & (c2sq > 0.0)
        angles = np.stack((th1, th2), axis=1)
        reason = np.zeros(pts.shape[0], dtype=np.int8)
        if not valid.all():
            angles[~valid] = 0.0
            reason = self._inverse_reasons(x, y, k1, k2, c1sq, c2sq, valid)
            valid = reason == Reason.OK
        return InverseResult(angles, valid, reason)

    def _inverse_reasons(self, x: FloatArray, y: FloatArray, k1: FloatArray, k2: FloatArray,
                         c1sq: FloatArray, c2sq: FloatArray,
                         valid: NDArray[np.bool_]) -> NDArray[np.int8]:
        """Reason codes for the rows that failed the fast check (rare path).

        Heron's K < 0 with the factor (a + b − c) negative means beyond reach, otherwise
        inside the dead zone; arm 1 is reported before arm 2, NOT_FINITE before both.
        """
        reason = np.zeros(x.shape[0], dtype=np.int8)
        arms = ((k2, c2sq, self.a2, self.b2, Reason.BEYOND_REACH_2, Reason.INSIDE_REACH_2,
                 Reason.AT_MOTOR_2),
                (k1, c1sq, self.a1, self.b1, Reason.BEYOND_REACH_1, Reason.INSIDE_REACH_1,
                 Reason.AT_MOTOR_1))
        with np.errstate(invalid="ignore"):
            for k, csq, a, b, beyond, inside, at_motor in arms:
                unreach = ~valid & (k < 0)
                far = (a + b - np.sqrt(csq)) < 0
                reason[unreach & far] = beyond
                reason[unreach & ~far] = inside
                reason[~valid & (k >= 0) & (csq == 0.0)] = at_motor
        reason[~(np.isfinite(x) & np.isfinite(y))] = Reason.NOT_FINITE
        return reason

    def _raise_inverse(self, p: FloatArray, reason: Reason) -> None:
        """Raise the documented error for one point, saying which limit and by how much."""
        where = (float(p[0]), float(p[1]))
        at = f"point ({p[0]:.9g}, {p[1]:.9g}) mm"
        if reason == Reason.NOT_FINITE:
            raise UnreachableError(f"{at}: coordinate is not a finite number", reason, where)
        arm = 1 if reason in (Reason.BEYOND_REACH_1, Reason.INSIDE_REACH_1,
                              Reason.AT_MOTOR_1) else 2
        a, b = (self.a1, self.b1) if arm == 1 else (self.a2, self.b2)
        mx = 0.0 if arm == 1 else self.w
        c = math.hypot(p[0] - mx, p[1])
        if reason in (Reason.AT_MOTOR_1, Reason.AT_MOTOR_2):
            raise DegenerateError(
                f"{at} is on motor M{arm} and a{arm} = b{arm}: θ{arm} is undetermined "
                "(the arm folds onto itself)", reason, where)
        if reason in (Reason.BEYOND_REACH_1, Reason.BEYOND_REACH_2):
            excess = c - (a + b)
            raise UnreachableError(
                f"{at} is beyond arm {arm}'s reach: |P − M{arm}| = {c:.12g} mm > "
                f"a{arm} + b{arm} = {a + b:.12g} mm (by {excess:.3g} mm)", reason, where, excess)
        excess = abs(a - b) - c
        raise UnreachableError(
            f"{at} is inside arm {arm}'s dead zone: |P − M{arm}| = {c:.12g} mm < "
            f"|a{arm} − b{arm}| = {abs(a - b):.12g} mm (by {excess:.3g} mm)", reason, where,
            excess)

    # ----------------------------------------------------------------- forward kinematics
    def elbows(self, angles: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Elbow positions R1, R2 (each (N, 2)) for motor angles (Eqs. 1–4)."""
        th, _ = as_points(angles, "angles")
        r1 = np.stack((self.a1 * np.cos(th[:, 0]), self.a1 * np.sin(th[:, 0])), axis=1)
        r2 = np.stack((self.w + self.a2 * np.cos(th[:, 1]), self.a2 * np.sin(th[:, 1])), axis=1)
        return r1, r2

    def forward(self, angles: ArrayLike, assembly: str | ArrayLike) -> FloatArray | ForwardResult:
        """End-effector points for motor angles in assembly mode `assembly`.

        `assembly` is "+" / "-" or a per-row array of ±1. A single (2,) pair returns a (2,)
        point or raises; an (N, 2) batch returns a `ForwardResult` with mask and reasons.
        """
        th, single = as_points(angles, "angles")
        res = self._forward_batch(th, assembly)
        if single:
            if not res.valid[0]:
                self._raise_forward(th[0], Reason(int(res.reason[0])))
            out: FloatArray = res.points[0]
            return out
        return res

    def forward_batch(self, angles: ArrayLike, assembly: str | ArrayLike) -> ForwardResult:
        """Like `forward` for an (N, 2) batch, typed to always return a `ForwardResult`."""
        th, _ = as_points(angles, "angles")
        return self._forward_batch(th, assembly)

    def _forward_batch(self, th: FloatArray, assembly: str | ArrayLike) -> ForwardResult:
        if isinstance(assembly, str):
            if assembly not in ("+", "-"):
                raise ValueError(f"assembly mode must be '+' or '-'; got {assembly!r}")
            sign: float | FloatArray = 1.0 if assembly == "+" else -1.0
        else:
            sign = np.asarray(assembly, dtype=np.float64)
            if sign.shape != (th.shape[0],) or not np.all(np.abs(sign) == 1.0):
                raise ValueError("per-row assembly must be an (N,) array of +1/-1")
        x1 = self.a1 * np.cos(th[:, 0])
        y1 = self.a1 * np.sin(th[:, 0])
        x2 = self.w + self.a2 * np.cos(th[:, 1])
        y2 = self.a2 * np.sin(th[:, 1])
        dx = x2 - x1
        dy = y2 - y1
        lsq = dx * dx + dy * dy
        # Circle–circle intersection along and across the chord R1→R2 (replaces Eqs. 9–15):
        # P = R1 + [(L² + b1² − b2²)·d + s·√K·d⊥] / (2L²), K = Heron(b1, b2, L) = 4L²h².
        k = _heron(self.b1, self.b2, np.sqrt(lsq))
        valid = (k >= 0.0) & (lsq > 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rootk = np.sqrt(np.maximum(k, 0.0)) * sign
            along = lsq + (self.b1 * self.b1 - self.b2 * self.b2)
            inv = 0.5 / lsq
            px = x1 + (along * dx - rootk * dy) * inv
            py = y1 + (along * dy + rootk * dx) * inv
        pts = np.stack((px, py), axis=1)
        reason = np.zeros(th.shape[0], dtype=np.int8)
        if not valid.all():
            pts[~valid] = 0.0
            lng = np.sqrt(lsq)
            reason[~valid & (lng > self.b1 + self.b2)] = Reason.ELBOWS_TOO_FAR
            reason[~valid & (lng < abs(self.b1 - self.b2))] = Reason.ELBOWS_TOO_CLOSE
            reason[~valid & (lsq == 0.0)] = (
                Reason.ELBOWS_COINCIDENT if self.b1 == self.b2 else Reason.ELBOWS_TOO_CLOSE)
            reason[~np.isfinite(th).all(axis=1)] = Reason.NOT_FINITE
            valid = reason == Reason.OK
        return ForwardResult(pts, valid, reason)

    def _raise_forward(self, th: FloatArray, reason: Reason) -> None:
        where = (float(th[0]), float(th[1]))
        at = f"motor angles ({th[0]:.9g}, {th[1]:.9g}) rad"
        if reason == Reason.NOT_FINITE:
            raise UnreachableError(f"{at}: angle is not a finite number", reason, where)
        r1, r2 = self.elbows(th)
        lng = float(np.hypot(*(r2[0] - r1[0])))
        if reason == Reason.ELBOWS_COINCIDENT:
            raise DegenerateError(
                f"{at}: elbows R1 and R2 coincide with b1 = b2, so P is free on a circle "
                "(Mode 1b class I singularity)", reason, where)
        if reason == Reason.ELBOWS_TOO_FAR:
            excess = lng - (self.b1 + self.b2)
            raise UnreachableError(
                f"{at}: elbows are {lng:.12g} mm apart > b1 + b2 = {self.b1 + self.b2:.12g} mm "
                f"(by {excess:.3g} mm)", reason, where, excess)
        excess = abs(self.b1 - self.b2) - lng
        raise UnreachableError(
            f"{at}: elbows are {lng:.12g} mm apart < |b1 − b2| = {abs(self.b1 - self.b2):.12g}"
            f" mm (by {excess:.3g} mm)", reason, where, excess)

    def pen_from_joint(self, r1: FloatArray, j: FloatArray) -> FloatArray:
        """The pen from elbow R1 and the joint J of the floating links (N, 2): the pen is
        the joint here; `kinematics.extension.ExtendedFiveBar` puts it on link b1."""
        del r1
        return j

    def joint_from_pen(self, r1: FloatArray, p: FloatArray) -> FloatArray:
        """The joint of the floating links from elbow R1 and the pen (N, 2): the pen here."""
        del r1
        return p

    # ----------------------------------------------------------------- pose measures
    def pose(self, angles: ArrayLike, points: ArrayLike) -> Pose:
        """Bundle motor angles and end-effector points with the elbows they imply."""
        th, _ = as_points(angles, "angles")
        p, _ = as_points(points, "points")
        r1, r2 = self.elbows(th)
        return Pose(th, r1, r2, p)

    def mode_of(self, points: ArrayLike, angles: ArrayLike) -> NDArray[np.int8]:
        """Working-mode signs (N, 2) of ±1 (0 exactly on a type-1 singularity):
        s_i = sign(cross(P − M_i, R_i − M_i))."""
        ps = self.pose(angles, points)
        m2x = self.w
        c1 = cross2d(ps.p[:, 0], ps.p[:, 1], ps.r1[:, 0], ps.r1[:, 1])
        c2 = cross2d(ps.p[:, 0] - m2x, ps.p[:, 1], ps.r2[:, 0] - m2x, ps.r2[:, 1])
        return np.stack((np.sign(c1), np.sign(c2)), axis=1).astype(np.int8)

    def assembly_of(self, angles: ArrayLike, points: ArrayLike) -> NDArray[np.int8]:
        """Assembly sign (N,) of ±1 (0 on a type-2 singularity): sign(cross(R2−R1, P−R1))."""
        ps = self.pose(angles, points)
        d = ps.r2 - ps.r1
        e = ps.p - ps.r1
        return np.sign(cross2d(d[:, 0], d[:, 1], e[:, 0], e[:, 1])).astype(np.int8)

    def transmission_angles(self, angles: ArrayLike, points: ArrayLike) -> FloatArray:
        """μ_i = ∠M_i R_i P in [0, π] (Eq. 23, computed with atan2 rather than arccos)."""
        ps = self.pose(angles, points)
        out = np.empty((ps.p.shape[0], 2))
        for i, (r, mx) in enumerate(((ps.r1, 0.0), (ps.r2, self.w))):
            ux, uy = mx - r[:, 0], -r[:, 1]
            vx, vy = ps.p[:, 0] - r[:, 0], ps.p[:, 1] - r[:, 1]
            out[:, i] = np.arctan2(np.abs(cross2d(ux, uy, vx, vy)), ux * vx + uy * vy)
        return out

    def singularity_margins(self, angles: ArrayLike, points: ArrayLike) -> FloatArray:
        """Signed angular distances (N, 3) rad to the singularities: columns are type 1 of
        arm 1, type 1 of arm 2 (a_i ∥ b_i: stretched or folded) and type 2 (b1 ∥ b2).

        Each is the acute angle between the two links' lines, in [0, π/2], signed by the
        working-mode sign of the arm (type 1) or by the assembly sign (type 2), so crossing a
        singularity changes the sign and one margin in degrees means the same everywhere.
        """
        ps = self.pose(angles, points)
        out = np.empty((ps.p.shape[0], 3))
        for i, (r, mx) in enumerate(((ps.r1, 0.0), (ps.r2, self.w))):
            # cross(M−R, P−R) = cross(P−M, R−M): positive iff s_i = "+".
            ux, uy = mx - r[:, 0], -r[:, 1]
            vx, vy = ps.p[:, 0] - r[:, 0], ps.p[:, 1] - r[:, 1]
            out[:, i] = np.arctan2(cross2d(ux, uy, vx, vy), np.abs(ux * vx + uy * vy))
        # cross(R1−P, R2−P) = cross(R2−R1, P−R1): positive iff assembly "+".
        ux, uy = ps.r1[:, 0] - ps.p[:, 0], ps.r1[:, 1] - ps.p[:, 1]
        vx, vy = ps.r2[:, 0] - ps.p[:, 0], ps.r2[:, 1] - ps.p[:, 1]
        out[:, 2] = np.arctan2(cross2d(ux, uy, vx, vy), np.abs(ux * vx + uy * vy))
        return out

    def jacobians(self, angles: ArrayLike, points: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Matrices A (N, 2, 2) and B (N, 2, 2) of the velocity relation A·ṗ = B·θ̇.

        Differentiating |P − R_i|² = b_i² gives (P − R_i)·ṗ = θ̇_i·cross(R_i − M_i, P − R_i):
        A's rows are (P − R_i); B is diagonal. det A = 0 at a type-2 singularity, B_ii = 0 at
        a type-1 singularity of arm i.
        """
        ps = self.pose(angles, points)
        n = ps.p.shape[0]
        a = np.empty((n, 2, 2))
        b = np.zeros((n, 2, 2))
        for i, (r, mx) in enumerate(((ps.r1, 0.0), (ps.r2, self.w))):
            e = ps.p - r
            a[:, i, :] = e
            b[:, i, i] = cross2d(r[:, 0] - mx, r[:, 1], e[:, 0], e[:, 1])
        return a, b

    def jacobian(self, angles: ArrayLike, points: ArrayLike) -> FloatArray:
        """Forward Jacobian J = A⁻¹B (N, 2, 2) so that ṗ = J·θ̇ (mm/rad); inf entries
        mean a type-2 singularity."""
        a, b = self.jacobians(angles, points)
        det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
        adj = np.empty_like(a)
        adj[:, 0, 0] = a[:, 1, 1]
        adj[:, 1, 1] = a[:, 0, 0]
        adj[:, 0, 1] = -a[:, 0, 1]
        adj[:, 1, 0] = -a[:, 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray((adj @ b) / det[:, None, None], dtype=np.float64)

    @property
    def reach(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Reach annuli ((lo1, hi1), (lo2, hi2)) of the two arms around M1 and M2, mm."""
        return ((abs(self.a1 - self.b1), self.a1 + self.b1),
                (abs(self.a2 - self.b2), self.a2 + self.b2))


def cross2d(ax: FloatArray, ay: FloatArray, bx: FloatArray, by: FloatArray) -> FloatArray:
    """z-component of the 2-D cross product a × b, elementwise."""
    return np.asarray(ax * by - ay * bx, dtype=np.float64)


def arm_inverse(dx: FloatArray, dy: FloatArray, a: float, b: float,
                 s: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Motor angle of one arm whose motor sits at the origin of (dx, dy).

    Law of cosines (Eq. 18) without arccos: with c² = dx² + dy², C = a² + c² − b² = 2ac·cos β
    and √K = 2ac·sin β (K = Heron(a, b, c)); the elbow direction is d rotated by s·β, so
    θ = atan2(dy·C + s·dx·√K, dx·C − s·dy·√K) — one atan2, valid in every quadrant
    (replaces Eqs. 21–22, which assume P above the motor axis). Returns (θ, K, c²).
    """
    csq = dx * dx + dy * dy
    k = _heron(a, b, np.sqrt(csq))
    with np.errstate(invalid="ignore"):
        rk = np.sqrt(k)
    if s < 0:
        rk = -rk
    cc = csq + (a * a - b * b)
    with np.errstate(invalid="ignore"):
        th = np.arctan2(dy * cc + dx * rk, dx * cc - dy * rk)
    return th, k, csq
