"""Text decorations drawn as single pen lines: `text-decoration` underline, overline and
line-through (CSS Text Decoration 3).

An element's decoration is drawn under (over, through) its own text and its descendants'
(§2: decorations propagate), at the position its own face gives — `underline-position`,
`overline-position`, `strikethrough-position` of the SVG font (defaults: 0.1 em below the
baseline, the ascent, half the x-height) — from its own baseline, so a superscript inside an
underlined element does not move the line (§2.2). A line runs from the first character's
position to the last one's advance, one line per run of characters that sit on one line: a
new text chunk, a change of y, a rotated glyph or text on a path (not decorated: noted)
ends a run. A pen has one width: `text-decoration-thickness` and styles (wavy, double …)
are drawn as one straight line.
"""

from __future__ import annotations

from collections.abc import Callable

from fivebar_host.toolpath.fonts.library import Face
from fivebar_host.toolpath.svg import textlayout as tl
from fivebar_host.toolpath.svg.textcontent import Content, own_decoration
from kinematics.arrays import FloatArray

Line = tuple[int, tuple[float, float, float, float]]


def decoration_lines(c: Content, lay: tl.Layout, faces: Callable[[int], list[Face]],
                     on: FloatArray) -> tuple[list[Line], bool]:
    """Each decorated run's line in user units with the source line of its element, and
    whether some decorated text lies on a path (not decorated)."""
    out: list[Line] = []
    on_path = False
    for node, k, a, b in c.ranges:
        kinds = own_decoration(c.spans[k].spec)
        if not kinds or b <= a:
            continue
        span = c.spans[k]
        if not span.painted:
            continue
        f = faces(k)[0].font
        scale = span.lengths.font_px / f.units_per_em
        base = tl.baseline_offset(c, k, faces)
        offsets = [{"underline": -f.underline_position, "overline": -f.overline_position,
                    "line-through": -f.strikethrough_position}[kd] * scale for kd in kinds]
        for i0, i1 in _runs(c, lay, a, b):
            if c.spans[c.span[i0]].path >= 0:
                on_path = True
                continue
            x0, x1 = float(lay.x[i0]), float(lay.x[i1] + lay.advance[i1])
            y = float(lay.y[i0]) + base
            if x1 > x0:
                out.extend((node.line, (x0, y + o, x1, y + o)) for o in offsets)
    return out, on_path


def _runs(c: Content, lay: tl.Layout, a: int, b: int) -> list[tuple[int, int]]:
    """[first, last] characters of each run in [a, b) (module doc)."""
    runs: list[tuple[int, int]] = []
    start = a
    for i in range(a + 1, b + 1):
        end = i == b or lay.chunk_start[i] or lay.y[i] != lay.y[i - 1] or \
            lay.rotate[i] != 0 or lay.rotate[i - 1] != 0 or \
            c.spans[c.span[i]].path != c.spans[c.span[i - 1]].path
        if end:
            runs.append((start, i - 1))
            start = i
    return runs
