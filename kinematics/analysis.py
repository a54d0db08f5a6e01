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
    "NoSafeRegionError",
    "PageFit",
    "Rect",
    "angles_within_limits",
    "default_resolution",
    "find_page_rectangle",
    "largest_page_rectangle",
    "point_safety",
    "safe_mask",
    "workspace_bounds",
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
                if kx > 3 and ht > 3 and score > best:
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
    was found in, the grid and safe mask it came from, and how many verification samples were
    checked (all of them safe)."""

    rect: Rect
    mode: str
    assembly: str
    xs: FloatArray
    ys: FloatArray
    mask: BoolArray
    resolution_mm: float
    samples_checked: int

    @property
    def usable_area_mm2(self) -> float:
        """Area of the safe region (this mode and assembly), mm², counted on the grid."""
        return float(self.mask.sum()) * self.resolution_mm ** 2


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
            return PageFit(rect, mode, assembly, xs, ys, mask, res, int(pts.shape[0]))
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
