"""Lettering without an SVG editor: lines of text as an SVG document (`fivebar text`).

`lettering_svg` writes the lines as one SVG `<text>` (a `<tspan>` per line, the font, size,
weight, style, anchor and letter-spacing as attributes), in a page sized to the text's
drawn extent plus a margin, user units in mm. Read back by the SVG reader it draws exactly
what `fivebar plot` draws for any `<text>`, and it stays editable. `strokes_svg` writes a
drawing's strokes as `<path>` elements instead: the single strokes themselves, for tools
that do not know fivebar's fonts (vpype, Inkscape, the AxiDraw software).
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from fivebar_host.errors import InputError
from fivebar_host.toolpath.extent import bbox
from fivebar_host.toolpath.fonts.library import TextConfig
from fivebar_host.toolpath.geometry import (
    ARC,
    CUBIC,
    Drawing,
    Polylines,
    flatten,
    start_points,
)
from fivebar_host.toolpath.svg.reader import read_svg
from kinematics.arrays import FloatArray, IntArray

#: Most characters `fivebar text` lays out (a plotter label, not a book).
MAX_CHARS = 100_000


@dataclass(frozen=True)
class Lettering:
    """What to letter: the lines, the CSS font-family, size (mm), bold, italic, anchor
    (start, middle, end), line height (a multiple of the size), letter-spacing (mm) and the
    page margin (mm)."""

    lines: tuple[str, ...]
    family: str = "sans-serif"
    size_mm: float = 10.0
    bold: bool = False
    italic: bool = False
    anchor: str = "start"
    line_height: float = 1.25
    letter_spacing_mm: float = 0.0
    margin_mm: float = 5.0


def _text_element(lt: Lettering, file: str) -> str:
    if sum(len(s) for s in lt.lines) > MAX_CHARS:
        raise InputError(f"more than {MAX_CHARS:,} characters to letter", file)
    attrs = {"font-family": lt.family, "font-size": f"{lt.size_mm:g}",
             "text-anchor": lt.anchor}
    if lt.bold:
        attrs["font-weight"] = "bold"
    if lt.italic:
        attrs["font-style"] = "italic"
    if lt.letter_spacing_mm:
        attrs["letter-spacing"] = f"{lt.letter_spacing_mm:g}"
    spans = "".join(f'<tspan x="0" y="{i * lt.line_height * lt.size_mm:g}">{escape(s)}</tspan>'
                    for i, s in enumerate(lt.lines))
    a = " ".join(f"{k}={quoteattr(v)}" for k, v in attrs.items())
    return f'<text xml:space="preserve" {a}>{spans}</text>'


def lettering_svg(lt: Lettering, text: TextConfig | None = None,
                  file: str = "<lettering>") -> str:
    """The SVG document of `lt` (module doc); `text`: the profile's font choices; `file`
    names the document in messages."""
    element = _text_element(lt, file)
    probe = (f'<svg xmlns="http://www.w3.org/2000/svg" width="1000mm" height="1000mm" '
             f'viewBox="-500 -500 1000 1000">{element}</svg>')
    d = read_svg(probe.encode(), file=file, text=text)
    x0, y0, x1, y1 = bbox(d)
    m = lt.margin_mm
    # the probe's drawing frame: x = user x + 500, y up from the page bottom (user y = 500)
    left, top = x0 - 500 - m, 500 - y1 - m
    w, h = x1 - x0 + 2 * m, y1 - y0 + 2 * m
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:.3f}mm" height="{h:.3f}mm" '
            f'viewBox="{left:.3f} {top:.3f} {w:.3f} {h:.3f}">\n  {element}\n</svg>\n')


def strokes_svg(d: Drawing) -> str:
    """A drawing's strokes as SVG paths in its page's mm (module doc): lines and cubics
    exactly, arcs flattened within 0.005 mm."""
    assert d.page_size_mm is not None
    w, h = d.page_size_mm
    flat = flatten(d, 0.005)
    first = start_points(d.kind, d.params)
    paths = []
    for s in range(d.n_strokes):
        sel = np.flatnonzero(d.stroke == s)
        if sel.size:
            paths.append(_path_data(d, sel, flat, first[sel[0]]))
    body = "\n".join(f'  <path d="{p}"/>' for p in paths)
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:.3f}mm" height="{h:.3f}mm" '
            f'viewBox="0 0 {w:.3f} {h:.3f}">\n<g fill="none" stroke="black" '
            f'stroke-width="0.3" stroke-linecap="round" stroke-linejoin="round">\n{body}\n'
            f"</g>\n</svg>\n")


def _path_data(d: Drawing, sel: IntArray, flat: Polylines, start: FloatArray) -> str:
    """One stroke's path data in page mm (y down)."""
    x0, y0 = d.to_file_frame(start)
    out = [f"M{x0:.4f} {y0:.4f}"]
    for i in sel.tolist():
        kind = int(d.kind[i])
        p = d.to_file_frame(d.params[i].reshape(4, 2))
        if kind == CUBIC:
            out.append("C" + " ".join(f"{x:.4f} {y:.4f}" for x, y in p[1:]))
        elif kind == ARC:
            pts = d.to_file_frame(flat.points[flat.prim == i])
            out.extend(f"L{x:.4f} {y:.4f}" for x, y in pts)
        else:
            out.append(f"L{p[1, 0]:.4f} {p[1, 1]:.4f}")
    return "".join(out)
