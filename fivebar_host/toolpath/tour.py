"""Local search on a tour of reversible paths (`toolpath.order`'s second stage), numpy only.

The tour is a sequence of positions 0..n+1: position 0 is the pen's start (only an exit
point; with no start position every distance from it is 0: the tour may begin anywhere),
positions 1..n are the paths, each entered at `A[k]` and left at `B[k]` (its start and end,
swapped when it is drawn reversed), and position n+1 the park position (only an entry point;
with no park position every distance to it is 0). The cost is the sum of the
travel edges B[k] → A[k+1]. Two kinds of moves, both proposed by pairs of near endpoints
(each endpoint with its K nearest, `neighbours`: a grid searched at growing cell sizes):

- 2-opt: reverse the block i..j (and every path in it): the edges B[i−1] → A[i] and
  B[j] → A[j+1] become B[i−1] → B[j] and A[i] → A[j+1]. A pair of near exits (or of near
  entries) proposes it; a single path's reversal is the block i..i.
- Or-opt: move the block i..j between k and k+1, forwards or reversed. A near exit/entry
  pair (the new edge B[k] → A[i] or B[j] → A[k+1]) or a near pair of exits or of entries
  (reversed insertion) proposes it with the block's other end 1–3 paths away, or, for a
  longer block (or-3opt), where the closing edge B[i−1] → A[j+1] joins near endpoints too.

A round takes the pairs of one kind of move, computes every proposed move's gain at once
(vectorised), then goes through the improving ones best first, each checked again on the
tour as the moves before it left it (positions shift, blocks turn round) and applied if it
still gains. Every applied move shortens the tour by its gain, so the search ends no longer
than it began. Endpoints whose edges changed are marked, and the next round of that kind
only looks at pairs with a marked endpoint (don't-look bits); reversing a block also turns
its inner endpoints from exits into entries against the rest of the tour, which changes the
2-opt moves they propose, so they are marked for 2-opt in blocks shorter than `FLIP_BLOCK`
(and for Or-opt in blocks shorter than `OR_BLOCK`). Rounds alternate between the kinds
until neither improves.
"""

from __future__ import annotations

import math
import time

import numpy as np

from fivebar_host import progress
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Moves gaining less than this (mm) are not taken (rounding noise).
EPS = 1e-9
#: A reversed block shorter than this marks its inner endpoints for Or-opt too.
OR_BLOCK = 50
#: ... and shorter than this for 2-opt (longer reversals mark their ends only: the inner
#: endpoints' new 2-opt moves are rarely worth looking at all of them again).
FLIP_BLOCK = 2000
#: Near endpoints per endpoint that may close a long Or-opt block.
LONG_K = 4
#: Above this many paths a move may span at most max(MIN_BLOCK, BIG_TOUR² / 10n) positions
#: (a reversal or a shift costs its length): the search stays about linear in n.
BIG_TOUR = 20_000
MIN_BLOCK = 1000
#: and the search stops once a 2-opt and an Or-opt round together gain less than this share.
BIG_TOUR_GAIN = 0.005
#: Pairs looked at per call of a round (bounds the vectorised temporaries).
CHUNK = 1 << 17
#: Points whose neighbours are looked for at once.
QUERY_CHUNK = 1 << 13


def neighbours(pts: FloatArray, k: int, owner: IntArray) -> tuple[IntArray, IntArray]:
    """Up to `k` nearest other points of every point (pairs (i, j), i's nearest first),
    skipping points with the same `owner`. Points are binned in a square grid of about one
    point per cell and each point's candidates are the points of its 3 × 3 block of cells
    (at most `4k + 8` from any one cell, so that many coincident points stay linear in work);
    points with fewer than `k` candidates are searched again in a grid twice as coarse, until
    every point has `k` or the grid covers the drawing. Queries go in chunks, so the
    temporaries stay bounded whatever the number of points."""
    m = pts.shape[0]
    lo = pts.min(axis=0)
    span = float(max(np.ptp(pts, axis=0).max(), 1e-9))
    h = span / max(1.0, np.sqrt(m))
    table = np.full((m, k), -1, dtype=np.int64)  # row i: i's neighbours, nearest first
    query = np.arange(m)
    while query.size:
        cells = np.floor((pts - lo) / h).astype(np.int64)
        g = int(cells.max()) + 3
        key = (cells[:, 0] + 1) * g + cells[:, 1] + 1
        srt = np.argsort(key, kind="stable")
        grid = (key, g, srt, *np.unique(key[srt], return_index=True, return_counts=True))
        left: list[IntArray] = []
        for c in range(0, query.size, QUERY_CHUNK):
            q = query[c:c + QUERY_CHUNK]
            found = _nearest_in_grid(pts, owner, k, q, grid, table)
            left.append(q[(found < k) & (h <= 2 * span)])
        query = np.concatenate(left)
        h *= 2.0
    pi = np.repeat(np.arange(m), (table >= 0).sum(axis=1))
    return pi, table[table >= 0]


def _nearest_in_grid(pts: FloatArray, owner: IntArray, k: int, q: IntArray,
                     grid: tuple[IntArray, int, IntArray, IntArray, IntArray, IntArray],
                     table: IntArray) -> IntArray:
    """`neighbours` for the points `q` in one grid (keys, width, points sorted by key, the
    occupied keys, their first index and count): writes each point's nearest (up to `k`) in
    its 3 × 3 block of cells into its row of `table`; returns how many each has."""
    key, g, srt, ukey, first, count = grid
    pi_l: list[IntArray] = []
    pj_l: list[IntArray] = []
    qkey = key[q]
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            nk = qkey + dx * g + dy
            c = np.minimum(np.searchsorted(ukey, nk), ukey.size - 1)
            hit = ukey[c] == nk
            qq, c = np.flatnonzero(hit), c[hit]
            cnt = np.minimum(count[c], 4 * k + 8)
            rep = np.repeat(np.arange(qq.size), cnt)
            off = np.arange(rep.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            pi_l.append(qq[rep])  # index into q
            pj_l.append(srt[first[c][rep] + off])
    pi = np.concatenate(pi_l)
    pj = np.concatenate(pj_l)
    ok = owner[q[pi]] != owner[pj]
    pi, pj = pi[ok], pj[ok]
    d2 = ((pts[q[pi]] - pts[pj]) ** 2).sum(axis=1)
    # by point, then distance: one float key (the point, plus its distance scaled into
    # [0, 0.5)), sorted once — several times faster than a two-key sort
    order = np.argsort(pi + d2 / (2.0 * float(d2.max(initial=0.0)) + 1e-300))
    pi, pj = pi[order], pj[order]
    rank = np.arange(pi.size) - np.searchsorted(pi, pi, side="left")
    keep = rank < k
    found = np.bincount(pi[keep], minlength=q.size)
    table[q] = -1  # a coarser grid's answer replaces a finer one's
    table[q[pi[keep]], rank[keep]] = pj[keep]
    return found


def _norm(dx: FloatArray, dy: FloatArray) -> FloatArray:
    """sqrt(dx² + dy²) in place of dx (a temporary): three times faster than np.hypot,
    whose overflow guard millimetre coordinates do not need."""
    dx *= dx
    dy *= dy
    dx += dy
    out: FloatArray = np.sqrt(dx, out=dx)
    return out


class Tour:
    """The tour's mutable state (module doc): path and reversal per position, entry (A) and
    exit (B) coordinates per position, and each path's position."""

    def __init__(self, starts: FloatArray, ends: FloatArray, order: IntArray, rev: BoolArray,
                 start: FloatArray | None, end: FloatArray | None) -> None:
        self.n = n = order.shape[0]
        #: the longest block a 2-opt move reverses (a reversal costs its length)
        self.max_block = n if n <= BIG_TOUR else max(MIN_BLOCK, BIG_TOUR * BIG_TOUR // n // 10)
        self.free_start = start is None
        self.free_end = end is None
        if start is None:  # a placeholder: every edge from it is free
            start = starts[order[0]]
        self.path = np.concatenate(([-1], order, [-1])).astype(np.int64)
        self.rev = np.concatenate(([False], rev, [False]))
        r = rev[:, None]
        a = np.concatenate((start[None], np.where(r, ends[order], starts[order]),
                            (start if end is None else end)[None]))
        b = np.concatenate((start[None], np.where(r, starts[order], ends[order]), a[-1:]))
        self.ax, self.ay = a[:, 0].copy(), a[:, 1].copy()
        self.bx, self.by = b[:, 0].copy(), b[:, 1].copy()
        # each path's position, then 0 and n + 1 for the start and the park (`roles`)
        self.posx = np.concatenate((np.empty(n, dtype=np.int64), [0, n + 1]))
        self.pos = self.posx[:n]  # a view: `reverse` and `move` keep both up to date
        self.pos[order] = np.arange(1, n + 1)
        #: per endpoint id: its path (n, n + 1: the start, the park), and whether it is the
        #: exit of an unreversed path (the start position is an exit, the park an entry)
        self.owner = np.concatenate((np.arange(n), np.arange(n), [n, n + 1]))
        self.side = np.concatenate((np.zeros(n, bool), np.ones(n, bool), [True, False]))

    def length(self) -> float:
        """The tour's travel."""
        return float(self.edges().sum())

    def edges(self) -> FloatArray:
        """The travel edges' lengths: edge k runs from B[k] to A[k+1] (k = 0..n)."""
        d = _norm(self.ax[1:] - self.bx[:-1], self.ay[1:] - self.by[:-1])
        if self.free_start:
            d[0] = 0.0
        if self.free_end:
            d[-1] = 0.0
        return d

    def roles(self, e: IntArray) -> tuple[IntArray, BoolArray]:
        """Position and whether it is the exit, of endpoint ids (id < n: start of path id,
        n ≤ id < 2n: end of path id − n, 2n: the start position, 2n + 1: the park)."""
        k = self.posx[self.owner[e]]
        return k, self.side[e] ^ self.rev[k]  # rev is False at 0 and n + 1

    def role(self, e: int) -> tuple[int, bool]:
        """`roles` of one endpoint."""
        n = self.n
        if e >= 2 * n:
            return (0, True) if e == 2 * n else (n + 1, False)
        k = int(self.pos[e % n])
        return k, (e >= n) != bool(self.rev[k])

    def dist(self, px: FloatArray, py: FloatArray, qx: FloatArray, qy: FloatArray,
             p: IntArray, q: IntArray) -> FloatArray:
        """|P − Q| for P at positions `p`, Q at positions `q`: 0 from the start position
        or to the park position where the tour has none (free ends)."""
        d = _norm(px - qx, py - qy)
        if self.free_start:
            d[p == 0] = 0.0
        if self.free_end:
            d[q == self.n + 1] = 0.0
        return d

    def d1(self, px: float, py: float, qx: float, qy: float, p: int, q: int) -> float:
        """`dist` of one pair."""
        if (self.free_start and p == 0) or (self.free_end and q == self.n + 1):
            return 0.0
        return math.hypot(px - qx, py - qy)

    def reverse(self, i: int, j: int) -> None:
        """Reverse the block i..j (and each path in it)."""
        s = slice(i, j + 1)
        self.path[s] = self.path[s][::-1].copy()
        self.rev[s] = ~self.rev[s][::-1]
        ax, ay = self.ax[s][::-1].copy(), self.ay[s][::-1].copy()
        self.ax[s], self.ay[s] = self.bx[s][::-1], self.by[s][::-1]
        self.bx[s], self.by[s] = ax, ay
        self.pos[self.path[s]] = np.arange(i, j + 1)

    def move(self, i: int, j: int, k: int, r: bool) -> None:
        """Move the block i..j after position k (k < i − 1 or k > j), reversed if `r`."""
        blk = np.arange(i, j + 1)
        if r:
            blk = blk[::-1]
        if k > j:
            lo, hi, idx = i, k, np.concatenate((np.arange(j + 1, k + 1), blk))
            b0 = k - (j - i)
        else:
            lo, hi, idx = k + 1, j, np.concatenate((blk, np.arange(k + 1, i)))
            b0 = k + 1
        s = slice(lo, hi + 1)
        ax, ay, bx, by = self.ax[idx], self.ay[idx], self.bx[idx], self.by[idx]
        rv = self.rev[idx]
        if r:
            b = slice(b0 - lo, b0 - lo + j - i + 1)
            ax[b], bx[b] = bx[b].copy(), ax[b].copy()
            ay[b], by[b] = by[b].copy(), ay[b].copy()
            rv[b] = ~rv[b]
        self.path[s] = self.path[idx]
        self.rev[s] = rv
        self.ax[s], self.ay[s], self.bx[s], self.by[s] = ax, ay, bx, by
        self.pos[self.path[s]] = np.arange(lo, hi + 1)


def _gain_2opt(t: Tour, i: IntArray, j: IntArray) -> FloatArray:
    """How much reversing each block i..j shortens the tour."""
    ax, ay, bx, by = t.ax, t.ay, t.bx, t.by
    e = t.edges()
    return (e[i - 1] + e[j] - t.dist(bx[i - 1], by[i - 1], bx[j], by[j], i - 1, j)
            - t.dist(ax[i], ay[i], ax[j + 1], ay[j + 1], i, j + 1))


def _move_2opt(t: Tour, x: int, y: int) -> tuple[int, int, float] | None:
    """The 2-opt move of the pair (x, y) now, and its gain (None: no valid move)."""
    kx, ex = t.role(x)
    ky, ey = t.role(y)
    if kx == ky or ex != ey:
        return None
    i, j = (min(kx, ky) + 1, max(kx, ky)) if ex else (min(kx, ky), max(kx, ky) - 1)
    if not (1 <= i <= j <= t.n and j - i < t.max_block):
        return None
    ax, ay, bx, by, d = t.ax, t.ay, t.bx, t.by, t.d1
    g = (d(bx[i - 1], by[i - 1], ax[i], ay[i], i - 1, i)
         + d(bx[j], by[j], ax[j + 1], ay[j + 1], j, j + 1)
         - d(bx[i - 1], by[i - 1], bx[j], by[j], i - 1, j)
         - d(ax[i], ay[i], ax[j + 1], ay[j + 1], i, j + 1))
    return i, j, g


def round_2opt(t: Tour, x: IntArray, y: IntArray, touched: BoolArray, inner: BoolArray,
               flipped: BoolArray) -> int:
    """Improving 2-opt moves proposed by the pairs (x, y), taken best first, each checked
    again on the tour as it is then; marks (at path + 1) the paths whose edges changed
    (`touched`), and those whose role changed (`flipped`; `inner` within short blocks).
    Returns the number of moves."""
    n = t.n
    if t.free_end:  # any exit may become the last: pair every exit with the last one
        p, rv = t.path[:n], t.rev[:n]
        ids = np.where(p < 0, 2 * n, p + np.where(rv, 0, n))
        x = np.concatenate((x, ids))
        y = np.concatenate((y, np.full(n, int(t.path[n]) + (0 if t.rev[n] else n))))
    if t.free_start:  # any entry may become the first: pair every entry with the first one
        p, rv = t.path[2:], t.rev[2:]
        ids = np.where(p < 0, 2 * n + 1, p + np.where(rv, n, 0))
        x = np.concatenate((x, np.full(n, int(t.path[1]) + (n if t.rev[1] else 0))))
        y = np.concatenate((y, ids))
    kx, ex = t.roles(x)
    ky, ey = t.roles(y)
    lo, hi = np.minimum(kx, ky), np.maximum(kx, ky)
    same = (ex == ey) & (kx != ky)
    i = np.where(ex, lo + 1, lo)
    j = np.where(ex, hi, hi - 1)
    ok = same & (i >= 1) & (i <= j) & (j <= n) & (j - i < t.max_block)
    x, y, i, j = x[ok], y[ok], i[ok], j[ok]
    gain = _gain_2opt(t, i, j)
    good = np.flatnonzero(gain > EPS)
    good = good[np.argsort(-gain[good], kind="stable")]
    moves = 0
    for xc, yc in zip(x[good].tolist(), y[good].tolist(), strict=True):
        mv = _move_2opt(t, xc, yc)
        if mv is None or mv[2] <= EPS:
            continue
        a, b, _ = mv
        touched[t.path[[a - 1, a, b, b + 1]] + 1] = True
        if b - a > 1:  # the block's endpoints change role (exit ↔ entry) against the rest
            if b - a < FLIP_BLOCK:
                flipped[t.path[a + 1:b] + 1] = True
            if b - a < OR_BLOCK:
                inner[t.path[a + 1:b] + 1] = True
        t.reverse(a, b)
        moves += 1
    return moves


def _oropt_of(kx: IntArray, ex: BoolArray, ky: IntArray, ey: BoolArray,
              L: IntArray) -> tuple[IntArray, IntArray, IntArray, BoolArray]:
    """Or-opt block i..j, insertion point k and reversal for pairs whose new edge is
    B[k] → A[i] (exit x, entry y: forwards), B[k] → B[j] (exits: reversed), B[j] → A[k+1]
    (entry x, exit y: forwards) or A[i] → A[k+1] (entries: reversed)."""
    i = np.where(ey, ky - L + 1, ky)
    j = np.where(ey, ky, ky + L - 1)
    k = np.where(ex, kx, kx - 1)
    return i, j, k, ex == ey


def _gain_oropt(t: Tour, i: IntArray, j: IntArray, k: IntArray, r: BoolArray) -> FloatArray:
    """How much moving each block i..j after k (reversed where `r`) shortens the tour."""
    ax, ay, bx, by, d = t.ax, t.ay, t.bx, t.by, t.dist
    e = t.edges()
    gain = e[i - 1] + e[j] + e[k] - d(bx[i - 1], by[i - 1], ax[j + 1], ay[j + 1], i - 1, j + 1)
    f, b = np.flatnonzero(~r), np.flatnonzero(r)
    i_f, j_f, k_f, i_b, j_b, k_b = i[f], j[f], k[f], i[b], j[b], k[b]
    gain[f] -= (d(bx[k_f], by[k_f], ax[i_f], ay[i_f], k_f, i_f)
                + d(bx[j_f], by[j_f], ax[k_f + 1], ay[k_f + 1], j_f, k_f + 1))
    gain[b] -= (d(bx[k_b], by[k_b], bx[j_b], by[j_b], k_b, j_b)
                + d(ax[i_b], ay[i_b], ax[k_b + 1], ay[k_b + 1], i_b, k_b + 1))
    return gain


def _gain_oropt1(t: Tour, i: int, j: int, k: int, r: bool) -> float:
    """`_gain_oropt` of one move."""
    ax, ay, bx, by, d = t.ax, t.ay, t.bx, t.by, t.d1
    rem = (d(bx[i - 1], by[i - 1], ax[i], ay[i], i - 1, i)
           + d(bx[j], by[j], ax[j + 1], ay[j + 1], j, j + 1)
           + d(bx[k], by[k], ax[k + 1], ay[k + 1], k, k + 1)
           - d(bx[i - 1], by[i - 1], ax[j + 1], ay[j + 1], i - 1, j + 1))
    if r:
        return (rem - d(bx[k], by[k], bx[j], by[j], k, j)
                - d(ax[i], ay[i], ax[k + 1], ay[k + 1], i, k + 1))
    return (rem - d(bx[k], by[k], ax[i], ay[i], k, i)
            - d(bx[j], by[j], ax[k + 1], ay[k + 1], j, k + 1))


def _long_blocks(t: Tour, nbr: IntArray, x: IntArray, y: IntArray, min_len: int
                 ) -> tuple[IntArray, IntArray, IntArray, IntArray, IntArray, BoolArray]:
    """Or-opt moves of blocks longer than `min_len` (or-3opt): the pair (x, y) gives the
    insertion edge and one end of the block (i if y is an entry, else j); the other end is
    where the closing edge B[i−1] → A[j+1] joins a near endpoint `z` of the block's outer
    neighbour. Returns the index of the pair, z, i, j, k and the reversal per candidate."""
    n = t.n
    kx, ex = t.roles(x)
    ky, ey = t.roles(y)
    # the endpoint before the block (exit at i − 1) or after it (entry at j + 1)
    q = np.where(ey, ky + 1, ky - 1)
    pq = t.path[q]
    rq = t.rev[q]
    w = np.where(ey, np.where(pq < 0, 2 * n + 1, pq + np.where(rq, n, 0)),
                 np.where(pq < 0, 2 * n, pq + np.where(rq, 0, n)))
    kk = nbr.shape[1]
    z = nbr[w].ravel()
    sel = np.repeat(np.arange(x.shape[0]), kk)
    has = z >= 0
    z, sel = z[has], sel[has]
    kz, ez = t.roles(z)
    eyy = ey[sel]
    # y entry (block starts at i = ky): z must be an entry after it, j = kz − 1;
    # y exit (block ends at j = ky): z must be an exit before it, i = kz + 1
    i = np.where(eyy, kz + 1, ky[sel])
    j = np.where(eyy, ky[sel], kz - 1)
    k = np.where(ex[sel], kx[sel], kx[sel] - 1)
    ok = ((ez == eyy) & (j - i + 1 > min_len) & (i >= 1) & (j <= n) & (k >= 0) & (k <= n)
          & ((k < i - 1) | (k > j)) & (np.abs(k - i) < t.max_block)
          & (j - i < t.max_block))
    sel, z = sel[ok], z[ok]
    return sel, z, i[ok], j[ok], k[ok], (ex == ey)[sel]


def _oropt_now(t: Tour, x: int, y: int, L: int, z: int) -> tuple[int, int, int, bool] | None:
    """The Or-opt move of candidate (x, y, L or z) on the tour as it is now (module doc)."""
    n = t.n
    kx, ex = t.role(x)
    ky, ey = t.role(y)
    k = kx if ex else kx - 1
    if z < 0:
        i, j = (ky, ky + L - 1) if not ey else (ky - L + 1, ky)
    else:
        kz, ez = t.role(z)
        if ez != ey:
            return None
        i, j = (ky, kz - 1) if not ey else (kz + 1, ky)
    if not (1 <= i <= j <= n and 0 <= k <= n and (k < i - 1 or k > j)
            and abs(k - i) < t.max_block and j - i < t.max_block):
        return None
    return i, j, k, ex == ey


def round_oropt(t: Tour, x: IntArray, y: IntArray, touched: BoolArray,
                nbr: IntArray | None = None, max_len: int = 3) -> int:
    """Improving Or-opt moves proposed by the pairs (x, y): blocks of 1..`max_len` paths,
    and with the neighbour table `nbr` longer blocks (`_long_blocks`); best first, each
    checked again on the tour as it is then; marks (at path + 1) the paths whose edges
    changed. Returns the number of moves."""
    n = t.n
    kx, ex = t.roles(x)
    ky, ey = t.roles(y)
    m = x.shape[0]
    xs, ys = np.tile(x, max_len), np.tile(y, max_len)
    L = np.repeat(np.arange(1, max_len + 1), m)
    i, j, k, r = _oropt_of(np.tile(kx, max_len), np.tile(ex, max_len), np.tile(ky, max_len),
                           np.tile(ey, max_len), L)
    ok = ((i >= 1) & (j <= n) & (k >= 0) & (k <= n) & ((k < i - 1) | (k > j))
          & (np.abs(k - i) < t.max_block))
    z = np.full(int(ok.sum()), -1, dtype=np.int64)
    xs, ys, L, i, j, k, r = xs[ok], ys[ok], L[ok], i[ok], j[ok], k[ok], r[ok]
    if nbr is not None:
        sel, z2, i2, j2, k2, r2 = _long_blocks(t, nbr, x, y, max_len)
        xs, ys = np.concatenate((xs, x[sel])), np.concatenate((ys, y[sel]))
        i, j, k, r = (np.concatenate(v) for v in ((i, i2), (j, j2), (k, k2), (r, r2)))
        L = np.concatenate((L, np.zeros(sel.size, dtype=np.int64)))
        z = np.concatenate((z, z2))
    gain = _gain_oropt(t, i, j, k, r)
    good = np.flatnonzero(gain > EPS)
    good = good[np.argsort(-gain[good], kind="stable")]
    moves = 0
    cand = zip(xs[good].tolist(), ys[good].tolist(), L[good].tolist(), z[good].tolist(),
               strict=True)
    for xc, yc, lc, zc in cand:
        mv = _oropt_now(t, xc, yc, lc, zc)
        if mv is None:
            continue
        ia, ja, ka, ra = mv
        if _gain_oropt1(t, ia, ja, ka, ra) <= EPS:
            continue
        touched[t.path[[ia - 1, ia, ja, ja + 1, ka, ka + 1]] + 1] = True
        t.move(ia, ja, ka, ra)
        moves += 1
    return moves


def _search(t: Tour, px: IntArray, py: IntArray, nbr: IntArray | None,
            max_rounds: int, marked: BoolArray | None = None) -> None:
    """Rounds of 2-opt and Or-opt until neither improves; each round only looks at pairs
    with an endpoint whose edges changed since that kind of round last looked."""
    n = t.n
    m = 2 * n + 2
    if marked is None:
        marked = np.ones(m, dtype=bool)
    look = [marked, marked.copy()]  # 2-opt, Or-opt
    idle = 0
    last = t.length()
    told = time.monotonic()
    for rnd in range(max_rounds):
        if n > BIG_TOUR and rnd % 2 == 0 and rnd:  # a large tour: stop when rounds gain little
            now = t.length()
            if now > last * (1 - BIG_TOUR_GAIN):
                break
            last = now
        kind = rnd % 2
        sel = look[kind][px] | look[kind][py]
        look[kind] = np.zeros(m, dtype=bool)
        touched = np.zeros(n + 1, dtype=bool)  # at path + 1 (0: the start and the park)
        inner = np.zeros(n + 1, dtype=bool)
        flipped = np.zeros(n + 1, dtype=bool)
        moves = 0
        for b in range(0, px.size, 8 * CHUNK):  # in chunks: bounded temporaries
            idx = np.flatnonzero(sel[b:b + 8 * CHUNK]) + b
            for c in range(0, idx.size, CHUNK):
                x, y = px[idx[c:c + CHUNK]], py[idx[c:c + CHUNK]]
                if kind == 0:
                    moves += round_2opt(t, x, y, touched, inner, flipped)
                else:
                    moves += round_oropt(t, x, y, touched, nbr)
        if not moves:
            idle += 1
            if idle >= 2:
                break
            continue
        idle = 0
        for lk, extra in ((look[0], flipped), (look[1], inner)):
            tp = np.flatnonzero((touched | extra)[1:])
            lk[tp] = lk[tp + n] = True
            lk[2 * n:] = True
        if progress.listening() and time.monotonic() >= told + 0.5:  # the second half
            told = time.monotonic()
            progress.report("ordering paths", 1.0 - 0.5 * float((look[0] | look[1]).mean()))


def candidates(starts: FloatArray, ends: FloatArray, start: FloatArray | None,
               end: FloatArray | None, k: int = 8) -> tuple[IntArray, IntArray]:
    """The near pairs (x, y) of endpoint ids (`Tour.roles`) that propose moves: each
    endpoint with its `k` nearest of other paths (`neighbours`), the start and park
    positions included (a placeholder point where that end of the tour is free)."""
    n = starts.shape[0]
    first = starts[0] if start is None else start
    park = first if end is None else end
    allp = np.concatenate((starts, ends, np.array([first, park], dtype=np.float64)))
    owner = np.concatenate((np.arange(n), np.arange(n), [n, n + 1]))
    return neighbours(allp, min(k, 2 * n), owner)


def improve(starts: FloatArray, ends: FloatArray, order: IntArray, rev: BoolArray,
            start: FloatArray | None, end: FloatArray | None, *, k: int = 8,
            max_rounds: int = 200, long_blocks: bool = True,
            pairs: tuple[IntArray, IntArray] | None = None,
            look: BoolArray | None = None) -> tuple[IntArray, BoolArray]:
    """2-opt and Or-opt from the tour (`order`, `rev`) until neither improves or after
    `max_rounds` rounds (module doc); `k` near endpoints per endpoint propose the moves
    (`pairs`: `candidates` computed already), `long_blocks` adds the or-3opt moves.
    `start`/`end` None: that end of the tour is free. `look`: the endpoint ids whose moves
    are looked at first (don't-look bits; None: all), for a tour already improved except
    around them."""
    n = order.shape[0]
    if n < 2:
        return order, rev
    t = Tour(starts, ends, order, rev, start, end)
    k = min(k, 2 * n)
    px, py = candidates(starts, ends, start, end, k) if pairs is None else pairs
    # a free end has no place: its edges cost nothing whatever is next to it (`round_2opt`
    # pairs the last exit itself; a block moved to the front is proposed by the first entry)
    free = [e for e, f in ((2 * n, start is None), (2 * n + 1, end is None)) if f]
    if free:
        keep = ~np.isin(px, free) & ~np.isin(py, free)
        px, py = px[keep], py[keep]
    nbr = None
    if long_blocks:
        nbr = np.full((2 * n + 2, LONG_K), -1, dtype=np.int64)
        rank = np.arange(px.size) - np.searchsorted(px, px, side="left")
        near = rank < LONG_K  # each endpoint's nearest (pairs come nearest first)
        nbr[px[near], rank[near]] = py[near]
    _search(t, px, py, nbr, max_rounds, look)
    return t.path[1:n + 1].copy(), t.rev[1:n + 1].copy()
