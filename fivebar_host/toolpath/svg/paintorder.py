"""The walker's record of each drawn shape's paint, in paint order (`fill.paint`), and the
edge a clip gives a filled shape.

A filled shape under a clip path, mask or clipping viewport shows the part of its fill
inside the clip (CSS Masking 1 §6 and §7: the clip applies to the element's whole
rendering, fill included). Its outline as a pen draws it is therefore the path clipped
(drawn by `Walker.emit`) *plus the clip's own edge where it crosses the fill*: a green
rectangle clipped to a star (resvg's `clip-path` tests) shows a star, which the clipped
rectangle outline alone never draws. That edge is added here as the shape's own strokes,
and the visible fill (fill region ∩ clip) is kept for hatching and hidden lines.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.errors import InputError
from fivebar_host.toolpath.fill.paint import NO_FILL, RULES
from fivebar_host.toolpath.geometry import LINE
from fivebar_host.toolpath.svg import clip
from fivebar_host.toolpath.svg.paint import colour, number_or_percent, painted
from fivebar_host.toolpath.svg.xmltree import Node

if TYPE_CHECKING:
    from fivebar_host.toolpath.svg.walk import Ctx, Walker


def fill_rule(node: Node, c: Ctx) -> int:
    """The shape's fill rule code, `NO_FILL` when nothing fills it (SVG 2 §13.2: `fill`
    none or transparent, zero `fill-opacity`; a `<line>` has no interior)."""
    p = c.props
    if node.tag == "line" or not painted(p["fill"]) or number_or_percent(
            p["fill-opacity"]) <= 0:
        return NO_FILL
    return RULES.get(p["fill-rule"].strip().lower(), RULES["nonzero"])


def stroke_painted(w: Walker, node: Node, c: Ctx) -> bool:
    """Whether the shape's stroke paints (colour, opacity and width above zero)."""
    p = c.props
    try:
        width = c.lengths.user(p["stroke-width"], w.file, node.line, "stroke-width")
    except InputError:
        width = 1.0  # an invalid declaration is ignored (CSS)
    return painted(p["stroke"]) and number_or_percent(p["stroke-opacity"]) > 0 and width > 0


def record_shape(w: Walker, node: Node, c: Ctx, subpaths: clip.Subpaths, src: int) -> None:
    """Record a drawn shape's paint under source `src` (−1 when its outline was clipped away
    entirely); for a filled shape under a clip, also draw the clip's edge inside the fill
    and keep the visible fill region (module doc)."""
    rule = fill_rule(node, c)
    stroked = stroke_painted(w, node, c)
    region: BaseGeometry | None = None
    if rule != NO_FILL and c.clip is not None:
        subs = clip.transform_subpaths(subpaths, c.matrix)
        clip.check_finite(subs, w.file, node.line, node.tag)
        name = "evenodd" if rule == RULES["evenodd"] else "nonzero"
        fill = clip.fill_region(subs, name, clip.tolerance(clip.extent(subs)))
        region = shapely.intersection(fill, c.clip)
        if region.is_empty:
            return
        edge = shapely.intersection(c.clip.boundary, fill)
        lines = [g for g in shapely.get_parts(shapely.line_merge(edge))
                 if g.geom_type == "LineString" and g.length > 0]
        if lines and src < 0:
            src = w.b.add_source(node.get("id"), node.line, node.tag, c.layer)
        for g in lines:
            xy = np.asarray(g.coords)
            w.b.begin_stroke(src)
            w.b.add_many([(LINE, (float(a[0]), float(a[1]), float(b[0]), float(b[1])))
                          for a, b in itertools.pairwise(xy)], node.line)
        if src < 0:  # the fill shows, nothing of its outline: a source for its hatch
            src = w.b.add_source(node.get("id"), node.line, node.tag, c.layer)
    if src >= 0:
        w.paint.record(src, rule, stroked, region, paper_white(c.props["fill"]))


def paper_white(fill: str) -> bool:
    """Whether a fill is the paper's colour (white, opaque): it hides what is beneath it
    but a pen has nothing to draw for it, so it is not hatched."""
    col = colour(fill)
    return col.known and col.alpha >= 1.0 and col.luminance >= 0.999
