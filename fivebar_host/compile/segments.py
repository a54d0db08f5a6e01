"""The job's segments in order, then in whole steps.

`assemble` merges the refined draw intervals and the pen-up travel pieces into one chain of
targets (row 0 = the homed pose; the travel into path j precedes its draw segments), with the
provenance of every segment; `drop_zero_moves` quantises the targets to absolute steps once
(`fivebar_host.compile.steps`, docs/architecture.md "Steps") and drops the segments that round to no
move.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fivebar_host.compile.model import compact_ints, compact_steps
from fivebar_host.compile.place import Home, Placed
from fivebar_host.compile.solve import Routed, Solved
from fivebar_host.compile.travel import Travel
from fivebar_host.config import Motors
from kinematics.arrays import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class Segments:
    """Targets (T+1 rows, row 0 = homed pose): joint angles `th`, pen points `pts`. Per
    segment (T rows): `draw`, job `path`, `source` element (−1 on travel), source `line`
    (0 on travel), requested pen-path `length` (mm; travel: between its targets), and `perm`:
    the segment's row in the draw intervals followed by the travel pieces (for provenance)."""

    th: FloatArray
    pts: FloatArray
    draw: BoolArray
    path: IntArray
    source: IntArray
    line: IntArray
    length: FloatArray
    perm: IntArray


@dataclass(frozen=True)
class Stepped(Segments):
    """`Segments` without the moves that round to zero steps, with the absolute `steps`
    (T+1, 2) of the targets: motor counts, which exceed the joint's steps by `slack`
    (T+1, 2) after `compile.backlash.take_up` (empty: no backlash, counts = joint)."""

    steps: IntArray
    slack: IntArray = field(default_factory=lambda: np.zeros((0, 2), np.int64), kw_only=True)


def _travel_pieces(home: Home, routed: Routed, solved: Solved,
                   tr: Travel) -> tuple[IntArray, IntArray, FloatArray, FloatArray]:
    """Travel pieces: uniform in joint space, or the given targets (Cartesian, mode change).
    Returns the travel of each piece, its number within its travel, its joint angles and its
    pen point."""
    npath = routed.npath
    t_from, t_to = tr.t_from, tr.t_to
    t_pieces = tr.pieces.copy()
    for j, tg in tr.targets.items():
        t_pieces[j] = tg.shape[0]
    t_move = np.repeat(np.arange(npath + 1), t_pieces)
    t_k = np.arange(t_move.shape[0]) - np.repeat(np.cumsum(t_pieces) - t_pieces, t_pieces)
    frac = (t_k + 1) / t_pieces[t_move]
    t_th = t_from[t_move] + frac[:, None] * (t_to[t_move] - t_from[t_move])
    for j, tg in tr.targets.items():
        t_th[t_move == j] = tg
    t_pts = solved.checker.forward(t_th)[0]
    return t_move, t_k, t_th, t_pts


def _index_dtype(largest: int) -> type[np.signedinteger]:
    """int32 for indices up to `largest` when they fit (as `compact_ints`), else int64."""
    return np.int32 if largest <= np.iinfo(np.int32).max else np.int64


def assemble(placed: Placed, home: Home, routed: Routed, solved: Solved,
             tr: Travel) -> Segments:
    """Draw segments and travel pieces merged into job order, with their provenance. Each
    output array is written once, the draw rows and the travel rows straight into their
    merged positions (no concatenated copy is made; memory on large drawings)."""
    ch, iv, drawing = routed.ch, solved.iv, placed.drawing
    a = ch.chord_from
    # Draw segments, in order (intervals are sorted by chord, chords by job order).
    dc = iv.chord
    d_path = ch.path_of_chord[dc]
    t_move, t_k, t_th, t_pts = _travel_pieces(home, routed, solved, tr)
    # Merge: key (path, part, sequence); travel into path j precedes its draw segments.
    n_d, n_t = dc.shape[0], t_move.shape[0]
    key_path = np.concatenate((d_path, t_move))
    del d_path
    key_part = np.concatenate((np.ones(n_d, np.int8), np.zeros(n_t, np.int8)))
    key_seq = np.concatenate((np.arange(n_d), t_k))
    perm = compact_ints(np.lexsort((key_seq, key_part, key_path)))
    del key_seq, key_part
    seg_path = compact_ints(key_path[perm])
    del key_path
    pos = np.empty(n_d + n_t, dtype=np.int64)  # merged position of every draw, travel row
    pos[perm] = np.arange(n_d + n_t)
    pd, pt = pos[:n_d], pos[n_d:]
    seg_draw = np.zeros(n_d + n_t, bool)
    seg_draw[pd] = True
    th_all = np.empty((n_d + n_t + 1, 2))
    th_all[0] = home.th[0]
    th_all[1:][pd] = iv.thb
    th_all[1:][pt] = t_th
    pts_all = np.empty_like(th_all)
    pts_all[0] = home.pt
    ad = a[dc]
    pts_all[1:][pd] = ch.pts[ad] + iv.sb[:, None] * (ch.pts[ad + 1] - ch.pts[ad])
    pts_all[1:][pt] = t_pts
    del t_th, t_pts
    # Per-segment provenance (draw only; −1 / 0 on travel).
    d_prim = ch.prim[dc]
    d_vprim = np.where(d_prim >= 0, d_prim, ch.vert_prim[ad])
    del d_prim
    seg_source = np.full(n_d + n_t, -1, dtype=_index_dtype(len(drawing.sources)))
    seg_source[pd] = drawing.stroke_source[drawing.stroke[d_vprim]]
    seg_line = np.zeros(n_d + n_t, dtype=_index_dtype(
        int(drawing.line.max()) if drawing.line.size else 0))
    seg_line[pd] = drawing.line[d_vprim]
    del d_vprim
    # Draw length: the interval's part of its chord; travel: between consecutive targets.
    length = np.empty(n_d + n_t)
    length[pd] = (iv.sb - iv.sa) * np.hypot(*(ch.pts[ad + 1] - ch.pts[ad]).T)
    length[pt] = np.hypot(*(pts_all[pt + 1] - pts_all[pt]).T)
    return Segments(th=th_all, pts=pts_all, draw=seg_draw, path=seg_path, source=seg_source,
                    line=seg_line, length=length, perm=perm)


def drop_zero_moves(mot: Motors, sg: Segments) -> Stepped:
    """Absolute steps of every target (rounded once); segments that round to no move go.
    The integer arrays are int32 where every value fits (`compact_ints`)."""
    st = compact_steps(sg.th, mot.home_rad, mot.steps_per_rev)
    rel = np.diff(st, axis=0)
    moving = (rel != 0).any(axis=1)
    keep_t = np.concatenate(([True], moving))
    return Stepped(th=sg.th[keep_t], pts=sg.pts[keep_t], draw=sg.draw[moving],
                   path=compact_ints(sg.path[moving]), source=compact_ints(sg.source[moving]),
                   line=compact_ints(sg.line[moving]), length=sg.length[moving],
                   perm=compact_ints(sg.perm[moving]), steps=st[keep_t])
