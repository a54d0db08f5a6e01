"""The pen off the joint: a five-bar whose end effector sits on an extension of distal link 1
(Plotclock's geometry, Line-us).

Frame and angle conventions are `kinematics.fivebar`'s. The mechanism is the plain five-bar
M1–R1–J–R2–M2 with the distal links meeting at the joint J (|J − R1| = b1, |J − R2| = b2);
the pen P is a point rigidly fixed to link b1, `extension` e mm beyond J, its direction
J→P turned by `extension_angle` γ (rad, counter-clockwise) from the link's direction R1→J
(γ = 0: a straight extension of b1). In complex numbers (z = x + iy):

    P − R1 = m·(J − R1),   m = 1 + (e/b1)·e^{iγ},   d = |P − R1| = b1·|m|        (X1)

so link 1 is, for the pen, a link of length d from R1, and J = R1 + (P − R1)/m.

Inverse kinematics (closed form; the seeds' thesis covers only the pen at the joint, so the
equations are derived here and the thesis numbers refer to the plain arm they reuse):
 1. arm 1 first, on the extended link: R1 lies at a1 from M1 and d from P — the circle
    intersection of the thesis' Eq. 18 (law of cosines) with b1 replaced by d, in Heron form
    (`arm_inverse`);
 2. then J = R1 + (P − R1)/m (X1), and arm 2 is the plain arm (a2, b2) reaching J.
Forward kinematics: J is the plain five-bar's forward solution (circles about R1, R2 of radii
b1, b2), then P = R1 + m·(J − R1) (X1).

Working modes and singularities redone for the extension. Differentiating the two loop
constraints |P − R1|² = d² and |J − R2|² = b2² with J = R1 + Q(P − R1) (Q the 2×2 form of
1/m) gives A·ṗ = B·θ̇ with

    A = [ (P − R1)ᵀ ; (Qᵀ(J − R2))ᵀ ],
    B = [ cross(R1 − M1, P − R1), 0 ; −(J − R2)·(I − Q)·(R1 − M1)⊥, cross(R2 − M2, J − R2) ].

B is triangular, so type 1 (an inverse singularity) is B11 = 0 — arm 1 stretched or folded
*onto the pen* (a1 ∥ R1P, |P − M1| = a1 ± d) — or B22 = 0 — arm 2 stretched or folded onto the
joint (a2 ∥ b2, |J − M2| = a2 ± b2). det A = cross(J − R1, J − R2) (Q is a scaled rotation),
so type 2 is the mechanism's own: b1 ∥ b2, wherever the pen is. The working-mode sign of arm 1
is thus the side of the elbow R1 of the chord M1→P, that of arm 2 the side of R2 of M2→J; the
assembly sign is the side of J of R1→R2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.arrays import FloatArray
from kinematics.fivebar import (
    DegenerateError,
    FiveBar,
    ForwardResult,
    InverseResult,
    Reason,
    UnreachableError,
    arm_inverse,
    as_points,
    cross2d,
    mode_signs,
)

__all__ = ["ExtendedFiveBar"]


@dataclass(frozen=True)
class ExtendedFiveBar(FiveBar):
    """A five-bar with the pen on an extension of distal link 1 (module docstring, Eq. X1).

    `extension` e ≥ 0 mm from the joint J to the pen along the extension, `extension_angle` γ
    rad (|γ| ≤ π) of J→P from R1→J. e = 0 is the plain five-bar."""

    extension: float = 0.0
    extension_angle: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("extension", "extension_angle"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number; got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.extension < 0.0:
            raise ValueError(f"extension must be ≥ 0 mm; got {self.extension!r}")
        if abs(self.extension_angle) > math.pi:
            raise ValueError(f"extension angle must lie in [−180°, 180°]; got "
                             f"{math.degrees(self.extension_angle):g}°")
        if self.pen_link <= 1e-9 * self.b1:
            raise ValueError("the extension puts the pen on the elbow R1 (e = b1, γ = 180°): "
                             "the pen would not move with arm 2")

    # ---------------------------------------------------------------- the extension (X1)
    @property
    def ratio(self) -> tuple[float, float]:
        """m = 1 + (e/b1)·e^{iγ} of Eq. X1 as (real, imaginary): P − R1 = m·(J − R1)."""
        k = self.extension / self.b1
        return 1.0 + k * math.cos(self.extension_angle), k * math.sin(self.extension_angle)

    @property
    def pen_link(self) -> float:
        """d = |P − R1| = b1·|m|: the length of link 1 as the pen sees it, mm."""
        return self.b1 * math.hypot(*self.ratio)

    def pen_from_joint(self, r1: FloatArray, j: FloatArray) -> FloatArray:
        """P = R1 + m·(J − R1) (Eq. X1), rows (N, 2)."""
        mr, mi = self.ratio
        dx, dy = j[:, 0] - r1[:, 0], j[:, 1] - r1[:, 1]
        return np.stack((r1[:, 0] + mr * dx - mi * dy, r1[:, 1] + mi * dx + mr * dy), axis=1)

    def joint_from_pen(self, r1: FloatArray, p: FloatArray) -> FloatArray:
        """J = R1 + (P − R1)/m (Eq. X1), rows (N, 2)."""
        mr, mi = self.ratio
        n2 = mr * mr + mi * mi
        dx, dy = p[:, 0] - r1[:, 0], p[:, 1] - r1[:, 1]
        return np.stack((r1[:, 0] + (mr * dx + mi * dy) / n2,
                         r1[:, 1] + (mr * dy - mi * dx) / n2), axis=1)

    def joints(self, angles: ArrayLike, points: ArrayLike) -> FloatArray:
        """The joint J (N, 2) of link b1 and b2 for motor angles and pen points."""
        th, _ = as_points(angles, "angles")
        p, _ = as_points(points, "points")
        r1, _ = self.elbows(th)
        return self.joint_from_pen(r1, p)

    # ---------------------------------------------------------------- inverse kinematics
    def _inverse_batch(self, pts: FloatArray, mode: str) -> InverseResult:
        s1, s2 = mode_signs(mode, "working mode")
        x, y = pts[:, 0], pts[:, 1]
        d = self.pen_link
        # 1. Arm 1 on the extended link: R1 at a1 from M1 and d from P (Eq. 18 with b1 → d).
        th1, k1, c1sq = arm_inverse(x, y, self.a1, d, s1)
        r1 = np.stack((self.a1 * np.cos(th1), self.a1 * np.sin(th1)), axis=1)
        # 2. The joint J from the pen (Eq. X1), then arm 2 reaching J.
        j = self.joint_from_pen(r1, pts)
        th2, k2, c2sq = arm_inverse(j[:, 0] - self.w, j[:, 1], self.a2, self.b2, s2)
        with np.errstate(invalid="ignore"):
            ok1 = (k1 >= 0.0) & (c1sq > 0.0)
            ok2 = (k2 >= 0.0) & (c2sq > 0.0)
        valid = ok1 & ok2
        angles = np.stack((th1, th2), axis=1)
        reason = np.zeros(pts.shape[0], dtype=np.int8)
        if not valid.all():
            angles[~valid] = 0.0
            with np.errstate(invalid="ignore"):
                for ok, k, csq, a, b, codes in (
                        (ok2, k2, c2sq, self.a2, self.b2, (Reason.BEYOND_REACH_2,
                                                           Reason.INSIDE_REACH_2,
                                                           Reason.AT_MOTOR_2)),
                        (ok1, k1, c1sq, self.a1, d, (Reason.BEYOND_REACH_1,
                                                     Reason.INSIDE_REACH_1,
                                                     Reason.AT_MOTOR_1))):
                    far = (a + b - np.sqrt(csq)) < 0
                    reason[~ok & (k < 0) & far] = codes[0]
                    reason[~ok & (k < 0) & ~far] = codes[1]
                    reason[~ok & (k >= 0) & (csq == 0.0)] = codes[2]
            reason[~(np.isfinite(x) & np.isfinite(y))] = Reason.NOT_FINITE
            valid = reason == Reason.OK
        return InverseResult(angles, valid, reason)

    def inverse(self, points: ArrayLike, mode: str) -> FloatArray | InverseResult:
        """As `FiveBar.inverse`; a single unreachable point raises naming arm 2's reach at
        the joint J."""
        pts, single = as_points(points, "points")
        res = self._inverse_batch(pts, mode)
        if not single:
            return res
        if not res.valid[0]:
            self._raise_at(pts[0], Reason(int(res.reason[0])), mode)
        out: FloatArray = res.angles[0]
        return out

    def _raise_at(self, p: FloatArray, reason: Reason, mode: str) -> None:
        """The documented error for one point; arm 2's reach is measured at the joint J."""
        where = (float(p[0]), float(p[1]))
        at = f"point ({p[0]:.9g}, {p[1]:.9g}) mm"
        if reason == Reason.NOT_FINITE:
            raise UnreachableError(f"{at}: coordinate is not a finite number", reason, where)
        arm = 1 if reason in (Reason.BEYOND_REACH_1, Reason.INSIDE_REACH_1,
                              Reason.AT_MOTOR_1) else 2
        if arm == 1:
            a, b, c, what = self.a1, self.pen_link, math.hypot(p[0], p[1]), "|P − M1|"
            names = "a1 + d"
        else:
            s1 = mode_signs(mode, "working mode")[0]
            th1 = float(arm_inverse(np.array([p[0]]), np.array([p[1]]), self.a1,
                                     self.pen_link, s1)[0][0])
            r1 = np.array([[self.a1 * math.cos(th1), self.a1 * math.sin(th1)]])
            j = self.joint_from_pen(r1, p.reshape(1, 2))[0]
            a, b, c, what = self.a2, self.b2, math.hypot(j[0] - self.w, j[1]), "|J − M2|"
            names = "a2 + b2"
        if reason in (Reason.AT_MOTOR_1, Reason.AT_MOTOR_2):
            raise DegenerateError(f"{at}: arm {arm} folds onto its motor, θ{arm} is "
                                  "undetermined", reason, where)
        if reason in (Reason.BEYOND_REACH_1, Reason.BEYOND_REACH_2):
            excess = c - (a + b)
            raise UnreachableError(
                f"{at} is beyond arm {arm}'s reach: {what} = {c:.12g} mm > {names} = "
                f"{a + b:.12g} mm (by {excess:.3g} mm)", reason, where, excess)
        excess = abs(a - b) - c
        raise UnreachableError(
            f"{at} is inside arm {arm}'s dead zone: {what} = {c:.12g} mm < "
            f"{abs(a - b):.12g} mm (by {excess:.3g} mm)", reason, where, excess)

    # ---------------------------------------------------------------- forward kinematics
    def _forward_batch(self, th: FloatArray, assembly: str | ArrayLike) -> ForwardResult:
        """The joint J by the plain five-bar's circle intersection, then the pen (X1)."""
        plain = super()._forward_batch(th, assembly)
        r1, _ = self.elbows(th)
        pts = self.pen_from_joint(r1, np.asarray(plain.points))
        pts[~plain.valid] = 0.0
        return ForwardResult(pts, plain.valid, plain.reason)

    # ---------------------------------------------------------------- pose measures
    def mode_of(self, points: ArrayLike, angles: ArrayLike) -> NDArray[np.int8]:
        """Working-mode signs (N, 2): arm 1 the side of R1 of M1→P, arm 2 of R2 of M2→J."""
        ps = self.pose(angles, points)
        j = self.joint_from_pen(ps.r1, ps.p)
        c1 = cross2d(ps.p[:, 0], ps.p[:, 1], ps.r1[:, 0], ps.r1[:, 1])
        c2 = cross2d(j[:, 0] - self.w, j[:, 1], ps.r2[:, 0] - self.w, ps.r2[:, 1])
        return np.stack((np.sign(c1), np.sign(c2)), axis=1).astype(np.int8)

    def assembly_of(self, angles: ArrayLike, points: ArrayLike) -> NDArray[np.int8]:
        """Assembly sign (N,): the side of the joint J of R1→R2."""
        ps = self.pose(angles, points)
        j = self.joint_from_pen(ps.r1, ps.p)
        d = ps.r2 - ps.r1
        e = j - ps.r1
        return np.sign(cross2d(d[:, 0], d[:, 1], e[:, 0], e[:, 1])).astype(np.int8)

    def transmission_angles(self, angles: ArrayLike, points: ArrayLike) -> FloatArray:
        """μ_i = ∠M_i R_i J in [0, π] (Eq. 23 at the joint: force goes through the links)."""
        ps = self.pose(angles, points)
        j = self.joint_from_pen(ps.r1, ps.p)
        out = np.empty((ps.p.shape[0], 2))
        for i, (r, mx) in enumerate(((ps.r1, 0.0), (ps.r2, self.w))):
            ux, uy = mx - r[:, 0], -r[:, 1]
            vx, vy = j[:, 0] - r[:, 0], j[:, 1] - r[:, 1]
            out[:, i] = np.arctan2(np.abs(cross2d(ux, uy, vx, vy)), ux * vx + uy * vy)
        return out

    def singularity_margins(self, angles: ArrayLike, points: ArrayLike) -> FloatArray:
        """Signed angular distances (N, 3) rad, as `FiveBar.singularity_margins`, for the
        singularities of the extension (module docstring): arm 1 a1 ∥ R1P, arm 2 a2 ∥ b2,
        type 2 b1 ∥ b2 (angle at J)."""
        ps = self.pose(angles, points)
        j = self.joint_from_pen(ps.r1, ps.p)
        out = np.empty((ps.p.shape[0], 3))
        for i, (r, mx, tip) in enumerate(((ps.r1, 0.0, ps.p), (ps.r2, self.w, j))):
            ux, uy = mx - r[:, 0], -r[:, 1]
            vx, vy = tip[:, 0] - r[:, 0], tip[:, 1] - r[:, 1]
            out[:, i] = np.arctan2(cross2d(ux, uy, vx, vy), np.abs(ux * vx + uy * vy))
        ux, uy = ps.r1[:, 0] - j[:, 0], ps.r1[:, 1] - j[:, 1]
        vx, vy = ps.r2[:, 0] - j[:, 0], ps.r2[:, 1] - j[:, 1]
        out[:, 2] = np.arctan2(cross2d(ux, uy, vx, vy), np.abs(ux * vx + uy * vy))
        return out

    def jacobians(self, angles: ArrayLike, points: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """A (N, 2, 2) and B (N, 2, 2) of A·ṗ = B·θ̇ (module docstring); B is lower
        triangular, not diagonal: arm 1 moves the joint J that arm 2 must reach."""
        ps = self.pose(angles, points)
        j = self.joint_from_pen(ps.r1, ps.p)
        mr, mi = self.ratio
        n2 = mr * mr + mi * mi
        qr, qi = mr / n2, -mi / n2  # q = 1/m
        n = ps.p.shape[0]
        a = np.empty((n, 2, 2))
        b = np.zeros((n, 2, 2))
        e1 = ps.p - ps.r1
        e2 = j - ps.r2
        a[:, 0, :] = e1
        # Qᵀ·v is conj(q)·v in complex form.
        a[:, 1, 0] = qr * e2[:, 0] + qi * e2[:, 1]
        a[:, 1, 1] = qr * e2[:, 1] - qi * e2[:, 0]
        b[:, 0, 0] = cross2d(ps.r1[:, 0], ps.r1[:, 1], e1[:, 0], e1[:, 1])
        b[:, 1, 1] = cross2d(ps.r2[:, 0] - self.w, ps.r2[:, 1], e2[:, 0], e2[:, 1])
        px, py = -ps.r1[:, 1], ps.r1[:, 0]  # (R1 − M1)⊥ = dR1/dθ1
        # (I − Q)·v with Q·v = q·v in complex form.
        wx = px - (qr * px - qi * py)
        wy = py - (qi * px + qr * py)
        b[:, 1, 0] = -(e2[:, 0] * wx + e2[:, 1] * wy)
        return a, b

    @property
    def reach(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Reach annuli about M1 and M2, mm: arm 1's is exact (a1 ± d); arm 2's bounds the
        pen's distance from M2 (the joint's annulus a2 ± b2 widened by e)."""
        d = self.pen_link
        lo2 = max(0.0, abs(self.a2 - self.b2) - self.extension)
        return ((abs(self.a1 - d), self.a1 + d),
                (lo2, self.a2 + self.b2 + self.extension))
