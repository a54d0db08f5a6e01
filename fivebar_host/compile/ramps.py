"""Step (2) of the planner (`compile.planner`, module doc): where to cut each segment's
speed-up and slow-down into pieces (new targets on the segment's stepped line), from the
continuous profile (`planner.Plan`), and which junctions are sharp — the piece next to a
sharp junction is cut off so that only it runs at the junction's speed."""

from __future__ import annotations

import numpy as np

from fivebar_host.compile.planner import Plan
from kinematics.arrays import BoolArray, FloatArray, IntArray


def ramp_fractions(pl: Plan, dist: FloatArray, alpha: float, piece_s: float,
                   min_piece_rad: float = 0.0,
                   sharp: tuple[BoolArray, BoolArray] | None = None,
                   sharp_s: float = 0.0) -> tuple[IntArray, FloatArray]:
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
    speed (`sharp_junctions`).  There the piece next to the junction is kept on its own
    even when the ramp fits one piece: cut to `SHARP_SHARE` of `min_piece_rad` where it
    lasts at least `sharp_s` (s) at the junction's planned speed, else grown to
    `min_piece_rad` when shorter (`_sharp_pieces`). The staircase runs that piece near the
    junction's speed, and the rest of the segment at its own (joined, the whole segment —
    or its neighbour — ran at the junction's speed: a short segment after a joint's reversal
    at a few per cent of its speed; measured against TOPP-RA, `benchmarks/topp.py`:
    planned/optimal on benchmarks/drawings/plotter.svg 1.346 → 1.108,
    examples/fivebar_text.svg 1.026 → 1.005 when the piece was first kept; the cut: the
    constants' comment)."""
    k = pl.v_entry.shape[0]
    d = np.asarray(dist, dtype=np.float64)
    s_in, s_out = sharp if sharp is not None else (np.zeros(k, bool), np.zeros(k, bool))
    counts: list[IntArray] = []
    fracs: list[FloatArray] = []
    for b in range(0, max(k, 1), RAMP_BLOCK):
        sl = slice(b, b + RAMP_BLOCK)
        n, f = _ramp_block((pl.v_entry[sl], pl.v_exit[sl], pl.v_peak[sl]), d[sl], alpha,
                           (piece_s, min_piece_rad, sharp_s), (s_in[sl], s_out[sl]))
        counts.append(n)
        fracs.append(f)
    if len(counts) == 1:
        return counts[0], fracs[0]
    return np.concatenate(counts), np.concatenate(fracs)


#: Segments cut at a time by `ramp_fractions`.
RAMP_BLOCK = 1 << 16
#: A sharp junction's piece (`ramp_fractions`): `SHARP_SHARE` of the least piece (2 of 3
#: steps), cut from segments at least `SHARP_ROOM` such pieces long, where it lasts at least
#: `SHARP_WAIT_S` at the junction's planned speed (first 2 × the firmware's floor of then,
#: 1.1 ms a segment) — a faster short piece runs at its link floor and holds its
#: neighbours back (the 5 × 1000-chord circle at 200 mm/s, 15 rad/s: 0.56 of the time at
#: 100 mm/s instead of 0.51). Elsewhere a piece shorter than the least grows to it, from
#: segments at least `GROW_ROOM` least pieces long (measured before the staircase's
#: path-speed rules: from shorter ones the cut cost more than it saved — a comb of 0.3 mm
#: teeth took 1.22× its continuous profile's time at 2, 1.01× at 8). Measured with
#: `python benchmarks/topp.py` against TOPP-RA on the uncut segments (the staircase's
#: path-speed rules, the grown piece only → these): benchmarks/drawings/bc_template.svg
#: 1.046 → 1.019, docs_command_line.svg 1.091 → 1.047, voronoi.svg 1.032 → 1.013; a 1-step
#: piece rounds the segment's direction off by up to half a step on the other motor (a
#: sharper junction) and lost to 2; without the pieces at stops 1.024, 1.052, 1.018.
#: With ramp pieces of 2 steps (`compile.timing.PLAN_MIN_PIECE_STEPS`), 0.6 of them (then 1 or
#: 2 steps as the start rounds; one step of the major motor since the pieces are cut on the
#: segment's stepped line, `compile.timing._on_steps`, where the three constants were measured
#: again: 0.4/0.5/0.6 of J, 0.4/1.0 of the least piece and 1.1/2.2 ms all longer on
#: bc_template) and 1.65 ms: bc_template 1.0123 → 1.0101 against 2/3 and
#: 2.2 ms, shorter on 11 of 13 other drawings, the same on two_layers_a4.svg and 0.0002
#: longer on the circle (benchmarks/topp.py; 1.1 ms: 1.0156; 2.75 ms: 1.0239; the link's
#: own floor, `compile.linkrate`, made no difference from 450 to 1100 µs a segment).
SHARP_SHARE = 0.6
SHARP_ROOM = 1.5
SHARP_WAIT_S = 1.65e-3
#: (24 steps at the least piece of 2 steps, as 8 × 3 before: at 8 × 2 the comb of 0.3 mm
#: teeth in tests/test_plan_sharp.py took 1.13× its continuous profile's time, at 12 1.010×)
GROW_ROOM = 12.0


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


def _ramp_block(speeds: tuple[FloatArray, FloatArray, FloatArray], d: FloatArray,
                alpha: float, cut: tuple[float, float, float],
                sharp: tuple[BoolArray, BoolArray]) -> tuple[IntArray, FloatArray]:
    """`ramp_fractions` on the segments with entry/exit/peak `speeds` v0, v1, vp and
    distances d, cut by (piece_s, min_piece_rad, sharp_s); each piece's position is
    computed only where it applies (ramp up, ramp down, else the cruise's end)."""
    v0, v1, vp = speeds
    piece_s, min_piece_rad, sharp_s = cut
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
    s_in, s_out = sharp
    keep = last | ~(((i == nas) & (nas == 1) & ~s_in[seg])
                    | ((i == nas + ncs) & (nds == 1) & (ncs == 1) & ~s_out[seg]))
    del i, nas, nds, ncs
    if min_piece_rad > 0.0:
        x, keep = _sharp_pieces(x, keep, (seg, last, ds), (v0[seg], v1[seg]),
                                (s_in[seg], s_out[seg]), (min_piece_rad, sharp_s))
    seg, x, ds = seg[keep], x[keep], ds[keep]
    # ascending within each segment (a sharp piece cut where a ramp's boundary was nearer
    # its junction): a boundary behind the one before it coincides with it, an empty
    # piece, which `compile.timing` drops with the pieces that round to no move
    same = seg[1:] == seg[:-1]
    while True:  # (exact: no boundary moves but onto the one before it)
        behind = np.flatnonzero(same & (x[1:] < x[:-1])) + 1
        if not behind.size:
            break
        x[behind] = x[behind - 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.clip(np.where(ds > 0, x / ds, 1.0), 0.0, 1.0)
    f[np.concatenate((seg[1:] != seg[:-1], [True])) if seg.size else np.zeros(0, bool)] = 1.0
    return np.bincount(seg, minlength=d.shape[0]).astype(np.int64), f


def _sharp_pieces(x: FloatArray, keep: BoolArray,
                  rows: tuple[IntArray, BoolArray, FloatArray],
                  v_ends: tuple[FloatArray, FloatArray], sharp: tuple[BoolArray, BoolArray],
                  least: tuple[float, float]) -> tuple[FloatArray, BoolArray]:
    """The pieces at sharp junctions (`ramp_fractions`), on the boundaries `x` of one block
    (per row: its segment, whether it is the segment's last, the segment's distance; the
    junction speeds and sharp flags at the row's segment's entry and exit; the least piece
    and `sharp_s`): a piece is cut to `SHARP_SHARE` of the least piece where it lasts at
    least `sharp_s` at the junction's planned speed and the segment has `SHARP_ROOM` of it;
    else one shorter than the least piece grows to it, where the segment has `GROW_ROOM`.
    Returns the boundaries and which rows to keep: the cut ones, and the others that leave
    pieces of the least length."""
    seg, last, ds = rows
    min_piece_rad, sharp_s = least
    first = np.concatenate(([True], seg[1:] != seg[:-1])) & ~last
    before_last = np.concatenate((last[1:], [False])) & ~last
    short = SHARP_SHARE * min_piece_rad
    room = ds >= SHARP_ROOM * short
    cut_in = first & room & sharp[0] & (short >= sharp_s * v_ends[0])
    cut_out = before_last & room & sharp[1] & (short >= sharp_s * v_ends[1])
    room = ds >= GROW_ROOM * min_piece_rad
    grow = first & room & sharp[0] & (x < min_piece_rad) & ~cut_in
    x[grow] = min_piece_rad
    grow = before_last & room & sharp[1] & (ds - x < min_piece_rad) & ~cut_out
    x[grow] = ds[grow] - min_piece_rad
    x[cut_in] = short
    x[cut_out] = ds[cut_out] - short
    prev = np.concatenate(([0.0], x[:-1]))
    prev[np.concatenate(([True], seg[1:] != seg[:-1]))] = 0.0
    keep &= (last | cut_in | cut_out
             | ((x - prev >= min_piece_rad) & (ds - x >= min_piece_rad)))
    return x, keep
