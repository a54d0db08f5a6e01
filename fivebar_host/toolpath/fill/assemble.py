"""The drawing rebuilt with its hatches and without its hidden parts, in paint order.

Each source's strokes (cut where hidden) come first, then the hatch lines of its fill as
strokes of a new source with role "hatch" (same id, line and layer, so layers, pen-change
stops and messages treat them as the element's), so document order — which layers and
sections follow — is kept. `FillResult` says what was done, for the dry run and the preview.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from fivebar_host.toolpath.fill.cuts import Visible, sub_primitives
from fivebar_host.toolpath.geometry import LINE, Drawing, SourceInfo
from kinematics.arrays import FloatArray, IntArray


@dataclass(frozen=True)
class FillResult:
    """What hatching and hidden-line removal did (lengths in the drawing's frame, mm):
    hatch lines and the pen-down links between them, the hatched regions (simple ones: one
    ring, no hole) and pen-down runs, the stroke length hidden under later fills, the outline
    length of fill-only shapes not drawn (`--hiding`), the hidden pieces as segments (H, 2, 2)
    for the preview, and one line each about the settings (`notes`)."""

    hatch_mm: float = 0.0
    link_mm: float = 0.0
    regions: int = 0
    simple_regions: int = 0
    hatch_runs: int = 0
    hatch_runs_simple: int = 0
    hidden_mm: float = 0.0
    unstroked_mm: float = 0.0
    hiding: bool = False
    hidden: FloatArray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    notes: tuple[str, ...] = ()
    #: the job's hatch in words ("0.4 mm at 45°"; "" without hatching)
    hatch: str = ""
    #: each hatch source's element: {hatch source index: element source index}
    hatch_of: dict[int, int] = field(default_factory=dict)

    def transformed(self, a: FloatArray, b: FloatArray) -> FillResult:
        """The hidden pieces mapped by x ↦ a·x + b (lengths are kept: the placement's
        figures are measured where they were made, in machine mm)."""
        h = self.hidden @ np.asarray(a, dtype=np.float64).T + np.asarray(b, dtype=np.float64)
        return replace(self, hidden=h)


@dataclass
class HatchStrokes:
    """Hatch runs of one source: polylines (each (M, 2), M ≥ 2), and runs of exact
    primitives (kinds (n,), params (n, 8): joint-iso arcs and their links)."""

    source: int
    runs: list[FloatArray]
    prims: list[tuple[NDArray[np.int8], FloatArray]] = field(default_factory=list)

    def all_runs(self) -> list[tuple[NDArray[np.int8], FloatArray]]:
        """Every run as primitives (a polyline's chords as lines)."""
        out = list(self.prims)
        for run in self.runs:
            p = np.zeros((run.shape[0] - 1, 8))
            p[:, 0:2], p[:, 2:4] = run[:-1], run[1:]
            out.append((np.full(p.shape[0], LINE, np.int8), p))
        return out


def rebuild(d: Drawing, vis: Visible, hatches: list[HatchStrokes], result: FillResult
            ) -> Drawing:
    """A drawing of the visible pieces and the hatch strokes (module doc)."""
    kind = d.kind[vis.prim]
    params = sub_primitives(kind, d.params[vis.prim], vis.a, vis.b)
    new_id = np.cumsum(vis.new_stroke) - 1
    first = np.flatnonzero(vis.new_stroke)
    old_stroke = d.stroke[vis.prim][first]
    src = d.stroke_source[old_stroke].astype(np.int64)
    # hatch strokes: LINE primitives, one stroke per run, under a new "hatch" source
    sources = list(d.sources)
    h_kind: list[NDArray[np.int8]] = []
    h_params: list[FloatArray] = []
    h_stroke_n: list[int] = []
    h_src: list[int] = []
    h_parent: list[int] = []
    h_line: list[int] = []
    for h in hatches:
        el = d.sources[h.source]
        hs = len(sources)
        sources.append(SourceInfo(hs, el.ident, el.line, el.tag, el.layer, role="hatch"))
        for k, p in h.all_runs():
            h_kind.append(k)
            h_params.append(p)
            h_stroke_n.append(p.shape[0])
            h_src.append(hs)
            h_parent.append(h.source)
            h_line.append(el.line or 0)
    n_out = int(first.shape[0])
    n_h = len(h_stroke_n)
    # strokes in paint order: by source (hatch strokes by their element), outline first
    key_src = np.concatenate((src, np.array(h_parent, dtype=np.int64)))
    key_sub = np.concatenate((np.zeros(n_out, np.int64), np.ones(n_h, np.int64)))
    order = np.lexsort((np.arange(n_out + n_h), key_sub, key_src))
    counts = np.concatenate((np.bincount(new_id, minlength=n_out) if n_out else
                             np.zeros(0, np.int64), np.array(h_stroke_n, dtype=np.int64)))
    all_kind = np.concatenate((kind, *h_kind))
    all_params = np.concatenate([params, *h_params]) if h_params else params
    all_line = np.concatenate((d.line[vis.prim].astype(np.int64),
                               np.repeat(np.array(h_line, dtype=np.int64),
                                         np.array(h_stroke_n, dtype=np.int64))))
    starts = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)
    prim_order = _ranges(starts[order], counts[order])
    stroke_src = np.concatenate((src, np.array(h_src, dtype=np.int64)))[order]
    power = np.concatenate((d.stroke_power[old_stroke], np.ones(n_h)))[order]
    feed = np.concatenate((d.stroke_feed_mm_s[old_stroke], np.full(n_h, np.nan)))[order]
    out_stroke = np.repeat(np.arange(n_out + n_h), counts[order])
    paint = None if d.paint is None else d.paint.extended(len(sources))
    result = replace(result, hatch_of={len(d.sources) + i: h.source
                                       for i, h in enumerate(hatches)})
    return Drawing(d.file, all_kind[prim_order], all_params[prim_order], out_stroke,
                   all_line[prim_order], stroke_src, power, feed, sources, d.page_height_mm,
                   d.page_size_mm, d.warnings, [], d.texts, paint, result)


def _ranges(starts: IntArray, counts: IntArray) -> IntArray:
    """Concatenated index ranges starts[i] … starts[i] + counts[i] − 1."""
    total = int(counts.sum())
    return np.repeat(starts, counts) + (np.arange(total) - np.repeat(np.cumsum(counts) - counts,
                                                                      counts))
