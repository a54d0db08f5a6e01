"""The page rectangle: the largest axis-aligned rectangle inside the safe region.

A drawing is placed on an axis-aligned page, so `fivebar workspace`, the layout of a job and
the design search all ask the same question — the largest rectangle (or one of a fixed
aspect) whose every point is safe (`kinematics.workspace.region.point_safety`). The answer is
found exactly on a grid and then verified densely with the point test, because the safe region
need not be convex (the Mode 1a hole, joint limits).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kinematics.arrays import BoolArray, FloatArray
from kinematics.fivebar import FiveBar
from kinematics.workspace.region import (
    Limits,
    NoSafeRegionError,
    assembly_sign,
    connected_component,
    default_resolution,
    point_safety,
    safe_mask,
    workspace_bounds,
)

__all__ = ["PageFit", "Rect", "find_page_rectangle", "largest_page_rectangle"]


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


def _grid(bounds: tuple[float, float, float, float],
          resolution_mm: float) -> tuple[FloatArray, FloatArray]:
    x_min, x_max, y_min, y_max = bounds
    if not (x_max > x_min and y_max > y_min):
        raise ValueError(f"empty search bounds {bounds}")
    nx = math.floor((x_max - x_min) / resolution_mm) + 1
    ny = math.floor((y_max - y_min) / resolution_mm) + 1
    return (x_min + resolution_mm * np.arange(nx, dtype=np.float64),
            y_min + resolution_mm * np.arange(ny, dtype=np.float64))


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
    assembly_sign(assembly)
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
