"""What the SVG reader keeps of each drawn element's paint, per source, for fills and hidden
lines: its fill rule (none when the fill is not painted), whether its stroke is painted, and
— for an element under a clip path, mask or clipping viewport — the visible part of its fill
as a region (the reader knows the clip; the drawing only keeps the clipped outline).

Paint order is source order: the reader adds sources in document order, an element's
markers after it (SVG 2 §13.3: fill, then stroke, then markers), so a later source paints
over an earlier one.

Regions of unclipped elements are not built here: they follow from the element's strokes in
the drawing (its subpaths, each closed implicitly when filled, SVG 2 §13.4.2), which the fill
stage builds only when hatching or hiding is asked for (`fill.regions`), so reading a
drawing costs the same as before.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry.base import BaseGeometry

from kinematics.arrays import BoolArray, FloatArray

#: Fill rules by code (0: the fill is not painted, or the element has no interior).
NO_FILL, NONZERO, EVENODD = 0, 1, 2
RULES = {"nonzero": NONZERO, "evenodd": EVENODD}


@dataclass
class PaintTable:
    """Per source (index into `Drawing.sources`): `rule` (`NO_FILL`, `NONZERO`, `EVENODD`),
    `stroked` (its stroke is painted; False for a fill-only shape), and `clipped`: the
    visible fill region of a filled element under a clip (drawing frame); an unclipped
    element's region follows from its strokes."""

    rule: NDArray[np.int8]
    stroked: BoolArray
    clipped: dict[int, BaseGeometry] = field(default_factory=dict)
    #: per source: its fill is the paper's colour (white): it hides, it is not hatched
    paper: BoolArray = field(default_factory=lambda: np.zeros(0, bool))

    @staticmethod
    def empty(n_sources: int) -> PaintTable:
        """Nothing filled, everything stroked (a G-code drawing, or text)."""
        return PaintTable(np.zeros(n_sources, np.int8), np.ones(n_sources, bool), {},
                          np.zeros(n_sources, bool))

    def extended(self, n_sources: int) -> PaintTable:
        """The table grown to `n_sources` (new sources: not filled, stroked)."""
        n = n_sources - self.rule.shape[0]
        if n <= 0:
            return self
        return PaintTable(np.concatenate((self.rule, np.zeros(n, np.int8))),
                          np.concatenate((self.stroked, np.ones(n, bool))), self.clipped,
                          np.concatenate((self.paper, np.zeros(n, bool))))

    def transformed(self, a: FloatArray, b: FloatArray) -> PaintTable:
        """The table with its regions mapped by x ↦ a·x + b."""
        if not self.clipped:
            return self
        m = np.asarray(a, dtype=np.float64)
        off = np.asarray(b, dtype=np.float64)
        keys = list(self.clipped)
        geoms = shapely.transform(np.array([self.clipped[k] for k in keys], dtype=object),
                                  lambda xy: xy @ m.T + off)
        return PaintTable(self.rule, self.stroked, dict(zip(keys, geoms, strict=True)),
                          self.paper)


class PaintRecorder:
    """Collects the paint of each source while the reader walks (`record`), then the table
    (`table`)."""

    def __init__(self) -> None:
        self.rule: dict[int, int] = {}
        self.unstroked: set[int] = set()
        self.clipped: dict[int, BaseGeometry] = {}
        self.paper: set[int] = set()

    def record(self, source: int, rule: int, stroked: bool,
               clipped: BaseGeometry | None = None, paper: bool = False) -> None:
        """One drawn element's paint (`rule` NO_FILL when its fill is not painted; `paper`:
        its fill is white)."""
        if rule != NO_FILL:
            self.rule[source] = rule
            if paper:
                self.paper.add(source)
        if not stroked:
            self.unstroked.add(source)
        if clipped is not None and rule != NO_FILL:
            self.clipped[source] = clipped

    def table(self, n_sources: int) -> PaintTable:
        t = PaintTable.empty(n_sources)
        for s, r in self.rule.items():
            t.rule[s] = r
        for s in self.unstroked:
            t.stroked[s] = False
        t.clipped = dict(self.clipped)
        for s in self.paper:
            t.paper[s] = True
        return t
