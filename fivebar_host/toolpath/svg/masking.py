"""`clip-path` and `mask` (CSS Masking 1) as regions the pen lines are clipped to.

- clip-path: `url(#id)` of a `<clipPath>`: the union of its shapes' fill areas, each with its
  own `clip-rule` and transforms, in `clipPathUnits` userSpaceOnUse (default) or
  objectBoundingBox (unit square = the element's bounding box), the `<clipPath>`'s own
  `transform` and `clip-path` applied. Strokes and paint of the content do not matter (spec).
  A clip path with no content clips everything away. CSS basic shapes (`circle(...)`) are
  refused with the reason; a reference to a missing element is ignored with a warning, as
  browsers ignore it.
- mask: a pen cannot draw partial opacity, so a mask becomes a region: its content is painted
  in order; where a shape paints an opaque colour, the mask there becomes that colour's
  luminance (alpha for `mask-type: alpha`): non-zero → the masked lines are drawn there,
  zero (black) → not drawn. Where the mask is grey or partly transparent the lines are
  drawn at full strength and a warning says so. Masks painted with gradients, patterns or
  images, or containing text, are refused (the region cannot be known). The mask's own
  rectangle (`maskUnits`, x/y/width/height, default −10 %/120 % of the bounding box) limits
  the region too.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.errors import InputError
from fivebar_host.toolpath.svg import clip
from fivebar_host.toolpath.svg.paint import colour, number_or_percent, painted
from fivebar_host.toolpath.svg.shapes import SHAPES, shape_subpaths
from fivebar_host.toolpath.svg.walk import Collected, Ctx, Walker
from fivebar_host.toolpath.svg.xmltree import Node

_URL = re.compile(r"url\(\s*['\"]?#([^'\")\s]+)['\"]?\s*\)$")
_CLIP_DEPTH_MAX = 16


class Masking:
    """Installs itself as the walker's region hook."""

    def __init__(self, w: Walker) -> None:
        self.w = w
        self.depth = 0
        w.region = self.apply

    def apply(self, node: Node, spec: dict[str, str], c: Ctx) -> Ctx:
        region: BaseGeometry | None = None
        for prop in ("clip-path", "mask"):
            value = spec.get(prop, "none").strip()
            if value.lower() in ("none", ""):
                continue
            ref = self._reference(node, prop, value)
            if ref is None:
                continue
            self.depth += 1
            try:
                if self.depth > _CLIP_DEPTH_MAX:
                    raise InputError(f"{prop} references nest too deeply (a cycle?)",
                                     self.w.file, node.line)
                r = self.clip_region(ref, node, c) if prop == "clip-path" else \
                    self.mask_region(ref, node, c)
            finally:
                self.depth -= 1
            region = r if region is None else region.intersection(r)
        if region is None:
            return c
        return replace(c, clip=region if c.clip is None else c.clip.intersection(region))

    def _reference(self, node: Node, prop: str, value: str) -> Node | None:
        m = _URL.match(value)
        want = "clipPath" if prop == "clip-path" else "mask"
        if not m:
            raise InputError(f"{node.describe()} {prop}: {value!r} is not supported (only "
                             f"url(#id) of a <{want}>); the drawing would not be clipped as "
                             "shown", self.w.file, node.line)
        ref = self.w.ids.get(m.group(1))
        if ref is None or ref.tag != want:
            self.w.note(f"{prop}-missing", node,
                        f"{prop} {value} does not name a <{want}> in this file; the "
                        "element is drawn unclipped, as browsers draw it")
            return None
        return ref

    # ---------------------------------------------------------------- collecting
    def collect(self, content: list[Node], c: Ctx, all_paint: bool) -> list[Collected]:
        """The shapes of these elements in the drawing frame, with their contexts."""
        w = self.w
        saved = (w.collector, w.collect_all_paint)
        w.collector, w.collect_all_paint = [], all_paint
        try:
            for child in content:
                w.walk(child, c)
            return w.collector
        finally:
            w.collector, w.collect_all_paint = saved

    def bbox(self, node: Node, c: Ctx) -> tuple[float, float, float, float]:
        """The element's bounding box in its own user space (fill geometry, no stroke)."""
        inner = replace(c, matrix=np.identity(3), clip=None)
        if node.tag in SHAPES:
            subs = shape_subpaths(node, c.lengths, self.w.file).subpaths
        else:
            w = self.w
            saved = (w.collector, w.collect_all_paint)
            w.collector, w.collect_all_paint = [], True
            try:
                if node.tag == "use":
                    w.walk_use(node, inner)
                else:
                    for child in node.children:
                        w.walk(child, inner)
                subs = [s for it in w.collector for s in it.subpaths]
            finally:
                w.collector, w.collect_all_paint = saved
        box = clip.extent(subs)
        if box is None:
            return 0.0, 0.0, 0.0, 0.0
        clip.check_finite(subs, self.w.file, node.line, node.tag)
        tol = clip.tolerance(box)
        pts = np.concatenate([clip.polyline(k, p, tol)[0] for s in subs for k, p in s])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def _units_matrix(self, ref: Node, attr: str, default: str, node: Node,
                      c: Ctx) -> np.ndarray | None:
        """The bounding-box map for objectBoundingBox units (None: userSpaceOnUse); a
        zero-sized box makes the reference draw nothing (spec), returned as all zeros."""
        units = (ref.get(attr) or default).strip()
        if units != "objectBoundingBox":
            return None
        x0, y0, x1, y1 = self.bbox(node, c)
        return np.array([[x1 - x0, 0.0, x0], [0.0, y1 - y0, y0], [0.0, 0.0, 1.0]])

    # ---------------------------------------------------------------- clip-path
    def clip_region(self, ref: Node, node: Node, c: Ctx) -> BaseGeometry:
        w = self.w
        m = c.matrix
        tf = ref.get("transform")
        if tf:
            m = m @ w.transform(tf, ref)
        bb = self._units_matrix(ref, "clipPathUnits", "userSpaceOnUse", node, c)
        if bb is not None:
            if bb[0, 0] <= 0 or bb[1, 1] <= 0:
                return shapely.Polygon()
            m = m @ bb
        for child in ref.children:
            if child.is_svg and child.tag in ("text", "flowRoot"):
                raise InputError(f"<clipPath id=\"{ref.get('id')}\"> contains text, which "
                                 "fivebar cannot turn into outlines: convert text to paths "
                                 "(Inkscape: Path > Object to Path)", w.file, child.line)
        spec = w.sheet.cascade(ref)
        inner = Ctx(m, w.props_at(ref), c.lengths, c.layer, True, None, 1.0)
        kids = [k for k in ref.children if k.tag in SHAPES or k.tag == "use"]
        items = self.collect(kids, inner, True)
        subs = [s for it in items for s in it.subpaths]
        tol = clip.tolerance(clip.extent(subs))
        parts = []
        for it in items:
            g = clip.fill_region(it.subpaths, it.ctx.props["clip-rule"].strip(), tol)
            parts.append(g if it.ctx.clip is None else g.intersection(it.ctx.clip))
        region = shapely.union_all(parts) if parts else shapely.Polygon()
        if "clip-path" in spec:
            own = self.apply(ref, {"clip-path": spec["clip-path"]}, replace(c, clip=None))
            if own.clip is not None:
                region = region.intersection(own.clip)
        return region

    # ---------------------------------------------------------------- mask
    def mask_region(self, ref: Node, node: Node, c: Ctx) -> BaseGeometry:
        w = self.w
        for d in _descendants(ref):
            if d.is_svg and d.tag in ("text", "flowRoot", "image", "pattern"):
                raise InputError(f"<mask id=\"{ref.get('id')}\"> contains <{d.tag}>: its "
                                 "coverage cannot be turned into a region a pen can draw; "
                                 "use a <clipPath> or remove the mask", w.file, d.line)
        m = c.matrix
        bb = self._units_matrix(ref, "maskContentUnits", "userSpaceOnUse", node, c)
        if bb is not None:
            m = m @ bb
        alpha_mask = (w.sheet.cascade(ref).get("mask-type") or ref.get("mask-type") or
                      "").strip() == "alpha"
        inner = Ctx(m, w.props_at(ref), c.lengths, c.layer, True, None, 1.0)
        items = self.collect(list(ref.children), inner, False)
        subs = [s for it in items for s in it.subpaths]
        tol = clip.tolerance(clip.extent(subs))
        region: BaseGeometry = shapely.Polygon()
        for it in items:
            region = self._paint_item(region, it, ref, alpha_mask, tol)
        return region.intersection(self._mask_rect(ref, node, c))

    def _paint_item(self, region: BaseGeometry, it: Collected, ref: Node, alpha_mask: bool,
                    tol: float) -> BaseGeometry:
        p = it.ctx.props
        layers = []
        if painted(p["fill"]):
            layers.append((p["fill"], number_or_percent(p["fill-opacity"]),
                           clip.fill_region(it.subpaths, p["fill-rule"].strip(), tol)))
        if painted(p["stroke"]):
            sw = it.ctx.lengths.user(p["stroke-width"], self.w.file, it.node.line,
                                     "stroke-width")
            scale = float(np.sqrt(abs(np.linalg.det(it.ctx.matrix[:2, :2]))))
            layers.append((p["stroke"], number_or_percent(p["stroke-opacity"]),
                           clip.stroke_region(it.subpaths, sw * scale, tol)))
        for value, opacity, g in layers:
            col = colour(value)
            if not col.known:
                if value.strip().lower().startswith("url("):
                    raise InputError(f"<mask id=\"{ref.get('id')}\"> paints with {value}: a "
                                     "gradient or pattern gives partial opacity, which a pen "
                                     "cannot draw; use a <clipPath>", self.w.file,
                                     it.node.line)
                col = replace(col, luminance=0.5)
            a = col.alpha * opacity * it.ctx.opacity
            v = 1.0 if alpha_mask else col.luminance
            if a <= 0:
                continue
            if a >= 1 and v <= 0:
                region = region.difference(g)
                continue
            if a < 1 or v < 1 - 1e-9:
                self.w.note("mask-partial", it.node,
                            f"mask <mask id=\"{ref.get('id')}\"> is partly transparent (grey "
                            "or translucent content); the masked lines are drawn at full "
                            "strength wherever the mask is not fully black")
            if v > 0:
                region = region.union(g)
        return region

    def _mask_rect(self, ref: Node, node: Node, c: Ctx) -> BaseGeometry:
        """The mask's own rectangle in the drawing frame."""
        f, ln = self.w.file, ref.line
        obb = (ref.get("maskUnits") or "objectBoundingBox").strip() == "objectBoundingBox"
        vals = {k: ref.get(k) for k in ("x", "y", "width", "height")}
        defaults = {"x": "-10%", "y": "-10%", "width": "120%", "height": "120%"}
        if obb:
            x0, y0, x1, y1 = self.bbox(node, c)
            num = {k: _fraction(vals[k] or defaults[k], f, ln, k) for k in defaults}
            x, y = x0 + num["x"] * (x1 - x0), y0 + num["y"] * (y1 - y0)
            rw, rh = num["width"] * (x1 - x0), num["height"] * (y1 - y0)
        else:
            x, y, rw, rh = (c.lengths.user(vals[k] or defaults[k], f, ln, k) for k in defaults)
        if rw <= 0 or rh <= 0:
            return shapely.Polygon()
        box = clip.transform_subpaths([[(0, (x, y, x + rw, y)), (0, (x + rw, y, x + rw, y + rh)),
                                        (0, (x + rw, y + rh, x, y + rh)),
                                        (0, (x, y + rh, x, y))]], c.matrix)
        clip.check_finite(box, f, ln, "mask")
        return clip.fill_region(box, "nonzero", clip.tolerance(clip.extent(box)))


def _fraction(text: str, f: str, ln: int, what: str) -> float:
    t = text.strip()
    try:
        return float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError as e:
        raise InputError(f"<mask> {what}={text!r} is not a number or percentage", f, ln) from e


def _descendants(n: Node) -> list[Node]:
    out, stack = [], list(n.children)
    while stack:
        d = stack.pop()
        out.append(d)
        stack.extend(d.children)
    return out
