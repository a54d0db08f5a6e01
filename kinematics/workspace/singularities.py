"""Singularity loci of the five-bar robot, exactly: the type-2 curves and type-1 circles.

Type 1 of arm i (thesis "Mode 2", a_i ∥ b_i) lies on circles about the motor and bounds the
workspace; type 2 (thesis "Mode 1", b1 ∥ b2, det A = 0) is the curve across which the assembly
mode flips. Both are drawn by `fivebar workspace` and the dry-run preview, and type 1 is what
a working-mode change drives through. Parametrised in closed form, not found on a grid, so
a thin curve is never missed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import BoolArray, FloatArray
from kinematics.extension import ExtendedFiveBar
from kinematics.fivebar import FiveBar

__all__ = ["SingularityTrace", "type1_circles", "type2_traces"]


@dataclass(frozen=True)
class SingularityTrace:
    """A type-2 singularity curve (thesis "Mode 1"), sampled as points (N, 2) mm.

    `kind` is "1a" (P between R1 and R2, floating links stretched into one line: the coupler
    curve of the degenerate four-bar, thesis Fig. 10), "1b-II" (P outside the segment, b1 ≠ b2)
    or "1b-I" (b1 = b2: R1 = R2 and P free on a circle of radius b about the common elbow,
    thesis Fig. 11). `modes` (N,) names the working mode of each point ("" where an arm is
    exactly on its own type-1 singularity); consecutive points of one curve are joined only
    where `breaks` is False (breaks[k] True means no segment from point k to k + 1).
    """

    kind: str
    points: FloatArray
    modes: NDArray[np.str_]
    breaks: BoolArray

    def polylines(self, mode: str) -> list[FloatArray]:
        """The parts of the curve that lie in working mode `mode`, as separate polylines."""
        sel = self.modes == mode
        pts, brk = self.points, self.breaks
        n = pts.shape[0]
        if n and not brk[-1] and sel[0] and sel[-1] and not sel.all():
            # A closed curve whose selected part wraps around the seam: start after a gap.
            shift = int(np.flatnonzero(~sel)[0])
            pts, sel, brk = (np.roll(pts, -shift, axis=0), np.roll(sel, -shift),
                             np.roll(brk, -shift))
        out: list[FloatArray] = []
        start: int | None = None
        for k in range(n + 1):
            inside = k < n and bool(sel[k])
            joined = start is not None and k < n and not bool(brk[k - 1])
            if inside and (start is None or not joined):
                if start is not None and k - start >= 2:
                    out.append(pts[start:k])
                start = k
            elif not inside:
                if start is not None and k - start >= 2:
                    out.append(pts[start:k])
                start = None
        return out


def _mode_strings(s1: FloatArray, s2: FloatArray) -> NDArray[np.str_]:
    """Working-mode strings from sign arrays; "" where either sign is 0."""
    table = {(1, 1): "++", (1, -1): "+-", (-1, 1): "-+", (-1, -1): "--"}
    out = np.full(s1.shape, "", dtype="<U2")
    for (a, b), name in table.items():
        out[(np.sign(s1) == a) & (np.sign(s2) == b)] = name
    return out


def _modes_from_pose(fb: FiveBar, p: FloatArray, r1: FloatArray,
                     r2: FloatArray) -> NDArray[np.str_]:
    """Working modes of pen points p with elbows r1, r2 (arm 2 reaches the joint)."""
    j = fb.joint_from_pen(r1, p)
    c1 = p[:, 0] * r1[:, 1] - p[:, 1] * r1[:, 0]
    c2 = (j[:, 0] - fb.w) * r2[:, 1] - j[:, 1] * (r2[:, 0] - fb.w)
    return _mode_strings(c1, c2)


def type2_traces(fb: FiveBar, n: int = 1440) -> list[SingularityTrace]:
    """All type-2 singularity curves of the machine (thesis Sec. 1.3.2, 7.2), exactly.

    Parametrised by θ1 over a full turn: R1 = a1(cos θ1, sin θ1); R2 lies on the circle
    |R2 − M2| = a2 at distance L from R1, with L = b1 + b2 (Mode 1a) or L = |b1 − b2| (Mode 1b
    class II) — a circle–circle intersection with two branches. P then lies on the line R1R2:
    P = R1 + b1·u (u = (R2 − R1)/L) for 1a and for 1b with b1 > b2, P = R1 − b1·u for 1b with
    b1 < b2. This is the thesis' "coupler curve of the degenerate four-bar". With b1 = b2,
    L = 0 forces R1 = R2 at the intersections of the circles |R − M1| = a1 and |R − M2| = a2,
    and each gives the Mode 1b class I circle of radius b1 about that point.
    """
    out: list[SingularityTrace] = []
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    r1 = np.stack((fb.a1 * np.cos(t), fb.a1 * np.sin(t)), axis=1)
    lengths: list[tuple[str, float]] = [("1a", fb.b1 + fb.b2)]
    if fb.b1 != fb.b2:
        lengths.append(("1b-II", abs(fb.b1 - fb.b2)))
    for kind, L in lengths:
        # Circle about R1 (radius L) ∩ circle about M2 (radius a2).
        dx = fb.w - r1[:, 0]
        dy = -r1[:, 1]
        d = np.hypot(dx, dy)
        k = (L + fb.a2 + d) * (L + fb.a2 - d) * (L - fb.a2 + d) * (-L + fb.a2 + d)
        ok = (k >= 0.0) & (d > 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            along = (d * d + L * L - fb.a2 * fb.a2) / (2.0 * d * d)
            across = np.sqrt(np.maximum(k, 0.0)) / (2.0 * d * d)
        for branch in (1.0, -1.0):
            r2 = np.stack((r1[:, 0] + along * dx - branch * across * dy,
                           r1[:, 1] + along * dy + branch * across * dx), axis=1)
            u = (r2 - r1) / L
            sgn = -1.0 if (kind == "1b-II" and fb.b1 < fb.b2) else 1.0
            p = fb.pen_from_joint(r1, r1 + sgn * fb.b1 * u)
            pts = p[ok]
            if pts.shape[0] < 2:
                continue
            modes = _modes_from_pose(fb, pts, r1[ok], r2[ok])
            idx = np.flatnonzero(ok)
            breaks = np.diff(idx) != 1
            # Close the loop when the whole turn is valid (the curve is periodic in θ1).
            breaks = np.append(breaks, not (ok.all()))
            out.append(SingularityTrace(kind, pts, modes, breaks))
    if fb.b1 == fb.b2:
        for centre in _circle_intersections((0.0, 0.0), fb.a1, (fb.w, 0.0), fb.a2):
            c = np.asarray(centre)
            r = np.broadcast_to(c, (n, 2)).copy()
            p = fb.pen_from_joint(r, c + fb.b1 * np.stack((np.cos(t), np.sin(t)), axis=1))
            modes = _modes_from_pose(fb, p, r, r)
            breaks = np.zeros(n, dtype=bool)
            out.append(SingularityTrace("1b-I", p, modes, breaks))
    return out


def _circle_intersections(c1: tuple[float, float], r1: float, c2: tuple[float, float],
                          r2: float) -> list[tuple[float, float]]:
    """Intersection points of two circles (0, 1 or 2)."""
    dx, dy = c2[0] - c1[0], c2[1] - c1[1]
    d = math.hypot(dx, dy)
    k = (r1 + r2 + d) * (r1 + r2 - d) * (r1 - r2 + d) * (-r1 + r2 + d)
    if d == 0.0 or k < 0.0:
        return []
    a = (d * d + r1 * r1 - r2 * r2) / (2.0 * d * d)
    h = math.sqrt(k) / (2.0 * d * d)
    pts = [(c1[0] + a * dx - h * dy, c1[1] + a * dy + h * dx),
           (c1[0] + a * dx + h * dy, c1[1] + a * dy - h * dx)]
    return pts[:1] if k == 0.0 else pts


def type1_circles(fb: FiveBar) -> list[tuple[int, str, tuple[float, float], float]]:
    """Type-1 singularity loci (thesis "Mode 2"): for each arm i, the circles about M_i of
    radius a_i + b_i (stretched) and |a_i − b_i| (folded; absent when a_i = b_i). They bound
    the workspace of every working mode. Returns (arm, "stretched"/"folded", centre, radius).

    With the pen on an extension of link 1 (`ExtendedFiveBar`) arm 1's circles have the pen
    link d for b1; arm 2's locus (|J − M2| = a2 ± b2) is no circle in pen coordinates and is
    not listed (the safe region, `point_safety`, still checks its margin)."""
    out: list[tuple[int, str, tuple[float, float], float]] = []
    arms = [(1, fb.a1, fb.b1, 0.0), (2, fb.a2, fb.b2, fb.w)]
    if isinstance(fb, ExtendedFiveBar) and fb.extension > 0.0:
        arms = [(1, fb.a1, fb.pen_link, 0.0)]
    for arm, a, b, cx in arms:
        out.append((arm, "stretched", (cx, 0.0), a + b))
        if a != b:
            out.append((arm, "folded", (cx, 0.0), abs(a - b)))
    return out
