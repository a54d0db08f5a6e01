"""Clipping of pen lines against a region (clip-path, mask, a viewport's overflow), with shapely.

A region is a shapely (Multi)Polygon in the drawing frame (mm). It is built from filled
subpaths with the SVG fill rule (`fill_region`: the subpaths' rings are noded, polygonised,
and each face kept by its winding number — nonzero or evenodd, SVG 2 §13.4.2 — so self-crossing
stars and holes come out as a renderer fills them), or from stroked subpaths (`stroke_region`,
a buffer of half the stroke width, for mask content).

`clip_subpaths` cuts a stroke (the pen line) against a region and keeps the parts inside it
(the boundary counts as inside: a line on a clip edge is half visible on screen and drawn by
the pen). The pieces stay exact primitives: the cut parameters are found on a fine polyline
(crossings with the region's boundary, projected back to the primitive's parameter), and each
primitive is split there exactly (lines and arcs by parameter, cubics by de Casteljau); only
where the cut falls depends on the flattening tolerance (`tolerance`).
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.errors import InputError
from fivebar_host.toolpath.fill.regions import winding
from fivebar_host.toolpath.geometry import ARC, CUBIC, LINE, MAX_COORD_MM, evaluate, piece_counts
from fivebar_host.toolpath.svg.pathdata import Prim
from kinematics.arrays import FloatArray

Subpaths = list[list[Prim]]


def check_finite(subpaths: Subpaths, file: str, line: int, tag: str) -> None:
    """Refuse coordinates that are not finite or beyond `MAX_COORD_MM` before geometry
    operations see them (the same rule the reader applies to every drawn primitive)."""
    for sub in subpaths:
        for _, p in sub:
            a = np.asarray(p, dtype=np.float64)
            if not np.isfinite(a).all() or np.abs(a).max(initial=0.0) > MAX_COORD_MM:
                raise InputError(f"<{tag}> has a coordinate that is not finite or larger "
                                 f"than {MAX_COORD_MM:g} mm", file, line)


def transform_subpaths(subpaths: Subpaths, m: np.ndarray) -> Subpaths:
    """Every primitive mapped by the affine 3×3 matrix m (exact for every kind)."""
    from fivebar_host.toolpath.geometry import transform

    out: Subpaths = []
    for sub in subpaths:
        kind = np.array([k for k, _ in sub], dtype=np.int8)
        params = np.array([tuple(p) + (0.0,) * (8 - len(p)) for _, p in sub], dtype=np.float64)
        with np.errstate(all="ignore"):
            q = transform(kind, params, m[:2, :2], m[:2, 2])
        out.append([(int(k), tuple(float(v) for v in row)) for k, row in zip(kind, q,
                                                                             strict=True)])
    return out


def polyline(kind: int, params: tuple[float, ...], tol: float) -> tuple[FloatArray, FloatArray]:
    """Points of one primitive at equal parameter steps within `tol`, and their parameters."""
    k = np.array([kind], dtype=np.int8)
    p = np.array([params], dtype=np.float64)
    n = int(min(piece_counts(k, p, tol)[0], 20000))
    t = np.linspace(0.0, 1.0, n + 1)
    return evaluate(np.full(n + 1, kind, dtype=np.int8), np.repeat(p, n + 1, 0), t), t


def extent(subpaths: Subpaths) -> tuple[float, float, float, float] | None:
    """A box (xmin, ymin, xmax, ymax) that contains the curves (control points; arcs by
    their centre ± largest radius)."""
    pts: list[FloatArray] = []
    for sub in subpaths:
        for kind, p in sub:
            a = np.asarray(p, dtype=np.float64)
            if kind == ARC:
                r = float(np.linalg.norm(a[2:6].reshape(2, 2), 2))
                pts.append(np.array([a[0:2] - r, a[0:2] + r]))
            else:
                pts.append(a[: 4 if kind == LINE else 8].reshape(-1, 2))
    if not pts:
        return None
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def tolerance(box: tuple[float, float, float, float] | None) -> float:
    """Flattening tolerance for clip work: 10⁻⁵ of the extent, at least 10⁻⁶ mm."""
    if box is None:
        return 1e-3
    return max(1e-6, 1e-5 * max(box[2] - box[0], box[3] - box[1]))


def fill_region(subpaths: Subpaths, rule: str, tol: float) -> BaseGeometry:
    """The area a renderer fills for these subpaths (each closed implicitly) under `rule`."""
    rings: list[FloatArray] = []
    for sub in subpaths:
        parts = [polyline(k, p, tol)[0] for k, p in sub]
        pts = np.concatenate([parts[0]] + [q[1:] for q in parts[1:]])
        if not np.array_equal(pts[0], pts[-1]):
            pts = np.vstack((pts, pts[:1]))
        if pts.shape[0] >= 4:
            rings.append(pts)
    if not rings:
        return shapely.Polygon()
    if len(rings) == 1:
        poly = shapely.Polygon(rings[0])
        if poly.is_valid:
            return poly
    noded = shapely.union_all([shapely.LineString(r) for r in rings])
    faces = [f for f in shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
             if f.area > 0]
    if not faces:
        return shapely.Polygon()
    reps = np.array([f.representative_point().coords[0] for f in faces])
    wn = winding(reps, rings)
    keep = wn % 2 == 1 if rule == "evenodd" else wn != 0
    return shapely.union_all([f for f, k in zip(faces, keep, strict=True) if k])


def stroke_region(subpaths: Subpaths, width: float, tol: float) -> BaseGeometry:
    """The area a stroke of `width` covers (round joins; caps as butt are close enough for a
    mask's coverage and never larger)."""
    lines = []
    for sub in subpaths:
        parts = [polyline(k, p, tol)[0] for k, p in sub]
        pts = np.concatenate([parts[0]] + [q[1:] for q in parts[1:]])
        if pts.shape[0] >= 2:
            lines.append(shapely.LineString(pts))
    if not lines or width <= 0:
        return shapely.Polygon()
    return shapely.union_all(lines).buffer(width / 2, cap_style="flat")


def clip_subpaths(subpaths: Subpaths, region: BaseGeometry, tol: float) -> Subpaths:
    """The parts of these strokes inside `region` (boundary included), as exact primitives;
    a stroke is split where it leaves the region."""
    box = extent(subpaths)
    if box is None or region.is_empty:
        return []
    env = shapely.box(*box)
    if region.contains(env):
        return subpaths
    if not region.intersects(env):
        return []
    grown = region.buffer(tol * 1e-4)  # a line on the clip edge is inside despite rounding
    runs: list[tuple[list[Prim], float]] = []
    for sub in subpaths:
        cur: list[Prim] = []
        length = 0.0
        for kind, p in sub:
            pieces = _inside_intervals(kind, p, grown, tol)
            if not pieces and cur:
                runs.append((cur, length))
                cur, length = [], 0.0
            for ta, tb, n in pieces:
                if cur and ta > 0.0:
                    runs.append((cur, length))
                    cur, length = [], 0.0
                cur.append(_sub_primitive(kind, p, ta, tb))
                length += n
                if tb < 1.0:
                    runs.append((cur, length))
                    cur, length = [], 0.0
        if cur:
            runs.append((cur, length))
    # A run shorter than 10 tolerances is where a line touches the region, not a line.
    return [r for r, n in runs if n >= 10 * tol]


def _inside_intervals(kind: int, p: tuple[float, ...], region: BaseGeometry,
                      tol: float) -> list[tuple[float, float, float]]:
    """Parameter intervals of a primitive inside `region`: each chord of a fine polyline is
    intersected with the region (straight pieces, so their ends map back to the chord's
    parameter without ambiguity), and touching pieces are merged. Each interval comes with
    its length."""
    pts, ts = polyline(kind, p, tol)
    a, b = pts[:-1], pts[1:]
    ab = b - a
    ll = np.einsum("ij,ij->i", ab, ab)
    ok = ll > 0
    if not ok.any():
        return []
    a, ab, ll, t0, dt = a[ok], ab[ok], ll[ok], ts[:-1][ok], np.diff(ts)[ok]
    chords = shapely.linestrings(np.stack((a, a + ab), axis=1))
    parts, idx = shapely.get_parts(shapely.intersection(chords, region), return_index=True)
    # LineString pieces (points are touches)
    lines = (shapely.get_type_id(parts) == 1) & ~shapely.is_empty(parts)
    parts, idx = parts[lines], idx[lines]
    if parts.shape[0] == 0:
        return []
    first = shapely.get_coordinates(shapely.get_point(parts, 0))
    last = shapely.get_coordinates(shapely.get_point(parts, -1))
    fa = np.einsum("ij,ij->i", first - a[idx], ab[idx]) / ll[idx]
    fb = np.einsum("ij,ij->i", last - a[idx], ab[idx]) / ll[idx]
    lo, hi = np.clip(np.minimum(fa, fb), 0, 1), np.clip(np.maximum(fa, fb), 0, 1)
    ta, tb = t0[idx] + lo * dt[idx], t0[idx] + hi * dt[idx]
    length = (hi - lo) * np.sqrt(ll[idx])
    order = np.argsort(ta, kind="stable")
    out: list[list[float]] = []
    for x, y, n in zip(ta[order], tb[order], length[order], strict=True):
        if out and x <= out[-1][1] + 1e-12:
            out[-1][1] = max(out[-1][1], float(y))
            out[-1][2] += float(n)
        else:
            out.append([float(x), float(y), float(n)])
    # Ends within rounding of the primitive's ends are the ends (keeps strokes chained).
    res = [(0.0 if x < 1e-12 else x, 1.0 if y > 1 - 1e-12 else y, n) for x, y, n in out]
    return [(x, y, n) for x, y, n in res if y - x > 1e-12]


def _sub_primitive(kind: int, p: tuple[float, ...], ta: float, tb: float) -> Prim:
    """The piece of a primitive over parameters [ta, tb], exactly."""
    if ta == 0.0 and tb == 1.0:
        return kind, p
    if kind == ARC:
        return ARC, (*p[:6], p[6] + ta * p[7], (tb - ta) * p[7])
    if kind == LINE:
        a = np.array(p[0:2])
        b = np.array(p[2:4])
        s, e = a + ta * (b - a), a + tb * (b - a)
        return LINE, (float(s[0]), float(s[1]), float(e[0]), float(e[1]))
    assert kind == CUBIC
    c = np.array(p[:8], dtype=np.float64).reshape(4, 2)
    c = _split_cubic(c, tb)[0]  # [0, tb]
    c = _split_cubic(c, ta / tb)[1] if tb > 0 else c  # [ta, tb]
    return CUBIC, tuple(float(v) for v in c.reshape(-1))


def _split_cubic(c: FloatArray, t: float) -> tuple[FloatArray, FloatArray]:
    """De Casteljau: the two halves of a cubic at t."""
    p01, p12, p23 = c[0] + t * (c[1] - c[0]), c[1] + t * (c[2] - c[1]), c[2] + t * (c[3] - c[2])
    p012, p123 = p01 + t * (p12 - p01), p12 + t * (p23 - p12)
    m = p012 + t * (p123 - p012)
    return np.array([c[0], p01, p012, m]), np.array([m, p123, p23, c[3]])
