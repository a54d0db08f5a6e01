"""Step (2) of the planner (`compile.planner`, module doc): where to cut each segment's
speed-up and slow-down into pieces (new targets on the same joint-space line), from the
continuous profile (`planner.Plan`), and which junctions are sharp — the piece next to a
sharp junction is cut off so that only it runs at the junction's speed."""

from __future__ import annotations

import numpy as np

from fivebar_host.compile.planner import Plan
from kinematics.arrays import BoolArray, FloatArray, IntArray


def ramp_fractions(pl: Plan, dist: FloatArray, alpha: float, piece_s: float,
                   min_piece_rad: float = 0.0,
                   sharp: tuple[BoolArray, BoolArray] | None = None
                   ) -> tuple[IntArray, FloatArray]:
    """Where to cut each segment so that its speed-up and slow-down parts (under the planned
    trapezoid with acceleration `alpha` along the Chebyshev distance `dist`) become pieces of
    at most `piece_s` each — the planned speed changes by at most alpha·piece_s within a
    piece. A cruise part stays whole, and so does a ramp that fits in one piece (it joins
    its neighbour). No piece is made shorter than `min_piece_rad` (a shorter one joins the
    piece before it). Returns the number of pieces per segment (K,) and every piece's end as
    a fraction of its segment's distance (ascending within a segment, the last exactly 1).
    Every segment is cut on its own, so the segments are cut in blocks of `RAMP_BLOCK`
    (bounded temporaries on large jobs; the same pieces as one pass).

    `sharp` (entry, exit), per segment: its junction there is sharp — the joints' speeds
    would jump by more than the junction allows if the whole segment ran at its peak
    speed (`sharp_junctions`).  There a ramp's piece next to the junction is kept on its
    own even when the ramp fits one piece, and grown to `min_piece_rad` when shorter: the
    staircase runs that piece near the junction's speed, and the rest of the segment at
    its own (joined, the whole segment — or its neighbour — ran at the junction's speed:
    a short segment after a joint's reversal at a few per cent of its speed; measured
    against TOPP-RA, `benchmarks/topp.py`: planned/optimal on benchmarks/drawings/plotter.svg
    1.346 → 1.108, examples/fivebar_text.svg 1.026 → 1.005)."""
    k = pl.v_entry.shape[0]
    d = np.asarray(dist, dtype=np.float64)
    s_in, s_out = sharp if sharp is not None else (np.zeros(k, bool), np.zeros(k, bool))
    counts: list[IntArray] = []
    fracs: list[FloatArray] = []
    for b in range(0, max(k, 1), RAMP_BLOCK):
        sl = slice(b, b + RAMP_BLOCK)
        n, f = _ramp_block(pl.v_entry[sl], pl.v_exit[sl], pl.v_peak[sl], d[sl], alpha,
                           piece_s, min_piece_rad, (s_in[sl], s_out[sl]))
        counts.append(n)
        fracs.append(f)
    if len(counts) == 1:
        return counts[0], fracs[0]
    return np.concatenate(counts), np.concatenate(fracs)


#: Segments cut at a time by `ramp_fractions`.
RAMP_BLOCK = 1 << 16
#: A sharp junction's piece is cut from a segment of at least this many least pieces
#: (`ramp_fractions`).  Measured (benchmarks/topp.py and a comb of 0.3 mm teeth): from
#: shorter segments the cut costs more than it saves — its short pieces' boundaries bind
#: the staircase's average acceleration (the comb took 1.22× its continuous profile's
#: time at 2, 1.01× at 8; the drawings' ratios moved by < 0.01 between 2 and 8).
SHARP_ROOM = 8.0


def sharp_junctions(dtheta_rad: FloatArray, pl: Plan, jump_rad_s: float,
                    stop_after: BoolArray | None = None) -> tuple[BoolArray, BoolArray]:
    """Per segment, whether its entry and its exit junction are sharp (`ramp_fractions`):
    with u the joints' speeds per unit of Chebyshev speed (dθ/D), the jump |u_k − u_j|∞ ·
    v_peak,k over the junction with neighbour j exceeds `jump_rad_s`; at a stop (and the
    job's ends) the neighbour is at rest (u_j = 0)."""
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    k = dth.shape[0]
    dist = np.abs(dth).max(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(dist[:, None] > 0, dth / dist[:, None], 0.0)
    rest = np.zeros(k, dtype=bool) if stop_after is None else np.asarray(stop_after, bool)
    prev = np.zeros_like(u)
    prev[1:] = np.where(rest[:-1, None], 0.0, u[:-1])
    nxt = np.zeros_like(u)
    nxt[:-1] = np.where(rest[:-1, None], 0.0, u[1:])
    vp = pl.v_peak
    return (np.abs(u - prev).max(axis=1) * vp > jump_rad_s,
            np.abs(nxt - u).max(axis=1) * vp > jump_rad_s)


def _ramp_block(v0: FloatArray, v1: FloatArray, vp: FloatArray, d: FloatArray, alpha: float,
                piece_s: float, min_piece_rad: float,
                sharp: tuple[BoolArray, BoolArray]) -> tuple[IntArray, FloatArray]:
    """`ramp_fractions` on the segments with entry/exit/peak speeds v0, v1, vp and
    distances d; each piece's position is computed only where it applies (ramp up, ramp
    down, else the cruise's end)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        ta = np.where(vp > v0, (vp - v0) / alpha, 0.0)
        td = np.where(vp > v1, (vp - v1) / alpha, 0.0)
        da = np.clip((vp * vp - v0 * v0) / (2 * alpha), 0.0, d)
        dd = np.clip((vp * vp - v1 * v1) / (2 * alpha), 0.0, d - da)
    dc = np.maximum(d - da - dd, 0.0)
    na = np.where(ta > 0, np.ceil(ta / piece_s), 0).astype(np.int64)
    nd = np.where(td > 0, np.ceil(td / piece_s), 0).astype(np.int64)
    nc = (dc > 0).astype(np.int64)
    n = np.maximum(na + nc + nd, 1)
    seg = np.repeat(np.arange(d.shape[0]), n)
    i = np.arange(seg.shape[0]) - np.repeat(np.cumsum(n) - n, n) + 1  # 1-based piece number
    nas, nds, ncs = na[seg], nd[seg], nc[seg]
    x = da[seg] + dc[seg]  # the cruise's end, unless the piece ends on a ramp
    r = np.flatnonzero(i <= nas)  # on the ramp up
    t_a = i[r] / np.maximum(nas[r], 1) * ta[seg[r]]
    x[r] = v0[seg[r]] * t_a + 0.5 * alpha * t_a * t_a
    r = np.flatnonzero(i > nas + ncs)  # on the ramp down
    t_d = (i[r] - nas[r] - ncs[r]) / np.maximum(nds[r], 1) * td[seg[r]]
    x[r] = da[seg[r]] + dc[seg[r]] + vp[seg[r]] * t_d - 0.5 * alpha * t_d * t_d
    del r, t_a, t_d
    ds = d[seg]
    last = np.concatenate((seg[1:] != seg[:-1], [True])) if seg.size else np.zeros(0, bool)
    x[last] = ds[last]
    # Boundaries not needed: after a one-piece ramp up, before a one-piece ramp down,
    # unless at a sharp junction (`ramp_fractions`).
    s_in, s_out = sharp[0][seg], sharp[1][seg]
    keep = last | ~(((i == nas) & (nas == 1) & ~s_in)
                    | ((i == nas + ncs) & (nds == 1) & (ncs == 1) & ~s_out))
    del i, nas, nds, ncs
    if min_piece_rad > 0.0:
        # a sharp junction's piece shorter than the least piece grows to it, where the
        # segment has room (`SHARP_ROOM`)
        first = np.concatenate(([True], seg[1:] != seg[:-1])) & ~last
        before_last = np.concatenate((last[1:], [False])) & ~last
        room = ds >= SHARP_ROOM * min_piece_rad
        grow = first & room & s_in & (x < min_piece_rad)
        x[grow] = min_piece_rad
        grow = before_last & room & s_out & (ds - x < min_piece_rad)
        x[grow] = ds[grow] - min_piece_rad
        del first, before_last, room, grow
        prev = np.concatenate(([0.0], x[:-1]))
        prev[np.concatenate(([True], seg[1:] != seg[:-1]))] = 0.0
        keep &= last | ((x - prev >= min_piece_rad) & (ds - x >= min_piece_rad))
        del prev
    seg, x, ds = seg[keep], x[keep], ds[keep]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.clip(np.where(ds > 0, x / ds, 1.0), 0.0, 1.0)
    f[np.concatenate((seg[1:] != seg[:-1], [True])) if seg.size else np.zeros(0, bool)] = 1.0
    return np.bincount(seg, minlength=d.shape[0]).astype(np.int64), f
