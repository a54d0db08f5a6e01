"""The SVG reader's walk over the element tree: cascade, transforms, viewports, `<use>`,
`<symbol>`, `<switch>`, visibility, and where each shape's primitives go (the drawing, or a
collector when a clip path, mask or bounding box is being measured).

- `<switch>` renders its first direct child whose conditional attributes all evaluate true
  (SVG 2 §5.8.2): `requiredExtensions` is true only if empty-free and absent (no extension is
  supported); `systemLanguage` matches the reader's language (default "en") by equality or
  by prefix up to a '-', either way; `requiredFeatures` was removed in SVG 2 and is ignored,
  as browsers do.
- `<use>` of a `<symbol>` (SVG 2 §5.6): the symbol's viewport is the use's width/height (else
  the symbol's own, else 100%), its viewBox and preserveAspectRatio map into it, and its
  content is clipped to it unless `overflow` is visible; the same for nested `<svg>`.
- Every kind of thing that is not drawn as the file shows (partial opacity, dashes, invalid
  path data, unsupported CSS) is said once per kind, naming the first element and the count.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from shapely.geometry.base import BaseGeometry

from fivebar_host.errors import InputError
from fivebar_host.toolpath.fill.paint import PaintRecorder
from fivebar_host.toolpath.fonts.library import FontLibrary
from fivebar_host.toolpath.geometry import DrawingBuilder, TextInfo
from fivebar_host.toolpath.svg import clip
from fivebar_host.toolpath.svg.css import StyleSheet
from fivebar_host.toolpath.svg.markers import Markers, expand_shorthand
from fivebar_host.toolpath.svg.paint import INHERITED, inherit, number_or_percent, painted
from fivebar_host.toolpath.svg.paintorder import record_shape
from fivebar_host.toolpath.svg.shapes import SHAPES, shape_subpaths
from fivebar_host.toolpath.svg.text import CharLayout, draw_text
from fivebar_host.toolpath.svg.undrawn import Undrawn
from fivebar_host.toolpath.svg.units import Lengths, numbers, viewport_transform
from fivebar_host.toolpath.svg.xmltree import INKSCAPE_NS, XLINK_NS, Node

#: Elements whose content is never drawn directly.
NOT_RENDERED = {"defs", "symbol", "clipPath", "mask", "marker", "pattern", "metadata", "title",
                "desc", "style", "script", "linearGradient", "radialGradient", "filter",
                "namedview", "foreignObject"}
#: Text the reader does not draw: Inkscape's flowed text (not SVG; browsers show nothing).
FLOWED = ("flowRoot",)
#: Elements instantiated through `<use>` before the file is refused (exponential nesting).
MAX_USE_VISITS = 500_000


@dataclass(frozen=True)
class Ctx:
    matrix: np.ndarray  # 3×3 user units → drawing frame (mm, y up)
    props: dict[str, str]  # inherited properties
    lengths: Lengths
    layer: str | None
    selected: bool
    clip: BaseGeometry | None = None
    opacity: float = 1.0


@dataclass
class Collected:
    """A shape met while collecting: its element, context and subpaths in the drawing frame."""

    node: Node
    ctx: Ctx
    subpaths: clip.Subpaths


class Walker:
    def __init__(self, file: str, layers: Sequence[str] | None, language: str,
                 max_segments: int | None = None, limit_hint: str = "",
                 fonts: FontLibrary | None = None) -> None:
        self.file = file
        self.fonts = fonts or FontLibrary()
        #: each drawn text element's character layout, when a caller asks (`read_svg`)
        self.layouts: list[CharLayout] | None = None
        self.layers = [s for s in (layers or []) if s]
        self.language = language.lower()
        self.found_layers: list[tuple[str | None, str | None]] = []
        self.b = DrawingBuilder(file, max_segments, limit_hint)
        self.ids: dict[str, Node] = {}
        self.sheet = StyleSheet()
        self.skipped_hidden = 0
        self.use_depth = 0
        self.use_visits = 0
        self.ignored_tags: dict[str, int] = {}
        self.text_nodes: list[Node] = []
        self.notes: dict[str, tuple[str, Node, int]] = {}
        self.undrawn = Undrawn()  # element kinds and properties not drawn (one note)
        self.markers = Markers(self)
        self.collector: list[Collected] | None = None
        self.collect_all_paint = False
        self.region: Callable[[Node, dict[str, str], Ctx], Ctx] | None = None
        self.paint = PaintRecorder()  # each drawn shape's fill rule and stroke, by source
        self.images: list[ImageRef] = []  # the drawn <image> elements, in paint order

    @property
    def texts(self) -> list[TextInfo]:
        """The text elements drawn so far (`svg.text`), kept by the builder."""
        return self.b.texts

    # ---------------------------------------------------------------- bookkeeping
    def note(self, kind: str, node: Node, message: str) -> None:
        """Remember a warning of this kind (first element, count)."""
        if self.collector is not None and kind not in ("path-data", "css"):
            return
        if kind in self.notes:
            msg, first, n = self.notes[kind]
            self.notes[kind] = (msg, first, n + 1)
        else:
            self.notes[kind] = (message, node, 1)

    def index(self, root: Node) -> None:
        """Ids of the whole document, first one wins (iteratively: files nest deeply). The
        style sheets come from the reader's first pass (`stream.scan`)."""
        stack = [root]
        while stack:
            node = stack.pop()
            ident = node.get("id")
            if ident and ident not in self.ids:
                self.ids[ident] = node
            stack.extend(reversed(node.children))

    def transform(self, text: str, node: Node) -> np.ndarray:
        # imported on first use: svgpathtools pulls in scipy (about 55 MiB and 0.4 s), which
        # a drawing without transforms never needs
        from svgpathtools.parser import parse_transform

        try:
            m = np.asarray(parse_transform(text, strict=True), dtype=np.float64)
        except (ValueError, TypeError, IndexError, OverflowError) as e:
            raise InputError(f"<{node.tag}> transform={text!r}: {e}", self.file,
                             node.line) from e
        if not np.isfinite(m).all():
            raise InputError(f"<{node.tag}> transform={text!r} is not finite", self.file,
                             node.line)
        return m

    def viewbox(self, node: Node) -> tuple[float, float, float, float] | None:
        text = node.get("viewBox")
        if text is None or not text.strip():
            return None
        v = numbers(text, self.file, node.line, "viewBox")
        if len(v) != 4 or not np.isfinite(v).all() or v[2] <= 0 or v[3] <= 0:
            raise InputError(f"viewBox={text!r} must be four numbers with positive width and "
                             "height", self.file, node.line)
        return v[0], v[1], v[2], v[3]

    def props_at(self, node: Node) -> dict[str, str]:
        """Inherited properties of an element from its own ancestors (for the content of a
        `<clipPath>` or `<mask>`, which inherits from where it is defined, not used)."""
        chain = []
        n: Node | None = node
        while n is not None:
            chain.append(n)
            n = n.parent
        props = root_props()
        for a in reversed(chain):
            props = inherit(props, expand_shorthand(self.sheet.cascade(a)))
        return props

    # ---------------------------------------------------------------- traversal
    def walk(self, node: Node, ctx: Ctx) -> None:
        if not node.is_svg:
            return
        if self.collector is None and self.undrawn.element(node):
            return
        if node.tag in NOT_RENDERED:
            return
        if self.use_depth:
            self.use_visits += 1
            if self.use_visits > MAX_USE_VISITS:
                raise InputError(f"<use> references expand to more than {MAX_USE_VISITS} "
                                 "elements", self.file, node.line)
        spec = self.sheet.cascade(node)
        if spec.get("display", "").strip().lower() == "none":
            self.skipped_hidden += self.collector is None
            return
        c = self.enter(node, spec, ctx, node.tag != "svg")
        if c.opacity <= 0.0:
            self.skipped_hidden += self.collector is None
            return
        if self.collector is None:
            self.undrawn.properties(node, spec)
        self.dispatch(node, c)

    def enter(self, node: Node, spec: dict[str, str], ctx: Ctx, own_transform: bool) -> Ctx:
        """The context of an element's content: transform, inherited properties, font size,
        opacity, layer, and its clip path and mask (intersected with the parent's region)."""
        m = ctx.matrix
        tf = node.get("transform")
        if tf and own_transform:
            m = m @ self.transform(tf, node)
        layer, selected = ctx.layer, ctx.selected
        if node.tag == "g" and node.get(f"{INKSCAPE_NS} groupmode") == "layer":
            label, ident = node.get(f"{INKSCAPE_NS} label"), node.get("id")
            self.found_layers.append((label, ident))
            layer = label or ident
            if self.layers:
                selected = selected or label in self.layers or ident in self.layers
        font = ctx.lengths.font_size(spec.get("font-size"), self.file, node.line) \
            if "font-size" in spec else ctx.lengths.font_px
        lengths = replace(ctx.lengths, font_px=font)
        c = Ctx(m, inherit(ctx.props, expand_shorthand(spec)), lengths, layer, selected,
                ctx.clip,
                ctx.opacity * number_or_percent(spec.get("opacity")))
        if self.region is not None and ("clip-path" in spec or "mask" in spec):
            c = self.region(node, spec, c)
        return c

    def dispatch(self, node: Node, c: Ctx) -> None:
        tag = node.tag
        if tag in ("g", "a"):
            for child in node.children:
                self.walk(child, c)
        elif tag == "switch":
            for child in node.children:
                if child.is_svg and self.conditions_hold(child):
                    self.walk(child, c)
                    break
        elif tag == "svg":
            self.walk_viewport(node, node, c, None, None)
        elif tag == "use":
            self.walk_use(node, c)
        elif tag in SHAPES:
            self.shape(node, c)
        elif tag == "text":
            draw_text(self, node, c)
        elif tag == "image":
            self.image(node, c)
        elif tag in FLOWED:
            if self.collector is None and c.props["visibility"] == "visible":
                self.text_nodes.append(node)
        elif self.collector is None:
            self.ignored_tags[tag] = self.ignored_tags.get(tag, 0) + 1

    def conditions_hold(self, node: Node) -> bool:
        """`<switch>` test of one child's conditional processing attributes."""
        ext = node.get("requiredExtensions")
        if ext is not None:
            return False  # present (empty or naming extensions): none is supported
        langs = node.get("systemLanguage")
        if langs is None:
            return True
        for tag in (t.strip().lower() for t in langs.split(",")):
            if tag and (tag == self.language or tag.startswith(self.language + "-")
                        or self.language.startswith(tag + "-")):
                return True
        return False

    def walk_viewport(self, node: Node, content: Node, ctx: Ctx, w_attr: str | None,
                      h_attr: str | None) -> None:
        """A nested `<svg>` or an instantiated `<symbol>`: x, y, width × height (100% by
        default) in the parent's user space, viewBox mapped into it, overflow clipped."""
        f, ln, lg = self.file, node.line, ctx.lengths
        x = lg.user(content.get("x"), f, ln, "x")
        y = lg.user(content.get("y"), f, ln, "y")
        vb = self.viewbox(content)
        w = lg.user(w_attr or content.get("width") or "100%", f, ln, "width")
        h = lg.user(h_attr or content.get("height") or "100%", f, ln, "height")
        if w <= 0 or h <= 0:
            return  # SVG: a zero-sized viewport disables rendering
        t = np.identity(3)
        t[0, 2], t[1, 2] = x, y
        base = ctx.matrix @ t
        c = replace(ctx, matrix=base @ viewport_transform(vb, w, h,
                                                          content.get("preserveAspectRatio")),
                    lengths=replace(lg, width=vb[2] if vb else w, height=vb[3] if vb else h))
        overflow = self.sheet.cascade(content).get("overflow", "hidden").strip().lower()
        if overflow not in ("visible", "auto"):
            box = clip.transform_subpaths([[(0, (0.0, 0.0, w, 0.0)), (0, (w, 0.0, w, h)),
                                            (0, (w, h, 0.0, h)), (0, (0.0, h, 0.0, 0.0))]], base)
            clip.check_finite(box, f, ln, node.tag)
            ring = clip.fill_region(box, "nonzero", clip.tolerance(clip.extent(box)))
            c = replace(c, clip=ring if ctx.clip is None else ctx.clip.intersection(ring))
        for child in content.children:
            self.walk(child, c)

    def walk_use(self, node: Node, ctx: Ctx) -> None:
        href = node.get("href") or node.get(f"{XLINK_NS} href") or ""
        if not href.startswith("#") or href[1:] not in self.ids:
            raise InputError(f"<use> references {href!r}, which is not an element id in "
                             "this file", self.file, node.line)
        if self.use_depth > 32:
            raise InputError("<use> references nest too deeply (a cycle?)", self.file,
                             node.line)
        t = np.identity(3)
        t[0, 2] = ctx.lengths.user(node.get("x"), self.file, node.line, "x")
        t[1, 2] = ctx.lengths.user(node.get("y"), self.file, node.line, "y")
        c = replace(ctx, matrix=ctx.matrix @ t)
        target = self.ids[href[1:]]
        if not target.is_svg:
            return
        self.use_depth += 1
        try:
            if target.tag in ("symbol", "svg"):
                spec = self.sheet.cascade(target)
                if spec.get("display", "").strip().lower() == "none":
                    return
                c = self.enter(target, spec, c, target.tag == "symbol")
                self.walk_viewport(node, target, c, node.get("width"), node.get("height"))
            else:
                self.walk(target, c)
        finally:
            self.use_depth -= 1

    # ---------------------------------------------------------------- shapes
    def image(self, node: Node, c: Ctx) -> None:
        """An `<image>`: its box and href kept for the raster route (`raster.svgimage`)."""
        if self.collector is not None or not c.selected:
            return
        if c.props["visibility"].strip().lower() in ("hidden", "collapse"):
            self.skipped_hidden += 1
            return
        f, ln, lg = self.file, node.line, c.lengths

        def size(attr: str) -> float | None:
            text = node.get(attr)
            if text is None or text.strip() in ("", "auto"):
                return None
            return lg.user(text, f, ln, attr)

        href = node.get("href") or node.get(f"{XLINK_NS} href") or ""
        self.images.append(ImageRef(node.line, node.get("id"), href.strip(),
                                    lg.user(node.get("x"), f, ln, "x"),
                                    lg.user(node.get("y"), f, ln, "y"), size("width"),
                                    size("height"), node.get("preserveAspectRatio"),
                                    c.matrix, c.clip))

    def visible(self, node: Node, c: Ctx) -> bool:
        """Whether a shape paints anything; warns about what a pen cannot show."""
        p = c.props
        if p["visibility"].strip().lower() in ("hidden", "collapse"):
            return False
        try:
            width = c.lengths.user(p["stroke-width"], self.file, node.line, "stroke-width")
        except InputError:
            width = 1.0  # an invalid declaration is ignored (CSS)
        stroke = (painted(p["stroke"]) and number_or_percent(p["stroke-opacity"]) > 0
                  and width > 0)
        fill = (node.tag != "line" and painted(p["fill"])
                and number_or_percent(p["fill-opacity"]) > 0)  # a line has no interior
        if not (stroke or fill):
            return False
        if c.opacity < 1.0 or (stroke and number_or_percent(p["stroke-opacity"]) < 1) or (
                not stroke and number_or_percent(p["fill-opacity"]) < 1):
            self.note("opacity", node, "partly transparent element(s) drawn as solid lines "
                                       "(a pen cannot draw partial opacity)")
        if stroke and p["stroke-dasharray"].strip().lower() not in ("none", "", "0"):
            self.note("dash", node, "dashed stroke(s) (stroke-dasharray) drawn as solid lines")
        return True

    def shape(self, node: Node, c: Ctx) -> None:
        if not c.selected and self.collector is None:
            return
        painted_too = True
        if self.collector is None or not self.collect_all_paint:
            painted_too = self.visible(node, c)
            marked = self.collector is None and any(
                c.props.get(p, "none").strip() not in ("none", "") for p in
                ("marker-start", "marker-mid", "marker-end"))
            if not painted_too and not (marked and c.props["visibility"].strip().lower()
                                        not in ("hidden", "collapse")):
                self.skipped_hidden += self.collector is None
                return
        elif c.props["visibility"].strip().lower() in ("hidden", "collapse"):
            return
        res = shape_subpaths(node, c.lengths, self.file)
        if res.error is not None:
            e = res.error
            attr = "d" if node.tag == "path" else "points"
            self.note("path-data", node,
                      f"invalid {attr} data at column {e.pos + 1}: {e.reason}; drawn up to "
                      "the error, as the SVG specification and browsers do")
        if not res.subpaths:
            return
        if self.collector is not None:
            subs = clip.transform_subpaths(res.subpaths, c.matrix)
            clip.check_finite(subs, self.file, node.line, node.tag)
            self.collector.append(Collected(node, c, subs))
            return
        if painted_too:
            record_shape(self, node, c, res.subpaths, self.emit(node, c, res.subpaths))
        self.markers.draw(node, c, res.subpaths)

    def emit(self, node: Node, c: Ctx, subpaths: clip.Subpaths, tag: str | None = None) -> int:
        """Draw an element's subpaths (user units) as one source, clipped by the context's
        region; into the collector when one is set. The source's index, −1 for none."""
        if self.collector is not None:
            subs = clip.transform_subpaths(subpaths, c.matrix)
            clip.check_finite(subs, self.file, node.line, node.tag)
            self.collector.append(Collected(node, c, subs))
            return -1
        src = self.b.add_source(node.get("id"), node.line, tag or node.tag, c.layer)
        n0 = len(self.b.kinds)
        if c.clip is None:
            mats = self.b.matrices
            # (the same context's matrix is the same object: no element-wise comparison)
            if not mats or (mats[-1] is not c.matrix and not np.array_equal(mats[-1], c.matrix)):
                mats.append(c.matrix)
            mid = len(mats) - 1
        else:
            subpaths = clip.transform_subpaths(subpaths, c.matrix)
            clip.check_finite(subpaths, self.file, node.line, node.tag)
            box = clip.extent(subpaths)
            subpaths = clip.clip_subpaths(subpaths, c.clip, clip.tolerance(box))
            mid = -1
        for sub in subpaths:
            self.b.begin_stroke(src)
            self.b.add_many(sub, node.line, mid)
        if len(self.b.kinds) == n0:
            self.b.sources.pop()
            return -1
        return src


@dataclass(frozen=True)
class ImageRef:
    """An `<image>` as met by the walk: its line and id, href, x/y/width/height in user
    units (None: the image's own size), preserveAspectRatio, the 3×3 map of its user units
    to the drawing frame (mm, y up) and the clip region of its ancestors (drawing frame)."""

    line: int
    ident: str | None
    href: str
    x: float
    y: float
    width: float | None
    height: float | None
    par: str | None
    matrix: np.ndarray
    clip: BaseGeometry | None


def root_props() -> dict[str, str]:
    return dict(INHERITED)
