"""Text on a path: `<textPath>` (SVG 2 §11.8.1, layout step "position on path" of §11.8.3).

The path is the `<path>` (or, as SVG 2 allows, the basic shape) that `href` names, in the
text element's user space with the shape's own `transform` as a supplemental transform
(SVG 1.1 §10.13.1). Its subpaths are measured one after the other (jumps between them do
not count). Each character's glyph is placed so that the middle of its advance lies on the
path at distance mid = startOffset + its position along the chunk + advance/2, rotated to
the path's direction there; a glyph whose mid lies before the start or beyond the end of the
path is not rendered (as Chromium and SVG 2 for open paths do). `dy` and baseline shifts
move glyphs perpendicular to the path. `startOffset` is a length or a percentage of the path
length, scaled by the path's `pathLength` when it has one. `side`, `method` and `spacing`
(which Chromium does not implement) and the SVG 2 `path` attribute are noted and not used.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import evaluate, piece_counts, transform
from fivebar_host.toolpath.svg.shapes import SHAPES, shape_subpaths
from fivebar_host.toolpath.svg.units import Lengths
from fivebar_host.toolpath.svg.xmltree import XLINK_NS, Node
from kinematics.arrays import FloatArray


@dataclass(frozen=True)
class PathGeometry:
    """A path measured by arc length: for each chord end the cumulative length `cum` (M,),
    and the primitive (`kind`, `params`) and parameter `t` it lies at, so that points and
    directions come from the exact curve."""

    kind: NDArray[np.int8]
    params: FloatArray
    prim: NDArray[np.int64]
    t: FloatArray
    cum: FloatArray
    length: float

    def at(self, s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Points (n, 2) and direction angles (n,) at arc lengths s (clamped to the path)."""
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, self.length)
        j = np.clip(np.searchsorted(self.cum, s, side="right"), 1, self.cum.shape[0] - 1)
        seg = self.cum[j] - self.cum[j - 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(seg > 0, (s - self.cum[j - 1]) / seg, 0.0)
        same = self.prim[j] == self.prim[j - 1]
        t0 = np.where(same, self.t[j - 1], 0.0)
        t = t0 + u * (self.t[j] - t0)
        k, p = self.kind[self.prim[j]], self.params[self.prim[j]]
        d = evaluate(k, p, t, 1)
        return evaluate(k, p, t), np.arctan2(d[:, 1], d[:, 0])


def referenced_shape(node: Node, ids: dict[str, Node]) -> Node | None:
    """The shape a `<textPath>` refers to (None: none, or not a shape)."""
    href = node.get("href") or node.get(f"{XLINK_NS} href") or ""
    target = ids.get(href[1:]) if href.startswith("#") else None
    return target if target is not None and target.is_svg and target.tag in SHAPES else None


def measure(shape: Node, lengths: Lengths, file: str,
            parse_transform: Callable[[str, Node], FloatArray]) -> PathGeometry | None:
    """The shape in the text's user space (its own transform applied), measured within a
    tolerance of 1e-4 of its extent; None when it has no length."""
    res = shape_subpaths(shape, lengths, file)
    prims = [(k, p + (0.0,) * (8 - len(p))) for sub in res.subpaths for k, p in sub]
    if not prims:
        return None
    kind = np.array([k for k, _ in prims], dtype=np.int8)
    params = np.array([p for _, p in prims], dtype=np.float64)
    tf = shape.get("transform")
    if tf:
        m = parse_transform(tf, shape)
        params = transform(kind, params, m[:2, :2], m[:2, 2])
    ext = float(np.ptp(params[:, :2], axis=0).max()) + float(np.abs(params).max()) * 1e-9
    n = piece_counts(kind, params, max(ext, 1e-9) * 1e-4)
    prim = np.repeat(np.arange(kind.shape[0]), n + 1)
    t = np.concatenate([np.linspace(0.0, 1.0, int(c) + 1) for c in n])
    pts = evaluate(kind[prim], params[prim], t)
    step = np.hypot(*np.diff(pts, axis=0).T)
    step[prim[1:] != prim[:-1]] = 0.0  # from one primitive's end to the next one's start
    cum = np.concatenate([[0.0], np.cumsum(step)])
    if cum[-1] <= 0:
        return None
    return PathGeometry(kind, params, prim, t, cum, float(cum[-1]))


def start_offset(tp: Node, shape: Node, geom: PathGeometry, lengths: Lengths,
                 file: str) -> float:
    """`startOffset` in user-space length along the path (module doc)."""
    text = (tp.get("startOffset") or "").strip()
    if not text:
        return 0.0
    if text.endswith("%"):
        try:
            return float(text[:-1]) / 100 * geom.length
        except ValueError:
            raise InputError(f"<textPath> startOffset={text!r} is not a length", file,
                             tp.line) from None
    v = lengths.user(text, file, tp.line, "startOffset")
    pl = shape.get("pathLength")
    try:
        author = float(pl) if pl else 0.0
    except ValueError:
        author = 0.0
    return v * geom.length / author if author > 0 and math.isfinite(author) else v


def place_on_path(geom: PathGeometry, along: FloatArray, glyph_advance: FloatArray,
                  offset: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Glyph origins (x, y), rotations (degrees) and which glyphs are on the path, for
    glyphs at distances `along` with advances `glyph_advance` and perpendicular offsets
    `offset` (user units, down from the path)."""
    mid = along + glyph_advance / 2
    on = (mid >= 0) & (mid <= geom.length)
    pts, ang = geom.at(mid)
    c, s = np.cos(ang), np.sin(ang)
    x = pts[:, 0] - glyph_advance / 2 * c - offset * s
    y = pts[:, 1] - glyph_advance / 2 * s + offset * c
    return x, y, np.degrees(ang), on.astype(np.float64)
