"""Order and join: the flattened strokes of a placed drawing become the job's paths, as one
array of vertices in machine mm with per-chord provenance and tolerance budgets (`Chords`).

Paths are ordered (nearest neighbour from the homed pen position, `toolpath.order`), reversed
where that shortens the travel, and consecutive paths whose gap is below the tolerance and
whose settings match are joined by a short pen-down bridge. Each chord's interpolation budget
tol_i follows the tolerance budget in `fivebar_host.compile.job`: tol − tol_f for chords of
curves, tol for straight input lines, tol − gap/2 for a bridge.

Before that, runs of straight input lines are simplified (`toolpath.simplify`, unless
switched off with `--no-simplify`): a chord that replaces several input lines is within
ε = tol_f of them, so its budget is tol − ε, and it records the range of primitives it
covers (`prim_first` … `prim`) so validation measures against the original lines.

With pen-change stops (`compile.layers`) each section of the drawing is ordered on its own,
the sections in document order, and no path joins across a section boundary.

A drawing with dwells (G-code `G4`, `geometry.Dwell`) keeps its file order and directions
(a dwell happens at a stroke's start or end, at its time in the file), and a path never
joins across a dwell, so every dwell stays at its path's start or end.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from fivebar_host.toolpath import order
from fivebar_host.toolpath.geometry import LINE, Drawing, Dwell, Polylines
from fivebar_host.toolpath.simplify import simplify_polylines
from kinematics.arrays import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class Chords:
    """The ordered, joined polylines in machine mm with per-chord provenance."""

    pts: FloatArray  # (M, 2)
    offsets: IntArray  # (P+1,)
    vert_prim: IntArray  # (M,) primitive the vertex lies on (for messages)
    chord_from: IntArray  # (C,) vertex index a of chord a → a+1
    prim: IntArray  # (C,) primitive, −1 for a join bridge
    prim_first: IntArray  # (C,) first primitive covered (< prim: simplified run of lines)
    tlo: FloatArray
    thi: FloatArray
    rev: BoolArray
    tol_i: FloatArray
    path_of_chord: IntArray  # (C,) job path
    path_source: IntArray  # (P,) first source element
    path_reversed: BoolArray
    power: FloatArray  # (P,) fraction
    feed: FloatArray  # (P,) mm/s or NaN
    joined: int
    travel_before: float
    travel_after: float
    simplified: int = 0  # input vertices removed by the simplification
    #: the drawing's dwells with `stroke` replaced by the job path they start or end
    dwells: tuple[Dwell, ...] = field(default_factory=tuple)
    #: (P,) the section of each path (`compile.layers`; all 0 without pen-change stops)
    path_section: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))

    def per_path(self) -> Chords:
        """The per-path arrays only (vertices and chords emptied, `offsets` kept so the
        number of paths stays): what timing and finishing read."""
        zi, zf = np.zeros(0, np.int64), np.zeros(0)
        return replace(self, pts=np.zeros((0, 2)), vert_prim=zi, chord_from=zi, prim=zi,
                       prim_first=zi, tlo=zf, thi=zf, rev=np.zeros(0, bool), tol_i=zf,
                       path_of_chord=zi)


def _order(starts: FloatArray, ends: FloatArray, start: FloatArray, keep_order: bool,
           path_sec: IntArray | None) -> order.Order:
    """`order.order_paths` over the whole drawing, or section by section in section order
    (each from where the previous one ended; the last returns to `start`)."""
    if path_sec is None:
        return order.order_paths(starts, ends, start, start, keep_order=keep_order)
    idx_all: list[IntArray] = []
    rev_all: list[np.ndarray] = []
    before = after = 0.0
    pen = start
    secs = np.unique(path_sec)
    for i, s in enumerate(secs.tolist()):
        idx = np.flatnonzero(path_sec == s)
        last = i == secs.shape[0] - 1
        od = order.order_paths(starts[idx], ends[idx], pen, start if last else None,
                               keep_order=keep_order)
        idx_all.append(idx[od.order])
        rev_all.append(od.reverse)
        before += od.travel_before_mm
        after += od.travel_after_mm
        k = int(idx[od.order[-1]])
        pen = starts[k] if od.reverse[-1] else ends[k]
    return order.Order(np.concatenate(idx_all), np.concatenate(rev_all), before, after)


def prepare_chords(drawing: Drawing, poly: Polylines, tol: float, tol_f: float,
                    start: FloatArray, keep_order: bool, simplify: bool = True,
                    stroke_section: IntArray | None = None) -> Chords:
    """Simplify runs of lines (ε = tol_f), order, reverse and join the flattened strokes;
    per-chord provenance and budgets. `stroke_section` (per drawing stroke, `compile.layers`)
    keeps the sections apart."""
    simp = simplify_polylines(poly, drawing.kind, tol_f if simplify else 0.0)
    poly = simp.poly
    pts0 = poly.points
    offs = poly.offsets
    starts = pts0[offs[:-1]]
    ends = pts0[offs[1:] - 1]
    path_sec0 = None if stroke_section is None else stroke_section[poly.stroke]
    od = _order(starts, ends, start, keep_order or bool(drawing.dwells), path_sec0)
    lens = np.diff(offs)
    ordered_lens = lens[od.order]
    # Vertex index map in the new order (reversed paths walk their vertices backwards).
    idx = _vertex_order(offs, od.order, od.reverse, ordered_lens)
    pts = pts0[idx]
    new_offs = np.concatenate(([0], np.cumsum(ordered_lens))).astype(np.int64)
    m = pts.shape[0]
    stroke = poly.stroke[od.order]
    power = drawing.stroke_power[stroke]
    feed = drawing.stroke_feed_mm_s[stroke]
    source = drawing.stroke_source[stroke]
    # Join consecutive paths whose gap is below the tolerance and whose settings match.
    gap = np.hypot(*(pts[new_offs[1:-1]] - pts[new_offs[1:-1] - 1]).T)
    same = (power[1:] == power[:-1]) & ((feed[1:] == feed[:-1])
                                        | (np.isnan(feed[1:]) & np.isnan(feed[:-1])))
    path_sec = (np.zeros(stroke.shape[0], dtype=np.int64) if path_sec0 is None
                else path_sec0[od.order])
    join = (gap < tol) & same & ~_dwell_between(drawing, stroke) & (
        path_sec[1:] == path_sec[:-1])
    bridge_at = new_offs[1:-1][join] - 1  # vertex that ends path p and starts the bridge
    is_end = np.zeros(m, dtype=bool)
    is_end[new_offs[1:] - 1] = True
    is_end[bridge_at] = False
    keep_path = np.concatenate(([True], ~join))
    new_path_of_old = np.cumsum(keep_path) - 1
    joined_offs = np.concatenate((new_offs[:-1][keep_path], [m])).astype(np.int64)
    chord_from = np.flatnonzero(~is_end)
    del is_end
    # Per-chord metadata (chord v → v+1 in the new order): forward, the chord lies on
    # prim[idx[v+1]] over [t0, t] of idx[v+1]; reversed, on idx[v]. Bridges: no primitive.
    revv = np.repeat(od.reverse, ordered_lens)[chord_from]
    owner = np.where(revv, idx[chord_from], idx[np.minimum(chord_from + 1, m - 1)])
    cp = poly.prim[owner]
    cf = simp.prim_first[owner]
    c_tlo, c_thi = poly.t0[owner], poly.t[owner]
    del owner
    bridge = np.searchsorted(chord_from, bridge_at)  # bridges among the chords
    cp[bridge] = -1
    cf[bridge] = -1
    bt = np.full(chord_from.shape[0], np.nan)
    bt[bridge] = tol - gap[join] / 2
    # Drop zero-length chords by merging their vertices (keeps paths ≥ 1 chord if possible).
    kind = drawing.kind
    is_line = np.zeros(chord_from.shape[0], dtype=bool)
    is_line[cp >= 0] = kind[cp[cp >= 0]] == LINE
    tol_i = np.where(is_line, np.where(cf < cp, tol - tol_f, tol), tol - tol_f)
    tol_i = np.where(np.isnan(bt), tol_i, bt)
    path_of_chord = np.searchsorted(new_offs, chord_from, side="right") - 1
    return Chords(pts=pts, offsets=joined_offs, vert_prim=poly.prim[idx],
                   chord_from=chord_from, prim=cp, prim_first=cf, tlo=c_tlo,
                   thi=c_thi, rev=revv, tol_i=tol_i,
                   path_of_chord=new_path_of_old[path_of_chord],
                   path_source=source[keep_path], path_reversed=od.reverse[keep_path],
                   power=power[keep_path], feed=feed[keep_path], joined=int(join.sum()),
                   travel_before=od.travel_before_mm, travel_after=od.travel_after_mm,
                   simplified=simp.removed,
                   dwells=_path_dwells(drawing, stroke, new_path_of_old),
                   path_section=path_sec[keep_path])


def _vertex_order(offs: IntArray, path_order: IntArray, reverse: BoolArray,
                  ordered_lens: IntArray) -> IntArray:
    """The old index of every vertex of the ordered paths (`path_order`, each walked
    backwards where `reverse`)."""
    base = np.repeat(offs[:-1][path_order], ordered_lens)
    k = np.arange(int(ordered_lens.sum())) - np.repeat(np.cumsum(ordered_lens) - ordered_lens,
                                                       ordered_lens)
    rev = np.repeat(reverse, ordered_lens)
    back = np.repeat(ordered_lens, ordered_lens) - 1 - k
    back += base  # base + len − 1 − k, as written out
    k += base
    return np.where(rev, back, k)


def _dwell_between(drawing: Drawing, stroke: IntArray) -> BoolArray:
    """For consecutive ordered strokes: whether a dwell ends the first or starts the
    second (such paths are not joined)."""
    n = drawing.n_strokes
    after = np.zeros(n + 1, dtype=bool)
    before = np.zeros(n + 1, dtype=bool)
    for d in drawing.dwells:
        (after if d.after else before)[d.stroke] = True
    return np.asarray(after[stroke[:-1]] | before[stroke[1:]], dtype=bool)


def _path_dwells(drawing: Drawing, stroke: IntArray,
                 path_of: IntArray) -> tuple[Dwell, ...]:
    """The dwells on job paths (order kept: a stroke's place in `stroke` is its path before
    joining, `path_of` maps it to the joined path)."""
    if not drawing.dwells:
        return ()
    where = np.full(drawing.n_strokes, -1, dtype=np.int64)
    where[stroke] = np.arange(stroke.shape[0])
    if (where[[d.stroke for d in drawing.dwells]] < 0).any():
        raise RuntimeError("a dwell's stroke has no path")
    return tuple(replace(d, stroke=int(path_of[where[d.stroke]])) for d in drawing.dwells)
