"""Path order: reorder and reverse whole paths to cut pen-up travel. Geometry never changes —
only which path comes next and in which direction it is drawn.

1. Greedy nearest neighbour from the start position over both ends of every remaining path
   (a uniform grid of cells searched ring by ring, ~O(P) for evenly spread drawings).
2. 2-opt with path reversal, restricted to a window of `window` consecutive paths: reversing
   the block i..j of the tour (and each path in it) replaces the travel edges e[i−1]→s[i] and
   e[j]→s[j+1] by e[i−1]→e[j] and s[i]→s[j+1]; the gains of every (i, j) in the window are
   computed at once, the best non-overlapping improving moves are applied, and this repeats
   until no move improves (or `max_rounds`). The tour starts at the start position and, if
   `end` is given, returns there (the park move is part of the cost).

`join` then merges consecutive paths whose gap is below the tolerance (and whose pen/laser
settings match): the pen stays down across the gap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host import progress
from kinematics.arrays import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class Order:
    """`order[k]` is the path drawn k-th; `reverse[k]` whether it is drawn end to start.
    Travel lengths (mm, straight-line pen-up distances incl. from start and back to end)."""

    order: IntArray
    reverse: BoolArray
    travel_before_mm: float
    travel_after_mm: float


def travel_length(starts: FloatArray, ends: FloatArray, order: IntArray, reverse: BoolArray,
                  start: FloatArray, end: FloatArray | None) -> float:
    """Total pen-up distance of a tour (straight lines)."""
    s = np.where(reverse[:, None], ends[order], starts[order])
    e = np.where(reverse[:, None], starts[order], ends[order])
    total = float(np.hypot(*(s[0] - start))) if len(order) else 0.0
    total += float(np.hypot(*(s[1:] - e[:-1]).T).sum())
    if end is not None and len(order):
        total += float(np.hypot(*(e[-1] - end)))
    return total


def _greedy(starts: FloatArray, ends: FloatArray, start: FloatArray) -> tuple[IntArray, BoolArray]:
    """Greedy nearest neighbour over both ends of every path, with a uniform grid of cells
    (about two entry points per cell) searched ring by ring around the pen: a ring r cells out
    holds no point nearer than (r − 1)·h, so the search stops once that exceeds the best."""
    n = starts.shape[0]
    order = np.empty(n, dtype=np.int64)
    rev = np.zeros(n, dtype=bool)
    pts = np.concatenate((starts, ends))  # candidate c < n: path c forward; else reversed
    lo = pts.min(axis=0)
    span = float(max(np.ptp(pts, axis=0).max(), 1e-9))
    g = max(1, int(np.sqrt(n)))
    h = span / g * (1 + 1e-9)
    cij = np.minimum(((pts - lo) / h).astype(np.int64), g - 1)
    cell_of = (cij[:, 0] * g + cij[:, 1]).tolist()  # cell (i, j) is cells[i·g + j]
    cells: list[list[int]] = [[] for _ in range(g * g)]
    for c, cell in enumerate(cell_of):
        cells[cell].append(c)
    xs = pts[:, 0].tolist()
    ys = pts[:, 1].tolist()
    px, py = float(start[0]), float(start[1])
    lx, ly = float(lo[0]), float(lo[1])
    ticker = progress.Ticker("ordering paths", n)
    for k in range(n):
        ticker.tick(k)
        ci = min(max(int((px - lx) / h), 0), g - 1)
        cj = min(max(int((py - ly) / h), 0), g - 1)
        best, best_d, best_d2 = -1, float("inf"), float("inf")  # best_d2 = best_d²
        r = 0
        while r <= g:
            if best >= 0 and (r - 1) * h > best_d:
                break
            for i in range(max(ci - r, 0), min(ci + r, g - 1) + 1):
                step = 1 if abs(i - ci) == r else 2 * r
                for j in range(cj - r, cj + r + 1, max(step, 1)):
                    if j < 0 or j >= g:
                        continue
                    for c in cells[i * g + j]:
                        d = (xs[c] - px) ** 2 + (ys[c] - py) ** 2
                        if d < best_d2 or best < 0:
                            best, best_d = c, d**0.5
                            best_d2 = best_d * best_d
            r += 1
        p = best % n
        order[k] = p
        rev[k] = best >= n
        cells[cell_of[p]].remove(p)
        cells[cell_of[p + n]].remove(p + n)
        q = p if rev[k] else p + n  # leave from the other end
        px, py = xs[q], ys[q]
    return order, rev


def _two_opt(starts: FloatArray, ends: FloatArray, order: IntArray, rev: BoolArray,
             start: FloatArray, end: FloatArray | None, window: int,
             max_rounds: int) -> tuple[IntArray, BoolArray]:
    n = order.shape[0]
    if n < 2:
        return order, rev
    order = order.copy()
    rev = rev.copy()
    for _ in range(max_rounds):
        s = np.where(rev[:, None], ends[order], starts[order])
        e = np.where(rev[:, None], starts[order], ends[order])
        # Padded node arrays: index 0 is the start (its "end" is the start position), index
        # n+1 the park position (its "start"); tour paths are 1..n. Coordinates apart
        # (x, y): every index range below is a slice, no gathered copies.
        sx, sy = np.concatenate((start[None], s, (end if end is not None else s[-1])[None])).T
        ex, ey = np.concatenate((start[None], e, e[-1][None])).T
        # the tour's own edges: into path i (from i−1) and out of path j (to j+1), i, j = 1..n
        edge_in = np.hypot(sx[1:n + 1] - ex[:n], sy[1:n + 1] - ey[:n])
        edge_out = np.hypot(sx[2:] - ex[1:n + 1], sy[2:] - ey[1:n + 1])
        best_gain = np.zeros(n + 2)
        best_j = np.full(n + 2, -1, dtype=np.int64)
        for w in range(min(window, n)):
            m = n - w  # blocks i..j = i + w with i = 1..m
            ii, jj = slice(1, m + 1), slice(1 + w, n + 1)
            i0, j1 = slice(0, m), slice(2 + w, n + 2)  # i − 1 and j + 1
            has_next = (np.arange(1 + w, n + 1) < n) | (end is not None)
            old = edge_in[:m] + np.where(has_next, edge_out[w:], 0.0)
            new = np.hypot(ex[jj] - ex[i0], ey[jj] - ey[i0]) + np.where(
                has_next, np.hypot(sx[j1] - sx[ii], sy[j1] - sy[ii]), 0.0)
            gain = old - new
            better = np.flatnonzero(gain > best_gain[ii] + 1e-9)
            best_gain[better + 1] = gain[better]
            best_j[better + 1] = better + 1 + w
        cand = np.flatnonzero(best_gain > 1e-9)
        if cand.size == 0:
            break
        cand = cand[np.argsort(-best_gain[cand], kind="stable")]
        taken = np.zeros(n + 2, dtype=bool)
        moves: list[tuple[int, int]] = []
        for ci in cand.tolist():
            cj = int(best_j[ci])
            # The move touches edges (ci−1, ci) and (cj, cj+1): keep nodes ci−1..cj+1 free.
            lo, hi = ci - 1, cj + 1
            if taken[lo:hi + 1].any():
                continue
            taken[lo:hi + 1] = True
            moves.append((ci, cj))
        for ci, cj in moves:
            a, b = ci - 1, cj - 1  # 0-based tour positions a..b inclusive
            order[a:b + 1] = order[a:b + 1][::-1].copy()
            rev[a:b + 1] = ~rev[a:b + 1][::-1]
    return order, rev


def order_paths(starts: FloatArray, ends: FloatArray, start: FloatArray,
                end: FloatArray | None = None, *, window: int = 12,
                max_rounds: int = 8, keep_order: bool = False) -> Order:
    """Choose the drawing order and directions of paths with the given start/end points."""
    starts = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
    ends = np.asarray(ends, dtype=np.float64).reshape(-1, 2)
    start = np.asarray(start, dtype=np.float64)
    n = starts.shape[0]
    ident = np.arange(n, dtype=np.int64)
    fwd = np.zeros(n, dtype=bool)
    before = travel_length(starts, ends, ident, fwd, start, end)
    if keep_order or n < 2:
        return Order(ident, fwd, before, before)
    order, rev = _greedy(starts, ends, start)
    order, rev = _two_opt(starts, ends, order, rev, start, end, window, max_rounds)
    after = travel_length(starts, ends, order, rev, start, end)
    if after > before:  # never worse than the file's own order
        return Order(ident, fwd, before, before)
    return Order(order, rev, before, after)
