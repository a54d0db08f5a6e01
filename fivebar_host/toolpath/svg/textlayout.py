"""Glyphs, advances and positions of a text element's characters, laid out as a browser lays
out SVG text (SVG 2 §11.8 "Text layout algorithm", horizontal left-to-right text).

- Glyphs: each character takes the first face of its element's font list that has it
  (CSS Fonts 4 §5: per-character fallback through `font-family`), then the profile's
  fallback face; a character no face has is reported by the caller. A ligature (an SVG
  font glyph for several characters) is used where nothing positions its later characters
  and letter-spacing is 0 (CSS Text 3 §8.2). Zero-width characters (ZWSP, ZWJ, ZWNJ, BOM,
  soft hyphen) draw nothing; a no-break or typographic space the face lacks takes the
  width Unicode gives it.
- Advances: the glyph's advance × font-size / units-per-em, less the font's kerning with
  the next glyph of the same element (`font-kerning` not none; SVG 1.1 §20.7), plus
  `letter-spacing` after every character and `word-spacing` after U+0020 and U+00A0
  (CSS Text 3 §8.1, §8.2).
- Positions (SVG 2 §11.8.3 steps "resolve character positioning" and "adjust positions"):
  the current text position starts at (0, 0); an `x`/`y` value sets it and starts a new
  text chunk, `dx`/`dy` move it, each character then advances it.
- Anchoring (same section, "apply anchoring"): per chunk, with a and b the least and
  greatest of every character's x and x + advance, the chunk moves by x₀ − a (start),
  x₀ − (a + b)/2 (middle) or x₀ − b (end), by the `text-anchor` of the chunk's first
  character. A chunk on a `<textPath>` is anchored along the path (`svg.textpath`).
- Baselines (CSS Inline 3 §4): the glyph origin moves from the position's y to the
  baseline that `dominant-baseline` (or an element's own `alignment-baseline`) names, from
  the face's metrics: alphabetic 0, middle x-height/2, central (ascent + descent)/2,
  mathematical ascent/2, hanging 0.8 ascent, text-before-edge the ascent,
  text-after-edge and ideographic the descent (descent < 0); then `baseline-shift`, where
  `sub`/`super` move by half the face's height (ascent − descent) at the size of the
  element that says it. These are the amounts headless Chromium uses (measured with a
  font of known metrics, `tests/test_text_browser.py`); Chromium ignores `text-top` and
  `text-bottom`, and so does this.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fivebar_host.errors import InputError
from fivebar_host.toolpath.fonts.library import Face
from fivebar_host.toolpath.fonts.svgfont import Glyph
from fivebar_host.toolpath.svg.paint import text_prop
from fivebar_host.toolpath.svg.textcontent import Content, Span
from kinematics.arrays import BoolArray, FloatArray

#: Characters that draw nothing and take no space.
ZERO_WIDTH = frozenset("\u200b\u200c\u200d\u2060\ufeff\u00ad")
#: Space characters a face may lack, with their width in em (Unicode's descriptions;
#: None: the width of the face's space).
SPACES: dict[str, float | None] = {
    "\u00a0": None, "\u202f": None, "\u2000": 0.5, "\u2001": 1.0, "\u2002": 0.5,
    "\u2003": 1.0, "\u2004": 1 / 3, "\u2005": 0.25, "\u2006": 1 / 6, "\u2007": 0.5,
    "\u2008": 0.25, "\u2009": 0.2, "\u200a": 0.1, "\u205f": 2 / 9, "\u3000": 1.0}
WORD_SEPARATORS = frozenset(" \u00a0")


@dataclass
class Layout:
    """Per character: the glyph drawn (None: nothing), its face, scale (user units per
    font unit), advance (with spacing and kerning, user units), the glyph's own advance,
    the position (x, y) after anchoring, the baseline's offset below it, rotation
    (degrees), the chunk it starts (-1: continues one) and whether it was drawn by the
    fallback face. `missing`: indices of characters no face has."""

    glyph: list[Glyph | None]
    face: list[Face | None]
    scale: FloatArray
    advance: FloatArray
    glyph_advance: FloatArray
    x: FloatArray
    y: FloatArray
    baseline: FloatArray
    rotate: FloatArray
    chunk_start: BoolArray
    fallback: BoolArray
    missing: list[int]


def spacing(span: Span, key: str, file: str) -> float:
    """`letter-spacing` / `word-spacing` in user units (`normal` is 0; % of the font-size)."""
    v = text_prop(span.props, key).lower()
    if v in ("normal", "", "0"):
        return 0.0
    if v.endswith("%"):
        try:
            return float(v[:-1]) / 100 * span.lengths.font_px
        except ValueError:
            return 0.0
    try:
        return span.lengths.user(v, file, span.node.line, key)
    except InputError:
        return 0.0  # an invalid declaration is ignored (CSS)


def baseline_offset(c: Content, k: int, faces: Callable[[int], list[Face]]) -> float:
    """The glyph origin's offset below the position's y for span k (module doc)."""
    span = c.spans[k]
    own = span.spec.get("alignment-baseline", "").strip().lower()
    which = own if own not in ("", "auto", "baseline") else text_prop(
        span.props, "dominant-baseline").lower()
    f = faces(k)[0].font
    off = {"middle": f.x_height / 2, "central": (f.ascent + f.descent) / 2,
           "mathematical": f.ascent / 2, "hanging": 0.8 * f.ascent,
           "text-before-edge": f.ascent, "text-after-edge": f.descent,
           "ideographic": f.descent}.get(which, 0.0)
    up = span.shift
    for sign, j in span.subsup:
        fj = faces(j)[0].font
        up += sign * (fj.ascent - fj.descent) / 2 * c.spans[j].lengths.font_px / fj.units_per_em
    return off * span.lengths.font_px / f.units_per_em - up


def select_glyphs(c: Content, faces: Callable[[int], list[Face]],
                  fallback: Face | None) -> Layout:
    """Glyphs and advances of every character (module doc); positions are left at 0."""
    n = len(c.chars)
    lay = Layout([None] * n, [None] * n, np.zeros(n), np.zeros(n), np.zeros(n),
                 np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n, bool),
                 np.zeros(n, bool), [])
    text = c.text
    i = 0
    while i < n:
        span = c.spans[c.span[i]]
        chosen = faces(c.span[i])
        i += _one(lay, c, text, i, span, chosen, fallback)
    return lay


def _one(lay: Layout, c: Content, text: str, i: int, span: Span, chosen: list[Face],
         fallback: Face | None) -> int:
    """Glyph of character i (and of a ligature's later characters): how many it covers."""
    ch = text[i]
    em = span.lengths.font_px
    if ch in ZERO_WIDTH or not em > 0:  # font-size 0 (or negative) renders nothing (CSS)
        lay.face[i] = chosen[0] if chosen else fallback
        return 1
    for k, face in enumerate([*chosen, *([fallback] if fallback else [])]):
        hit = face.font.match(text, i)
        if hit is not None and hit[1] > 1 and not _ligature_ok(c, i, hit[1]):
            single = face.font.glyph(ch)
            hit = None if single is None else (single, 1)
        if hit is None:
            continue
        glyph, count = hit
        scale = em / face.font.units_per_em
        lay.glyph[i], lay.face[i], lay.scale[i] = glyph, face, scale
        lay.glyph_advance[i] = glyph.advance * scale
        lay.fallback[i] = k >= len(chosen)
        for j in range(i + 1, i + count):
            lay.face[j], lay.scale[j] = face, scale
        return count
    if ch in SPACES and chosen:
        face = chosen[0]
        width = SPACES[ch]
        scale = em / face.font.units_per_em
        space = face.font.glyph(" ")
        lay.face[i], lay.scale[i] = face, scale
        lay.glyph_advance[i] = (width * em if width is not None else
                                (space.advance if space else face.font.missing_advance) * scale)
        return 1
    lay.missing.append(i)
    return 1


def _ligature_ok(c: Content, i: int, count: int) -> bool:
    """A ligature may cover characters i … i+count−1: same element, nothing positions the
    later ones, no letter-spacing."""
    later = slice(i + 1, i + count)
    if any(c.span[j] != c.span[i] for j in range(i + 1, i + count)):
        return False
    if not all(np.isnan(a[later]).all() for a in (c.x, c.y, c.dx, c.dy, c.rotate)):
        return False
    return text_prop(c.spans[c.span[i]].props, "letter-spacing").lower() in ("normal", "0", "")


def advances(lay: Layout, c: Content, file: str) -> None:
    """Each character's advance: glyph advance, kerning, letter- and word-spacing."""
    n = len(c.chars)
    lay.advance[:] = lay.glyph_advance
    cache: dict[int, tuple[float, float, bool]] = {}
    for i in range(n):
        k = c.span[i]
        if k not in cache:
            sp = c.spans[k]
            cache[k] = (spacing(sp, "letter-spacing", file), spacing(sp, "word-spacing", file),
                        text_prop(sp.props, "font-kerning").lower() != "none")
        letter, word, kern = cache[k]
        g = lay.glyph[i]
        if kern and g is not None and i + 1 < n and c.span[i + 1] == k:
            nxt, face = lay.glyph[i + 1], lay.face[i]
            if nxt is not None and face is not None and lay.face[i + 1] is face:
                lay.advance[i] -= face.font.kerning(g, nxt) * lay.scale[i]
        if lay.face[i] is not None and (g is not None or lay.glyph_advance[i] > 0):
            lay.advance[i] += letter + (word if c.chars[i] in WORD_SEPARATORS else 0.0)


def positions(lay: Layout, c: Content, faces: Callable[[int], list[Face]],
              path_ends: list[tuple[float, float]]) -> None:
    """Current text positions, chunks and the baseline offsets (module doc), before
    anchoring. A `<textPath>` starts a chunk and its x values are distances along it; the
    text after it goes on from the path's end point (`path_ends`), as in Chromium."""
    cx = cy = 0.0
    path = -1
    baselines: dict[int, float] = {}
    for i in range(len(c.chars)):
        k = c.span[i]
        span = c.spans[k]
        new = i == 0 or span.path != path
        if span.path != path:
            if path >= 0 and span.path < 0:
                cx, cy = path_ends[path]
            path = span.path
            if path >= 0:
                cx = cy = 0.0  # along the path from its start (+ startOffset), across it
        if not math.isnan(c.x[i]):
            cx, new = float(c.x[i]), True
        if not math.isnan(c.y[i]):
            cy, new = (cy if path >= 0 else float(c.y[i])), True
        if not math.isnan(c.dx[i]):
            cx += float(c.dx[i])
        if not math.isnan(c.dy[i]):
            cy += float(c.dy[i])
        lay.chunk_start[i] = new
        lay.x[i], lay.y[i] = cx, cy
        if k not in baselines:
            baselines[k] = baseline_offset(c, k, faces)
        lay.baseline[i] = baselines[k]
        lay.rotate[i] = 0.0 if math.isnan(c.rotate[i]) else float(c.rotate[i])
        cx += float(lay.advance[i])


def chunks(lay: Layout) -> list[tuple[int, int]]:
    """The text chunks as [a, b) character ranges."""
    starts = [*np.flatnonzero(lay.chunk_start).tolist(), lay.x.shape[0]]
    return [(a, b) for a, b in itertools.pairwise(starts) if b > a]


def anchor_shift(lay: Layout, a: int, b: int, anchor: str) -> float:
    """How far chunk [a, b) moves for its `text-anchor` (module doc)."""
    xs, adv = lay.x[a:b], lay.advance[a:b]
    lo = float(np.minimum(xs, xs + adv).min())
    hi = float(np.maximum(xs, xs + adv).max())
    x0 = float(lay.x[a])
    return {"middle": x0 - (lo + hi) / 2, "end": x0 - hi}.get(anchor, x0 - lo)
