"""The stroke goals: no glyph stroke is drawn twice, and a compiled job lifts the pen no
more often than the glyphs have strokes.

- Drawn once: on the corpus (`tests/text_corpus.py`; Relief SingleLine also on its non-ASCII
  strings) in every bundled font, painted as fill only, stroke only and both, each text
  element draws exactly its glyphs' strokes (no stroke twice: fill and stroke are one pen
  line), and no two drawn chords overlap along the same line by more than 0.05 mm
  (`text_support.doubled`) beyond what the font data itself retraces. The bundled data
  retraces in one glyph only: the "B" of Hershey Gothic Italian (gothicita, gothitt) runs 2
  Hershey units back along its stem; it is counted from the font and reported, not drawn
  twice by fivebar.
- Pen lifts: a compiled job of a line in each family has no more pen-down paths than
  its glyph strokes (ordering joins strokes whose ends meet; it never splits one).
"""

from __future__ import annotations

import functools
from xml.sax.saxutils import escape

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, compile_drawing
from fivebar_host.config import load_profile
from fivebar_host.toolpath.fonts.library import FACES, FontLibrary
from fivebar_host.toolpath.geometry import flatten
from fivebar_host.toolpath.svg import read_svg
from tests.text_corpus import LATIN, corpus
from tests.text_support import doubled, segments_of
from tests.web_support import record

PAINTS = ('fill="black"', 'fill="none" stroke="black"', 'fill="red" stroke="black"')
SIZE = 10.0


def glyph_doubles(font: str, text: str) -> int:
    """Retraced chord pairs inside the glyphs themselves (the font's data) at SIZE."""
    return sum(text.count(ch) * char_doubles(font, ch) for ch in set(text))


@functools.cache
def char_doubles(font: str, ch: str) -> int:
    """Retraced chord pairs inside one glyph alone (0 for a missing or empty glyph)."""
    g = FontLibrary().load(font).glyph(ch)
    if g is None or g.n_strokes == 0:
        return 0
    d = read_svg(f'<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="50mm" '
                 f'viewBox="0 0 100 50"><text x="10" y="30" font-family="\'{font}\'" '
                 f'font-size="{SIZE}">{escape(ch)}</text></svg>'.encode())
    return _doubles(d)


def _doubles(d: object) -> int:
    p = flatten(d, 0.005)  # type: ignore[arg-type]
    pts = [p.points[a:b] for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True)]
    return doubled(segments_of(pts))


@pytest.mark.parametrize("font", list(FACES))
def test_no_glyph_stroke_is_drawn_twice(font: str) -> None:
    strings = corpus() + (LATIN if font == "relief" else [])
    lib = FontLibrary()
    extra = inherent = strokes = 0
    for paint in PAINTS:
        body = "".join(f'<text x="5" y="{15 * (i + 1)}" {paint}>{escape(s)}</text>'
                       for i, s in enumerate(strings))
        h = 15 * (len(strings) + 1)
        d = read_svg(f'<svg xmlns="http://www.w3.org/2000/svg" width="400mm" height="{h}mm" '
                     f'viewBox="0 0 400 {h}" font-family="\'{font}\'" font-size="{SIZE}">'
                     f"{body}</svg>".encode())
        f = lib.load(font)
        for info, s in zip(d.texts, strings, strict=True):
            want = sum(g.n_strokes for g in (f.glyph(c) for c in s) if g is not None)
            assert info.strokes == want and int(np.sum(
                d.stroke_source == info.source)) == want, (font, paint, s)
            strokes += want
        p = flatten(d, 0.005)
        for info in d.texts:
            sel = np.flatnonzero(d.stroke_source[p.stroke] == info.source)
            pts = [p.points[p.offsets[k]:p.offsets[k + 1]] for k in sel]
            found = doubled(segments_of(pts))
            own = glyph_doubles(font, strings[info.source])
            assert found == own, (font, paint, strings[info.source], found, own)
            extra += found - own
            inherent += own
    record(f"text_doubled_{font}", {"strokes": strokes, "doubled_by_fivebar": extra,
                                    "retraced_in_font_data": inherent})


@pytest.mark.parametrize("font", ["futural", "timesr", "scripts", "gothiceng", "relief",
                                  "hersheysansmono"])
def test_pen_lifts_are_at_most_the_glyph_strokes(font: str) -> None:
    d = read_svg(f'<svg xmlns="http://www.w3.org/2000/svg" width="60mm" height="20mm" '
                 f'viewBox="0 0 60 20"><text x="2" y="12" font-family="\'{font}\'" '
                 f'font-size="6">Lift 42, go!</text></svg>'.encode())
    strokes = d.texts[0].strokes
    job = compile_drawing(d, load_profile(), CompileOptions())
    assert 0 < job.n_paths <= strokes
    record(f"text_pen_lifts_{font}", {"glyphs": d.texts[0].glyphs, "strokes": strokes,
                                      "pen_down_paths": job.n_paths})
