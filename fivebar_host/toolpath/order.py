"""Path order: reorder and reverse whole paths to cut pen-up travel. Geometry never changes —
only which path comes next and in which direction it is drawn.

1. Two starting tours: greedy nearest neighbour from the start position over both ends of
   every remaining path (a uniform grid of cells searched ring by ring, ~O(P) for evenly
   spread drawings), and greedy edge (`toolpath.greedy_edge`: the shortest joins of path
   endpoints first, never closing a cycle). Neither is better on every drawing (measured on
   the 20 real drawings of `benchmarks/ordering.py`: each wins on about half), so up to
   `TWO_STARTS` paths both are improved and the shorter result kept; above that only the
   greedy-edge tour is (on 10,000 random strokes its local search ends 3 % shorter and
   takes a quarter less time), unless it ends longer than the nearest-neighbour tour itself.
2. Local search (`toolpath.tour`): 2-opt with path reversal and Or-opt (blocks of paths
   moved elsewhere, forwards or reversed, short ones and long ones), moves proposed by the
   nearest endpoints of every endpoint and taken best first, until neither improves (or
   `max_rounds`). The tour starts at the start position and, if `end` is given, returns
   there (the park move is part of the cost); without `end` the tour may end anywhere. Every
   move shortens the tour, so the result is never longer than the nearest-neighbour order.
3. The best direction of every path for that order (`toolpath.orient`, an exact dynamic
   programme over the directions; never longer).

`join` then merges consecutive paths whose gap is below the tolerance (and whose pen/laser
settings match): the pen stays down across the gap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host import progress
from fivebar_host.toolpath import tour
from fivebar_host.toolpath.greedy_edge import greedy_edge
from fivebar_host.toolpath.orient import best_directions
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Up to this many paths both starting tours are improved (module doc, step 1).
TWO_STARTS = 5000
#: Direction programmes (each followed by local search around the turned paths) per tour.
DIRECTION_ROUNDS = 3


@dataclass(frozen=True)
class Order:
    """`order[k]` is the path drawn k-th; `reverse[k]` whether it is drawn end to start.
    Travel lengths (mm, straight-line pen-up distances incl. from start and back to end)."""

    order: IntArray
    reverse: BoolArray
    travel_before_mm: float
    travel_after_mm: float


def travel_length(starts: FloatArray, ends: FloatArray, order: IntArray, reverse: BoolArray,
                  start: FloatArray | None, end: FloatArray | None) -> float:
    """Total pen-up distance of a tour (straight lines); without `start` (`end`) the move
    to the first path (from the last) is not counted."""
    s = np.where(reverse[:, None], ends[order], starts[order])
    e = np.where(reverse[:, None], starts[order], ends[order])
    total = float(np.hypot(*(s[0] - start))) if len(order) and start is not None else 0.0
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
    ticker = progress.Ticker("ordering paths", 2 * n)  # the first half; `tour` the second
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


def _improved_tour(starts: FloatArray, ends: FloatArray, start: FloatArray | None,
                   end: FloatArray | None, max_rounds: int) -> tuple[IntArray, BoolArray]:
    """Steps 1–3 of the module doc: the shortest improved tour of the starting tours."""
    n = starts.shape[0]
    nn = _greedy(starts, ends, starts[0] if start is None else start)
    pairs = tour.candidates(starts, ends, start, end)  # found once, used by every stage
    ge = greedy_edge(starts, ends, start, pairs)
    best: tuple[float, IntArray, BoolArray] | None = None
    for first in ((ge, nn) if n <= TWO_STARTS else (ge,)):
        order, rev = _local_search(starts, ends, first, start, end, max_rounds, pairs)
        length = travel_length(starts, ends, order, rev, start, end)
        if best is None or length < best[0]:
            best = (length, order, rev)
    assert best is not None
    if best[0] > travel_length(starts, ends, *nn, start, end):  # never longer than NN
        return _local_search(starts, ends, nn, start, end, max_rounds, pairs)
    return best[1], best[2]


def _local_search(starts: FloatArray, ends: FloatArray, first: tuple[IntArray, BoolArray],
                  start: FloatArray | None, end: FloatArray | None, max_rounds: int,
                  pairs: tuple[IntArray, IntArray]) -> tuple[IntArray, BoolArray]:
    """Local search from the tour `first`, then the best directions for its order; where
    those turned paths round, local search again around them (they propose new moves),
    until the directions stay (at most `DIRECTION_ROUNDS` times). Each step only
    shortens the tour."""
    n = starts.shape[0]
    order, rev = tour.improve(starts, ends, *first, start, end, max_rounds=max_rounds,
                              pairs=pairs)
    for _ in range(DIRECTION_ROUNDS):
        best = best_directions(starts, ends, order, start, end)
        turned = np.flatnonzero(best != rev)
        rev = best
        if not turned.size:
            break
        near = np.unique(np.clip(np.concatenate((turned - 1, turned, turned + 1)), 0, n - 1))
        look = np.zeros(2 * n + 2, dtype=bool)
        look[order[near]] = look[order[near] + n] = True
        look[2 * n:] = True
        order, rev = tour.improve(starts, ends, order, rev, start, end, max_rounds=max_rounds,
                                  pairs=pairs, look=look)
    return order, rev


def order_paths(starts: FloatArray, ends: FloatArray, start: FloatArray | None,
                end: FloatArray | None = None, *, max_rounds: int = 200,
                keep_order: bool = False) -> Order:
    """Choose the drawing order and directions of paths with the given start/end points,
    from the pen's `start` and back to `end` (None: the tour may begin, or end, anywhere,
    and that move is not counted; the nearest-neighbour stage then begins at the first
    path's start)."""
    starts = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
    ends = np.asarray(ends, dtype=np.float64).reshape(-1, 2)
    start = None if start is None else np.asarray(start, dtype=np.float64)
    n = starts.shape[0]
    ident = np.arange(n, dtype=np.int64)
    fwd = np.zeros(n, dtype=bool)
    before = travel_length(starts, ends, ident, fwd, start, end)
    if keep_order or n < 2:
        return Order(ident, fwd, before, before)
    order, rev = _improved_tour(starts, ends, start, end, max_rounds)
    after = travel_length(starts, ends, order, rev, start, end)
    if after > before:  # never worse than the file's own order
        return Order(ident, fwd, before, before)
    return Order(order, rev, before, after)
