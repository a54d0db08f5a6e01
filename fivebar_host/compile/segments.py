"""The job's segments in order, then in whole steps.

`assemble` merges the refined draw intervals and the pen-up travel pieces into one chain of
targets (row 0 = the homed pose; the travel into path j precedes its draw segments), with the
provenance of every segment; `drop_zero_moves` quantises the targets to absolute steps once
(`fivebar_host.steps`, docs/architecture.md "Steps") and drops the segments that round to no
move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host import steps
from fivebar_host.compile.model import compact_ints
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
    (T+1, 2) of the targets."""

    steps: IntArray


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


def assemble(placed: Placed, home: Home, routed: Routed, solved: Solved,
             tr: Travel) -> Segments:
    """Draw segments and travel pieces merged into job order, with their provenance."""
    ch, iv, drawing = routed.ch, solved.iv, placed.drawing
    a = ch.chord_from
    # Draw segments, in order (intervals are sorted by chord, chords by job order).
    dc = iv.chord
    d_path = ch.path_of_chord[dc]
    d_end_pts = ch.pts[a[dc]] + iv.sb[:, None] * (ch.pts[a[dc] + 1] - ch.pts[a[dc]])
    t_move, t_k, t_th, t_pts = _travel_pieces(home, routed, solved, tr)
    # Merge: key (path, part, sequence); travel into path j precedes its draw segments.
    n_d, n_t = dc.shape[0], t_move.shape[0]
    key_path = np.concatenate((d_path, t_move))
    key_part = np.concatenate((np.ones(n_d, np.int64), np.zeros(n_t, np.int64)))
    key_seq = np.concatenate((np.arange(n_d), t_k))
    perm = np.lexsort((key_seq, key_part, key_path))
    seg_draw = np.concatenate((np.ones(n_d, bool), np.zeros(n_t, bool)))[perm]
    end_th = np.concatenate((iv.thb, t_th))[perm]
    end_pts = np.concatenate((d_end_pts, t_pts))[perm]
    seg_path = key_path[perm]
    th_all = np.concatenate((home.th, end_th))
    pts_all = np.concatenate((home.pt[None], end_pts))
    # Per-segment provenance (draw only; −1 / 0 on travel).
    d_prim = ch.prim[dc]
    d_vprim = np.where(d_prim >= 0, d_prim, ch.vert_prim[a[dc]])
    d_src = drawing.stroke_source[drawing.stroke[d_vprim]]
    d_line = drawing.line[d_vprim]
    seg_source = np.concatenate((d_src, np.full(n_t, -1)))[perm]
    seg_line = np.concatenate((d_line, np.zeros(n_t, np.int64)))[perm]
    length = np.concatenate((
        (iv.sb - iv.sa) * np.hypot(*(ch.pts[a[dc] + 1] - ch.pts[a[dc]]).T),
        np.zeros(n_t)))[perm]
    # Travel length: distance between consecutive target points.
    tl = np.hypot(*np.diff(pts_all, axis=0).T)
    length = np.where(seg_draw, length, tl)
    return Segments(th=th_all, pts=pts_all, draw=seg_draw, path=seg_path, source=seg_source,
                    line=seg_line, length=length, perm=perm)


def drop_zero_moves(mot: Motors, sg: Segments) -> Stepped:
    """Absolute steps of every target (rounded once); segments that round to no move go.
    The integer arrays are int32 where every value fits (`compact_ints`)."""
    st = steps.absolute_steps(sg.th, mot.home_rad, mot.steps_per_rev)
    rel = np.diff(st, axis=0)
    moving = (rel != 0).any(axis=1)
    keep_t = np.concatenate(([True], moving))
    return Stepped(th=sg.th[keep_t], pts=sg.pts[keep_t], draw=sg.draw[moving],
                   path=compact_ints(sg.path[moving]), source=compact_ints(sg.source[moving]),
                   line=compact_ints(sg.line[moving]), length=sg.length[moving],
                   perm=compact_ints(sg.perm[moving]), steps=compact_ints(st[keep_t]))
