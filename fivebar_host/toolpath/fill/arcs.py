"""Hatching along joint-iso arcs: one motor held still, the other moving.

With motor i still, elbow R_i = M_i + a_i·(cos θ_i, sin θ_i) does not move and the pen, at
distance b_i from it, swings on a circle of radius b_i about it. Such an arc is what the
machine draws best: the firmware's joint-space interpolation moves one motor only, so the
pen stays on the arc exactly between any two targets, and the still motor sits on a whole
step, so step quantisation cannot move the line sideways.

The arcs of a region are those of θ_i = home_i + m·k·step (m whole, k whole steps apart),
so every arc is on the step grid. Neighbouring arcs are not parallel: where the pen is, the
gap between the arcs of θ and θ + Δθ is a_i·Δθ·|sin φ|, φ the angle between link a_i and
link b_i (zero at the type-1 singularity, where the arm is stretched or folded). k is the
largest number of steps that keeps the widest gap in the region at most the nominal
spacing; the narrowest gap follows from the geometry and is reported, so the variation is
bounded (by the spread of |sin φ| over the region, which the singularity margins keep away
from zero) and said.

Only the part of an arc where the arm keeps the job's working-mode sign is used (the same
circle crosses the region a second time with the arm on its other side, where the still
motor would have to be elsewhere).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops
from numpy.typing import NDArray
from shapely.geometry.base import BaseGeometry

from fivebar_host.toolpath.geometry import ARC, LINE
from kinematics.arrays import FloatArray
from kinematics.fivebar import FiveBar


@dataclass(frozen=True)
class ArcFrame:
    """The machine a joint-iso hatch is made for: geometry, working mode, the still arm
    (1 or 2), its homed angle and its step (rad)."""

    fb: FiveBar
    mode: str
    arm: int
    home_rad: float
    step_rad: float

    @property
    def base(self) -> FloatArray:
        return np.array([0.0, 0.0]) if self.arm == 1 else np.array([self.fb.w, 0.0])

    @property
    def a(self) -> float:
        return self.fb.a1 if self.arm == 1 else self.fb.a2

    @property
    def b(self) -> float:
        return self.fb.b1 if self.arm == 1 else self.fb.b2

    @property
    def sign(self) -> float:
        return 1.0 if self.mode[self.arm - 1] == "+" else -1.0

    def elbow(self, th: FloatArray) -> FloatArray:
        return self.base + self.a * np.stack((np.cos(th), np.sin(th)), axis=-1)


@dataclass(frozen=True)
class ArcHatch:
    """A region's arcs as pen-down runs of primitives (kinds, params (n, 8)), the number of
    steps between neighbouring arcs, and the narrowest and widest gap in the region (mm)."""

    runs: list[tuple[NDArray[np.int8], FloatArray]]
    steps: int
    gap_min: float
    gap_max: float


def _samples(region: BaseGeometry, n: int = 400) -> FloatArray:
    """Points of the region: its boundary's vertices and a grid inside."""
    edge = shapely.get_coordinates(region.boundary)
    x0, y0, x1, y1 = region.bounds
    gx, gy = np.meshgrid(np.linspace(x0, x1, 20), np.linspace(y0, y1, 20))
    grid = np.stack((gx.ravel(), gy.ravel()), axis=1)
    grid = grid[shapely.contains_xy(region, grid[:, 0], grid[:, 1])]
    pts = np.concatenate((edge, grid))
    return pts[:: max(1, pts.shape[0] // n)] if pts.shape[0] > 4 * n else pts


def _angles(fr: ArcFrame, pts: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The still arm's angle at each point (job's working mode) and |sin φ| there."""
    inv = fr.fb.inverse_batch(pts, fr.mode)
    th = inv.angles[:, fr.arm - 1][inv.valid]
    p = pts[inv.valid]
    r = fr.elbow(th)
    u, v = (r - fr.base) / fr.a, (p - r) / fr.b
    return th, np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])


def arc_hatch(region: BaseGeometry, fr: ArcFrame, spacing: float, eps: float,
              tol: float) -> ArcHatch:
    """The joint-iso arcs through `region` (machine frame; module doc), at most `spacing`
    apart, joined by links inside the region where they can be; each arc cut into pieces
    short enough (`piece_angle`) that the pipeline draws every piece as one chord whose
    ends are on the arc, so no target is ever placed off it."""
    th, sin_phi = _angles(fr, _samples(region))
    if th.size == 0:
        return ArcHatch([], 0, 0.0, 0.0)
    widest = fr.a * float(sin_phi.max())
    k = max(1, math.floor(spacing / (widest * fr.step_rad)))
    dth = k * fr.step_rad
    m0 = math.ceil((float(th.min()) - fr.home_rad) / dth)
    m1 = math.floor((float(th.max()) - fr.home_rad) / dth)
    grown = region.buffer(eps)
    shapely.prepare(grown)
    longest = max(10 * spacing, 2.0)
    done: list[list[tuple[int, tuple[float, ...]]]] = []
    # open runs: (primitives, end point, the arc they last took a piece from)
    open_: list[tuple[list[tuple[int, tuple[float, ...]]], FloatArray, int]] = []
    for j, m in enumerate(range(m0, m1 + 1)):
        c = fr.elbow(np.array(fr.home_rad + m * dth))
        still = [r for r in open_ if r[2] >= j - 1]
        done.extend(r[0] for r in open_ if r[2] < j - 1)
        open_ = []
        for a0, a1 in _inside(region, fr, c, eps):
            ends = [c + fr.b * np.array([math.cos(t), math.sin(t)]) for t in (a0, a1)]
            best: tuple[float, int, int, FloatArray] | None = None
            for i, (_, end, _j) in enumerate(still):
                for side in (0, 1):  # enter the piece at a0 (side 0) or at a1
                    d = float(np.hypot(*(ends[side] - end)))
                    if d <= longest and (best is None or d < best[0]):
                        best = (d, i, side, ends[side])
            arc = (ARC, (float(c[0]), float(c[1]), fr.b, 0.0, 0.0, fr.b, a0, a1 - a0))
            link = None if best is None else _link(region, grown, still[best[1]][1],
                                                   best[3], eps, longest)
            if best is not None and link is not None:
                prims, _, _ = still.pop(best[1])
                prims.extend((LINE, (*p, *q)) for p, q in itertools.pairwise(link))
                if best[2] == 1:
                    arc = (ARC, (*arc[1][:6], a1, a0 - a1))
                prims.append(arc)
                open_.append((prims, ends[1 - best[2]], j))
            else:
                open_.append(([arc], ends[1], j))
        open_.extend(still)
    done.extend(r[0] for r in open_)
    most = piece_angle(fr.b, tol)
    runs = [_split_arcs(*_prims(r), most) for r in done if r]
    gap = fr.a * dth
    return ArcHatch(runs, k, gap * float(sin_phi.min()), gap * float(sin_phi.max()))


def _link(region: BaseGeometry, grown: BaseGeometry, a: FloatArray, b: FloatArray,
          eps: float, longest: float) -> FloatArray | None:
    """A pen-down link from a to b inside the region: the straight line when it stays
    inside, else the shorter way along the ring both lie on when that is at most
    `longest` (a pen lift is cheaper than drawing half a ring); None otherwise."""
    if grown.covers(shapely.LineString([a, b])):
        return np.array([a, b])
    pa, pb = shapely.Point(a), shapely.Point(b)
    for ring in (region.exterior, *region.interiors):
        if ring.distance(pa) > 2 * eps or ring.distance(pb) > 2 * eps:
            continue
        n, da, db = ring.length, ring.project(pa), ring.project(pb)
        fw = (db - da) % n
        if min(fw, n - fw) > longest:
            return None
        if fw <= n / 2:
            parts = [(da, min(da + fw, n))] + ([(0.0, da + fw - n)] if da + fw > n else [])
        else:
            bw = n - fw
            parts = [(da, max(da - bw, 0.0))] + ([(n, n + da - bw)] if da - bw < 0 else [])
        pts = [a]
        for s0, s1 in parts:
            sub = shapely.ops.substring(ring, s0, s1)
            pts.extend(np.asarray(sub.coords)[1:] if sub.geom_type == "LineString" else [])
        pts.append(b)
        return np.array(pts)
    return None


def piece_angle(b: float, tol: float) -> float:
    """The largest arc angle drawn as one chord with no target between its ends: its
    sagitta b·Δ²/8 within 0.35·tol (below the flattening's tol/2 and the refinement's split
    threshold, 0.8 of the other half), and the pen's move b·Δ within 1 mm (below the
    planner's joint-step cap on any usable linkage)."""
    return min(math.sqrt(8 * 0.35 * tol / b), 1.0 / b)


def _split_arcs(kinds: NDArray[np.int8], params: FloatArray, most: float
                ) -> tuple[NDArray[np.int8], FloatArray]:
    """Every arc of a run cut into equal pieces of at most `most` radians."""
    n = np.where(kinds == ARC, np.maximum(1, np.ceil(np.abs(params[:, 7]) / most)),
                 1).astype(np.int64)
    idx = np.repeat(np.arange(kinds.shape[0]), n)
    j = np.arange(idx.shape[0]) - np.repeat(np.cumsum(n) - n, n)
    out = params[idx].copy()
    arc = kinds[idx] == ARC
    d = out[arc, 7] / n[idx][arc]
    out[arc, 6] = out[arc, 6] + j[arc] * d
    out[arc, 7] = d
    return kinds[idx], out


def _prims(run: list[tuple[int, tuple[float, ...]]]) -> tuple[NDArray[np.int8], FloatArray]:
    kinds = np.array([k for k, _ in run], dtype=np.int8)
    params = np.zeros((len(run), 8))
    for i, (_, p) in enumerate(run):
        params[i, :len(p)] = p
    return kinds, params


def _inside(region: BaseGeometry, fr: ArcFrame, c: FloatArray,
            eps: float) -> list[tuple[float, float]]:
    """The angle intervals (increasing) of the circle about elbow c of radius b inside the
    region with the arm's working-mode sign, ends found by bisection to `eps`."""
    n = max(64, math.ceil(2 * math.pi / math.sqrt(8 * eps / fr.b)))
    psi = np.linspace(-math.pi, math.pi, n + 1)[:-1]

    def ok(a: FloatArray) -> NDArray[np.bool_]:
        p = c + fr.b * np.stack((np.cos(a), np.sin(a)), axis=-1)
        rel, arm = p - fr.base, c - fr.base
        side = (rel[:, 0] * arm[1] - rel[:, 1] * arm[0]) * fr.sign > 0
        return np.asarray(side & shapely.contains_xy(region, p[:, 0], p[:, 1]))

    inside = ok(psi)
    if not inside.any():
        return []
    if inside.all():
        return [(-math.pi, math.pi)]
    k0 = int(np.flatnonzero(~inside)[0])  # start the walk outside: runs never wrap
    order = (np.arange(n) + k0) % n
    flags = inside[order]
    ang = psi[order] + np.where(order < k0, 2 * math.pi, 0.0)
    rise = np.flatnonzero(~flags[:-1] & flags[1:]) + 1
    fall = np.flatnonzero(flags[:-1] & ~flags[1:]) + 1
    if flags[-1]:
        fall = np.append(fall, n)
    step = 2 * math.pi / n
    lo_out, lo_in = ang[rise] - step, ang[rise]
    hi_in = ang[fall - 1]
    hi_out = hi_in + step
    for _ in range(40):  # bisection of every end at once
        mid = 0.5 * (lo_out + lo_in)
        inn = ok(mid)
        lo_in, lo_out = np.where(inn, mid, lo_in), np.where(inn, lo_out, mid)
        mid = 0.5 * (hi_in + hi_out)
        inn = ok(mid)
        hi_in, hi_out = np.where(inn, mid, hi_in), np.where(inn, hi_out, mid)
    return [(float(a), float(b)) for a, b in zip(lo_in, hi_in, strict=True) if b > a]
