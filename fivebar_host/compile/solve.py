"""Order the paths, give each its working mode, and solve them: checked inverse kinematics of
every vertex and the chords refined in joint space.

`route` orders and joins the flattened strokes (`chords.prepare_chords`) and, for
`--mode auto` with pen-up changes, plans a working mode per path (`modes.plan_path_modes`);
`solve` runs the pose checks (reach, joint limits, both singularity margins, assembly) on
every vertex in its path's mode and refines every chord until the joint-interpolated pen
path stays within the chord's budget tol_i (`toolpath.segment.refine`, at most
`MAX_STEP_RAD` per piece).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile.chords import Chords, prepare_chords
from fivebar_host.compile.layers import Sections
from fivebar_host.compile.model import MAX_STEP_RAD
from fivebar_host.compile.modes import merge_intervals, plan_path_modes
from fivebar_host.compile.place import Home, Placed, Setup, fail, where_at
from fivebar_host.errors import Where
from fivebar_host.toolpath.segment import CheckFailedError, Intervals, PoseChecker, refine
from kinematics.arrays import FloatArray


@dataclass(frozen=True)
class Routed:
    """The job's paths (`Chords`), the working mode of each, and the planned joint path of
    each working-mode change by the travel that runs it (travel j goes into path j)."""

    ch: Chords
    path_mode: NDArray[np.str_]
    changes: Mapping[int, FloatArray]
    sections: Sections | None = None  # pen-change stops (`compile.layers`)

    @property
    def npath(self) -> int:
        return int(self.ch.offsets.shape[0] - 1)

    def per_path(self) -> Routed:
        """Only the per-path part (the vertices and chords are dropped: after the requested
        geometry is taken, timing and finishing need the paths alone)."""
        return replace(self, ch=self.ch.per_path())


@dataclass(frozen=True)
class Solved:
    """One `PoseChecker` per working mode in use, the checked joint angles of every vertex
    (M, 2), and the refined draw intervals in job order."""

    checkers: dict[str, PoseChecker]
    th_v: FloatArray
    iv: Intervals

    @property
    def checker(self) -> PoseChecker:
        """For forward kinematics (the same in every working mode)."""
        return next(iter(self.checkers.values()))

    def summarised(self) -> Solved:
        """The checkers, the intervals' smallest margins and largest deviation as one row
        each (what finishing reads) and what assembling the segments reads (each interval's
        chord, part σ_a … σ_b of it and end angles), without the per-vertex angles: once the
        travel is planned, the rest of the per-interval arrays can go."""
        iv = self.iv
        margin = (iv.min_margin.min(axis=0, keepdims=True) if iv.min_margin.size
                  else iv.min_margin)
        dev = iv.dev_mm.max(keepdims=True) if iv.dev_mm.size else iv.dev_mm
        return Solved(self.checkers, np.zeros((0, 2)),
                      Intervals(iv.chord, iv.sa, iv.sb, np.zeros((0, 2)), iv.thb, margin, dev))

    def per_path(self) -> Solved:
        """`summarised` without any per-interval array (after the segments are assembled
        and the requested geometry is taken)."""
        s = self.summarised()
        z = np.zeros((0, 2))
        return Solved(self.checkers, z, replace(s.iv, chord=np.zeros(0, np.int64),
                                                sa=np.zeros(0), sb=np.zeros(0), thb=z))


def route(su: Setup, placed: Placed, home: Home, keep_order: bool,
          plan_modes: bool, simplify: bool = True, sections: Sections | None = None) -> Routed:
    """Order and join the paths from the homed pen position (section by section with
    pen-change stops); without `plan_modes` every path is drawn in `su.mode`, with it the
    modes (and changes) come from `plan_modes`."""
    ch = prepare_chords(placed.drawing, placed.poly, su.tol, su.tol_f, home.pt, keep_order,
                         simplify, None if sections is None else sections.of_stroke)
    changes: dict[int, FloatArray] = {}
    if plan_modes:
        first = ch

        def where_of(p: int, point: FloatArray) -> Where:
            return where_at(placed.drawing.file, placed.drawing, placed.pl,
                            (float(point[0]), float(point[1])),
                            int(first.vert_prim[first.offsets[p]]))

        ch, path_mode, changes = plan_path_modes(ch, su.fb, home.th[0], home.mode, su.asm,
                                             su.min1, su.min2, su.limits, where_of)
    else:
        path_mode = np.full(ch.offsets.shape[0] - 1, su.mode)
    return Routed(ch=ch, path_mode=path_mode, changes=changes, sections=sections)


def solve(su: Setup, placed: Placed, routed: Routed) -> Solved:
    """Checked inverse kinematics of every vertex, in its path's working mode, then every
    chord refined in joint space within its budget (intervals merged back into job order)."""
    ch, path_mode = routed.ch, routed.path_mode
    checkers = {m: PoseChecker(su.fb, m, su.assembly, su.min1, su.min2, su.limits)
                for m in dict.fromkeys(path_mode.tolist())}
    th_v = _vertex_angles(su, placed, ch, path_mode, checkers)
    a = ch.chord_from
    chord_mode = path_mode[ch.path_of_chord]
    parts: list[Intervals] = []
    for m, chk in checkers.items():
        cs = np.flatnonzero(chord_mode == m)
        try:
            r = _refine_blocks(chk, ch, th_v, cs, summarise=len(checkers) == 1)
        except CheckFailedError as cf:
            c = int(cs[cf.index])
            raise fail(su, placed, cf, int(ch.prim[c]) if ch.prim[c] >= 0
                       else int(ch.vert_prim[a[c]]), in_mode=m) from None
        parts.append(r if len(checkers) == 1 else replace(r, chord=cs[r.chord]))
    return Solved(checkers=checkers, th_v=th_v, iv=merge_intervals(parts))


def _vertex_angles(su: Setup, placed: Placed, ch: Chords, path_mode: NDArray[np.str_],
                   checkers: dict[str, PoseChecker]) -> FloatArray:
    """Checked inverse kinematics of every vertex (M, 2) in its path's working mode (with one
    mode, of all the vertices at once, without index copies)."""
    if len(checkers) == 1:
        ((m, chk),) = checkers.items()
        try:
            return chk.inverse(ch.pts)
        except CheckFailedError as cf:
            raise fail(su, placed, cf, int(ch.vert_prim[cf.index]), in_mode=m) from None
    vert_mode = np.repeat(path_mode, np.diff(ch.offsets))
    th_v = np.empty_like(ch.pts)
    for m, chk in checkers.items():
        idx = np.flatnonzero(vert_mode == m)
        try:
            th_v[idx] = chk.inverse(ch.pts[idx], idx)
        except CheckFailedError as cf:
            raise fail(su, placed, cf, int(ch.vert_prim[cf.index]), in_mode=m) from None
    return th_v


def _summary(iv: Intervals) -> Intervals:
    """`iv` without its start angles, its margins and deviations reduced to their smallest
    margins and largest deviation (one row each; empty stays empty), as `Solved.summarised`
    reads them: the minimum of the blocks' minima is the minimum of all."""
    margin = iv.min_margin.min(axis=0, keepdims=True) if iv.min_margin.size else iv.min_margin
    dev = iv.dev_mm.max(keepdims=True) if iv.dev_mm.size else iv.dev_mm
    return replace(iv, tha=np.zeros((0, 2)), min_margin=margin, dev_mm=dev)


#: Chords refined at a time: every chord is refined on its own, so blocks give the same
#: intervals as one pass while the refinement's temporaries (samples, checks, candidate
#: pieces: a few hundred bytes a chord) stay bounded on large drawings.
REFINE_BLOCK = 1 << 16


def _refine_blocks(chk: PoseChecker, ch: Chords, th_v: FloatArray,
                   cs: NDArray[np.int64], summarise: bool = False) -> Intervals:
    """`refine` of chords `cs` in blocks of `REFINE_BLOCK`; chord ids (and a failure's
    index) are positions in `cs`, as one call of `refine` would give. `summarise` (one
    working mode, no merge follows): each block keeps only what `Solved.summarised` keeps
    (no start angles, its smallest margins and largest deviation as one row), so the
    per-interval arrays that nothing reads are never held for the whole job."""
    a = ch.chord_from
    out: list[Intervals] = []
    for i in range(0, max(cs.shape[0], 1), REFINE_BLOCK):
        b = cs[i:i + REFINE_BLOCK]
        try:
            r = refine(chk, ch.pts[a[b]], ch.pts[a[b] + 1], th_v[a[b]], th_v[a[b] + 1],
                       ch.tol_i[b], MAX_STEP_RAD)
        except CheckFailedError as cf:
            cf.index += i
            raise
        if i:
            r = replace(r, chord=r.chord + i)
        out.append(_summary(r) if summarise else r)
    if len(out) == 1:
        return out[0]
    # field by field, each block's part dropped once copied (not every field twice at once)
    parts = [{f.name: getattr(r, f.name) for f in fields(Intervals)} for r in out]
    del out
    return Intervals(*(np.concatenate([p.pop(f.name) for p in parts])
                       for f in fields(Intervals)))
