"""The characters of one `<text>` element, their styles and their position attributes.

What a browser does before it places a glyph (SVG 2 §11.4–11.6, CSS Text 3 §4):

- Content: the character data of `<text>`, `<tspan>`, `<textPath>` and `<a>` in document
  order. `display:none` removes an element's characters; `visibility:hidden` keeps their
  space. `<tref>` (removed in SVG 2, not rendered by browsers) and other elements are not
  text content; they are noted, not drawn.
- White space (CSS Text 3 §4.1 with SVG 2's mapping of `xml:space`): newlines, carriage
  returns and tabs become spaces; with `xml:space="default"` (or CSS white-space normal,
  nowrap, pre-line) a space that follows another collapsible space, or starts the text, is
  removed, as are spaces at the end of the text; `xml:space="preserve"` (white-space pre,
  pre-wrap, break-spaces) keeps every one. Removed characters are not addressable: position
  attributes skip them, as headless Chromium counts them (`getNumberOfChars`).
- `text-transform` (CSS Text 3 §2.1) maps characters one to one after that.
- Position attributes (SVG 2 §11.5.2 "Resolving character positioning"): the n-th value of
  `x`, `y`, `dx`, `dy` on an element applies to the n-th addressable character it contains
  (a descendant's own values take precedence); `rotate` applies its last value to the rest
  of the element's characters. Lengths take CSS units, `em` of the element's font-size.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from fivebar_host.errors import InputError
from fivebar_host.toolpath.svg.paint import inherit, painted, text_prop
from fivebar_host.toolpath.svg.units import Lengths
from fivebar_host.toolpath.svg.xmltree import XML_NS, Node
from kinematics.arrays import FloatArray

#: Elements whose character data is text content (SVG 2 §11.1).
TEXT_CONTENT = ("tspan", "textPath", "a")
#: Elements that may appear in text and are never rendered: skipped without a note.
SILENT = ("title", "desc", "metadata")
_LIST_SEP = re.compile(r"[\s,]+")


@dataclass(frozen=True)
class Span:
    """One text content element's computed text style: its inherited properties, the
    lengths its values refer to (font-size = `lengths.font_px`), its specified values,
    the baseline shift accumulated from it and its ancestors (lengths and percentages in
    user units, up; `sub`/`super` as (±1, the span that says it), whose font sets the
    amount), the text decorations in force and the `<textPath>` it lies in (index into
    `Content.paths`)."""

    node: Node
    props: dict[str, str]
    lengths: Lengths
    spec: dict[str, str]
    shift: float
    decoration: frozenset[str]
    path: int = -1
    subsup: tuple[tuple[int, int], ...] = ()

    @property
    def painted(self) -> bool:
        """Whether its glyphs draw (fill or stroke painted, visible): text is drawn as its
        single strokes either way (module doc of `svg.text`)."""
        p = self.props
        return (p["visibility"].strip().lower() == "visible"
                and (painted(p["fill"]) or painted(p["stroke"])))


@dataclass
class Content:
    """The addressable characters of a text element (one code point each) with their span,
    position attributes (NaN: not given) and the text content elements with their character
    ranges (pre-order)."""

    chars: list[str] = field(default_factory=list)
    span: list[int] = field(default_factory=list)
    spans: list[Span] = field(default_factory=list)
    paths: list[Node] = field(default_factory=list)
    ranges: list[tuple[Node, int, int, int]] = field(default_factory=list)  # node, span, a, b
    collapsible: list[bool] = field(default_factory=list)
    x: FloatArray = field(default_factory=lambda: np.zeros(0))
    y: FloatArray = field(default_factory=lambda: np.zeros(0))
    dx: FloatArray = field(default_factory=lambda: np.zeros(0))
    dy: FloatArray = field(default_factory=lambda: np.zeros(0))
    rotate: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def text(self) -> str:
        return "".join(self.chars)


class Collector:
    """Builds the `Content` of one text element (module doc). `cascade` gives an element's
    specified properties; `note(kind, node, message)` records what is not drawn;
    `path_ok(textPath)` says whether a `<textPath>` has a path to lie on."""

    def __init__(self, file: str, cascade: Callable[[Node], dict[str, str]],
                 note: Callable[[str, Node, str], None],
                 path_ok: Callable[[Node], bool]) -> None:
        self.file = file
        self.cascade = cascade
        self.note = note
        self.path_ok = path_ok
        self.c = Content()

    def collect(self, node: Node, props: dict[str, str], lengths: Lengths) -> Content:
        spec = self.cascade(node)
        shift, sign = _shift(spec, lengths, 0.0, self.file, node.line)
        self._element(node, Span(node, props, lengths, spec, shift,
                                 _decoration(spec, frozenset()), -1,
                                 ((sign, 0),) if sign else ()), _preserved(node))
        while self.c.chars and self.c.chars[-1] == " " and self.c.collapsible[-1]:
            self._pop()  # spaces at the end of the (single) line are removed
        n = len(self.c.chars)
        self.c.x, self.c.y, self.c.dx, self.c.dy, self.c.rotate = (
            np.full(n, np.nan) for _ in range(5))
        for node_, span, a, b in self.c.ranges:
            self._positions(node_, self.c.spans[span].lengths, a, b)
        return self.c

    # ------------------------------------------------------------------ content
    def _element(self, node: Node, span: Span, preserve: bool) -> None:
        c = self.c
        space = node.get(f"{XML_NS} space")
        if space is not None:
            preserve = space.strip() == "preserve"
        ws = text_prop(span.props, "white-space").lower()
        if ws in ("pre", "pre-wrap", "break-spaces"):
            preserve = True
        elif ws in ("normal", "nowrap", "pre-line"):
            preserve = False
        c.spans.append(span)
        k = len(c.spans) - 1
        start = len(c.chars)
        index = len(c.ranges)
        c.ranges.append((node, k, start, start))
        self._add(node.text, k, preserve)
        for child in node.children:
            self._child(child, span, preserve)
            self._add(child.tail, k, preserve)
        c.ranges[index] = (node, k, start, len(c.chars))

    def _child(self, child: Node, span: Span, preserve: bool) -> None:
        if not child.is_svg or child.tag in SILENT:
            return
        if child.tag not in TEXT_CONTENT:
            self.note(f"text-{child.tag}", child, f"<{child.tag}> inside <text> is not text "
                      "content: not drawn, as browsers show it")
            return
        spec = self.cascade(child)
        if spec.get("display", "").strip().lower() == "none":
            return
        font = (span.lengths.font_size(spec.get("font-size"), self.file, child.line)
                if "font-size" in spec else span.lengths.font_px)
        lengths = Lengths(span.lengths.width, span.lengths.height, font)
        path = span.path
        if child.tag == "textPath":
            if span.path >= 0:
                self.note("text-nested-path", child,
                          "<textPath> inside <textPath> laid out as a <tspan>")
            elif not self.path_ok(child):
                return  # refers to no path: not rendered (SVG 2 §11.8.1); noted by path_ok
            else:
                self.c.paths.append(child)
                path = len(self.c.paths) - 1
        shift, sign = _shift(spec, lengths, span.shift, self.file, child.line)
        terms = (*span.subsup, (sign, len(self.c.spans))) if sign else span.subsup
        sub = Span(child, inherit(span.props, spec), lengths, spec, shift,
                   _decoration(spec, span.decoration), path, terms)
        self._element(child, sub, preserve)

    def _add(self, text: str, span: int, preserve: bool) -> None:
        if not text:
            return
        c = self.c
        tt = text_prop(c.spans[span].props, "text-transform").lower()
        for ch in text:
            if ch in "\n\r\t":
                ch = " "
            if ch == " " and not preserve and (
                    not c.chars or (c.chars[-1] == " " and c.collapsible[-1])):
                continue
            c.chars.append(_transform(ch, tt, c.chars[-1] if c.chars else " "))
            c.span.append(span)
            c.collapsible.append(not preserve)

    def _pop(self) -> None:
        c = self.c
        c.chars.pop()
        c.span.pop()
        c.collapsible.pop()
        n = len(c.chars)
        c.ranges = [(nd, k, min(a, n), min(b, n)) for nd, k, a, b in c.ranges]

    # ------------------------------------------------------------------ positions
    def _positions(self, node: Node, lengths: Lengths, a: int, b: int) -> None:
        c = self.c
        if node.tag == "textPath" or b <= a:
            return  # a textPath has no position attributes (SVG 2 §11.8.1)
        for attr, arr in (("x", c.x), ("y", c.y), ("dx", c.dx), ("dy", c.dy)):
            values = _length_list(node, attr, lengths, self.file)
            m = min(len(values), b - a)
            if m:
                arr[a:a + m] = values[:m]
        rot = node.get("rotate")
        if rot is not None and rot.strip():
            vals = _number_list(rot, self.file, node.line, "rotate")
            if vals:
                idx = np.minimum(np.arange(b - a), len(vals) - 1)
                c.rotate[a:b] = np.asarray(vals)[idx]


def _preserved(node: Node) -> bool:
    """Whether the nearest `xml:space` above a text element says preserve (XML 1.0 §2.10:
    the attribute applies to the element's content and inherits)."""
    n = node.parent
    while n is not None:
        v = n.get(f"{XML_NS} space")
        if v is not None:
            return v.strip() == "preserve"
        n = n.parent
    return False


def _transform(ch: str, how: str, prev: str) -> str:
    """CSS `text-transform` of one character, when it maps one to one (ß stays ß)."""
    if how == "uppercase" or (how == "capitalize" and not prev.isalnum()):
        up = ch.upper()
        return up if len(up) == 1 else ch
    if how == "lowercase":
        low = ch.lower()
        return low if len(low) == 1 else ch
    return ch


def _number_list(text: str, file: str, line: int, what: str) -> list[float]:
    out = []
    for tok in text.replace(",", " ").split():
        try:
            v = float(tok)
        except ValueError:
            raise InputError(f"{what}={text!r}: {tok!r} is not a number", file, line) from None
        if not math.isfinite(v):
            raise InputError(f"{what}={text!r}: {tok!r} is not finite", file, line)
        out.append(v)
    return out


def _length_list(node: Node, attr: str, lengths: Lengths, file: str) -> list[float]:
    text = node.get(attr)
    if text is None or not text.strip():
        return []
    toks = [t for t in _LIST_SEP.split(text.strip()) if t]
    return [lengths.user(t, file, node.line, attr) for t in toks]


def _shift(spec: dict[str, str], lengths: Lengths, parent: float, file: str,
           line: int) -> tuple[float, int]:
    """The accumulated `baseline-shift` (user units, up) of lengths and percentages (of the
    font-size: SVG 1.1 §10.9.2 takes the line-height, which SVG text sets to the
    font-size), and −1 for `sub`, +1 for `super` (their amount depends on the face:
    `textlayout`), else 0."""
    v = spec.get("baseline-shift", "").strip().lower()
    if v in ("", "baseline", "0", "initial", "inherit"):
        return parent, 0
    if v in ("sub", "super"):
        return parent, -1 if v == "sub" else 1
    if v.endswith("%"):
        try:
            return parent + float(v[:-1]) / 100 * lengths.font_px, 0
        except ValueError:
            return parent, 0
    try:
        return parent + lengths.user(v, file, line, "baseline-shift"), 0
    except InputError:
        return parent, 0  # an invalid declaration is ignored (CSS)


def own_decoration(spec: dict[str, str]) -> tuple[str, ...]:
    """The decoration lines an element sets itself (`text-decoration-line`, or the lines of
    the `text-decoration` shorthand), in a fixed order."""
    v = (spec.get("text-decoration-line") or spec.get("text-decoration") or "").lower()
    words = v.split()
    return tuple(w for w in ("underline", "overline", "line-through") if w in words)


def _decoration(spec: dict[str, str], parent: frozenset[str]) -> frozenset[str]:
    """Text decorations in force: an element's own lines added to its ancestors' (CSS Text
    Decoration 3 §2: decorations propagate to the text of descendants)."""
    return parent | set(own_decoration(spec))
