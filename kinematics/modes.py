"""Working-mode planning: which working mode draws each point, and the pen-up joint moves
between modes (thesis Sec. 1.3.2 last paragraph, Sec. 7.2).

A drawing that no single working mode covers safely is split into pieces, each drawn in one
mode; between two pieces the pen lifts and the arm whose mode sign changes is driven through
its type-1 singularity, along a joint-space path that keeps the assembly mode and the type-2
margin (the singularity the motors cannot control). `plan_joint_move` finds such a path (also
used for the move home), `plan_working_modes` assigns the modes. Pure numpy.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.arrays import BoolArray, FloatArray
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace import (
    Limits,
    NoSafeRegionError,
    angles_within_limits,
    assembly_sign,
    point_safety,
)

Node = tuple[int, int]

__all__ = ["DrawPiece", "ModePlan", "Transition", "plan_joint_move", "plan_working_modes"]


@dataclass(frozen=True)
class Transition:
    """A pen-up change of working mode (thesis Sec. 7.2): a joint-space path from the last pose
    of one drawn piece to the first pose of the next, which drives the arm(s) whose sign
    changes through their type-1 singularity (stretched or folded; the motor moves freely
    through it, thesis Sec. 1.3.2) while every pose keeps the assembly mode and clears the
    type-2 margin — the singularity the motors cannot control.

    joint_path (M, 2) rad and pen_path (M, 2) mm (forward kinematics) sample the move at most
    `step_rad` apart; crossings lists (arm, "stretched"/"folded", x, y) where an arm passes its
    type-1 singularity; min_type2_rad is the smallest type-2 margin met."""

    from_mode: str
    to_mode: str
    joint_path: FloatArray
    pen_path: FloatArray
    crossings: list[tuple[int, str, float, float]]
    min_type2_rad: float


@dataclass(frozen=True)
class DrawPiece:
    """Points start..stop-1 of stroke `stroke`, drawn pen-down in working mode `mode`;
    `transition` is the mode change planned before it (None: same mode as the piece before,
    or the first piece in the starting mode)."""

    stroke: int
    start: int
    stop: int
    mode: str
    transition: Transition | None


@dataclass(frozen=True)
class ModePlan:
    """Working-mode assignment of a whole drawing, with the planned transitions."""

    pieces: list[DrawPiece]
    assembly: str

    @property
    def transitions(self) -> list[Transition]:
        """The mode changes, in order."""
        return [p.transition for p in self.pieces if p.transition is not None]

    def describe(self) -> list[str]:
        """One line per mode change, for the dry-run report."""
        lines = []
        for p in self.pieces:
            t = p.transition
            if t is None:
                continue
            how = ", ".join(f"arm {a} {k} at ({x:.1f}, {y:.1f}) mm" for a, k, x, y in t.crossings)
            lines.append(
                f"pen up; working mode {t.from_mode} → {t.to_mode} before stroke {p.stroke} "
                f"point {p.start}: {how or 'no arm crossing'}; {t.joint_path.shape[0]} joint "
                f"samples, type-2 margin ≥ {math.degrees(t.min_type2_rad):.1f}°")
        return lines


def _wrap_into(th: FloatArray, lo: FloatArray) -> FloatArray:
    """Angles moved by whole turns into [lo, lo + 2π)."""
    return np.asarray(lo + np.mod(th - lo, 2.0 * math.pi), dtype=np.float64)


def _check_joint_path(fb: FiveBar, path: FloatArray, sign: float, min2: float,
                      limits: Limits | None) -> tuple[bool, FloatArray, float]:
    """Whether every pose of a joint path exists in the assembly, clears the type-2 margin
    and the joint limits; with the pen path and the smallest type-2 margin."""
    fw = fb.forward_batch(path, "+" if sign > 0 else "-")
    if not fw.valid.all():
        return False, fw.points, 0.0
    m2 = fb.singularity_margins(path, fw.points)[:, 2] * sign
    ok = bool((m2 >= min2).all())
    if limits is not None:
        ok &= bool(angles_within_limits(path, limits).all())
    return ok, fw.points, float(m2.min())


def _two_leg_route(fb: FiveBar, a: FloatArray, b: FloatArray, sign: float, min2: float,
                   limits: Limits | None,
                   step_rad: float) -> tuple[FloatArray, FloatArray, float] | None:
    """Two straight legs through one waypoint of a 16 × 16 joint-space lattice, shortest
    first: simple moves that rarely pass a type-1 singularity more often than the mode change
    needs. Returns (joint path, pen path, smallest type-2 margin) or None."""
    if limits is not None:
        box_lo = np.array([float(limits[0][0]), float(limits[1][0])])
        box_hi = np.array([float(limits[0][1]), float(limits[1][1])])
    else:
        box_lo, box_hi = np.minimum(a, b) - math.pi, np.maximum(a, b) + math.pi
    g1, g2 = np.meshgrid(np.linspace(box_lo[0], box_hi[0], 16),
                         np.linspace(box_lo[1], box_hi[1], 16))
    way = np.stack((g1.ravel(), g2.ravel()), axis=1)
    cost = np.abs(way - a).sum(axis=1) + np.abs(b - way).sum(axis=1)
    for k in np.argsort(cost, kind="stable"):
        path = _densify([a, way[k], b], step_rad)
        ok, pen, m = _check_joint_path(fb, path, sign, min2, limits)
        if ok:
            return path, pen, m
    return None


def plan_joint_move(fb: FiveBar, th_from: ArrayLike, th_to: ArrayLike, assembly: str,
                    min_type2_rad: float, limits_rad: Limits | None = None,
                    step_rad: float = math.radians(0.5),
                    cell_rad: float = math.radians(2.0)) -> tuple[FloatArray, FloatArray,
                                                                 float] | None:
    """A pen-up joint-space path between two poses of the same assembly mode that keeps the
    type-2 margin ≥ `min_type2_rad` (at least 1°) and the joint limits; type-1 singularities
    may be crossed (that is how an arm changes its working-mode sign).

    First the straight line in joint space, then two straight legs through the shortest
    workable waypoint of a 16 × 16 lattice; if both fail, a breadth-first search over a
    `cell_rad` lattice of joint space (8-neighbour; a box inside the joint limits, or the
    torus without limits) whose nodes clear the margin by 2° more, then a dense re-check of
    the whole path with the exact margin. Returns (joint path (M, 2) rad at most `step_rad`
    apart, pen path (M, 2) mm, smallest type-2 margin) or None if no path exists at that
    lattice resolution."""
    sign = assembly_sign(assembly)
    if sign == 0.0:
        raise ValueError("plan_joint_move needs an assembly sign '+' or '-'")
    min2 = max(float(min_type2_rad), math.radians(1.0))
    a = np.asarray(th_from, dtype=np.float64).reshape(2)
    b = np.asarray(th_to, dtype=np.float64).reshape(2)
    if limits_rad is not None:
        lo = np.array([float(limits_rad[0][0]), float(limits_rad[1][0])])
        a, b = _wrap_into(a, lo), _wrap_into(b, lo)
    else:
        b = a + np.mod(b - a + math.pi, 2.0 * math.pi) - math.pi
    direct = _densify([a, b], step_rad)
    ok, pen, m = _check_joint_path(fb, direct, sign, min2, limits_rad)
    if ok:
        return direct, pen, m
    legs = _two_leg_route(fb, a, b, sign, min2, limits_rad, step_rad)
    if legs is not None:
        return legs
    route = _lattice_route(fb, a, b, sign, min2, limits_rad, cell_rad, step_rad)
    if route is None and cell_rad > math.radians(0.75):
        route = _lattice_route(fb, a, b, sign, min2, limits_rad, cell_rad / 2.0, step_rad)
    if route is None:
        return None
    path = _densify(route, step_rad)
    ok, pen, m = _check_joint_path(fb, path, sign, min2, limits_rad)
    return (path, pen, m) if ok else None


def _densify(points: Sequence[FloatArray], step_rad: float) -> FloatArray:
    """Join joint-space waypoints by straight legs sampled at most `step_rad` apart."""
    out = [np.asarray(points[0], dtype=np.float64).reshape(1, 2)]
    for p, q in itertools.pairwise(points):
        n = max(2, math.ceil(float(np.abs(q - p).max()) / step_rad) + 1)
        out.append(p + np.linspace(0.0, 1.0, n)[1:, None] * (q - p))
    return np.concatenate(out)


@dataclass(frozen=True)
class _Lattice:
    """A joint-space lattice of `cell` pitch from `lo`, n (2,) nodes per axis (g1, g2 the node
    angles), on the torus if `wrap` (no joint limits); `free` (n1, n2) marks the nodes whose
    pose exists in the assembly and clears the type-2 margin by 2° more than asked."""

    lo: FloatArray
    n: NDArray[np.int64]
    cell: float
    wrap: bool
    g1: FloatArray
    g2: FloatArray
    free: BoolArray

    def node(self, i: int, j: int, near: FloatArray) -> FloatArray:
        """Joint angles of node (i, j), moved by whole turns next to `near` on the torus."""
        return _unwrap_to(np.array([self.g1[i], self.g2[j]]), near, self.wrap)

    def index(self, i: int, j: int) -> Node | None:
        """(i, j) wrapped on the torus, or None outside the box."""
        if self.wrap:
            return i % int(self.n[0]), j % int(self.n[1])
        if not (0 <= i < self.n[0] and 0 <= j < self.n[1]):
            return None
        return i, j


def _build_lattice(fb: FiveBar, a: FloatArray, sign: float, min2: float,
                   limits: Limits | None, cell: float) -> _Lattice:
    """The lattice over the joint-limit box, or over the torus centred on pose `a`."""
    if limits is not None:
        lo = np.array([float(limits[0][0]), float(limits[1][0])])
        span = np.array([float(limits[0][1]), float(limits[1][1])]) - lo
        n = np.floor(span / cell).astype(int) + 1
    else:
        lo = a - math.pi
        n = np.full(2, round(2.0 * math.pi / cell))
    g1 = lo[0] + cell * np.arange(n[0])
    g2 = lo[1] + cell * np.arange(n[1])
    t1, t2 = np.meshgrid(g1, g2, indexing="ij")
    nodes = np.stack((t1.ravel(), t2.ravel()), axis=1)
    fw = fb.forward_batch(nodes, "+" if sign > 0 else "-")
    good = fw.valid.copy()
    if good.any():
        m2 = fb.singularity_margins(nodes[good], fw.points[good])[:, 2] * sign
        good[np.flatnonzero(good)] = m2 >= min2 + math.radians(2.0)
    free = good.reshape(int(n[0]), int(n[1]))
    return _Lattice(lo, n, cell, limits is None, g1, g2, free)


def _attach(fb: FiveBar, lat: _Lattice, p: FloatArray, sign: float, min2: float,
            limits: Limits | None, step_rad: float) -> list[Node]:
    """Free nodes near p (at most 3), nearest first, that a straight leg from p reaches
    safely."""
    rel = (p - lat.lo) / lat.cell
    if lat.wrap:
        rel = np.mod(rel, lat.n)
    base = np.floor(rel).astype(int)
    cands = []
    for di in range(-2, 4):
        for dj in range(-2, 4):
            ij = lat.index(int(base[0] + di), int(base[1] + dj))
            if ij is not None and lat.free[ij]:
                q = lat.node(*ij, p)
                cands.append((float(np.abs(q - p).sum()), *ij))
    out: list[Node] = []
    for _, i, j in sorted(cands):
        q = lat.node(i, j, p)
        if _check_joint_path(fb, _densify([p, q], step_rad), sign, min2, limits)[0]:
            out.append((i, j))
            if len(out) >= 3:
                break
    return out


def _breadth_first(lat: _Lattice, starts: list[Node], goals: list[Node]) -> list[Node] | None:
    """Shortest 8-neighbour chain of free nodes from any start to any goal, or None."""
    goal_set = set(goals)
    prev: dict[Node, Node | None] = {s: None for s in starts}
    queue = deque(starts)
    hit: Node | None = None
    while queue:
        cur = queue.popleft()
        if cur in goal_set:
            hit = cur
            break
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                nxt = None if di == dj == 0 else lat.index(cur[0] + di, cur[1] + dj)
                if nxt is not None and lat.free[nxt] and nxt not in prev:
                    prev[nxt] = cur
                    queue.append(nxt)
    if hit is None:
        return None
    chain: list[Node] = []
    node: Node | None = hit
    while node is not None:
        chain.append(node)
        node = prev[node]
    chain.reverse()
    return chain


def _lattice_route(fb: FiveBar, a: FloatArray, b: FloatArray, sign: float, min2: float,
                   limits: Limits | None, cell: float,
                   step_rad: float) -> list[FloatArray] | None:
    """Breadth-first search on a joint-space lattice; returns waypoints a, nodes…, b."""
    lat = _build_lattice(fb, a, sign, min2, limits, cell)
    starts = _attach(fb, lat, a, sign, min2, limits, step_rad)
    goals = _attach(fb, lat, b, sign, min2, limits, step_rad)
    if not starts or not goals:
        return None
    chain = _breadth_first(lat, starts, goals)
    if chain is None:
        return None
    way = [a]
    for i, j in chain:
        way.append(lat.node(i, j, way[-1]))
    # On the torus the route may end a whole turn away from b: the same pose, and the
    # motor really does turn that far.
    way.append(_unwrap_to(b, way[-1], lat.wrap))
    return way


def _unwrap_to(q: FloatArray, ref: FloatArray, wrap: bool) -> FloatArray:
    """q moved by whole turns to lie within π of ref (only on the torus)."""
    if not wrap:
        return q
    return np.asarray(ref + np.mod(q - ref + math.pi, 2.0 * math.pi) - math.pi,
                      dtype=np.float64)


def _crossings(fb: FiveBar, path: FloatArray, pen: FloatArray) -> list[tuple[int, str, float,
                                                                              float]]:
    """Where an arm's type-1 margin changes sign along a joint path (linear interpolation)."""
    mar = fb.singularity_margins(path, pen)
    out: list[tuple[int, str, float, float]] = []
    for arm in (0, 1):
        m = mar[:, arm]
        for k in np.flatnonzero(np.sign(m[:-1]) * np.sign(m[1:]) < 0):
            t = m[k] / (m[k] - m[k + 1])
            p = pen[k] + t * (pen[k + 1] - pen[k])
            lo, hi = fb.reach[arm]  # the arm's annulus (exact but for arm 2 off the joint)
            mx = 0.0 if arm == 0 else fb.w
            d = math.hypot(p[0] - mx, p[1])
            kind = "stretched" if abs(d - hi) < abs(d - lo) else "folded"
            out.append((arm + 1, kind, float(p[0]), float(p[1])))
    return out


def _safe_runs(safe: dict[str, BoolArray], modes: Sequence[str], k: int,
               n: int) -> dict[str, int]:
    """Per mode, how many points from point k on are safe in a row."""
    runs: dict[str, int] = {}
    for m in modes:
        bad = np.flatnonzero(~safe[m][k:])
        runs[m] = int(bad[0]) if bad.size else n - k
    return runs


@dataclass
class _Walk:
    """`plan_working_modes` walking a drawing: the machine and its checks, the current working
    mode and the last pose drawn (None until the first piece without a start pose). The last
    pose is always in the current mode."""

    fb: FiveBar
    modes: Sequence[str]
    assembly: str
    min_type2_rad: float
    limits_rad: Limits | None
    mode: str
    pose: FloatArray | None

    def stroke(self, si: int, pts: FloatArray, safe: dict[str, BoolArray]) -> list[DrawPiece]:
        """The pieces of stroke `si` (points pts, per-mode safety `safe`)."""
        n = pts.shape[0]
        pieces: list[DrawPiece] = []
        k = 0
        while k < n:
            runs = _safe_runs(safe, self.modes, k, n)
            best = max(runs.values())
            if best == 0:
                raise NoSafeRegionError(
                    f"stroke {si} point {k} ({pts[k, 0]:.3f}, {pts[k, 1]:.3f}) mm is not safe in "
                    f"any working mode ({', '.join(self.modes)}) with assembly {self.assembly}")
            new = self.mode if runs[self.mode] == best else max(self.modes,
                                                                key=lambda m: runs[m])
            start = k
            if new != self.mode and k > 0:
                if not safe[new][k - 1]:
                    raise NoSafeRegionError(
                        f"stroke {si}: the segment from point {k - 1} to {k} has no working "
                        f"mode in which both ends are safe ({self.mode} → {new}); segment it "
                        "more finely or move the drawing")
                start = k - 1
            first = np.asarray(self.fb.inverse(pts[start], new), dtype=np.float64)
            trans: Transition | None = None
            if self.pose is not None and new != self.mode:
                trans = self.transition(new, first, f"stroke {si} point {start}")
            stop = k + runs[new]
            pieces.append(DrawPiece(si, start, stop, new, trans))
            self.mode = new
            self.pose = np.asarray(self.fb.inverse(pts[stop - 1], new), dtype=np.float64)
            k = stop
        return pieces

    def transition(self, new: str, first: FloatArray, where: str) -> Transition:
        """The pen-up move from the last pose to `first` (mode `new`) before `where`."""
        assert self.pose is not None
        planned = plan_joint_move(self.fb, self.pose, first, self.assembly, self.min_type2_rad,
                                  self.limits_rad)
        if planned is None:
            raise NoSafeRegionError(
                f"no pen-up path from working mode {self.mode} to {new} before {where} "
                "keeps the type-2 margin and joint limits")
        path, pen, m2 = planned
        return Transition(self.mode, new, path, pen, _crossings(self.fb, path, pen), m2)


def plan_working_modes(fb: FiveBar, strokes: Sequence[ArrayLike], start_mode: str,
                       min_type1_rad: float, min_type2_rad: float,
                       limits_rad: Limits | None = None, *, assembly: str,
                       start_angles: ArrayLike | None = None,
                       modes: Sequence[str] = WORKING_MODES) -> ModePlan:
    """Assign a working mode to every pen-down point of a drawing and plan the pen-up mode
    changes (thesis Sec. 1.3.2 last paragraph, Sec. 7.2).

    Each stroke (polyline (n, 2) mm) is walked from its start; the current mode is kept while
    its points are safe (`point_safety` with the fixed `assembly`), else the mode whose safe
    run from that point is longest is taken. A stroke split between two modes resumes at the
    last point of the previous piece, so the segment joining them is drawn in the new mode.
    Every mode change gets a `plan_joint_move` from the last pose of the previous piece (or
    `start_angles`, the pose before the job) to the first pose of the next piece. Without
    `start_angles` the first piece may begin in a mode other than `start_mode` with no
    transition planned before it: pass the homed pose.

    Only sample points are tested: the caller must segment strokes finely (the pipeline's
    one tolerance does). Raises `NoSafeRegionError` naming the stroke and point if a point is
    unsafe in every mode, if a segment joins points that share no safe mode, or if no
    transition path exists.
    """
    sign = assembly_sign(assembly)
    if sign == 0.0:
        raise ValueError("plan_working_modes needs the machine's assembly sign '+' or '-'")
    if start_mode not in modes:
        raise ValueError(f"start mode {start_mode!r} is not among the allowed modes {modes}")
    pose: FloatArray | None = (None if start_angles is None
                               else np.asarray(start_angles, dtype=np.float64).reshape(2))
    walk = _Walk(fb, modes, assembly, min_type2_rad, limits_rad, start_mode, pose)
    pieces: list[DrawPiece] = []
    for si, stroke in enumerate(strokes):
        pts = np.asarray(stroke, dtype=np.float64).reshape(-1, 2)
        safe = {m: point_safety(fb, m, pts, min_type1_rad, min_type2_rad, limits_rad,
                                assembly=assembly) for m in modes}
        pieces += walk.stroke(si, pts, safe)
    return ModePlan(pieces, assembly)
