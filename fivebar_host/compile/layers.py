"""Layers and pen-change pauses: which strokes belong to which Inkscape layer, where the plot
stops for a pen change, and where those stops fall in the compiled job.

A layer is a run of consecutive strokes (document order) with the same layer name (the SVG
reader records each element's innermost `inkscape:groupmode="layer"` label, else its id).
The job stops for a pen change before a layer when `--layer-pause` is given (between
layers, not before the first) or when the layer's name starts with "!" (AxiDraw's
convention, also before the first layer); `--no-pause` switches both off. The stops cut the
drawing into *sections*: paths are ordered and joined within a section only, sections are
drawn in document order, and the planner comes to rest at every section boundary, so the
pen can go up there and the machine can wait (`compile.chords`, `compile.timing`). Without
any stop there are no sections and the whole drawing is ordered at once, as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host.compile.model import LayerPause
from fivebar_host.toolpath.geometry import Drawing
from kinematics.arrays import BoolArray, IntArray

#: The name a layer report uses for strokes outside every Inkscape layer.
NO_LAYER = "(no layer)"
#: A layer whose name starts with this pauses before it (AxiDraw's convention).
PAUSE_MARK = "!"


@dataclass(frozen=True)
class Sections:
    """The pause-separated sections of a drawing: per drawing stroke its section (−1 for
    strokes not drawn), and per section the first layer's name and 1-based number among
    the `n_layers` layers, and whether the section starts with a stop (`pause`; section 0
    only for a "!" layer)."""

    of_stroke: IntArray
    names: tuple[str, ...]
    numbers: tuple[int, ...]
    pause: tuple[bool, ...]
    n_layers: int

    @property
    def count(self) -> int:
        return len(self.names)


def stroke_layers(drawing: Drawing) -> list[str]:
    """The layer name of every stroke of `drawing` (`NO_LAYER` outside every layer)."""
    names = [s.layer for s in drawing.sources]
    return [names[int(i)] or NO_LAYER for i in drawing.stroke_source.tolist()]


def sections(drawing: Drawing, strokes: IntArray, layer_pause: bool,
             no_pause: bool) -> Sections | None:
    """The sections of the drawn `strokes` (the strokes that have a polyline), or None
    when the job has no stop (module doc)."""
    if no_pause or drawing.n_strokes == 0:
        return None
    layer = stroke_layers(drawing)
    drawn = np.unique(np.asarray(strokes, dtype=np.int64))
    run_of = np.full(drawing.n_strokes, -1, dtype=np.int64)
    run_names: list[str] = []
    for s in drawn.tolist():
        if not run_names or layer[s] != run_names[-1]:
            run_names.append(layer[s])
        run_of[s] = len(run_names) - 1
    stop = [name.startswith(PAUSE_MARK) or (layer_pause and i > 0)
            for i, name in enumerate(run_names)]
    if not any(stop):
        return None
    sec_of_run = np.cumsum([i > 0 and s for i, s in enumerate(stop)], dtype=np.int64)
    firsts = [0] + [i for i in range(1, len(stop)) if stop[i]]
    of_stroke = np.where(run_of >= 0, sec_of_run[np.maximum(run_of, 0)], -1)
    return Sections(of_stroke=of_stroke, names=tuple(run_names[i] for i in firsts),
                    numbers=tuple(i + 1 for i in firsts), pause=tuple(stop[i] for i in firsts),
                    n_layers=len(run_names))


def section_of_segments(path_section: IntArray, seg_path: IntArray) -> IntArray:
    """Per job segment its section: a segment belongs to the path it draws or travels to;
    the park move (path = number of paths) to the last section."""
    ext = np.concatenate((path_section, path_section[-1:] if path_section.size else [0]))
    return np.asarray(ext[seg_path], dtype=np.int64)


def section_stops(path_section: IntArray, seg_path: IntArray) -> BoolArray:
    """Per job segment: True where the next segment starts another section (the planner
    must arrive at rest there, as before a dwell)."""
    sec = section_of_segments(path_section, seg_path)
    stop = np.zeros(sec.shape[0], dtype=bool)
    stop[:-1] = sec[1:] != sec[:-1]
    return stop


def layer_pauses(sec: Sections | None, path_section: IntArray,
                 seg_path: IntArray) -> tuple[LayerPause, ...]:
    """The job's pen-change stops: before the first segment of every section that starts
    with one (the travel into its first path, or segment 0 for the first section)."""
    if sec is None:
        return ()
    seg_sec = section_of_segments(path_section, seg_path)
    out: list[LayerPause] = []
    for s in range(sec.count):
        if not sec.pause[s]:
            continue
        at = np.flatnonzero(seg_sec == s)
        if at.size:
            out.append(LayerPause(0 if s == 0 else int(at[0]), sec.names[s], sec.numbers[s],
                                  sec.n_layers))
    return tuple(out)


def break_switches(tool_on: BoolArray, pauses: tuple[LayerPause, ...]) -> int:
    """Pen-change stops that fall inside a run of segments with the tool on: each costs an
    extra pen up and down (the pen always goes up for a stop)."""
    n = tool_on.shape[0]
    return sum(1 for p in pauses if 0 < p.segment < n and tool_on[p.segment - 1]
               and tool_on[p.segment])
