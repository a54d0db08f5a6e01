"""Scanline hatching of a region: parallel lines `spacing` apart at `angle`, cut exactly by
the region's rings (the boundary of a shapely (Multi)Polygon: the fill rule has already been
applied by `fill.regions`, so pairing the crossings of each line in order is exact).

The lines lie on one grid for the whole drawing, y' = (k + ½)·spacing in the frame turned by
−angle about the origin, so the hatches of neighbouring shapes line up. A part of the region
that no grid line crosses (a sliver thinner than the spacing, a dot) gets one line of its own
through the middle of its extent across the lines: a thin object is never left blank.

Each crossing keeps its ring and its arc-length position on the ring, so the lines can be
joined along the region's boundary (`fill.chains`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from kinematics.arrays import FloatArray, IntArray


@dataclass(frozen=True)
class Rings:
    """A region's rings in the hatch frame (turned by −angle): vertices `xy` (V, 2) with
    CSR `offsets` per ring (each ring closed: last vertex = first), the arc length at each
    vertex `cum` (from the ring's start), each ring's `part` (which polygon of the region)."""

    xy: FloatArray
    offsets: IntArray
    cum: FloatArray
    part: IntArray

    def perimeter(self, r: int) -> float:
        return float(self.cum[self.offsets[r + 1] - 1])


@dataclass(frozen=True)
class Lines:
    """Hatch segments in the hatch frame, sorted by line then x: segment i lies on line
    `line[i]` (y = `y[i]`) from `x0[i]` to `x1[i]`; its ends are crossings 2i (left) and
    2i + 1 (right), each on ring `ring[e]` at arc-length position `pos[e]`."""

    line: IntArray
    y: FloatArray
    x0: FloatArray
    x1: FloatArray
    ring: IntArray
    pos: FloatArray

    @property
    def count(self) -> int:
        return int(self.line.shape[0])


def rotation(angle_rad: float) -> FloatArray:
    """The 2×2 map into the hatch frame (the hatch direction becomes +x)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, s], [-s, c]])


def rings_of(region: BaseGeometry, rot: FloatArray) -> Rings:
    """The rings of a (Multi)Polygon in the hatch frame."""
    parts = shapely.get_parts(region)
    rings, part = [], []
    for i, p in enumerate(parts.tolist()):
        if p.geom_type != "Polygon" or p.is_empty:
            continue
        for r in (p.exterior, *p.interiors):
            rings.append(r)
            part.append(i)
    if not rings:
        z = np.zeros(0, np.int64)
        return Rings(np.zeros((0, 2)), np.zeros(1, np.int64), np.zeros(0), z)
    xy, idx = shapely.get_coordinates(np.array(rings, dtype=object), return_index=True)
    xy = xy @ rot.T
    counts = np.bincount(idx, minlength=len(rings))
    offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    step = np.hypot(*np.diff(xy, axis=0).T)
    step[offsets[1:-1] - 1] = 0.0  # no step from one ring's last vertex to the next's first
    cum = np.concatenate(([0.0], np.cumsum(step)))
    cum -= np.repeat(cum[offsets[:-1]], counts)
    return Rings(xy, offsets, cum, np.array(part, dtype=np.int64))


def crossings(rg: Rings, ys: FloatArray, line_ids: IntArray, rings: IntArray | None = None
              ) -> Lines:
    """Where the lines y = ys[j] (sorted) cross the rings (`rings`: only these), paired into
    inside segments. Each edge counts the lines in [y_low, y_high), so a line through a
    vertex is counted once per side change, and horizontal edges not at all."""
    n_v = rg.xy.shape[0]
    if n_v == 0 or ys.size == 0:
        return _no_lines()
    ring_of_v = np.repeat(np.arange(rg.offsets.shape[0] - 1), np.diff(rg.offsets))
    e0 = np.arange(n_v - 1)
    e0 = e0[ring_of_v[e0] == ring_of_v[e0 + 1]]  # edges within a ring
    if rings is not None:
        e0 = e0[np.isin(ring_of_v[e0], rings)]
    a, b = rg.xy[e0], rg.xy[e0 + 1]
    ylo, yhi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    lo = np.searchsorted(ys, ylo, "left")
    hi = np.searchsorted(ys, yhi, "left")
    cnt = np.maximum(hi - lo, 0)
    total = int(cnt.sum())
    if total == 0:
        return _no_lines()
    edge = np.repeat(np.arange(e0.shape[0]), cnt)
    j = np.repeat(lo, cnt) + (np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    y = ys[j]
    pa, pb = a[edge], b[edge]
    t = (y - pa[:, 1]) / (pb[:, 1] - pa[:, 1])
    x = pa[:, 0] + t * (pb[:, 0] - pa[:, 0])
    v = e0[edge]
    pos = rg.cum[v] + t * (rg.cum[v + 1] - rg.cum[v])
    ring = ring_of_v[v]
    order = np.lexsort((x, j))
    j, x, pos, ring, y = j[order], x[order], pos[order], ring[order], y[order]
    # pairs within each line: (0, 1), (2, 3), ... (each line crosses closed rings evenly)
    first = np.concatenate(([True], j[1:] != j[:-1]))
    rank = np.arange(total) - np.maximum.accumulate(np.where(first, np.arange(total), 0))
    left = np.flatnonzero(rank % 2 == 0)
    left = left[left + 1 < total]
    left = left[j[left + 1] == j[left]]
    right = left + 1
    keep = x[right] > x[left]
    left, right = left[keep], right[keep]
    ends = np.stack((left, right), axis=1).reshape(-1)
    return Lines(line=line_ids[j[left]], y=y[left], x0=x[left], x1=x[right], ring=ring[ends],
                 pos=pos[ends])


def _no_lines() -> Lines:
    z, f = np.zeros(0, np.int64), np.zeros(0)
    return Lines(z, f, f, f, z, f)


def hatch_lines(rg: Rings, spacing: float) -> Lines:
    """The grid's lines through the rings, plus one middle line for every polygon of the
    region no grid line crosses (module doc)."""
    if rg.xy.shape[0] == 0:
        return _no_lines()
    y = rg.xy[:, 1]
    k0 = math.ceil(float(y.min()) / spacing - 0.5)
    k1 = math.floor(float(y.max()) / spacing - 0.5)
    ks = np.arange(k0, k1 + 1, dtype=np.int64)
    lines = crossings(rg, (ks + 0.5).astype(np.float64) * spacing, ks)
    hit = np.zeros(int(rg.part.max()) + 1, dtype=bool)
    hit[rg.part[lines.ring]] = True
    missed = np.flatnonzero(~hit)
    if missed.size == 0:
        return lines
    extra = [lines]
    ring_of_v = np.repeat(np.arange(rg.offsets.shape[0] - 1), np.diff(rg.offsets))
    for m in missed.tolist():
        rings = np.flatnonzero(rg.part == m)
        vy = y[np.isin(ring_of_v, rings)]
        mid = 0.5 * (float(vy.min()) + float(vy.max()))
        # its own id below the grid's: drawn as a line of its own
        extra.append(crossings(rg, np.array([mid]), np.array([-(1 << 40) - m]), rings))
    return _concat(extra)


def _concat(parts: list[Lines]) -> Lines:
    """Several `Lines` as one, sorted by line id then x."""
    cat = Lines(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                  ("line", "y", "x0", "x1", "ring", "pos")))
    order = np.lexsort((cat.x0, cat.line))
    ends = np.stack((2 * order, 2 * order + 1), axis=1).reshape(-1)
    return Lines(cat.line[order], cat.y[order], cat.x0[order], cat.x1[order],
                 cat.ring[ends], cat.pos[ends])
