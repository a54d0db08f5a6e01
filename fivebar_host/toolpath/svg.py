"""SVG reader: every visible outline of an SVG document as exact primitives in millimetres.

- Path data through svgpathtools (`parse_path`: M L H V C S Q T A Z, relative and absolute);
  `<line> <polyline> <polygon> <rect>` (rounded corners, radii clamped as in SVG 1.1 §9.2)
  `<circle> <ellipse>` built directly as exact lines and elliptical arcs.
- Transforms: `transform` on any element, nested groups, `<use>` (x, y and the referenced
  element's own transform), nested `<svg>` viewports; parsed with svgpathtools'
  `parse_transform` (strict). Composed into one 3×3 matrix per element.
- Page: root `width`/`height` in mm, cm, in, pt, pc, px (96 px/in) or unitless (px), and
  `viewBox` with `preserveAspectRatio` (align + meet/slice, or none). Units are converted
  once here: the `Drawing` is in mm, y up, origin at the page's bottom-left corner (the page's
  y-down frame is flipped here, at the edge).
- Visibility: `display:none` hides a subtree; `visibility:hidden|collapse` is inherited and
  can be overridden by a child; an element whose computed stroke and fill are both `none` is
  invisible. Strokes only: outlines are drawn, fills are never hatched.
- Inkscape layers (`<g inkscape:groupmode="layer">`) selectable by label or id.

Errors (unreadable file, malformed XML with its line and column, a bad attribute, NaN or
enormous coordinates, no strokes) raise `InputError` naming the file and line.
"""

from __future__ import annotations

import itertools
import math
import re
import xml.parsers.expat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import svgpathtools
from svgpathtools.parser import parse_transform

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import (
    ARC,
    CUBIC,
    LINE,
    MAX_COORD_MM,
    Drawing,
    DrawingBuilder,
    read_source,
)

SVG_NS = "http://www.w3.org/2000/svg"
XLINK_NS = "http://www.w3.org/1999/xlink"
INKSCAPE_NS = "http://www.inkscape.org/namespaces/inkscape"

MM_PER_PX = 25.4 / 96.0
#: mm per unit for the absolute length units of CSS/SVG.
UNIT_MM = {"": MM_PER_PX, "px": MM_PER_PX, "mm": 1.0, "cm": 10.0, "in": 25.4,
           "pt": 25.4 / 72.0, "pc": 25.4 / 6.0, "q": 0.25}
_LENGTH_RE = re.compile(r"\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([a-zA-Z%]*)\s*$")
_NUMBER_SPLIT = re.compile(r"[\s,]+")
_NUMBER_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")

SHAPES = ("path", "line", "polyline", "polygon", "rect", "circle", "ellipse")
#: Elements whose content is never drawn directly.
NOT_RENDERED = {"defs", "symbol", "clipPath", "mask", "marker", "pattern", "metadata", "title",
                "desc", "style", "script", "linearGradient", "radialGradient", "filter",
                "namedview", "foreignObject"}


@dataclass
class Node:
    """A parsed XML element: local tag, namespace, attributes (local names; foreign
    namespaces as 'ns local'), children and its 1-based source line."""

    tag: str
    ns: str
    attrs: dict[str, str]
    line: int
    children: list[Node] = field(default_factory=list)

    def get(self, key: str, default: str | None = None) -> str | None:
        return self.attrs.get(key, default)


def _parse_xml(data: bytes, file: str) -> Node:
    """Parse with expat (keeps line numbers); external entities are never fetched."""
    parser = xml.parsers.expat.ParserCreate(namespace_separator=" ")
    root: list[Node] = []
    stack: list[Node] = []

    def start(name: str, attrs: dict[str, str]) -> None:
        ns, _, local = name.rpartition(" ")
        clean: dict[str, str] = {}
        for k, v in attrs.items():
            kns, _, kl = k.rpartition(" ")
            clean[kl if kns in ("", SVG_NS) else f"{kns} {kl}"] = v
        node = Node(local, ns, clean, parser.CurrentLineNumber)
        if stack:
            stack[-1].children.append(node)
        else:
            root.append(node)
        stack.append(node)

    def end(name: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as e:
        raise InputError(f"malformed XML: {xml.parsers.expat.ErrorString(e.code)} "
                         f"(line {e.lineno}, column {e.offset + 1})", file, e.lineno) from e
    if not root:
        raise InputError("no XML root element", file)
    return root[0]


def parse_length(text: str | None, file: str, line: int, what: str,
                 default_mm: float | None = None, percent_of_mm: float | None = None) -> float:
    """A CSS length → mm. Unitless means px (96 px/in); % needs `percent_of_mm`."""
    if text is None or not text.strip():
        if default_mm is None:
            raise InputError(f"missing {what}", file, line)
        return default_mm
    m = _LENGTH_RE.match(text)
    if not m:
        raise InputError(f"{what} = {text!r} is not a length", file, line)
    value, unit = float(m.group(1)), m.group(2).lower()
    if unit == "%":
        if percent_of_mm is None:
            if default_mm is None:
                raise InputError(f"{what} = {text!r}: percent needs a reference size", file,
                                 line)
            return default_mm
        return value / 100.0 * percent_of_mm
    if unit not in UNIT_MM:
        raise InputError(f"{what} = {text!r}: unsupported unit {unit!r} "
                         f"(use mm, cm, in, pt, pc, px)", file, line)
    mm = value * UNIT_MM[unit]
    if not math.isfinite(mm) or abs(mm) > MAX_COORD_MM:
        raise InputError(f"{what} = {text!r} is not a usable size", file, line)
    return mm


def _user_length(text: str | None, file: str, line: int, what: str,
                 default: float = 0.0) -> float:
    """A length in user units (unitless = user unit = px; absolute units converted to px)."""
    if text is None or not text.strip():
        return default
    m = _LENGTH_RE.match(text)
    if not m:
        raise InputError(f"{what} = {text!r} is not a number", file, line)
    value, unit = float(m.group(1)), m.group(2).lower()
    if unit == "%" or unit not in UNIT_MM:
        raise InputError(f"{what} = {text!r}: unsupported unit {unit!r}", file, line)
    v = value * UNIT_MM[unit] / MM_PER_PX
    if not math.isfinite(v):
        raise InputError(f"{what} = {text!r} is not a finite number", file, line)
    return v


def _numbers(text: str, file: str, line: int, what: str) -> list[float]:
    toks = [t for t in _NUMBER_SPLIT.split(text.strip()) if t]
    out: list[float] = []
    for tok in toks:
        if not _NUMBER_RE.fullmatch(tok):
            raise InputError(f"{what}: {tok!r} is not a number", file, line)
        out.append(float(tok))
    return out


def viewport_transform(viewbox: Sequence[float] | None, width: float, height: float,
                       par: str | None) -> np.ndarray:
    """3×3 map from viewBox user units to the viewport (width × height, same units),
    per SVG 1.1 §7.8 (preserveAspectRatio: align and meet|slice, or none)."""
    t = np.identity(3)
    if viewbox is None:
        return t
    vx, vy, vw, vh = viewbox
    sx, sy = width / vw, height / vh
    words = (par or "xMidYMid meet").split()
    align = words[0] if words else "xMidYMid"
    if align == "defer" and len(words) > 1:
        words = words[1:]
        align = words[0]
    slice_ = len(words) > 1 and words[1] == "slice"
    if align == "none":
        t[0, 0], t[1, 1] = sx, sy
        t[0, 2], t[1, 2] = -vx * sx, -vy * sy
        return t
    s = max(sx, sy) if slice_ else min(sx, sy)
    tx, ty = -vx * s, -vy * s
    ax = align[1:4].lower() if len(align) >= 8 else "mid"
    ay = align[5:8].lower() if len(align) >= 8 else "mid"
    if ax == "mid":
        tx += (width - vw * s) / 2
    elif ax == "max":
        tx += width - vw * s
    if ay == "mid":
        ty += (height - vh * s) / 2
    elif ay == "max":
        ty += height - vh * s
    t[0, 0] = t[1, 1] = s
    t[0, 2], t[1, 2] = tx, ty
    return t


def _style(node: Node) -> dict[str, str]:
    """Presentation attributes overridden by the `style` attribute (CSS declarations)."""
    out: dict[str, str] = {}
    for key in ("display", "visibility", "stroke", "fill"):
        v = node.get(key)
        if v is not None:
            out[key] = v.strip()
    st = node.get("style")
    if st:
        for decl in st.split(";"):
            if ":" in decl:
                k, v = decl.split(":", 1)
                k = k.strip().lower()
                if k in ("display", "visibility", "stroke", "fill"):
                    out[k] = v.replace("!important", "").strip()
    return out


@dataclass(frozen=True)
class _Ctx:
    matrix: np.ndarray  # 3×3 user units → page px-mm (page frame, y down, mm)
    visibility: str
    stroke: str
    fill: str
    layer: str | None
    selected: bool


class _Reader:
    def __init__(self, file: str, layers: Sequence[str] | None) -> None:
        self.file = file
        self.layers = [s for s in (layers or []) if s]
        self.found_layers: list[tuple[str | None, str | None]] = []
        self.b = DrawingBuilder(file)
        self.ids: dict[str, Node] = {}
        self.skipped_hidden = 0
        self.use_depth = 0
        self.ignored_tags: dict[str, int] = {}

    # ---------------------------------------------------------------- traversal
    def index_ids(self, node: Node) -> None:
        ident = node.get("id")
        if ident:
            self.ids.setdefault(ident, node)
        for c in node.children:
            self.index_ids(c)

    def walk(self, node: Node, ctx: _Ctx) -> None:
        if node.ns not in ("", SVG_NS):
            return  # foreign elements (Inkscape's sodipodi:namedview, metadata, ...)
        tag = node.tag
        if tag in NOT_RENDERED:
            return
        st = _style(node)
        if st.get("display", "") == "none":
            self.skipped_hidden += 1
            return
        m = ctx.matrix
        tf = node.get("transform")
        if tf and tag != "svg":
            m = m @ self._transform(tf, node)
        layer, selected = ctx.layer, ctx.selected
        if tag == "g" and node.get(f"{INKSCAPE_NS} groupmode") == "layer":
            label = node.get(f"{INKSCAPE_NS} label")
            ident = node.get("id")
            self.found_layers.append((label, ident))
            layer = label or ident
            if self.layers:
                selected = selected or label in self.layers or ident in self.layers
        c = _Ctx(m, st.get("visibility", ctx.visibility), st.get("stroke", ctx.stroke),
                 st.get("fill", ctx.fill), layer, selected)
        if tag in ("g", "a", "switch"):
            for child in node.children:
                self.walk(child, c)
        elif tag == "svg":
            self.walk_nested_svg(node, c)
        elif tag == "use":
            self.walk_use(node, c)
        elif tag in SHAPES:
            if not c.selected:
                return
            if c.visibility in ("hidden", "collapse") or (c.stroke == "none"
                                                          and c.fill == "none"):
                self.skipped_hidden += 1
                return
            self.shape(node, c)
        else:
            self.ignored_tags[tag] = self.ignored_tags.get(tag, 0) + 1

    def walk_nested_svg(self, node: Node, ctx: _Ctx) -> None:
        x = _user_length(node.get("x"), self.file, node.line, "x")
        y = _user_length(node.get("y"), self.file, node.line, "y")
        vb = self._viewbox(node)
        w = _user_length(node.get("width"), self.file, node.line, "width",
                         vb[2] if vb else 0.0)
        h = _user_length(node.get("height"), self.file, node.line, "height",
                         vb[3] if vb else 0.0)
        t = np.identity(3)
        t[0, 2], t[1, 2] = x, y
        m = ctx.matrix @ t @ viewport_transform(vb, w, h, node.get("preserveAspectRatio"))
        c = _Ctx(m, ctx.visibility, ctx.stroke, ctx.fill, ctx.layer, ctx.selected)
        for child in node.children:
            self.walk(child, c)

    def walk_use(self, node: Node, ctx: _Ctx) -> None:
        href = node.get("href") or node.get(f"{XLINK_NS} href") or ""
        if not href.startswith("#") or href[1:] not in self.ids:
            raise InputError(f"<use> references {href!r}, which is not an element id in "
                             "this file", self.file, node.line)
        if self.use_depth > 32:
            raise InputError("<use> references nest too deeply (a cycle?)", self.file,
                             node.line)
        t = np.identity(3)
        t[0, 2] = _user_length(node.get("x"), self.file, node.line, "x")
        t[1, 2] = _user_length(node.get("y"), self.file, node.line, "y")
        c = _Ctx(ctx.matrix @ t, ctx.visibility, ctx.stroke, ctx.fill, ctx.layer,
                 ctx.selected)
        target = self.ids[href[1:]]
        self.use_depth += 1
        try:
            if target.tag == "symbol":
                for child in target.children:
                    self.walk(child, c)
            else:
                self.walk(target, c)
        finally:
            self.use_depth -= 1

    def _transform(self, text: str, node: Node) -> np.ndarray:
        try:
            return np.asarray(parse_transform(text, strict=True), dtype=np.float64)
        except (ValueError, TypeError, IndexError) as e:
            raise InputError(f"<{node.tag}> transform={text!r}: {e}", self.file,
                             node.line) from e

    def _viewbox(self, node: Node) -> tuple[float, float, float, float] | None:
        text = node.get("viewBox")
        if text is None:
            return None
        v = _numbers(text, self.file, node.line, "viewBox")
        if len(v) != 4 or not all(math.isfinite(x) for x in v) or v[2] <= 0 or v[3] <= 0:
            raise InputError(f"viewBox={text!r} must be four numbers with positive width and "
                             "height", self.file, node.line)
        return v[0], v[1], v[2], v[3]

    # ---------------------------------------------------------------- shapes
    def shape(self, node: Node, ctx: _Ctx) -> None:
        src = self.b.add_source(node.get("id"), node.line, node.tag, ctx.layer)
        n0 = len(self.b.kinds)
        mid = self._matrix_id(ctx.matrix)
        for sub in self._segments(node):
            self.b.begin_stroke(src)
            self.b.add_many(sub, node.line, mid)
        if len(self.b.kinds) == n0:
            self.b.sources.pop()

    def _matrix_id(self, m: np.ndarray) -> int:
        """Index of matrix m in the builder's list (consecutive shapes share one entry)."""
        mats = self.b.matrices
        if not mats or not np.array_equal(mats[-1], m):
            mats.append(m)
        return len(mats) - 1

    def _segments(self, node: Node) -> Iterator[list[tuple[int, tuple[float, ...]]]]:
        """Subpaths (pen-down runs) of one shape, in user units, untransformed."""
        f, ln, tag = self.file, node.line, node.tag
        if tag == "path":
            yield from _path_subpaths(node.get("d") or "", f, ln)
        elif tag == "line":
            x1, y1, x2, y2 = (_user_length(node.get(k), f, ln, k) for k in
                              ("x1", "y1", "x2", "y2"))
            if (x1, y1) != (x2, y2):
                yield [(LINE, (x1, y1, x2, y2))]
        elif tag in ("polyline", "polygon"):
            v = _numbers(node.get("points") or "", f, ln, "points")
            if len(v) % 2:
                raise InputError(f"<{tag}> points has an odd number of coordinates "
                                 f"({len(v)})", f, ln)
            pts = list(zip(v[0::2], v[1::2], strict=True))
            if tag == "polygon" and len(pts) > 1 and pts[0] != pts[-1]:
                pts.append(pts[0])
            seg: list[tuple[int, tuple[float, ...]]] = [
                (LINE, (*a, *b)) for a, b in itertools.pairwise(pts) if a != b]
            if seg:
                yield seg
        elif tag == "rect":
            yield from _rect(node, f, ln)
        elif tag in ("circle", "ellipse"):
            cx = _user_length(node.get("cx"), f, ln, "cx")
            cy = _user_length(node.get("cy"), f, ln, "cy")
            if tag == "circle":
                rx = ry = _user_length(node.get("r"), f, ln, "r")
            else:
                rx = _user_length(node.get("rx"), f, ln, "rx", -1.0)
                ry = _user_length(node.get("ry"), f, ln, "ry", -1.0)
                rx, ry = (ry if rx < 0 else rx), (rx if ry < 0 else ry)  # SVG 2 auto
            if rx < 0 or ry < 0:
                raise InputError(f"<{tag}> has a negative radius", f, ln)
            if rx > 0 and ry > 0:
                # Starts at 3 o'clock and runs with increasing angle in the page's y-down
                # frame (clockwise on screen), as the SVG spec's equivalent path does.
                yield [(ARC, (cx, cy, rx, 0.0, 0.0, ry, 0.0, 2 * math.pi))]


def _rect(node: Node, f: str, ln: int) -> Iterator[list[tuple[int, tuple[float, ...]]]]:
    """<rect>, rounded corners per SVG 1.1 §9.2: rx, ry default to each other and are clamped
    to half the width and height."""
    x = _user_length(node.get("x"), f, ln, "x")
    y = _user_length(node.get("y"), f, ln, "y")
    w = _user_length(node.get("width"), f, ln, "width")
    h = _user_length(node.get("height"), f, ln, "height")
    if w < 0 or h < 0:
        raise InputError("<rect> has a negative width or height", f, ln)
    if w == 0 or h == 0:
        return
    rxs, rys = node.get("rx"), node.get("ry")
    rx = _user_length(rxs, f, ln, "rx") if rxs not in (None, "auto") else None
    ry = _user_length(rys, f, ln, "ry") if rys not in (None, "auto") else None
    if rx is None and ry is None:
        rx = ry = 0.0
    elif rx is None:
        rx = ry
    elif ry is None:
        ry = rx
    assert rx is not None and ry is not None
    rx, ry = min(max(rx, 0.0), w / 2), min(max(ry, 0.0), h / 2)
    if rx == 0 or ry == 0:
        pts = [(x, y), (x + w, y), (x + w, y + h), (x, y + h), (x, y)]
        yield [(LINE, (*a, *b)) for a, b in itertools.pairwise(pts)]
        return
    segs: list[tuple[int, tuple[float, ...]]] = []
    hp = math.pi / 2

    def line(x1: float, y1: float, x2: float, y2: float) -> None:
        if (x1, y1) != (x2, y2):
            segs.append((LINE, (x1, y1, x2, y2)))

    def arc(cx: float, cy: float, th0: float) -> None:
        segs.append((ARC, (cx, cy, rx, 0.0, 0.0, ry, th0, hp)))

    line(x + rx, y, x + w - rx, y)
    arc(x + w - rx, y + ry, -hp)
    line(x + w, y + ry, x + w, y + h - ry)
    arc(x + w - rx, y + h - ry, 0.0)
    line(x + w - rx, y + h, x + rx, y + h)
    arc(x + rx, y + h - ry, hp)
    line(x, y + h - ry, x, y + ry)
    arc(x + rx, y + ry, math.pi)
    yield segs


def _path_subpaths(d: str, f: str, ln: int) -> Iterator[list[tuple[int, tuple[float, ...]]]]:
    """Path data through svgpathtools, split into continuous subpaths."""
    if not d.strip():
        return
    try:
        path = svgpathtools.parse_path(d)
    except Exception as e:  # svgpathtools raises ValueError/IndexError/... on bad data
        raise InputError(f"<path> d attribute cannot be parsed: {e}", f, ln) from e
    cur: list[tuple[int, tuple[float, ...]]] = []
    last_end: complex | None = None
    for seg in path:
        s, en = seg.start, seg.end
        if last_end is not None and s != last_end:
            if cur:
                yield cur
            cur = []
        last_end = en
        if isinstance(seg, svgpathtools.Line):
            if s != en:
                cur.append((LINE, (s.real, s.imag, en.real, en.imag)))
        elif isinstance(seg, svgpathtools.CubicBezier):
            c1, c2 = seg.control1, seg.control2
            if not (s == c1 == c2 == en):
                cur.append((CUBIC, (s.real, s.imag, c1.real, c1.imag, c2.real, c2.imag,
                                    en.real, en.imag)))
        elif isinstance(seg, svgpathtools.QuadraticBezier):
            q = seg.control
            if not (s == q == en):
                # Exact degree elevation: c1 = s + 2/3 (q − s), c2 = en + 2/3 (q − en).
                c1 = s + (q - s) * (2.0 / 3.0)
                c2 = en + (q - en) * (2.0 / 3.0)
                cur.append((CUBIC, (s.real, s.imag, c1.real, c1.imag, c2.real, c2.imag,
                                    en.real, en.imag)))
        elif isinstance(seg, svgpathtools.Arc):
            if s == en:
                continue  # SVG: an arc with equal end points is omitted
            rx, ry = seg.radius.real, seg.radius.imag
            if rx == 0 or ry == 0:
                cur.append((LINE, (s.real, s.imag, en.real, en.imag)))  # SVG: treated as line
                continue
            phi = math.radians(seg.rotation)
            cphi, sphi = math.cos(phi), math.sin(phi)
            # point(t) = center + R(φ)·(rx cos a, ry sin a), a = θ + tΔ (svgpathtools Arc)
            cur.append((ARC, (seg.center.real, seg.center.imag, rx * cphi, -ry * sphi,
                              rx * sphi, ry * cphi, math.radians(seg.theta),
                              math.radians(seg.delta))))
        else:  # pragma: no cover - svgpathtools has no other segment types
            raise InputError(f"<path> has an unsupported segment {type(seg).__name__}", f, ln)
    if cur:
        yield cur


def read_svg(source: str | Path | bytes, layers: Sequence[str] | None = None,
             file: str | None = None) -> Drawing:
    """Read an SVG file (path or bytes) into a `Drawing` in mm, y up, page bottom-left at 0.

    `layers`: Inkscape layer labels or ids to draw (None: everything visible).
    """
    data, name = read_source(source, file, "<svg>")
    root = _parse_xml(data, name)
    if root.tag != "svg":
        raise InputError(f"root element is <{root.tag}>, not <svg>", name, root.line)
    r = _Reader(name, layers)
    r.index_ids(root)
    vb = r._viewbox(root)
    default_w = vb[2] * MM_PER_PX if vb else None
    default_h = vb[3] * MM_PER_PX if vb else None
    width_mm = parse_length(root.get("width"), name, root.line, "width", default_w)
    height_mm = parse_length(root.get("height"), name, root.line, "height", default_h)
    if width_mm <= 0 or height_mm <= 0:
        raise InputError(f"page size {width_mm:g} × {height_mm:g} mm must be positive", name,
                         root.line)
    # user units → viewport px → mm: viewBox mapping in mm directly.
    if vb is not None:
        page = viewport_transform(vb, width_mm, height_mm, root.get("preserveAspectRatio"))
    else:
        page = np.diag([MM_PER_PX, MM_PER_PX, 1.0])
    # page frame (mm, y down) → drawing frame (mm, y up, bottom-left origin)
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, height_mm], [0.0, 0.0, 1.0]])
    st = _style(root)
    ctx = _Ctx(flip @ page, st.get("visibility", "visible"), st.get("stroke", "none"),
               st.get("fill", "black"), None, not r.layers)
    if st.get("display") == "none":
        raise InputError("the root <svg> has display:none", name, root.line)
    for child in root.children:
        r.walk(child, ctx)
    if r.layers:
        names = {n for pair in r.found_layers for n in pair if n}
        missing = [x for x in r.layers if x not in names]
        if missing:
            avail = ", ".join(sorted(f'"{lb}" (id {i})' for lb, i in r.found_layers)) or "none"
            raise InputError(f"no layer named {', '.join(map(repr, missing))}; layers in "
                             f"this file: {avail}", name)
    for tag, n in sorted(r.ignored_tags.items()):
        r.b.warnings.append(f"ignored {n} <{tag}> element(s) (only outlines of shapes are "
                            "drawn; convert text to paths)" if tag == "text"
                            else f"ignored {n} <{tag}> element(s)")
    if r.skipped_hidden:
        r.b.warnings.append(f"skipped {r.skipped_hidden} hidden element(s)")
    drawing = r.b.build(page_height_mm=height_mm, page_size_mm=(width_mm, height_mm))
    # Coordinates must be finite and of sane size once in mm (checked once, vectorised).
    bad = ~np.isfinite(drawing.params).all(axis=1) | (
        np.abs(np.nan_to_num(drawing.params, nan=0.0)).max(axis=1, initial=0.0) > MAX_COORD_MM)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        src = drawing.sources[int(drawing.stroke_source[drawing.stroke[i]])]
        raise InputError(f"<{src.tag}> has a coordinate that is not finite or larger than "
                         f"{MAX_COORD_MM:g} mm", name, int(drawing.line[i]))
    if drawing.kind.shape[0] == 0:
        what = f" in layer(s) {', '.join(r.layers)}" if r.layers else ""
        raise InputError(f"no strokes to draw{what}: the file has no visible path, line, "
                         "polyline, polygon, rect, circle or ellipse with a non-zero extent",
                         name)
    return drawing
