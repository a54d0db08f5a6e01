"""Greedy-edge construction of a path tour (`toolpath.order`'s second starting tour).

Each path is a fixed piece between its two endpoints; the tour joins the endpoints of
different paths by pen-up edges, one per endpoint (the path itself is the other "edge" of
the endpoint), without closing a cycle. The greedy-edge (greedy matching) heuristic takes
candidate joins shortest first and keeps one when both endpoints are still free and belong
to different chains (union-find over paths): the classic greedy TSP construction, which
starts local search from a better tour than nearest neighbour on many drawings, since it
never makes the long "return" jumps a nearest-neighbour walk leaves behind once its
surroundings are used up (Johnson & McGeoch, "The TSP: a case study in local
optimization", 1997, §2.3: greedy ~16–19 % above the Held–Karp bound against ~25 % for
nearest neighbour on uniform instances).

Candidates are each free endpoint's K nearest free endpoints of other chains
(`tour.neighbours`, a grid: linear work, bounded temporaries); once those are used up the
same is done again on the chains' remaining free ends, until one chain is left — each pass
at least joins the nearest pair of free ends of different chains, so it terminates.
"""

from __future__ import annotations

import numpy as np

from fivebar_host.toolpath import tour
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Nearest free endpoints of other chains per free endpoint, per pass.
K = 8
#: Candidate joins handled at once (bounds the temporaries and the Python lists).
CHUNK = 1 << 16


def _link(starts: FloatArray, ends: FloatArray,
          pairs: tuple[IntArray, IntArray] | None) -> list[int]:
    """`link[x]`: the endpoint joined to endpoint x by a pen-up edge (x < n: start of path x,
    else end of path x − n), −1 for the two ends of the single chain left. `pairs`: near
    pairs of endpoint ids found already (`tour.candidates`) for the first pass."""
    n = starts.shape[0]
    pts = np.concatenate((starts, ends))
    link = [-1] * (2 * n)
    parent = list(range(n))  # union-find over paths: one root per chain

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    free = np.arange(2 * n)
    chain = np.concatenate((np.arange(n), np.arange(n)))
    chains = n
    while chains > 1:
        if pairs is not None and chains == n:  # the first pass: ids are endpoint ids
            pi, pj = pairs
            keep = (pi < pj) & (pj < 2 * n)  # each pair once, not the start and park
            pi, pj = pi[keep], pj[keep]
        else:
            pi, pj = tour.neighbours(pts[free], min(K, free.size - 1), chain)
            keep = pi < pj  # each pair once
            pi, pj = free[pi[keep]], free[pj[keep]]
        d = np.empty(pi.size)
        for c in range(0, pi.size, CHUNK):  # in chunks: bounded temporaries
            a, b = pi[c:c + CHUNK], pj[c:c + CHUNK]
            d[c:c + CHUNK] = (pts[a, 0] - pts[b, 0]) ** 2 + (pts[a, 1] - pts[b, 1]) ** 2
        by_length = np.argsort(d, kind="stable")  # squared lengths: the same order
        del d
        for c in range(0, by_length.size, CHUNK):
            sel = by_length[c:c + CHUNK]
            for a, b in zip(pi[sel].tolist(), pj[sel].tolist(), strict=True):
                if link[a] >= 0 or link[b] >= 0:
                    continue
                ra, rb = find(a % n), find(b % n)
                if ra == rb:  # would close a cycle
                    continue
                parent[ra] = rb
                link[a], link[b] = b, a
                chains -= 1
        free = np.flatnonzero(np.array(link) < 0)
        chain = np.array([find(int(x) % n) for x in free.tolist()], dtype=np.int64)
    return link


def greedy_edge(starts: FloatArray, ends: FloatArray, start: FloatArray | None,
                pairs: tuple[IntArray, IntArray] | None = None) -> tuple[IntArray, BoolArray]:
    """The greedy-edge tour (module doc) as (order, reverse), walked from the chain's free
    end nearer `start` (None: the first free end); `pairs`: `tour.candidates` if known."""
    n = starts.shape[0]
    order = np.zeros(n, dtype=np.int64)
    rev = np.zeros(n, dtype=bool)
    if n < 2:
        return order, rev
    link = _link(starts, ends, pairs)
    a, b = (x for x in range(2 * n) if link[x] < 0)
    if start is not None:
        pts = np.concatenate((starts, ends))
        if np.hypot(*(pts[b] - start)) < np.hypot(*(pts[a] - start)):
            a = b
    cur = a
    for k in range(n):  # enter path cur % n at endpoint cur, leave at its other end
        order[k] = cur % n
        rev[k] = cur >= n
        cur = link[cur - n if cur >= n else cur + n]
    return order, rev
