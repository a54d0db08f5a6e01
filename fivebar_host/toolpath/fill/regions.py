"""The fill region of every filled source, with the exact fill rule (SVG 2 §13.4.2).

An element's fill is the area its subpaths enclose, each subpath closed implicitly, under
its `fill-rule`: `nonzero` keeps the points around which the subpaths wind a non-zero number
of times (summed over every subpath, with their directions), `evenodd` the points crossed an
odd number of times. A compound path's holes, a self-crossing star, nested rings and
subpaths that overlap therefore come out as a browser fills them.

How: one simple ring (the common case) is its own region under both rules and is built in
bulk (`shapely.polygons` over all such sources at once). Anything else is noded (every ring
split where rings cross, `shapely.union_all` of their lines), polygonised into faces, and
each face kept by the winding number of an interior point against the original rings —
the rule's definition applied face by face, not a guess from ring orientation (which is
what flips even-odd tests in tools that offset rings one by one).

The rings are the drawing's strokes flattened within `tol` (the strokes of a filled source
are its subpaths; a clipped element's visible region comes from the reader instead,
`fill.paint`).
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.toolpath.fill.paint import EVENODD, NO_FILL, PaintTable
from fivebar_host.toolpath.geometry import Drawing, Polylines, flatten
from kinematics.arrays import FloatArray, IntArray


def winding(points: FloatArray, rings: list[FloatArray]) -> IntArray:
    """Winding number of each point with respect to closed rings (crossing rule: +1 for an
    upward edge with the point on its left, −1 for a downward one with it on its right)."""
    wn = np.zeros(points.shape[0], dtype=np.int64)
    px, py = points[:, 0:1], points[:, 1:2]
    for r in rings:
        a, b = r[:-1], r[1:]
        ax, ay, bx, by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
        left = (bx - ax) * (py - ay) - (px - ax) * (by - ay)
        up = (ay <= py) & (by > py) & (left > 0)
        down = (ay > py) & (by <= py) & (left < 0)
        wn += up.sum(axis=1) - down.sum(axis=1)
    return wn


def region_of_rings(rings: list[FloatArray], rule: int) -> BaseGeometry:
    """The area closed rings fill under `rule` (`NONZERO` or `EVENODD`), noded and kept face
    by face (module doc)."""
    rings = [r for r in rings if r.shape[0] >= 4]
    if not rings:
        return shapely.Polygon()
    noded = shapely.union_all(shapely.linestrings(np.concatenate(rings),
                                                  indices=np.repeat(np.arange(len(rings)),
                                                                    [r.shape[0] for r in rings])))
    faces = np.array([f for f in shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
                      if f.area > 0], dtype=object)
    if faces.size == 0:
        return shapely.Polygon()
    reps = shapely.get_coordinates(shapely.point_on_surface(faces))
    wn = winding(reps, rings)
    keep = wn % 2 == 1 if rule == EVENODD else wn != 0
    if not keep.any():
        return shapely.Polygon()
    return shapely.union_all(faces[keep])


def closed_rings(poly: Polylines, strokes: IntArray) -> list[FloatArray]:
    """The flattened strokes `strokes` (indices into `poly`'s polylines), each closed."""
    out = []
    for i in strokes.tolist():
        pts = poly.points[poly.offsets[i]:poly.offsets[i + 1]]
        if pts.shape[0] and not np.array_equal(pts[0], pts[-1]):
            pts = np.vstack((pts, pts[:1]))
        out.append(pts)
    return out


def fill_regions(drawing: Drawing, tol: float, poly: Polylines | None = None,
                 wanted: IntArray | None = None) -> dict[int, BaseGeometry]:
    """The non-empty fill region of every filled source (of `wanted`, None: all), in the
    drawing's frame: a clipped element's from the reader, the others from their strokes
    flattened within `tol` (`poly`: the drawing already flattened, to reuse)."""
    paint = drawing.paint or PaintTable.empty(len(drawing.sources))
    rule = paint.rule
    filled = np.flatnonzero(rule != NO_FILL)
    if wanted is not None:
        filled = np.intersect1d(filled, wanted)
    out: dict[int, BaseGeometry] = {}
    for s in filled.tolist():
        if s in paint.clipped:
            out[s] = paint.clipped[s]
    todo = np.array([s for s in filled.tolist() if s not in paint.clipped], dtype=np.int64)
    if todo.size == 0:
        return out
    poly = poly if poly is not None else flatten(drawing, tol)
    src_of = drawing.stroke_source[poly.stroke]
    sel = np.flatnonzero(np.isin(src_of, todo))
    if sel.size == 0:
        return out
    order = sel[np.argsort(src_of[sel], kind="stable")]
    srcs, first, count = np.unique(src_of[order], return_index=True, return_counts=True)
    single = count == 1
    _simple_regions(poly, srcs[single], order[first[single]], out, rule)
    for s, f, n in zip(srcs[~single].tolist(), first[~single].tolist(),
                       count[~single].tolist(), strict=True):
        g = region_of_rings(closed_rings(poly, order[f:f + n]), int(rule[s]))
        if not g.is_empty:
            out[s] = g
    return out


def _simple_regions(poly: Polylines, srcs: IntArray, strokes: IntArray,
                    out: dict[int, BaseGeometry], rule: np.ndarray) -> None:
    """Sources of one ring each: built in bulk; a ring that is not simple (it crosses or
    touches itself) goes through `region_of_rings`."""
    if srcs.size == 0:
        return
    rings = closed_rings(poly, strokes)
    ok = np.array([r.shape[0] >= 4 for r in rings])
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return
    lens = [rings[i].shape[0] for i in idx.tolist()]
    lr = shapely.linearrings(np.concatenate([rings[i] for i in idx.tolist()]),
                             indices=np.repeat(np.arange(idx.size), lens))
    polys = shapely.polygons(lr)
    valid = shapely.is_valid(polys) & (shapely.area(polys) > 0)
    for j, i in enumerate(idx.tolist()):
        s = int(srcs[i])
        if valid[j]:
            out[s] = polys[j]
        else:
            g = region_of_rings([rings[i]], int(rule[s]))
            if not g.is_empty:
                out[s] = g
