"""Hatch segments joined into pen-down runs (a boustrophedon), with links that stay inside the
region.

Two crossings that follow each other along a ring are joined by the piece of boundary
between them, and that piece lies between two neighbouring hatch lines (or between two
crossings of one line, around a bump): it is inside the region (its boundary counts as
inside) and about one spacing long. So from the end of a segment the walk takes the ring
neighbour of that end that starts an unvisited segment, draws that segment to its other
end, and so on: on a convex shape this is the zig-zag, and where the region splits (a fork,
a hole) the walk follows one branch.

When no ring neighbour is left, the walk goes on to the unvisited segment nearest along the
same ring (the boundary again: inside, pen down) or through a straight link when that is
shorter and inside the region. A simple region (one ring, no hole) is therefore always one
run: at most one pen lift. Only a region with holes or several parts may need more, when the
remaining segments touch none of the rings the walk can follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.toolpath.fill.hatch import Lines, Rings
from kinematics.arrays import BoolArray, FloatArray


@dataclass(frozen=True)
class Run:
    """One pen-down run in the hatch frame: vertices (M, 2) and, per chord, whether it is a
    hatch line (else a link)."""

    xy: FloatArray
    hatch: BoolArray


class _Walk:
    """The walk's state over one region's segments (module doc)."""

    def __init__(self, rg: Rings, ln: Lines, region: BaseGeometry, eps: float) -> None:
        self.rg, self.ln, self.region, self.eps = rg, ln, region, eps
        n = ln.count
        self.x: list[float] = np.stack((ln.x0, ln.x1), axis=1).reshape(-1).tolist()
        self.y: list[float] = np.repeat(ln.y, 2).tolist()
        self.ring: list[int] = ln.ring.tolist()
        self.pos: list[float] = ln.pos.tolist()
        self.perim = [rg.perimeter(r) for r in range(rg.offsets.shape[0] - 1)]
        # ring neighbours of every crossing (cyclic order by position on its ring)
        order = np.lexsort((ln.pos, ln.ring))
        nxt = np.empty(2 * n, np.int64)
        prv = np.empty(2 * n, np.int64)
        r_sorted = ln.ring[order]
        starts = np.flatnonzero(np.concatenate(([True], r_sorted[1:] != r_sorted[:-1])))
        ends = np.append(starts[1:], 2 * n)
        for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
            grp = order[a:b]
            nxt[grp] = np.roll(grp, -1)
            prv[grp] = np.roll(grp, 1)
        self.nxt: list[int] = nxt.tolist()
        self.prv: list[int] = prv.tolist()
        self.done = [False] * n
        self.left = n
        self.start_order: list[int] = np.lexsort((ln.x0, ln.line)).tolist()
        self.start_at = 0
        self.prepared = False

    def ring_step(self, a: int, b: int, forward: bool) -> float:
        """Arc length from crossing a to crossing b along their ring, forwards or back."""
        d: float = self.pos[b] - self.pos[a]
        p: float = self.perim[self.ring[a]]
        return d % p if forward else (-d) % p

    def boundary(self, a: int, b: int, forward: bool) -> list[tuple[float, float]]:
        """The ring's vertices strictly between crossings a and b, walking one way."""
        rg, r = self.rg, self.ring[a]
        o0, o1 = int(rg.offsets[r]), int(rg.offsets[r + 1]) - 1  # last vertex = first
        cum = rg.cum[o0:o1]  # each vertex once (the closing one left out)
        pa, pb = self.pos[a], self.pos[b]
        if forward:
            mid = np.flatnonzero((cum > pa) & (cum < pb)) if pb > pa else \
                np.concatenate((np.flatnonzero(cum > pa), np.flatnonzero(cum < pb)))
        elif pb < pa:
            mid = np.flatnonzero((cum < pa) & (cum > pb))[::-1]
        else:
            mid = np.concatenate((np.flatnonzero(cum < pa)[::-1],
                                  np.flatnonzero(cum > pb)[::-1]))
        return [(float(p[0]), float(p[1])) for p in rg.xy[o0 + mid]]

    def inside(self, a: int, b: int) -> bool:
        """Whether the straight link between crossings a and b lies in the region."""
        if not self.prepared:
            self.region = self.region.buffer(self.eps)
            shapely.prepare(self.region)
            self.prepared = True
        link = shapely.LineString([(self.x[a], self.y[a]), (self.x[b], self.y[b])])
        return bool(self.region.covers(link))

    def next_start(self) -> int:
        while self.done[self.start_order[self.start_at]]:
            self.start_at += 1
        return self.start_order[self.start_at]

    def nearest(self, e: int) -> tuple[int, str, bool]:
        """The unvisited crossing to go to from crossing e when no ring neighbour is free:
        (crossing, how: "ring", "line" or "lift", ring direction)."""
        ring, x, y = self.ring[e], self.x[e], self.y[e]
        best_ring, best_d, best_fw = -1, np.inf, True
        best_e, best_euc = -1, np.inf
        for c in range(2 * len(self.done)):
            if self.done[c >> 1]:
                continue
            if self.ring[c] == ring:
                for fw in (True, False):
                    d = self.ring_step(e, c, fw)
                    if d < best_d:
                        best_ring, best_d, best_fw = c, d, fw
            d2 = (self.x[c] - x) ** 2 + (self.y[c] - y) ** 2
            if d2 < best_euc:
                best_e, best_euc = c, d2
        if best_e >= 0 and (best_ring < 0 or best_euc ** 0.5 < best_d) and \
                self.inside(e, best_e):
            return best_e, "line", True
        if best_ring >= 0:
            return best_ring, "ring", best_fw
        return best_e, "lift", True


def join_segments(rg: Rings, ln: Lines, region: BaseGeometry, eps: float) -> list[Run]:
    """The region's hatch segments as pen-down runs (module doc); `region` in the hatch
    frame, `eps` the distance a straight link may leave it by (rounding)."""
    if ln.count == 0:
        return []
    w = _Walk(rg, ln, region, eps)
    runs: list[Run] = []
    pts: list[tuple[float, float]] = []
    flags: list[bool] = []
    e = -1  # the crossing the pen is at
    while w.left:
        if e < 0:
            s = w.next_start()
            entry = 2 * s
        else:
            entry, how, fw = _step(w, e)
            if how == "lift":
                runs.append(Run(np.array(pts), np.array(flags, dtype=bool)))
                pts, flags = [], []
            elif how == "ring":
                link = w.boundary(e, entry, fw)
                pts.extend(link)
                flags.extend([False] * len(link))
                pts.append((w.x[entry], w.y[entry]))
                flags.append(False)
            else:
                pts.append((w.x[entry], w.y[entry]))
                flags.append(False)
        s = entry >> 1
        exit_ = entry ^ 1
        if not pts:
            pts.append((w.x[entry], w.y[entry]))
        pts.append((w.x[exit_], w.y[exit_]))
        flags.append(True)
        w.done[s] = True
        w.left -= 1
        e = exit_
    runs.append(Run(np.array(pts), np.array(flags, dtype=bool)))
    return runs


def _step(w: _Walk, e: int) -> tuple[int, str, bool]:
    """Where the walk goes from crossing e: a free ring neighbour (the nearer one along the
    ring), else `_Walk.nearest`."""
    best, best_d, best_fw = -1, np.inf, True
    for c, fw in ((w.nxt[e], True), (w.prv[e], False)):
        if c != e and not w.done[c >> 1]:
            d = w.ring_step(e, c, fw)
            if d < best_d:
                best, best_d, best_fw = c, d, fw
    if best >= 0:
        return best, "ring", best_fw
    return w.nearest(e)
