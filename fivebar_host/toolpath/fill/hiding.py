"""Hidden lines: the parts of each stroke that a fill painted later covers, found exactly.

In paint order (SVG 2 §13.3: later elements paint over earlier ones) a filled element hides
whatever lies beneath it. The fills are cut into convex pieces (a convex fill is its own
piece; any other, holes included, is triangulated with its edges kept: shapely's
constrained Delaunay triangulation), the strokes are flattened into fine chords, and an
STR tree pairs every chord with the pieces whose boxes it meets. For each pair painted
later than the chord the covered part of the chord is one parameter interval, found by
Cyrus–Beck clipping against the piece's edges (vectorised over all pairs at once). The
union of a chord's intervals is what is hidden; what is left is cut out of the original
primitives exactly (`fill.cuts`).

Every kind of filled element occludes — paths, circles, ellipses, rounded rectangles,
`<use>` instances, clipped fills — not only polygons, and an element never hides itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.toolpath.geometry import Polylines
from kinematics.arrays import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class Pieces:
    """Convex pieces of the occluding fills: CCW vertices `xy` (V, 2) with CSR `offsets`
    (each piece open: its last vertex is not repeated), the owner source of each piece,
    and their shapely polygons (for the tree)."""

    xy: FloatArray
    offsets: IntArray
    owner: IntArray
    polys: np.ndarray


def convex_pieces(regions: dict[int, BaseGeometry]) -> Pieces:
    """The regions as convex pieces (module doc), owners = the regions' keys."""
    keys = list(regions)
    parts, idx = shapely.get_parts(np.array([regions[k] for k in keys], dtype=object),
                                   return_index=True)
    ok = (shapely.get_type_id(parts) == 3) & (shapely.area(parts) > 0)
    parts, owner_of = parts[ok], np.array(keys, dtype=np.int64)[idx[ok]]
    convex = (shapely.get_num_interior_rings(parts) == 0) & (
        shapely.area(parts) >= shapely.area(shapely.convex_hull(parts)) * (1 - 1e-12))
    polys: list[BaseGeometry] = parts[convex].tolist()
    owners: list[int] = owner_of[convex].tolist()
    for p, s in zip(parts[~convex].tolist(), owner_of[~convex].tolist(), strict=True):
        tri = shapely.get_parts(shapely.constrained_delaunay_triangles(p)).tolist()
        polys.extend(tri)
        owners.extend([s] * len(tri))
    if not polys:
        z = np.zeros(0, np.int64)
        return Pieces(np.zeros((0, 2)), np.zeros(1, np.int64), z, np.array([], dtype=object))
    arr = shapely.orient_polygons(np.array(polys, dtype=object), exterior_cw=False)
    xy, idx = shapely.get_coordinates(shapely.get_exterior_ring(arr), return_index=True)
    last = np.concatenate((idx[1:] != idx[:-1], [True]))  # drop each ring's closing vertex
    xy, idx = xy[~last], idx[~last]
    counts = np.bincount(idx, minlength=len(polys))
    offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    return Pieces(xy, offsets, np.array(owners, dtype=np.int64), arr)


def covered_intervals(a: FloatArray, b: FloatArray, pc: Pieces, chord: IntArray,
                      piece: IntArray) -> tuple[FloatArray, FloatArray]:
    """For pairs (chord, piece): the parameter interval [t0, t1] of the chord a→b inside
    the convex piece (Cyrus–Beck; empty where t1 ≤ t0). Vectorised over the pairs and
    their pieces' edges."""
    n_e = np.diff(pc.offsets)[piece]
    total = int(n_e.sum())
    pair = np.repeat(np.arange(piece.shape[0]), n_e)
    k = np.arange(total) - np.repeat(np.cumsum(n_e) - n_e, n_e)
    v = pc.offsets[piece][pair] + k
    nxt = np.where(k + 1 == n_e[pair], pc.offsets[piece][pair], v + 1)
    p0, p1 = pc.xy[v], pc.xy[nxt]
    e = p1 - p0
    nx, ny = -e[:, 1], e[:, 0]  # inward normal of a CCW edge
    A, D = a[chord][pair], (b - a)[chord][pair]
    num = nx * (A[:, 0] - p0[:, 0]) + ny * (A[:, 1] - p0[:, 1])
    den = nx * D[:, 0] + ny * D[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -num / den
    enter = np.where(den > 0, t, -np.inf)
    leave = np.where(den < 0, t, np.inf)
    outside = (den == 0) & (num < 0)
    leave = np.where(outside, -np.inf, leave)
    starts = np.cumsum(n_e) - n_e
    t0 = np.maximum(np.maximum.reduceat(enter, starts), 0.0) if total else np.zeros(0)
    t1 = np.minimum(np.minimum.reduceat(leave, starts), 1.0) if total else np.zeros(0)
    return t0, t1


def union_per_chord(chord: IntArray, t0: FloatArray, t1: FloatArray
                    ) -> tuple[IntArray, FloatArray, FloatArray]:
    """Per chord, the union of its intervals as disjoint sorted intervals."""
    keep = t1 > t0
    chord, t0, t1 = chord[keep], t0[keep], t1[keep]
    if chord.size == 0:
        return chord, t0, t1
    order = np.lexsort((t0, chord))
    chord, t0, t1 = chord[order], t0[order], t1[order]
    g = chord.astype(np.float64) * 4.0  # intervals lie in [0, 1]: groups never mix
    reach = np.maximum.accumulate(t1 + g) - g
    new = np.ones(chord.shape[0], bool)
    new[1:] = (chord[1:] != chord[:-1]) | (t0[1:] > reach[:-1])
    starts = np.flatnonzero(new)
    ends = np.append(starts[1:], chord.shape[0]) - 1
    return chord[starts], t0[starts], reach[ends]


@dataclass(frozen=True)
class Hidden:
    """The hidden intervals of the flattened strokes' chords: chord (index of its end
    vertex in the polylines) and [u0, u1] along it."""

    chord: IntArray
    u0: FloatArray
    u1: FloatArray


def hidden_chords(poly: Polylines, chord_source: IntArray, pc: Pieces,
                  occludable: BoolArray, occluding: BoolArray) -> Hidden:
    """The hidden parts of every chord of `poly` (a chord ends at vertex v, its source is
    `chord_source[v]`, −1 for no chord): covered by a piece whose owner was painted later,
    where the chord's source may be hidden (`occludable`, per source) and the owner may
    hide (`occluding`, per source)."""
    z = Hidden(np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    v = np.flatnonzero(chord_source >= 0)
    v = v[occludable[chord_source[v]]]
    if v.size == 0 or pc.owner.size == 0:
        return z
    a, b = poly.points[v - 1], poly.points[v]
    lines = shapely.linestrings(np.stack((a, b), axis=1))
    tree = shapely.STRtree(pc.polys)
    ci, pj = tree.query(lines)
    src = chord_source[v][ci]
    own = pc.owner[pj]
    ok = (own > src) & occluding[own]
    ci, pj = ci[ok], pj[ok]
    if ci.size == 0:
        return z
    t0 = np.empty(ci.shape[0])
    t1 = np.empty(ci.shape[0])
    block = 1 << 18  # pairs at a time (bounds the per-edge temporaries)
    for i in range(0, ci.shape[0], block):
        sl = slice(i, i + block)
        t0[sl], t1[sl] = covered_intervals(a, b, pc, ci[sl], pj[sl])
    c, u0, u1 = union_per_chord(ci, t0, t1)
    return Hidden(v[c], u0, u1)
