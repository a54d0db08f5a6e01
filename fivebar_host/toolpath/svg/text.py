"""SVG `<text>` drawn with single-stroke fonts: the walker's entry point `draw_text`.

A pen draws a glyph's centre-lines, so text is the documented exception to "a shape draws
its outline": a `<text>` whose fill or stroke is painted draws each glyph's strokes once —
never an outline, never the outline and a hatching. Steps: the characters and their
attributes (`textcontent`), each element's faces (`fonts.library`, from `font-family`,
`font-weight`, `font-style`), glyphs, advances and positions (`textlayout`), text on a path
(`textpath`), then each glyph placed by one affine map (position, rotation, baseline,
synthesized oblique, font-size, the y-flip of font units) into the drawing.

What the reader says: every character no face has is an `InputError` naming its code point,
its position in the text and the element (file:line); a character drawn by the profile's
fallback face, a `font-family` it does not know, and anything a pen does not draw as a
screen shows it are warnings, once per kind. Vertical writing modes and right-to-left text
are refused. Each drawn `<text>` leaves a `TextInfo` (its faces, size, glyphs) for the dry
run.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fivebar_host.errors import InputError
from fivebar_host.toolpath.fonts.library import OBLIQUE_DEG, Face, FontLibrary
from fivebar_host.toolpath.geometry import LINE, TextInfo, affine_scale, transform
from fivebar_host.toolpath.svg import textlayout as tl
from fivebar_host.toolpath.svg import textpath as tp
from fivebar_host.toolpath.svg.paint import number_or_percent, text_prop
from fivebar_host.toolpath.svg.textcontent import Collector, Content, Span
from fivebar_host.toolpath.svg.textdeco import Line, decoration_lines
from fivebar_host.toolpath.svg.xmltree import Node
from kinematics.arrays import BoolArray, FloatArray, IntArray

if TYPE_CHECKING:
    from fivebar_host.toolpath.svg.walk import Ctx, Walker

@dataclass(frozen=True)
class CharLayout:
    """Where one text element's characters went (for tools and the tests that compare the
    layout with a browser's): the element's id, its addressable characters, each glyph's
    origin on its baseline in the text's user space and in the drawing frame (mm, y up),
    its rotation in user space (degrees), whether it is placed (a glyph off its path is not)
    and whether it draws strokes."""

    ident: str | None
    chars: str
    user: FloatArray
    drawing: FloatArray
    rotate: FloatArray
    placed: BoolArray
    drawn: BoolArray


_FAMILY = re.compile(r"""\s*(?:"([^"]*)"|'([^']*)'|([^,]+))\s*(?:,|$)""")
#: Characters of a text shown in the dry run before it is shortened.
SHOWN = 40


def family_list(value: str) -> list[tuple[str, bool]]:
    """A CSS `font-family` value as (name, quoted) pairs (CSS Fonts 4 §2.1: quoted strings
    or sequences of identifiers, comma-separated; only unquoted names can be generic)."""
    out = []
    for m in _FAMILY.finditer(value):
        quoted = m.group(1) is not None or m.group(2) is not None
        name = m.group(1) if m.group(1) is not None else m.group(2) if m.group(2) is not None \
            else " ".join(m.group(3).split())
        if name.strip():
            out.append((name.strip(), quoted))
    return out


def weight_and_style(props: dict[str, str]) -> tuple[bool, bool]:
    """(bold, italic) from `font-weight` (≥ 600, bold, bolder) and `font-style`."""
    w = text_prop(props, "font-weight").lower()
    bold = w in ("bold", "bolder") or (w.isdigit() and int(w) >= 600)
    style = text_prop(props, "font-style").lower().split()
    return bold, bool(style) and style[0] in ("italic", "oblique")


class TextDrawer:
    """Lays out and draws one `<text>` element for a walker (module doc)."""

    def __init__(self, w: Walker, node: Node, ctx: Ctx) -> None:
        self.w, self.node, self.ctx = w, node, ctx
        self.fonts: FontLibrary = w.fonts
        self.faces_cache: dict[tuple[str, bool, bool], list[Face]] = {}
        self.paths: list[tuple[tp.PathGeometry, float]] = []
        self.face_lists: list[list[Face]] = []

    # ------------------------------------------------------------------ faces
    def faces(self, span: Span) -> list[Face]:
        """The faces of an element's `font-family` list; unknown names are noted, and a
        list with no known name draws in the profile's default family."""
        fam = text_prop(span.props, "font-family") or self.fonts.default_family()
        bold, italic = weight_and_style(span.props)
        key = (fam, bold, italic)
        if key not in self.faces_cache:
            found = []
            for name, quoted in family_list(fam):
                face = self.fonts.face(name, bold, italic, quoted=quoted)
                if face is None:
                    self.w.note(f"font-{name.lower()}", span.node,
                                f"font-family {name!r} is not a single-stroke font fivebar "
                                "knows (bundled, [text] aliases or font_dirs): the next in the "
                                f"list or the default ({self.fonts.default_family()}) draws")
                else:
                    found.append(face)
            if not found:
                face = self.fonts.face(self.fonts.default_family(), bold, italic, True)
                if face is None:
                    raise InputError(f"[text] default = {self.fonts.default_family()!r} names "
                                     "no font", self.fonts.config.source)
                found.append(face)
            self.faces_cache[key] = found
        return self.faces_cache[key]

    # ------------------------------------------------------------------ paths
    def path_ok(self, node: Node) -> bool:
        """Whether a `<textPath>` lies on a shape; measures it (module doc of textpath)."""
        shape = tp.referenced_shape(node, self.w.ids)
        if shape is None:
            self.w.note("textpath-ref", node, "<textPath> refers to no path or shape: its "
                        "text is not drawn (SVG 2 §11.8.1, as browsers)")
            return False
        for attr in ("side", "method", "spacing", "path"):
            if node.get(attr) not in (None, "", "left", "align", "exact", "auto"):
                self.w.note(f"textpath-{attr}", node, f"<textPath> {attr} is not used (as "
                            "in Chromium): the text runs along the path from its start")
        lengths = self.ctx.lengths
        geom = tp.measure(shape, lengths, self.w.file, self.w.transform)
        if geom is None:
            self.w.note("textpath-empty", node, "<textPath> path has no length: its text is "
                        "not drawn")
            return False
        self.paths.append((geom, tp.start_offset(node, shape, geom, lengths, self.w.file)))
        return True

    # ------------------------------------------------------------------ layout
    def layout(self) -> tuple[Content, tl.Layout, FloatArray] | None:
        """Characters, glyphs and positions; per character its `on` flag (drawn)."""
        w, node, ctx = self.w, self.node, self.ctx
        self._refuse_direction(ctx.props)
        c = Collector(w.file, w.sheet.cascade, w.note, self.path_ok).collect(
            node, ctx.props, ctx.lengths)
        if not c.chars:
            return None
        face_lists = self.face_lists = [self.faces(s) for s in c.spans]
        lay = tl.select_glyphs(c, lambda k: face_lists[k], self.fonts.fallback())
        if lay.missing:
            self._missing(c, lay, face_lists)
        tl.advances(lay, c, w.file)
        ends = [(float(p[0][0]), float(p[0][1])) for p in
                (g.at(np.array([g.length]))[0] for g, _ in self.paths)]
        tl.positions(lay, c, lambda k: face_lists[k], ends)
        on = np.ones(len(c.chars))
        for a, b in tl.chunks(lay):
            anchor = text_prop(c.spans[c.span[a]].props, "text-anchor").lower()
            path = c.spans[c.span[a]].path
            shift = tl.anchor_shift(lay, a, b, anchor)
            lay.x[a:b] += shift
            if path >= 0:
                self._on_path(lay, c, a, b, path, on)
        return c, lay, on

    def _on_path(self, lay: tl.Layout, c: Content, a: int, b: int, path: int,
                 on: FloatArray) -> None:
        geom, offset = self.paths[path]
        sl = slice(a, b)
        x, y, ang, ok = tp.place_on_path(geom, lay.x[sl] + offset, lay.glyph_advance[sl],
                                         lay.y[sl] + lay.baseline[sl])
        lay.x[sl], lay.y[sl], lay.baseline[sl] = x, y, 0.0
        lay.rotate[sl] += ang
        on[sl] = ok

    def _refuse_direction(self, props: dict[str, str]) -> None:
        wm = text_prop(props, "writing-mode").lower()
        if wm not in ("horizontal-tb", "lr", "lr-tb", "rl", "rl-tb", ""):
            raise InputError(f"{self.node.describe()} has writing-mode {wm!r}: vertical text "
                             "is not supported (horizontal left-to-right only)", self.w.file,
                             self.node.line)
        if text_prop(props, "direction").lower() == "rtl":
            raise InputError(f"{self.node.describe()} has direction rtl: right-to-left text "
                             "is not supported", self.w.file, self.node.line)

    def _missing(self, c: Content, lay: tl.Layout, face_lists: list[list[Face]]) -> None:
        i = lay.missing[0]
        span = c.spans[c.span[i]]
        ch = c.chars[i]
        tried = ", ".join(f.label for f in face_lists[c.span[i]])
        fb = self.fonts.fallback()
        fbt = f" nor the fallback {fb.label}" if fb is not None else " (no [text] fallback)"
        more = f" ({len(lay.missing)} characters have none)" if len(lay.missing) > 1 else ""
        raise InputError(f"character {ch!r} (U+{ord(ch):04X}) at position {i + 1} of the text "
                         f"of {self.node.describe()} (in {span.node.describe()}) has no "
                         f"glyph in {tried}{fbt}{more}: choose a font that has it "
                         "(docs/text.md lists each font's characters) or a [text] fallback",
                         self.w.file, span.node.line)


def glyph_matrices(lay: tl.Layout, idx: IntArray) -> FloatArray:
    """The 3×3 maps from font units to user units of the glyphs `idx` (module doc)."""
    n = idx.shape[0]
    m = np.zeros((n, 3, 3))
    s = lay.scale[idx]
    th = np.radians(lay.rotate[idx])
    c, sn = np.cos(th), np.sin(th)
    shear = np.array([math.tan(math.radians(OBLIQUE_DEG)) if f is not None and f.oblique
                      else 0.0 for f in (lay.face[i] for i in idx.tolist())])
    b = lay.baseline[idx]
    # T(x, y) · R(θ) · T(0, b) · S(s, −s) · Shear(k): font units (y up, sheared x + k·y
    # for a synthesized oblique) → user units (y down)
    m[:, 0, 0], m[:, 0, 1] = c * s, c * s * shear + sn * s
    m[:, 1, 0], m[:, 1, 1] = sn * s, sn * s * shear - c * s
    m[:, 0, 2] = lay.x[idx] - sn * b
    m[:, 1, 2] = lay.y[idx] + c * b
    m[:, 2, 2] = 1.0
    return m


def draw_text(w: Walker, node: Node, ctx: Ctx) -> None:
    """Draw one `<text>` element (module doc)."""
    if not ctx.selected and w.collector is None:
        return
    d = TextDrawer(w, node, ctx)
    res = d.layout()
    if res is None:
        return
    c, lay, on = res
    idx = np.flatnonzero([_drawn(c, lay, on, i) for i in range(len(c.chars))])
    lines, on_path = decoration_lines(c, lay, lambda k: d.face_lists[k], on)
    _notes(w, node, ctx, c, lay, on_path)
    glyphs = glyph_matrices(lay, idx) if idx.size else np.zeros((0, 3, 3))
    if w.collector is not None or ctx.clip is not None:
        subs = _subpaths(c, lay, idx, glyphs) + [[(LINE, p)] for _, p in lines]
        src = w.emit(node, ctx, subs, "text") if subs else -1
    else:
        src = _emit_fast(w, node, ctx, c, lay, idx, ctx.matrix @ glyphs, lines)
    if w.collector is None:
        _record(w, node, ctx, c, lay, idx, src, len(lines))
        if w.layouts is not None:
            w.layouts.append(_char_layout(node, ctx, c, lay, on, idx))


def _char_layout(node: Node, ctx: Ctx, c: Content, lay: tl.Layout, on: FloatArray,
                 idx: IntArray) -> CharLayout:
    every = np.arange(len(c.chars))
    m = glyph_matrices(lay, every)
    user = m[:, :2, 2]
    drawing = user @ ctx.matrix[:2, :2].T + ctx.matrix[:2, 2]
    drawn = np.zeros(len(c.chars), dtype=bool)
    drawn[idx] = True
    return CharLayout(node.get("id"), c.text, user, drawing, lay.rotate.copy(), on > 0, drawn)


def _drawn(c: Content, lay: tl.Layout, on: FloatArray, i: int) -> bool:
    """Whether character i draws: a glyph with strokes, on its path, painted."""
    g = lay.glyph[i]
    return g is not None and g.n_strokes > 0 and on[i] > 0 and c.spans[c.span[i]].painted


def _emit_fast(w: Walker, node: Node, ctx: Ctx, c: Content, lay: tl.Layout,
               idx: IntArray, mats: FloatArray, lines: list[Line]) -> int:
    """Glyph strokes straight into the builder, each glyph with its own matrix (user
    units → drawing frame included), then the decoration lines; the source index, −1 when
    nothing is drawn."""
    if not idx.size and not lines:
        return -1
    b = w.b
    src = b.add_source(node.get("id"), node.line, "text", ctx.layer)
    for k, i in enumerate(idx.tolist()):
        g = lay.glyph[i]
        assert g is not None
        b.matrices.append(mats[k])
        b.add_strokes(src, g.kinds, g.params, g.starts, c.spans[c.span[i]].node.line,
                      len(b.matrices) - 1)
    if lines:
        b.matrices.append(ctx.matrix)
        one = np.zeros(1, dtype=np.int64)
        for line, p in lines:
            b.add_strokes(src, np.array([LINE], dtype=np.int8),
                          np.array([[*p, 0.0, 0.0, 0.0, 0.0]]), one, line,
                          len(b.matrices) - 1)
    return src


def _subpaths(c: Content, lay: tl.Layout, idx: IntArray,
              glyphs: FloatArray) -> list[list[tuple[int, tuple[float, ...]]]]:
    """Glyph strokes as subpaths in user units (for a clip region or a collector)."""
    subs = []
    for k, i in enumerate(idx.tolist()):
        g = lay.glyph[i]
        assert g is not None
        m = glyphs[k]
        q = transform(g.kinds, g.params, m[:2, :2], m[:2, 2])
        ends = [*g.starts.tolist()[1:], g.kinds.shape[0]]
        for a, e in zip(g.starts.tolist(), ends, strict=True):
            subs.append([(int(g.kinds[j]), tuple(float(v) for v in q[j])) for j in range(a, e)])
    return subs


def _notes(w: Walker, node: Node, ctx: Ctx, c: Content, lay: tl.Layout,
           deco_on_path: bool) -> None:
    """What the pen draws other than the screen shows, once per kind."""
    if lay.fallback.any():
        i = int(np.flatnonzero(lay.fallback)[0])
        chars = "".join(sorted({c.chars[j] for j in np.flatnonzero(lay.fallback)}))[:20]
        face = lay.face[i]
        w.note("text-fallback", c.spans[c.span[i]].node,
               f"character(s) {chars!r} (first U+{ord(c.chars[i]):04X} at position {i + 1}) "
               f"are not in the chosen font: drawn with the fallback "
               f"{face.label if face else '?'}")
    p = ctx.props
    if ctx.opacity < 1.0 or number_or_percent(p["fill-opacity"]) < 1:
        w.note("opacity", node, "partly transparent element(s) drawn as solid lines "
                                "(a pen cannot draw partial opacity)")
    if node.get("textLength") or node.get("lengthAdjust"):
        w.note("text-length", node, "textLength is not applied: the text is drawn at its "
                                    "font's natural length")
    if any(text_prop(s.props, "font-variant").lower() not in ("normal", "none", "")
           for s in c.spans):
        w.note("text-variant", node, "font-variant (small-caps …) is not applied: the "
                                     "characters are drawn as written")
    if deco_on_path:
        w.note("text-decoration", node, "text-decoration on a <textPath> is not drawn")


def _record(w: Walker, node: Node, ctx: Ctx, c: Content, lay: tl.Layout, idx: IntArray,
            src: int, lines: int) -> None:
    """The dry run's record of this text element."""
    labels: list[str] = []
    for i in idx.tolist():
        face = lay.face[i]
        if face is not None:
            label = face.label + (" (fallback)" if lay.fallback[i] else "")
            if label not in labels:
                labels.append(label)
    text = "".join((" / " if lay.chunk_start[i] and i else "") + ch  # chunks: lines
                   for i, ch in enumerate(c.chars))
    shown = text if len(text) <= SHOWN else text[:SHOWN - 1] + "…"
    mm = c.spans[0].lengths.font_px * affine_scale(ctx.matrix[:2, :2])
    strokes = sum(g.n_strokes for g in (lay.glyph[i] for i in idx.tolist()) if g is not None)
    w.texts.append(TextInfo(src, node.describe(), node.line, shown, tuple(labels), mm,
                            int(idx.size), int(strokes) + lines))
