"""Markers (SVG 2 §11.6, "Markers"): `marker-start`, `marker-mid`, `marker-end` (and the
`marker` shorthand) on `<path>`, `<line>`, `<polyline>` and `<polygon>` draw the content of
the referenced `<marker>` at the shape's vertices, as browsers render them:

- **Vertices**: every primitive's start, and the last one's end. `marker-start` is on the
  path's first vertex, `marker-end` on its last, `marker-mid` on every other one (the starts
  and ends of inner subpaths included).
- **orient**: a number (deg, rad, grad, turn) fixes the angle; `auto` follows the path: at a
  vertex between two segments the bisector of the incoming and outgoing directions, at an
  open end the one direction there; a closed subpath (its end at its start) joins its last
  and first segments; `auto-start-reverse` turns the start marker by 180°. Directions are
  the primitives' tangents (a zero tangent: the chord).
- **Viewport**: `markerWidth` × `markerHeight` (default 3 × 3), the `viewBox` and
  `preserveAspectRatio` mapping the content into it; `refX`/`refY` (content units) is the
  point put on the vertex (SVG 2's keywords left/center/right are 0, as Chromium reads them);
  `markerUnits="strokeWidth"` (default) scales the viewport by the shape's stroke width,
  `userSpaceOnUse` does not. The content is clipped to the viewport unless `overflow` is
  visible or auto (browsers' `marker { overflow: hidden }`), and by the shape's own clip.
- **Style**: the content inherits from the marker's own ancestors, not from the shape.

Markers inside a marker's content are not drawn (browsers do not either).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from fivebar_host.toolpath.geometry import evaluate
from fivebar_host.toolpath.svg import clip
from fivebar_host.toolpath.svg.units import viewport_transform
from fivebar_host.toolpath.svg.xmltree import Node

if TYPE_CHECKING:
    from fivebar_host.toolpath.svg.walk import Ctx, Walker

MARKABLE = ("path", "line", "polyline", "polygon")
PROPS = ("marker-start", "marker-mid", "marker-end")
_URL = re.compile(r"^\s*url\(\s*['\"]?#([^'\")\s]+)['\"]?\s*\)\s*$")
_ANGLE = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(deg|rad|grad|turn)?\s*$")
_TO_RAD = {"deg": math.pi / 180, "rad": 1.0, "grad": math.pi / 200, "turn": 2 * math.pi,
           None: math.pi / 180}
_KEYWORDS = ("left", "top", "center", "right", "bottom")


def expand_shorthand(spec: dict[str, str]) -> dict[str, str]:
    """`marker: url(#a)` sets the three longhands an element does not set itself."""
    if "marker" not in spec:
        return spec
    out = {k: v for k, v in spec.items() if k != "marker"}
    for p in PROPS:
        out.setdefault(p, spec["marker"])
    return out


@dataclass(frozen=True)
class Vertex:
    """A vertex of a shape (user units) and the directions into and out of it (radians;
    None at an open end)."""

    x: float
    y: float
    into: float | None
    out: float | None


def _direction(kind: int, params: tuple[float, ...], t: float) -> float | None:
    """The direction of a primitive at t = 0 or 1 (the chord when the tangent is zero)."""
    p = np.array([params + (0.0,) * (8 - len(params))])
    d = evaluate(np.array([kind], np.int8), p, np.array([t]), 1)[0]
    if math.hypot(d[0], d[1]) < 1e-12:
        ends = evaluate(np.array([kind], np.int8), p, np.array([0.0, 1.0]))
        d = ends[1] - ends[0]
        if math.hypot(d[0], d[1]) < 1e-12:
            return None
    return math.atan2(d[1], d[0])


def vertices(subpaths: clip.Subpaths) -> list[Vertex]:
    """The shape's vertices in order, with their directions (module doc)."""
    out: list[Vertex] = []
    for sub in subpaths:
        if not sub:
            continue
        ks = [k for k, _ in sub]
        ps = [tuple(p) for _, p in sub]
        pts = evaluate(np.array(ks, np.int8),
                       np.array([p + (0.0,) * (8 - len(p)) for p in ps]),
                       np.zeros(len(ks)))
        end = evaluate(np.array(ks[-1:], np.int8),
                       np.array([ps[-1] + (0.0,) * (8 - len(ps[-1]))]), np.ones(1))[0]
        closed = math.hypot(end[0] - pts[0, 0], end[1] - pts[0, 1]) < 1e-9
        first_in = _direction(ks[-1], ps[-1], 1.0) if closed else None
        last_out = _direction(ks[0], ps[0], 0.0) if closed else None
        for i in range(len(ks)):
            into = first_in if i == 0 else _direction(ks[i - 1], ps[i - 1], 1.0)
            out.append(Vertex(float(pts[i, 0]), float(pts[i, 1]), into,
                              _direction(ks[i], ps[i], 0.0)))
        out.append(Vertex(float(end[0]), float(end[1]), _direction(ks[-1], ps[-1], 1.0),
                          last_out))
    return out


def _auto(v: Vertex) -> float:
    """orient="auto": the bisector of the two directions, or the one there is."""
    if v.into is None:
        return 0.0 if v.out is None else v.out
    if v.out is None:
        return v.into
    return math.atan2(math.sin(v.into) + math.sin(v.out), math.cos(v.into) + math.cos(v.out))


class Markers:
    """Draws the markers of the shapes the walker emits (`draw`)."""

    def __init__(self, walker: Walker) -> None:
        self.w = walker
        self.inside = False  # walking a marker's content: no markers there

    def draw(self, node: Node, c: Ctx, subpaths: clip.Subpaths) -> None:
        """Every marker of one shape (module doc)."""
        if self.inside or node.tag not in MARKABLE:
            return
        refs = {p: self._marker(c.props.get(p, "none")) for p in PROPS}
        if not any(refs.values()) or not subpaths:
            return
        vs = vertices(subpaths)
        if not vs:
            return
        for i, v in enumerate(vs):
            which = "marker-start" if i == 0 else "marker-end" if i == len(vs) - 1 \
                else "marker-mid"
            todo = [which] + (["marker-end"] if len(vs) == 1 else [])
            for prop in todo:
                marker = refs[prop]
                if marker is not None:
                    self._instance(marker, node, c, v, prop == "marker-start")

    def _marker(self, value: str) -> Node | None:
        m = _URL.match(value or "")
        ref = self.w.ids.get(m.group(1)) if m else None
        return ref if ref is not None and ref.tag == "marker" else None

    def _instance(self, marker: Node, node: Node, c: Ctx, v: Vertex, start: bool) -> None:
        """One marker's content at vertex `v`, in the drawing frame."""
        f, ln = self.w.file, marker.line
        lg = c.lengths
        mw = lg.user(marker.get("markerWidth"), f, ln, "markerWidth", 3.0)
        mh = lg.user(marker.get("markerHeight"), f, ln, "markerHeight", 3.0)
        if mw <= 0 or mh <= 0:
            return  # a zero-sized viewport disables rendering
        vb = self.w.viewbox(marker)
        to_viewport = viewport_transform(vb, mw, mh, marker.get("preserveAspectRatio"))
        ref = to_viewport @ np.array([self._ref(marker.get("refX"), vb, 0, mw, lg, f, ln),
                                      self._ref(marker.get("refY"), vb, 1, mh, lg, f, ln), 1.0])
        angle = self._orient(marker.get("orient"), v, start)
        scale = 1.0
        if (marker.get("markerUnits") or "strokeWidth").strip() != "userSpaceOnUse":
            scale = lg.user(c.props["stroke-width"], f, node.line, "stroke-width", 1.0)
        place = _affine(v.x, v.y, angle, scale) @ _translate(-ref[0], -ref[1])
        base = c.matrix @ place
        region = c.clip
        overflow = self.w.sheet.cascade(marker).get("overflow", "hidden").strip().lower()
        if overflow not in ("visible", "auto"):
            box = clip.transform_subpaths([[(0, (0.0, 0.0, mw, 0.0)), (0, (mw, 0.0, mw, mh)),
                                            (0, (mw, mh, 0.0, mh)), (0, (0.0, mh, 0.0, 0.0))]],
                                          base)
            clip.check_finite(box, f, ln, "marker")
            ring = clip.fill_region(box, "nonzero", clip.tolerance(clip.extent(box)))
            region = ring if region is None else region.intersection(ring)
        from fivebar_host.toolpath.svg.walk import Ctx

        inner = Ctx(base @ to_viewport, self.w.props_at(marker),
                    replace(lg, width=vb[2] if vb else mw, height=vb[3] if vb else mh),
                    c.layer, c.selected, region, c.opacity)
        self.inside = True
        try:
            for child in marker.children:
                self.w.walk(child, inner)
        finally:
            self.inside = False

    @staticmethod
    def _ref(text: str | None, vb: tuple[float, float, float, float] | None, axis: int,
             size: float, lg: object, f: str, ln: int) -> float:
        """refX/refY in content units: a number, or a keyword of the viewBox (viewport)."""
        t = (text or "0").strip().lower()
        if t in _KEYWORDS:
            return 0.0  # SVG 2's keywords: Chromium takes them as invalid (0), as here
        from fivebar_host.toolpath.svg.units import Lengths

        assert isinstance(lg, Lengths)
        return lg.user(t, f, ln, "refX" if axis == 0 else "refY")

    @staticmethod
    def _orient(text: str | None, v: Vertex, start: bool) -> float:
        """The marker's angle at `v`, radians (module doc)."""
        t = (text or "0").strip().lower()
        if t == "auto":
            return _auto(v)
        if t == "auto-start-reverse":
            return _auto(v) + (math.pi if start else 0.0)
        m = _ANGLE.match(t)
        return float(m.group(1)) * _TO_RAD[m.group(2)] if m else 0.0


def _affine(x: float, y: float, angle: float, scale: float) -> np.ndarray:
    """translate(x, y) · rotate(angle) · scale(scale)."""
    c, s = math.cos(angle) * scale, math.sin(angle) * scale
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def _translate(x: float, y: float) -> np.ndarray:
    t = np.identity(3)
    t[0, 2], t[1, 2] = x, y
    return t
