"""SVG basic shapes as exact primitives in user units (SVG 2 §10): `<line> <polyline> <polygon>
<rect>` (rounded corners, radii clamped as in SVG 1.1 §9.2) `<circle> <ellipse>`, and
`<path>` through `pathdata`. Each shape yields its subpaths (pen-down runs); lengths go
through `Lengths`, so `%`, `em` and `ex` work as on the web.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import ARC, LINE
from fivebar_host.toolpath.svg.pathdata import PathDataError, PathResult, Prim, parse_path
from fivebar_host.toolpath.svg.units import Lengths, number_prefix
from fivebar_host.toolpath.svg.xmltree import Node

SHAPES = ("path", "line", "polyline", "polygon", "rect", "circle", "ellipse")


def shape_subpaths(node: Node, lengths: Lengths, f: str) -> PathResult:
    """Subpaths of one shape (a path's result carries its first data error, if any)."""
    ln, tag = node.line, node.tag
    if tag == "path":
        return parse_path(node.get("d") or "")
    if tag == "line":
        x1, y1, x2, y2 = (lengths.user(node.get(k), f, ln, k) for k in ("x1", "y1", "x2", "y2"))
        return PathResult([[(LINE, (x1, y1, x2, y2))]] if (x1, y1) != (x2, y2) else [])
    if tag in ("polyline", "polygon"):
        return _poly(node, f)
    if tag == "rect":
        return PathResult(list(_rect(node, lengths, f)))
    return PathResult(list(_ellipse(node, lengths, f)))


def _poly(node: Node, f: str) -> PathResult:
    """Points as lines; an odd count is an error (SVG 2 §10.6): drawn up to it, the last
    number left out, as browsers do, with the error returned for a warning."""
    text = node.get("points") or ""
    v, bad = number_prefix(text)
    err = None if bad is None else PathDataError(bad, f"{text[bad:bad + 12]!r} is not a number")
    if len(v) % 2:
        err = err or PathDataError(len(text), f"odd number of coordinates ({len(v)}); the "
                                              "last one is left out")
        v = v[:-1]
    pts = list(zip(v[0::2], v[1::2], strict=True))
    if node.tag == "polygon" and len(pts) > 1 and pts[0] != pts[-1]:
        pts.append(pts[0])
    seg: list[Prim] = [(LINE, (*a, *b)) for a, b in itertools.pairwise(pts) if a != b]
    return PathResult([seg] if seg else [], err)


def _ellipse(node: Node, lengths: Lengths, f: str) -> Iterator[list[Prim]]:
    ln, tag = node.line, node.tag
    cx = lengths.user(node.get("cx"), f, ln, "cx")
    cy = lengths.user(node.get("cy"), f, ln, "cy")
    if tag == "circle":
        rx = ry = lengths.user(node.get("r"), f, ln, "r")
    else:
        rxs, rys = node.get("rx"), node.get("ry")
        rx = lengths.user(rxs, f, ln, "rx", -1.0) if rxs != "auto" else -1.0
        ry = lengths.user(rys, f, ln, "ry", -1.0) if rys != "auto" else -1.0
        rx, ry = (ry if rx < 0 else rx), (rx if ry < 0 else ry)  # SVG 2 auto
    if rx < 0 or ry < 0:
        if tag == "circle" or (node.get("rx") is not None and node.get("ry") is not None):
            raise InputError(f"<{tag}> has a negative radius", f, ln)
        return
    if rx > 0 and ry > 0:
        # Starts at 3 o'clock and runs with increasing angle in the page's y-down
        # frame (clockwise on screen), as the SVG spec's equivalent path does.
        yield [(ARC, (cx, cy, rx, 0.0, 0.0, ry, 0.0, 2 * math.pi))]


def _rect(node: Node, lengths: Lengths, f: str) -> Iterator[list[Prim]]:
    """<rect>, rounded corners per SVG 1.1 §9.2: rx, ry default to each other and are clamped
    to half the width and height."""
    ln = node.line
    x = lengths.user(node.get("x"), f, ln, "x")
    y = lengths.user(node.get("y"), f, ln, "y")
    w = lengths.user(node.get("width"), f, ln, "width")
    h = lengths.user(node.get("height"), f, ln, "height")
    if w < 0 or h < 0:
        raise InputError("<rect> has a negative width or height", f, ln)
    if w == 0 or h == 0:
        return
    rxs, rys = node.get("rx"), node.get("ry")
    rx = lengths.user(rxs, f, ln, "rx") if rxs not in (None, "auto") else None
    ry = lengths.user(rys, f, ln, "ry") if rys not in (None, "auto") else None
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
    segs: list[Prim] = []
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
