"""The best direction of every path for a fixed drawing order (`toolpath.order`'s last step).

For a fixed order the travel is a sum over consecutive pairs of terms that depend only on
the two paths' directions, so the shortest choice is a shortest path through a chain of
two states per path (forwards, reversed): a dynamic programme, exact and O(n)
(f_k(r) = min over r' of f_{k−1}(r') + |exit_{k−1}(r') − entry_k(r)|, then backtrack).
Local search flips one block at a time; this changes any set of directions at once, and the
result is never longer than the directions it was given.
"""

from __future__ import annotations

import numpy as np

from kinematics.arrays import BoolArray, FloatArray, IntArray


def best_directions(starts: FloatArray, ends: FloatArray, order: IntArray,
                    start: FloatArray | None, end: FloatArray | None) -> BoolArray:
    """The reversal flags minimising the travel of `order` from `start` to `end` (None:
    that move is free), by the dynamic programme of the module doc."""
    n = order.shape[0]
    s, e = starts[order], ends[order]
    entry, leave = (s, e), (e, s)  # by direction r: entry point, exit point
    # cost[r'][r][k]: path k drawn in direction r' then path k + 1 in direction r
    cost = [[np.hypot(*(entry[r][1:] - leave[q][:-1]).T).tolist() for r in (0, 1)]
            for q in (0, 1)]
    f = [0.0, 0.0] if start is None else [float(np.hypot(*(entry[r][0] - start)))
                                          for r in (0, 1)]
    came: list[tuple[int, int]] = [(0, 0)]  # best previous direction for each direction
    c00, c01, c10, c11 = cost[0][0], cost[0][1], cost[1][0], cost[1][1]
    for k in range(n - 1):
        a0, b0 = f[0] + c00[k], f[1] + c10[k]
        a1, b1 = f[0] + c01[k], f[1] + c11[k]
        came.append((0 if a0 <= b0 else 1, 0 if a1 <= b1 else 1))
        f = [min(a0, b0), min(a1, b1)]
    if end is not None:
        f = [f[r] + float(np.hypot(*(leave[r][-1] - end))) for r in (0, 1)]
    rev = np.zeros(n, dtype=bool)
    r = 0 if f[0] <= f[1] else 1
    for k in range(n - 1, -1, -1):
        rev[k] = bool(r)
        r = came[k][r]
    return rev
