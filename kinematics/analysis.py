"""Design and diagnosis of the five-bar robot: safe workspace, page rectangle, singularity
traces, transmission angle, error sensitivity and link-length search.

Pure numpy, no I/O. Frame, angle and mode conventions are those of `kinematics.fivebar`
(motor M1 at (0, 0), M2 at (w, 0), mm, rad from +x counter-clockwise).

Vocabulary (thesis Sec. 1.3.2 vs. this project). The thesis calls a singularity that involves a
driving link "Mode 2" (a_i ∥ b_i: the arm is stretched or folded, P on a reach circle) and the
one between the floating links "Mode 1" (b1 ∥ b2). We say *type 1* and *type 2*, as
`FiveBar.singularity_margins` does:

- type 1 of arm i ⇔ thesis Mode 2: |P − M_i| = a_i + b_i or |a_i − b_i|. These circles bound
  the workspace (the same for all four working modes); the motor drives through them, and that
  is how an arm changes its working-mode sign.
- type 2 ⇔ thesis Mode 1: P on the line R1R2, det A = 0. Mode 1a is P between R1 and R2
  (|R1R2| = b1 + b2); its trace in the working mode "++"/"--" is the curve that cuts a hole in
  the workspace (thesis Fig. 10). Mode 1b is P outside the segment (|R1R2| = |b1 − b2|); with
  b1 = b2 (class I) R1 = R2 and the trace is a circle of radius b about that common elbow.

A point is *safe* in a working mode if the inverse kinematics (Eqs. 16–22) exist there, the
motor angles lie within the joint limits and both singularity margins clear the configured
minima. Across the type-2 curve the assembly mode flips, which the motors cannot control, so a
safe region is also tied to one assembly sign ("+" iff P lies left of R1→R2).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.fivebar import WORKING_MODES, FiveBar

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Limits = Sequence[Sequence[float]]  # ((lo1, hi1), (lo2, hi2)) in rad

__all__ = [
    "DesignCandidate",
    "DesignResult",
    "DrawPiece",
    "ModePlan",
    "NoSafeRegionError",
    "PageFit",
    "PageStats",
    "PointMeasures",
    "Rect",
    "SingularityTrace",
    "Transition",
    "WorkspaceReport",
    "angles_within_limits",
    "condition_numbers",
    "default_resolution",
    "design_search",
    "find_page_rectangle",
    "largest_page_rectangle",
    "measures",
    "page_stats",
    "perturbation_displacements",
    "plan_joint_move",
    "plan_working_modes",
    "point_safety",
    "safe_mask",
    "step_quantum",
    "type1_circles",
    "type2_traces",
    "workspace_bounds",
    "workspace_report",
]


class NoSafeRegionError(ValueError):
    """No point of the searched area is safe (or no rectangle of the asked shape fits)."""


# ----------------------------------------------------------------------------- rectangles
@dataclass(frozen=True)
class Rect:
    """An axis-aligned rectangle in the machine frame, mm: lower-left corner and size."""

    x0: float
    y0: float
    width: float
    height: float

    @property
    def x1(self) -> float:
        """Right edge, mm."""
        return self.x0 + self.width

    @property
    def y1(self) -> float:
        """Top edge, mm."""
        return self.y0 + self.height

    @property
    def area(self) -> float:
        """Area, mm²."""
        return self.width * self.height

    @property
    def center(self) -> tuple[float, float]:
        """Centre point, mm."""
        return (self.x0 + 0.5 * self.width, self.y0 + 0.5 * self.height)

    def sample(self, spacing_mm: float, boundary_spacing_mm: float | None = None) -> FloatArray:
        """Points (N, 2) covering the rectangle: a grid of at most `spacing_mm` pitch over the
        interior (edges included) plus its boundary walked at `boundary_spacing_mm` (default
        a quarter of `spacing_mm`). Used to verify that a rectangle lies in a region that
        need not be convex, so no part of it is taken on trust from the corners."""
        if spacing_mm <= 0:
            raise ValueError(f"spacing must be positive; got {spacing_mm}")
        bs = boundary_spacing_mm if boundary_spacing_mm is not None else spacing_mm / 4.0
        nx = max(2, math.ceil(self.width / spacing_mm) + 1)
        ny = max(2, math.ceil(self.height / spacing_mm) + 1)
        gx, gy = np.meshgrid(np.linspace(self.x0, self.x1, nx), np.linspace(self.y0, self.y1, ny))
        bx = max(2, math.ceil(self.width / bs) + 1)
        by = max(2, math.ceil(self.height / bs) + 1)
        tx = np.linspace(self.x0, self.x1, bx)
        ty = np.linspace(self.y0, self.y1, by)
        edges = [np.stack((tx, np.full(bx, self.y0)), axis=1),
                 np.stack((tx, np.full(bx, self.y1)), axis=1),
                 np.stack((np.full(by, self.x0), ty), axis=1),
                 np.stack((np.full(by, self.x1), ty), axis=1)]
        return np.concatenate([np.stack((gx.ravel(), gy.ravel()), axis=1), *edges])


# ----------------------------------------------------------------------------- safety
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


def _check_assembly(assembly: str | None) -> float:
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
    sign = _check_assembly(assembly)
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
    the point (xs[i], ys[j]) — the layout of `np.meshgrid(xs, ys)` and of matplotlib images.
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
    of the two outer reach circles |P − M_i| ≤ a_i + b_i (their intersection is smaller)."""
    r1, r2 = fb.a1 + fb.b1, fb.a2 + fb.b2
    x_min = max(-r1, fb.w - r2)
    x_max = min(r1, fb.w + r2)
    r = min(r1, r2)
    return (x_min, x_max, -r, r)


def _grid(bounds: tuple[float, float, float, float],
          resolution_mm: float) -> tuple[FloatArray, FloatArray]:
    x_min, x_max, y_min, y_max = bounds
    if not (x_max > x_min and y_max > y_min):
        raise ValueError(f"empty search bounds {bounds}")
    nx = math.floor((x_max - x_min) / resolution_mm) + 1
    ny = math.floor((y_max - y_min) / resolution_mm) + 1
    return (x_min + resolution_mm * np.arange(nx, dtype=np.float64),
            y_min + resolution_mm * np.arange(ny, dtype=np.float64))


def default_resolution(fb: FiveBar) -> float:
    """Grid pitch, mm, that puts about 400 cells across the workspace box."""
    x_min, x_max, y_min, y_max = workspace_bounds(fb)
    return max(x_max - x_min, y_max - y_min) / 400.0


# ----------------------------------------------------------------------------- rectangle search
def _max_rectangle(mask: BoolArray) -> tuple[int, int, int, int] | None:
    """Largest all-True sub-rectangle of a boolean (ny, nx) grid, by the histogram-and-stack
    method (every maximal rectangle is visited once per row, O(nx·ny)).

    The objective is the area *after* the conservative one-cell shrink, (kx − 3)(ky − 3) for
    kx × ky nodes, which is monotone in both spans, so maximising over the maximal rectangles
    is exact. Returns (i0, i1, j0, j1) inclusive node indices, or None if nothing fits.
    """
    ny, nx = mask.shape
    heights = np.zeros(nx + 1, dtype=np.int64)  # sentinel 0 at the end flushes the stack
    best = 0
    found: tuple[int, int, int, int] | None = None
    for j in range(ny):
        row = mask[j]
        heights[:nx] = np.where(row, heights[:nx] + 1, 0)
        h = heights.tolist()
        stack: list[int] = []
        for i in range(nx + 1):
            while stack and h[stack[-1]] >= h[i]:
                top = stack.pop()
                ht = h[top]
                left = stack[-1] + 1 if stack else 0
                kx = i - left
                score = (kx - 3) * (ht - 3)
                # ≥: among equal rectangles keep the last found, the highest (paper side).
                if kx > 3 and ht > 3 and score >= best and score > 0:
                    best = score
                    found = (left, i - 1, j - ht + 1, j)
            stack.append(i)
    return found


def _fit_aspect(mask: BoolArray, res: float, aspect: float) -> tuple[int, int, float] | None:
    """Largest height H (mm) such that a W = aspect·H by H rectangle, grown by one cell on
    every side, covers only True nodes somewhere on the grid. Binary search on H with a
    summed-area table (feasibility is monotone in H). Returns (i, j, H): the window's
    lower-left node and the height."""
    ny, nx = mask.shape
    sat = np.zeros((ny + 1, nx + 1), dtype=np.int64)
    sat[1:, 1:] = np.cumsum(np.cumsum(mask.astype(np.int64), axis=0), axis=1)

    def place(height: float) -> tuple[int, int] | None:
        kx = math.ceil(aspect * height / res - 1e-9) + 3
        ky = math.ceil(height / res - 1e-9) + 3
        if kx > nx or ky > ny:
            return None
        tot = sat[ky:, kx:] - sat[:-ky, kx:] - sat[ky:, :-kx] + sat[:-ky, :-kx]
        hits = np.argwhere(tot == kx * ky)
        if hits.size == 0:
            return None
        # Prefer the placement nearest the middle of the candidates (a stable, central pick).
        mid = hits.mean(axis=0)
        k = int(np.argmin(((hits - mid) ** 2).sum(axis=1)))
        return int(hits[k, 1]), int(hits[k, 0])

    lo, hi = 0.0, min(ny * res, nx * res / aspect)
    best: tuple[int, int, float] | None = None
    if place(res * 1e-3) is None:
        return None
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        p = place(mid)
        if p is None:
            hi = mid
        else:
            lo = mid
            best = (p[0], p[1], mid)
        if hi - lo < 1e-4 * res:
            break
    if best is None:
        p = place(res * 1e-3)
        assert p is not None
        best = (p[0], p[1], res * 1e-3)
    return best


@dataclass(frozen=True)
class PageFit:
    """Result of a page-rectangle search: the rectangle, the working mode and assembly sign it
    was found in, the grid and safe mask it came from (`mask`: all safe nodes of that mode and
    assembly; `region`: the connected part of it that holds the rectangle — the part the pen
    can move through without leaving the safe region), and how many verification samples
    were checked (all of them safe)."""

    rect: Rect
    mode: str
    assembly: str
    xs: FloatArray
    ys: FloatArray
    mask: BoolArray
    region: BoolArray
    resolution_mm: float
    samples_checked: int

    @property
    def usable_area_mm2(self) -> float:
        """Area of the connected safe region that holds the page, mm², counted on the grid
        (other safe islands of the same mode cannot be reached without leaving it)."""
        return float(self.region.sum()) * self.resolution_mm ** 2


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


def _search_one(fb: FiveBar, mode: str, assembly: str, min1: float, min2: float,
                limits: Limits | None, aspect: float | None, res: float,
                bounds: tuple[float, float, float, float]) -> PageFit | None:
    xs, ys = _grid(bounds, res)
    mask = safe_mask(fb, mode, xs, ys, min1, min2, limits, assembly=assembly)
    work = mask.copy()
    ny, nx = mask.shape
    for _ in range(25):
        if aspect is None:
            found = _max_rectangle(work)
            if found is None:
                return None
            i0, i1, j0, j1 = found
            rect = Rect(float(xs[i0 + 1]), float(ys[j0 + 1]),
                        float(xs[i1 - 1] - xs[i0 + 1]), float(ys[j1 - 1] - ys[j0 + 1]))
        else:
            fit = _fit_aspect(work, res, aspect)
            if fit is None:
                return None
            i, j, height = fit
            width = aspect * height
            kx = math.ceil(width / res - 1e-9) + 3
            ky = math.ceil(height / res - 1e-9) + 3
            # Centre the rectangle in the window's interior (one cell in from each side).
            cx = 0.5 * (xs[i] + xs[i + kx - 1])
            cy = 0.5 * (ys[j] + ys[j + ky - 1])
            rect = Rect(float(cx - 0.5 * width), float(cy - 0.5 * height), width, height)
        pts = rect.sample(res / 2.0, res / 8.0)
        ok = point_safety(fb, mode, pts, min1, min2, limits, assembly=assembly)
        if ok.all():
            cx, cy = rect.center
            seed = (int(np.clip(np.rint((cy - ys[0]) / res), 0, ny - 1)),
                    int(np.clip(np.rint((cx - xs[0]) / res), 0, nx - 1)))
            region = connected_component(mask, seed)
            return PageFit(rect, mode, assembly, xs, ys, mask, region, res,
                           int(pts.shape[0]))
        # A thin unsafe feature slipped between the grid nodes: mark the nodes around each
        # failing sample unsafe and search again.
        bad = pts[~ok]
        bi = np.clip(np.rint((bad[:, 0] - xs[0]) / res).astype(int), 0, nx - 1)
        bj = np.clip(np.rint((bad[:, 1] - ys[0]) / res).astype(int), 0, ny - 1)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                work[np.clip(bj + dj, 0, ny - 1), np.clip(bi + di, 0, nx - 1)] = False
    raise RuntimeError("page rectangle verification did not converge")  # pragma: no cover


def find_page_rectangle(fb: FiveBar, mode: str, min_type1_rad: float, min_type2_rad: float,
                        limits_rad: Limits | None = None, aspect: float | None = None,
                        resolution_mm: float | None = None, *, assembly: str | None = None,
                        bounds: tuple[float, float, float, float] | None = None) -> PageFit:
    """Largest axis-aligned rectangle in the safe region of `mode`, with its provenance.

    The safe region is sampled on a grid of `resolution_mm` (default: ~400 cells across the
    workspace); the largest all-safe block of nodes is found exactly on that grid, then shrunk
    by one cell on every side, then verified by sampling its interior at half a cell and its
    boundary at an eighth of a cell with the exact point test. The region need not be convex
    (the Mode 1a hole, joint limits): if any sample fails, the nodes around it are marked
    unsafe and the search repeats. `aspect` = width / height fixes the shape (for fitting a
    drawing). With `assembly` None both assembly signs are searched and the larger wins (a
    rectangle can never straddle the type-2 curve). `bounds` = (x_min, x_max, y_min, y_max)
    limits the search (default: `workspace_bounds`). Raises `NoSafeRegionError` if nothing fits.
    """
    if aspect is not None and not (math.isfinite(aspect) and aspect > 0):
        raise ValueError(f"aspect (width/height) must be positive; got {aspect!r}")
    res = default_resolution(fb) if resolution_mm is None else float(resolution_mm)
    if not (math.isfinite(res) and res > 0):
        raise ValueError(f"resolution_mm must be positive; got {resolution_mm!r}")
    box = workspace_bounds(fb) if bounds is None else bounds
    _check_assembly(assembly)
    signs = ("+", "-") if assembly is None else (assembly,)
    fits = [f for s in signs
            if (f := _search_one(fb, mode, s, min_type1_rad, min_type2_rad, limits_rad, aspect,
                                 res, box)) is not None]
    if not fits:
        what = "rectangle" if aspect is None else f"rectangle of aspect {aspect:g}"
        raise NoSafeRegionError(
            f"no {what} fits in the safe region of working mode {mode} (margins type 1 ≥ "
            f"{math.degrees(min_type1_rad):g}°, type 2 ≥ {math.degrees(min_type2_rad):g}°"
            f"{', joint limits' if limits_rad is not None else ''}) at {res:g} mm resolution")
    return max(fits, key=lambda f: f.rect.area)


def largest_page_rectangle(fb: FiveBar, mode: str, min_type1_rad: float, min_type2_rad: float,
                           limits_rad: Limits | None = None, aspect: float | None = None,
                           resolution_mm: float | None = None, *, assembly: str | None = None,
                           bounds: tuple[float, float, float, float] | None = None) -> Rect:
    """Largest axis-aligned rectangle (optionally of fixed `aspect` = width/height) that lies
    inside the safe region of working mode `mode`; see `find_page_rectangle`."""
    return find_page_rectangle(fb, mode, min_type1_rad, min_type2_rad, limits_rad, aspect,
                               resolution_mm, assembly=assembly, bounds=bounds).rect


# ----------------------------------------------------------------------------- singularity traces
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
    c1 = p[:, 0] * r1[:, 1] - p[:, 1] * r1[:, 0]
    c2 = (p[:, 0] - fb.w) * r2[:, 1] - p[:, 1] * (r2[:, 0] - fb.w)
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
            p = r1 + sgn * fb.b1 * u
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
            p = c + fb.b1 * np.stack((np.cos(t), np.sin(t)), axis=1)
            r = np.broadcast_to(c, p.shape).copy()
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
    the workspace of every working mode. Returns (arm, "stretched"/"folded", centre, radius)."""
    out: list[tuple[int, str, tuple[float, float], float]] = []
    for arm, (a, b, cx) in enumerate(((fb.a1, fb.b1, 0.0), (fb.a2, fb.b2, fb.w)), start=1):
        out.append((arm, "stretched", (cx, 0.0), a + b))
        if a != b:
            out.append((arm, "folded", (cx, 0.0), abs(a - b)))
    return out


# ----------------------------------------------------------------------------- maps
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


# ----------------------------------------------------------------------------- design search
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


@dataclass(frozen=True)
class DesignCandidate:
    """One verified design: geometry, where the page goes, and its figures over the page.

    `score` = worst |μ − 90°| / 50° + worst sensitivity / page diagonal (mm/rad per mm): a
    transmission angle at the thesis' recommended limit weighs as much as a pen that moves one
    page diagonal per radian of the worst motor. Lower is better."""

    geometry: FiveBar
    page: Rect
    mode: str
    stats: PageStats
    score: float


@dataclass(frozen=True)
class DesignResult:
    """Outcome of `design_search`: the best verified candidates (best first) and counts."""

    candidates: list[DesignCandidate]
    evaluated: int
    feasible: int
    verified: int


def _sample_designs(rng: np.random.Generator, n: int, diag: float,
                    motor_spacing: float | tuple[float, float] | None,
                    symmetric_fraction: float) -> FloatArray:
    """Random candidate link lengths (n, 5) = (a1, b1, a2, b2, w), mm, scaled to the page
    diagonal: a ∈ [0.3, 1.5]·D, b ∈ [0.5, 2.5]·D, w ∈ [0.05, 1]·D (or the given spacing).
    A fraction are mirror-symmetric (a1 = a2, b1 = b2), the usual build."""
    a1 = rng.uniform(0.3, 1.5, n) * diag
    b1 = rng.uniform(0.5, 2.5, n) * diag
    a2 = rng.uniform(0.3, 1.5, n) * diag
    b2 = rng.uniform(0.5, 2.5, n) * diag
    sym = rng.random(n) < symmetric_fraction
    a2[sym] = a1[sym]
    b2[sym] = b1[sym]
    if motor_spacing is None:
        w = rng.uniform(0.05, 1.0, n) * diag
    elif isinstance(motor_spacing, tuple):
        w = rng.uniform(motor_spacing[0], motor_spacing[1], n)
    else:
        w = np.full(n, float(motor_spacing))
    return np.stack((a1, b1, a2, b2, w), axis=1)


def _arm(dx: FloatArray, dy: FloatArray, a: FloatArray, b: FloatArray,
         s: float) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """Broadcasting inverse of one arm (motor at the origin of dx, dy), Eq. 18 without arccos:
    returns θ, the elbow offset (ex, ey) = R − M and validity. |(dx·C − s·dy·√K, dy·C +
    s·dx·√K)| = 2a·c², so the elbow needs no trigonometry."""
    csq = dx * dx + dy * dy
    c = np.sqrt(csq)
    k = (a + b + c) * (a + b - c) * (a - b + c) * (b - a + c)
    ok = (k >= 0.0) & (csq > 0.0)
    rk = s * np.sqrt(np.maximum(k, 0.0))
    cc = csq + a * a - b * b
    vx = dx * cc - dy * rk
    vy = dy * cc + dx * rk
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = 1.0 / (2.0 * np.where(csq > 0, csq, 1.0))
    return np.arctan2(vy, vx), vx * inv, vy * inv, ok


def _limits_ok(th: FloatArray, lo: float, hi: float) -> BoolArray:
    t = lo + np.mod(th - lo, 2.0 * math.pi)
    return np.asarray((t <= hi + 1e-12) | (t - lo >= 2.0 * math.pi - 1e-12), dtype=bool)


def _screen(geo: FloatArray, x: FloatArray, y: FloatArray, mode: str, min1: float,
            min2: float, limits: Limits | None) -> tuple[BoolArray, FloatArray, FloatArray]:
    """Vectorised page check. geo (C, 5); x, y (C, K, P): P samples of K placements per
    candidate. Returns feasible (C, K), worst |μ − 90°| (C, K), worst |∂P/∂θ_i| (C, K)."""
    a1, b1, a2, b2, w = (geo[:, i, None, None] for i in range(5))
    s1 = 1.0 if mode[0] == "+" else -1.0
    s2 = 1.0 if mode[1] == "+" else -1.0
    th1, e1x, e1y, ok1 = _arm(x, y, a1, b1, s1)
    th2, e2x, e2y, ok2 = _arm(x - w, y, a2, b2, s2)
    ok = ok1 & ok2
    # Floating links f_i = P − R_i; transmission angle μ_i between (M_i − R_i) and f_i.
    f1x, f1y = x - e1x, y - e1y
    f2x, f2y = x - w - e2x, y - e2y
    mu1 = np.arctan2(np.abs(-e1x * f1y + e1y * f1x), -e1x * f1x - e1y * f1y)
    mu2 = np.arctan2(np.abs(-e2x * f2y + e2y * f2x), -e2x * f2x - e2y * f2y)
    half = 0.5 * math.pi
    ok &= (np.minimum(mu1, math.pi - mu1) >= min1) & (np.minimum(mu2, math.pi - mu2) >= min1)
    # Type 2: signed angle between the lines of b1 and b2 (Eq. det A = cross(f1, f2)).
    det = f1x * f2y - f1y * f2x
    psi = np.arctan2(det, np.abs(f1x * f2x + f1y * f2y))
    ok &= np.abs(psi) >= min2
    if limits is not None:
        ok &= _limits_ok(th1, float(limits[0][0]), float(limits[0][1]))
        ok &= _limits_ok(th2, float(limits[1][0]), float(limits[1][1]))
    feas = ok.all(axis=2)
    same = (np.sign(psi) == np.sign(psi[..., :1])).all(axis=2)
    feas &= same
    # |J col i| = |B_ii|·b_j/|det A| with B_ii = cross(R_i − M_i, P − R_i).
    with np.errstate(divide="ignore", invalid="ignore"):
        bb1 = np.abs(e1x * f1y - e1y * f1x)
        bb2 = np.abs(e2x * f2y - e2y * f2x)
        sens = np.maximum(bb1 * b2, bb2 * b1) / np.abs(det)
    mudev = np.maximum(np.abs(mu1 - half), np.abs(mu2 - half))
    return feas, mudev.max(axis=2), np.where(ok, sens, np.inf).max(axis=2)


def design_search(page_w: float, page_h: float, mode: str, min_type1_rad: float,
                  min_type2_rad: float, limits_rad: Limits | None, rad_per_step: float, *,
                  n_candidates: int = 10_000, motor_spacing: float | tuple[float, float] |
                  None = None, seed: int = 0, top: int = 5, symmetric_fraction: float = 0.5,
                  chunk: int = 256) -> DesignResult:
    """Search link lengths (a1, b1, a2, b2, w) for a five-bar that carries a `page_w` × `page_h`
    mm page inside its safe workspace (thesis Sec. 7.3), ranked by `DesignCandidate.score`.

    1. `n_candidates` random geometries (`_sample_designs`); for each, 3 × 12 placements of
       the page (centre x = w/2 + {−0.15, 0, 0.15}·D, bottom edge y from 0 up to the reach),
       all above the motor axis. The page is grown by three grid cells of the `workspace`
       command's default grid so that its grid search is sure to find it again.
    2. Vectorised screen: corners and edge midpoints first (cheap rejection), then 7 × 5
       interior + 32 edge samples: reach, joint limits, both margins, one assembly sign; the
       best feasible placement per candidate by score.
    3. The best screened candidates are verified by the exact point test on a dense sample
       of the grown page (`Rect.sample` at one grid cell) and re-scored on a dense grid;
       the first `top` that pass are returned.
    """
    if not (page_w > 0 and page_h > 0):
        raise ValueError(f"page size must be positive; got {page_w} x {page_h}")
    if mode not in WORKING_MODES:
        raise ValueError(f"working mode must be one of {', '.join(WORKING_MODES)}; got {mode!r}")
    rng = np.random.default_rng(seed)
    diag = math.hypot(page_w, page_h)
    geo = _sample_designs(rng, n_candidates, diag, motor_spacing, symmetric_fraction)
    # Unit samples on [-1, 1]²: interior grid plus the edges.
    gx, gy = np.meshgrid(np.linspace(-1, 1, 7), np.linspace(-1, 1, 5))
    t = np.linspace(-1, 1, 9)[1:-1]
    ux = np.concatenate([gx.ravel(), t, t, -np.ones(8), np.ones(8)])
    uy = np.concatenate([gy.ravel(), -np.ones(7), np.ones(7), np.linspace(-1, 1, 8),
                         np.linspace(-1, 1, 8)])
    qx = np.array([-1.0, 1.0, -1.0, 1.0, 0.0, 0.0, -1.0, 1.0])
    qy = np.array([-1.0, -1.0, 1.0, 1.0, -1.0, 1.0, 0.0, 0.0])
    shifts = np.array([-0.15, 0.0, 0.15]) * diag
    fracs = np.linspace(0.0, 1.0, 12)
    best_score = np.full(n_candidates, np.inf)
    best_place = np.zeros((n_candidates, 2))
    for c0 in range(0, n_candidates, chunk):
        g = geo[c0:c0 + chunk]
        reach = np.minimum(g[:, 0] + g[:, 1], g[:, 2] + g[:, 3])
        ext = np.maximum(g[:, 0] + g[:, 1], g[:, 2] + g[:, 3]) * 2.0 + g[:, 4]
        grow = 3.0 * ext / 400.0  # three cells of `default_resolution`
        hw = 0.5 * page_w + grow
        hh = 0.5 * page_h + grow
        cx = 0.5 * g[:, 4, None] + shifts[None, :]                     # (C, 3)
        y0 = fracs[None, :] * np.maximum(reach - 2 * hh, 0.0)[:, None]  # (C, 12)
        cy = y0 + hh[:, None]
        pcx = np.repeat(cx, fracs.size, axis=1)                         # (C, 36)
        pcy = np.tile(cy, (1, shifts.size))
        # Quick rejection on the 4 corners and 4 edge midpoints, then the full sample set
        # only for the placements that survive (most candidates fail on reach).
        x = pcx[:, :, None] + qx[None, None, :] * hw[:, None, None]
        y = pcy[:, :, None] + qy[None, None, :] * hh[:, None, None]
        quick, _, _ = _screen(g, x, y, mode, min_type1_rad, min_type2_rad, limits_rad)
        ci, ki = np.nonzero(quick)
        score = np.full(quick.shape, np.inf)
        if ci.size:
            xs_ = pcx[ci, ki][:, None, None] + ux[None, None, :] * hw[ci, None, None]
            ys_ = pcy[ci, ki][:, None, None] + uy[None, None, :] * hh[ci, None, None]
            feas, mudev, sens = _screen(g[ci], xs_, ys_, mode, min_type1_rad, min_type2_rad,
                                        limits_rad)
            score[ci, ki] = np.where(feas[:, 0], mudev[:, 0] / math.radians(50.0)
                                     + sens[:, 0] / diag, np.inf)
        k = np.argmin(score, axis=1)
        rows = np.arange(g.shape[0])
        best_score[c0:c0 + chunk] = score[rows, k]
        best_place[c0:c0 + chunk] = np.stack((pcx[rows, k], pcy[rows, k]), axis=1)
    feasible = np.flatnonzero(np.isfinite(best_score))
    order = feasible[np.argsort(best_score[feasible])]
    out: list[DesignCandidate] = []
    verified = 0
    for idx in order[: max(10 * top, 50)]:
        a1, b1, a2, b2, w = (float(v) for v in geo[idx])
        try:
            fb = FiveBar(a1, b1, a2, b2, w)
        except ValueError:
            continue
        res = default_resolution(fb)
        cx, cy = best_place[idx]
        page = Rect(float(cx) - 0.5 * page_w, float(cy) - 0.5 * page_h, page_w, page_h)
        grown = Rect(page.x0 - 3 * res, page.y0 - 3 * res, page_w + 6 * res, page_h + 6 * res)
        pts = grown.sample(res, res / 4.0)
        try:
            st = page_stats(fb, mode, page, rad_per_step)
        except NoSafeRegionError:
            continue
        asm = st.assembly
        if not point_safety(fb, mode, pts, min_type1_rad, min_type2_rad, limits_rad,
                            assembly=asm).all():
            continue
        verified += 1
        total = st.worst_mu_dev_rad / math.radians(50.0) + st.worst_sens_mm_per_rad / diag
        out.append(DesignCandidate(fb, page, mode, st, total))
        if len(out) >= top:
            break
    out.sort(key=lambda d: d.score)
    return DesignResult(out, n_candidates, int(feasible.size), verified)


# ----------------------------------------------------------------------------- mode transitions
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
    return np.asarray(lo + np.mod(th - lo, 2.0 * math.pi), dtype=np.float64)


def _check_joint_path(fb: FiveBar, path: FloatArray, sign: float, min2: float,
                      limits: Limits | None) -> tuple[bool, FloatArray, float]:
    fw = fb.forward_batch(path, "+" if sign > 0 else "-")
    if not fw.valid.all():
        return False, fw.points, 0.0
    m2 = fb.singularity_margins(path, fw.points)[:, 2] * sign
    ok = bool((m2 >= min2).all())
    if limits is not None:
        ok &= bool(angles_within_limits(path, limits).all())
    return ok, fw.points, float(m2.min())


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
    sign = _check_assembly(assembly)
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
    # Two straight legs through one waypoint of a coarse lattice, shortest first: simple
    # moves that rarely pass a type-1 singularity more often than the mode change needs.
    if limits_rad is not None:
        box_lo = np.array([float(limits_rad[0][0]), float(limits_rad[1][0])])
        box_hi = np.array([float(limits_rad[0][1]), float(limits_rad[1][1])])
    else:
        box_lo, box_hi = np.minimum(a, b) - math.pi, np.maximum(a, b) + math.pi
    g1, g2 = np.meshgrid(np.linspace(box_lo[0], box_hi[0], 16),
                         np.linspace(box_lo[1], box_hi[1], 16))
    way = np.stack((g1.ravel(), g2.ravel()), axis=1)
    cost = np.abs(way - a).sum(axis=1) + np.abs(b - way).sum(axis=1)
    for k in np.argsort(cost, kind="stable"):
        path = _densify([a, way[k], b], step_rad)
        ok, pen, m = _check_joint_path(fb, path, sign, min2, limits_rad)
        if ok:
            return path, pen, m
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


def _lattice_route(fb: FiveBar, a: FloatArray, b: FloatArray, sign: float, min2: float,
                   limits: Limits | None, cell: float,
                   step_rad: float) -> list[FloatArray] | None:
    """Breadth-first search on a joint-space lattice; returns waypoints a, nodes…, b."""
    from collections import deque

    wrap = limits is None
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

    def attach(p: FloatArray) -> list[tuple[int, int]]:
        """Free nodes near p, nearest first, that a straight leg from p reaches safely."""
        rel = (p - lo) / cell
        if wrap:
            rel = np.mod(rel, n)
        base = np.floor(rel).astype(int)
        cands = []
        for di in range(-2, 4):
            for dj in range(-2, 4):
                i, j = int(base[0] + di), int(base[1] + dj)
                if wrap:
                    i, j = i % int(n[0]), j % int(n[1])
                elif not (0 <= i < n[0] and 0 <= j < n[1]):
                    continue
                if free[i, j]:
                    q = _unwrap_to(np.array([g1[i], g2[j]]), p, wrap)
                    cands.append((float(np.abs(q - p).sum()), i, j))
        out = []
        for _, i, j in sorted(cands):
            q = _unwrap_to(np.array([g1[i], g2[j]]), p, wrap)
            if _check_joint_path(fb, _densify([p, q], step_rad), sign, min2, limits)[0]:
                out.append((i, j))
                if len(out) >= 3:
                    break
        return out

    starts, goals = attach(a), attach(b)
    if not starts or not goals:
        return None
    goal_set = set(goals)
    prev: dict[tuple[int, int], tuple[int, int] | None] = {s: None for s in starts}
    queue = deque(starts)
    hit: tuple[int, int] | None = None
    while queue:
        cur = queue.popleft()
        if cur in goal_set:
            hit = cur
            break
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                if di == 0 and dj == 0:
                    continue
                i, j = cur[0] + di, cur[1] + dj
                if wrap:
                    i, j = i % int(n[0]), j % int(n[1])
                elif not (0 <= i < n[0] and 0 <= j < n[1]):
                    continue
                if free[i, j] and (i, j) not in prev:
                    prev[(i, j)] = cur
                    queue.append((i, j))
    if hit is None:
        return None
    chain: list[tuple[int, int]] = []
    node: tuple[int, int] | None = hit
    while node is not None:
        chain.append(node)
        node = prev[node]
    chain.reverse()
    way = [a]
    for i, j in chain:
        way.append(_unwrap_to(np.array([g1[i], g2[j]]), way[-1], wrap))
    # On the torus the route may end a whole turn away from b: the same pose, and the
    # motor really does turn that far.
    way.append(_unwrap_to(b, way[-1], wrap))
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
            a, b = (fb.a1, fb.b1) if arm == 0 else (fb.a2, fb.b2)
            mx = 0.0 if arm == 0 else fb.w
            d = math.hypot(p[0] - mx, p[1])
            kind = "stretched" if abs(d - (a + b)) < abs(d - abs(a - b)) else "folded"
            out.append((arm + 1, kind, float(p[0]), float(p[1])))
    return out


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
    sign = _check_assembly(assembly)
    if sign == 0.0:
        raise ValueError("plan_working_modes needs the machine's assembly sign '+' or '-'")
    if start_mode not in modes:
        raise ValueError(f"start mode {start_mode!r} is not among the allowed modes {modes}")
    pieces: list[DrawPiece] = []
    mode = start_mode
    pose: FloatArray | None = (None if start_angles is None
                               else np.asarray(start_angles, dtype=np.float64).reshape(2))
    pose_mode = start_mode
    for si, stroke in enumerate(strokes):
        pts = np.asarray(stroke, dtype=np.float64).reshape(-1, 2)
        n = pts.shape[0]
        safe = {m: point_safety(fb, m, pts, min_type1_rad, min_type2_rad, limits_rad,
                                assembly=assembly) for m in modes}
        k = 0
        while k < n:
            runs: dict[str, int] = {}
            for m in modes:
                bad = np.flatnonzero(~safe[m][k:])
                runs[m] = int(bad[0]) if bad.size else n - k
            best = max(runs.values())
            if best == 0:
                raise NoSafeRegionError(
                    f"stroke {si} point {k} ({pts[k, 0]:.3f}, {pts[k, 1]:.3f}) mm is not safe in "
                    f"any working mode ({', '.join(modes)}) with assembly {assembly}")
            new = mode if runs[mode] == best else max(modes, key=lambda m: runs[m])
            start = k
            if new != mode and k > 0:
                if not safe[new][k - 1]:
                    raise NoSafeRegionError(
                        f"stroke {si}: the segment from point {k - 1} to {k} has no working "
                        f"mode in which both ends are safe ({mode} → {new}); segment it "
                        "more finely or move the drawing")
                start = k - 1
            first = np.asarray(fb.inverse(pts[start], new), dtype=np.float64)
            trans: Transition | None = None
            if pose is not None and new != pose_mode:
                planned = plan_joint_move(fb, pose, first, assembly, min_type2_rad, limits_rad)
                if planned is None:
                    raise NoSafeRegionError(
                        f"no pen-up path from working mode {pose_mode} to {new} before stroke "
                        f"{si} point {start} keeps the type-2 margin and joint limits")
                path, pen, m2 = planned
                trans = Transition(pose_mode, new, path, pen, _crossings(fb, path, pen), m2)
            stop = k + runs[new]
            pieces.append(DrawPiece(si, start, stop, new, trans))
            mode = new
            pose_mode = new
            pose = np.asarray(fb.inverse(pts[stop - 1], new), dtype=np.float64)
            k = stop
    return ModePlan(pieces, assembly)


# ----------------------------------------------------------------------------- full report
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
    _check_assembly(assembly)
    fits: dict[str, PageFit | None] = {}
    for m in WORKING_MODES:
        try:
            fits[m] = find_page_rectangle(fb, m, min_type1_rad, min_type2_rad, limits_rad,
                                          resolution_mm=resolution_mm, assembly=assembly)
        except NoSafeRegionError:
            fits[m] = None
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
            f"{math.degrees(min_type1_rad):g}°, type 2 ≥ {math.degrees(min_type2_rad):g}°)")
    stats = page_stats(fb, mode, fit.rect, rad_per_step)
    xs, ys = fit.xs, fit.ys
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack((gx.ravel(), gy.ravel()), axis=1)
    pm = measures(fb, mode, pts)
    shape = gx.shape
    step = _max_disp(perturbation_displacements(fb, mode, pts, rad_per_step))
    delta = _max_disp(perturbation_displacements(fb, mode, pts, delta_rad))
    placed: Rect | None = None
    if page is not None:
        pw, ph = page
        try:
            pf = find_page_rectangle(fb, mode, min_type1_rad, min_type2_rad, limits_rad,
                                     aspect=pw / ph, resolution_mm=resolution_mm,
                                     assembly=fit.assembly)
            if pf.rect.height >= ph * (1.0 - 1e-9):
                cx, cy = pf.rect.center
                placed = Rect(cx - 0.5 * pw, cy - 0.5 * ph, pw, ph)
        except NoSafeRegionError:
            placed = None
    return WorkspaceReport(
        mode=mode, fits=fits, fit=fit, stats=stats, xs=xs, ys=ys,
        reach=pm.valid.reshape(shape), safe=fit.mask,
        mu=pm.mu.reshape(*shape, 2), step=step.reshape(*shape, 2),
        delta=delta.reshape(*shape, 2), sens=pm.sens.reshape(*shape, 2),
        cond=pm.cond.reshape(shape), traces=type2_traces(fb), delta_rad=delta_rad,
        rad_per_step=rad_per_step, page_asked=page, page=placed)
