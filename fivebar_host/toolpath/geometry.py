"""The drawing as a table of exact curve primitives, and their vectorised flattening.

Every reader (SVG, G-code) produces a `Drawing`: a flat table of primitives in millimetres in
the *drawing frame* (x right, y up; for SVG the page's bottom-left corner is the origin, the
y-flip of the page is done by the reader), each primitive one of

- LINE:  p0, p1                              (params[0:4])
- CUBIC: p0, p1, p2, p3 (Bézier control pts) (params[0:8]); quadratics are degree-elevated
- ARC:   c, M (2×2, row-major), θ0, Δθ       (params[0:8]); E(θ) = c + M·(cos θ, sin θ)

The ARC form is the affine image of the unit circle, so an SVG elliptical arc under any
transform (rotation, non-uniform scale, skew) stays exact: the transform multiplies M. Every
primitive is therefore mapped exactly by an affine map (`transform`), and the layout can place
the drawing before flattening so the flattening tolerance is in machine millimetres.

Primitives are grouped into *strokes* (pen-down runs; an SVG subpath or a G-code cutting run):
`stroke` is non-decreasing and a stroke's primitives are contiguous and chained end to start.

A G-code dwell (`G4`) is a `Dwell` attached to a stroke: at its start (before it is drawn) or
at its end (after it). A dwell ends a stroke, so its place is always a stroke's end point.
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from fivebar_host.errors import InputError
from kinematics.arrays import FloatArray, IntArray

if TYPE_CHECKING:
    from fivebar_host.toolpath.fill.assemble import FillResult
    from fivebar_host.toolpath.fill.paint import PaintTable

LINE = 0
CUBIC = 1
ARC = 2

#: Largest coordinate accepted anywhere, mm. Anything larger is a unit mistake or garbage.
MAX_COORD_MM = 1.0e6
_PAD = (0.0,) * 8  # primitive parameters are padded to 8


@dataclass(frozen=True)
class SourceInfo:
    """One user-visible input element: SVG element or G-code cutting run."""

    index: int  # 0-based, in document order (SVG elements that draw; G-code strokes)
    ident: str | None  # SVG id attribute
    line: int | None  # 1-based line in the input file
    tag: str  # "path", "circle", ..., or "gcode"
    layer: str | None = None
    #: "" for the element's own outline; "hatch" for the hatch lines of its fill
    #: (`toolpath.fill`), which share its id, line and layer
    role: str = ""


@dataclass(frozen=True)
class TextInfo:
    """One drawn SVG `<text>` element, for the dry run: its source (index into
    `Drawing.sources`), element and line, the text (shortened), the faces that drew it (in
    order of first use; the profile's fallback marked), the font-size in the drawing's mm,
    and its glyph and stroke counts."""

    source: int
    element: str
    line: int
    text: str
    fonts: tuple[str, ...]
    size_mm: float
    glyphs: int
    strokes: int


@dataclass(frozen=True)
class Dwell:
    """A pause (G-code `G4`) at the start (`after` False) or the end (`after` True) of stroke
    `stroke`: `seconds` long, with the tool on (`tool_on`: laser at `power`, a fraction of
    the profile's power like `Drawing.stroke_power`; pen down) or off, from file line
    `line`."""

    stroke: int
    after: bool
    seconds: float
    tool_on: bool
    power: float
    line: int


@dataclass
class Drawing:
    """Primitives of a whole drawing plus per-stroke and per-source metadata (see module doc).

    Arrays: `kind` (N,) int8, `params` (N, 8) float64 mm, `stroke` (N,) int64, `line` (N,)
    int64 (source line, 0 if unknown). Per stroke: `stroke_source` (S,) index into `sources`,
    `stroke_power` (S,) laser power as a fraction 0..1 of the profile's power, `stroke_feed_mm_s`
    (S,) requested feed (NaN: the profile's draw feed). `dwells`: the G-code dwells, in file
    order (none for an SVG). `texts`: the SVG text elements drawn (`TextInfo`).
    """

    file: str
    kind: NDArray[np.int8]
    params: FloatArray
    stroke: IntArray
    line: IntArray
    stroke_source: IntArray
    stroke_power: FloatArray
    stroke_feed_mm_s: FloatArray
    sources: list[SourceInfo]
    page_height_mm: float | None = None  # SVG: to map back to page coords (y down)
    page_size_mm: tuple[float, float] | None = None
    warnings: list[str] = field(default_factory=list)
    dwells: list[Dwell] = field(default_factory=list)
    texts: list[TextInfo] = field(default_factory=list)
    #: per source: fill rule, stroke painted, clipped fill regions (SVG; `fill.paint`)
    paint: PaintTable | None = None
    #: what hatching and hidden-line removal did (`fill.assemble`; None: neither ran)
    fill: FillResult | None = None
    #: SVG: the drawn `<image>` elements (`svg.walk.ImageRef`), burned by `raster.svgimage`
    images: list[Any] = field(default_factory=list)

    @property
    def n_strokes(self) -> int:
        return int(self.stroke_source.shape[0])

    def to_file_frame(self, pts: FloatArray) -> FloatArray:
        """Drawing-frame points (y up) → the file's own frame (SVG page: y down from the top)."""
        out = np.array(pts, dtype=np.float64, copy=True)
        if self.page_height_mm is not None:
            out[..., 1] = self.page_height_mm - out[..., 1]
        return out

    def transformed(self, a: FloatArray, b: FloatArray) -> Drawing:
        """A copy with every primitive mapped by x ↦ a·x + b (exact for all kinds)."""
        return Drawing(self.file, self.kind, transform(self.kind, self.params, a, b),
                       self.stroke, self.line, self.stroke_source, self.stroke_power,
                       self.stroke_feed_mm_s, self.sources, self.page_height_mm,
                       self.page_size_mm, self.warnings, self.dwells, self.texts,
                       None if self.paint is None else self.paint.transformed(a, b),
                       None if self.fill is None else self.fill.transformed(a, b))


class DrawingBuilder:
    """Accumulates primitives from a reader; `build` returns the `Drawing` arrays.

    Primitives go into typed `array.array` buffers (8 bytes a number) rather than lists of
    tuples (about 30 bytes a number as Python floats), so a large drawing's memory while it
    is read is close to that of its final arrays. `limit` (None: none) is the largest number
    of primitives accepted: the next one raises `InputError` naming the file, so a drawing
    too large for the memory stops while it is read, not when the memory runs out."""

    def __init__(self, file: str, limit: int | None = None, limit_hint: str = "") -> None:
        self.file = file
        self.limit = limit
        self.limit_hint = limit_hint
        self.kinds = array("b")
        self.params = array("d")
        self.strokes = array("q")
        self.lines = array("q")
        self.stroke_source: list[int] = []
        self.stroke_power: list[float] = []
        self.stroke_feed: list[float] = []
        self.sources: list[SourceInfo] = []
        self.warnings: list[str] = []
        self.dwells: list[Dwell] = []
        self.texts: list[TextInfo] = []
        self.matrices: list[NDArray[np.float64]] = []
        self.matrix_ids = array("q")
        self._open = False

    def add_source(self, ident: str | None, line: int | None, tag: str,
                   layer: str | None = None) -> int:
        self.sources.append(SourceInfo(len(self.sources), ident, line, tag, layer))
        return len(self.sources) - 1

    def begin_stroke(self, source: int, power: float = 1.0, feed_mm_s: float = math.nan) -> None:
        """Start a new stroke; an empty previous stroke is discarded."""
        if self._open and (not self.strokes or self.strokes[-1] != len(self.stroke_source) - 1):
            self.stroke_source.pop()
            self.stroke_power.pop()
            self.stroke_feed.pop()
        self.stroke_source.append(source)
        self.stroke_power.append(power)
        self.stroke_feed.append(feed_mm_s)
        self._open = True

    def add(self, kind: int, params: tuple[float, ...], line: int) -> None:
        """Append one primitive to the open stroke (params padded to 8): `add_many` of one,
        without its lists (the G-code reader adds one a line)."""
        if not self._open:
            raise RuntimeError("add() before begin_stroke()")
        if self.limit is not None and len(self.kinds) >= self.limit:
            self._over_limit(line)
        self.kinds.append(kind)
        self.params.extend(params + _PAD[len(params):])
        self.strokes.append(len(self.stroke_source) - 1)
        self.lines.append(line)
        self.matrix_ids.append(-1)

    def _over_limit(self, line: int) -> NoReturn:
        raise InputError(f"the drawing has more than {self.limit:,} path segments (lines, "
                         f"curves, arcs), the limit{self.limit_hint}", self.file, line)

    def add_many(self, prims: list[tuple[int, tuple[float, ...]]], line: int,
                 matrix: int = -1) -> None:
        """Append primitives (kind, params) of one source line to the open stroke; `matrix`
        indexes `self.matrices` (the affine map applied at `build`), −1 for none."""
        if not self._open:
            raise RuntimeError("add() before begin_stroke()")
        n = len(prims)
        if self.limit is not None and len(self.kinds) + n > self.limit:
            self._over_limit(line)
        stroke = len(self.stroke_source) - 1
        for kind, p in prims:
            self.kinds.append(kind)
            self.params.extend(p + _PAD[len(p):])
        self.strokes.extend([stroke] * n)
        self.lines.extend([line] * n)
        self.matrix_ids.extend([matrix] * n)

    def add_strokes(self, source: int, kinds: NDArray[np.int8], params: FloatArray,
                    starts: IntArray, line: int, matrix: int) -> None:
        """Append whole strokes at once (a placed glyph): primitives `kinds` (N,), `params`
        (N, 8), stroke `starts` (S,) into them, all from source line `line` and mapped by
        `self.matrices[matrix]` at `build`; each stroke has at least one primitive."""
        n = int(kinds.shape[0])
        if n == 0:
            return
        if self.limit is not None and len(self.kinds) + n > self.limit:
            raise InputError(f"the drawing has more than {self.limit:,} path segments (lines, "
                             f"curves, arcs), the limit{self.limit_hint}", self.file, line)
        if self._open and (not self.strokes or self.strokes[-1] != len(self.stroke_source) - 1):
            self.stroke_source.pop()  # an empty stroke left open before
            self.stroke_power.pop()
            self.stroke_feed.pop()
        first = len(self.stroke_source)
        s = int(starts.shape[0])
        self.stroke_source.extend([source] * s)
        self.stroke_power.extend([1.0] * s)
        self.stroke_feed.extend([math.nan] * s)
        ids = first + np.repeat(np.arange(s), np.diff(np.append(starts, n)))
        self.kinds.frombytes(np.ascontiguousarray(kinds, dtype=np.int8).tobytes())
        self.params.frombytes(np.ascontiguousarray(params, dtype=np.float64).tobytes())
        self.strokes.frombytes(ids.astype(np.int64).tobytes())
        self.lines.frombytes(np.full(n, line, dtype=np.int64).tobytes())
        self.matrix_ids.frombytes(np.full(n, matrix, dtype=np.int64).tobytes())
        self._open = True

    def build(self, page_height_mm: float | None = None,
              page_size_mm: tuple[float, float] | None = None) -> Drawing:
        if self._open and (not self.strokes or self.strokes[-1] != len(self.stroke_source) - 1):
            self.stroke_source.pop()
            self.stroke_power.pop()
            self.stroke_feed.pop()
        self._open = False
        params = np.frombuffer(self.params, dtype=np.float64).reshape(-1, 8)
        kind = np.frombuffer(self.kinds, dtype=np.int8)
        ids = np.frombuffer(self.matrix_ids, dtype=np.int64)
        if self.matrices and ids.size:
            params = _transform_by_matrix(kind, params, np.stack(self.matrices), ids)
        else:
            params = params.copy()
        self.params = array("d")
        return Drawing(
            file=self.file,
            kind=kind.copy(),
            params=params,
            stroke=_compact(self.strokes),
            line=_compact(self.lines),
            stroke_source=np.array(self.stroke_source, dtype=np.int64),
            stroke_power=np.array(self.stroke_power, dtype=np.float64),
            stroke_feed_mm_s=np.array(self.stroke_feed, dtype=np.float64),
            sources=self.sources,
            page_height_mm=page_height_mm,
            page_size_mm=page_size_mm,
            warnings=self.warnings,
            dwells=self.dwells,
            texts=self.texts,
        )


def _compact(values: array[int]) -> IntArray:
    """The builder's per-primitive numbers (stroke, source line) as int32 when every value
    fits, else int64 (4 bytes a primitive each on large drawings; the same values)."""
    out = np.frombuffer(values, dtype=np.int64) if len(values) else np.zeros(0, np.int64)
    if out.size and (out.max() >= 1 << 31 or out.min() < -(1 << 31)):
        return out.copy()
    return out.astype(np.int32)


#: Primitives mapped per block by `_transform_by_matrix` (bounds its temporary arrays).
TRANSFORM_BLOCK = 1 << 16


def _transform_by_matrix(kind: NDArray[np.int8], params: FloatArray, mats: FloatArray,
                         ids: NDArray[np.int64]) -> FloatArray:
    """Primitive i mapped by the affine map mats[ids[i]] (3×3; −1: identity), in blocks so
    the per-primitive matrices never exist for the whole drawing at once (each row's
    arithmetic is the same as in one pass)."""
    out = np.empty_like(params)
    for i in range(0, kind.shape[0], TRANSFORM_BLOCK):
        sl = slice(i, i + TRANSFORM_BLOCK)
        bid = ids[sl]
        m = mats[np.maximum(bid, 0)]
        m[bid < 0] = np.identity(3)
        out[sl] = _transform_each(kind[sl], params[sl], m[:, :2, :2], m[:, :2, 2])
    return out


# --------------------------------------------------------------------------- affine maps
def transform(kind: NDArray[np.int8], params: FloatArray, a: FloatArray,
              b: FloatArray) -> FloatArray:
    """Map primitives by x ↦ a·x + b. Lines/cubics: map control points (Bézier curves are
    affine invariant). Arcs: c ↦ a·c + b, M ↦ a·M (E(θ) = c + M·u(θ) maps to itself)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    out = params.copy()
    pts = params.reshape(-1, 4, 2)
    mapped = pts @ a.T + b
    is_arc = kind == ARC
    res = out.reshape(-1, 4, 2)
    res[~is_arc] = mapped[~is_arc]
    if is_arc.any():
        ar = params[is_arc]
        c = ar[:, 0:2] @ a.T + b
        m = ar[:, 2:6].reshape(-1, 2, 2)
        m2 = np.einsum("ij,njk->nik", a, m).reshape(-1, 4)
        out[is_arc, 0:2] = c
        out[is_arc, 2:6] = m2
    return out


def _transform_each(kind: NDArray[np.int8], params: FloatArray, a: FloatArray,
                    b: FloatArray) -> FloatArray:
    """Like `transform` with a different map per primitive: a (N, 2, 2), b (N, 2)."""
    out = params.copy()
    pts = params.reshape(-1, 4, 2)
    mapped = np.einsum("nij,nkj->nki", a, pts) + b[:, None, :]
    is_arc = kind == ARC
    out.reshape(-1, 4, 2)[~is_arc] = mapped[~is_arc]
    if is_arc.any():
        ar = params[is_arc]
        aa = a[is_arc]
        out[is_arc, 0:2] = np.einsum("nij,nj->ni", aa, ar[:, 0:2]) + b[is_arc]
        out[is_arc, 2:6] = np.einsum("nij,njk->nik", aa,
                                     ar[:, 2:6].reshape(-1, 2, 2)).reshape(-1, 4)
    return out


def affine_scale(a: FloatArray) -> float:
    """Largest singular value of a 2×2 matrix: the most any length can grow under it."""
    return float(np.linalg.norm(np.asarray(a, dtype=np.float64), 2))


# --------------------------------------------------------------------------- evaluation
def evaluate(kind: NDArray[np.int8], params: FloatArray, t: FloatArray,
             order: int = 0) -> FloatArray:
    """Point (order 0), first or second derivative w.r.t. t of primitive i at t[i]; (n, 2)."""
    t = np.asarray(t, dtype=np.float64)
    out = np.empty((t.shape[0], 2))
    line = kind == LINE
    if line.any():
        p = params[line]
        tt = t[line, None]
        if order == 0:
            out[line] = p[:, 0:2] + tt * (p[:, 2:4] - p[:, 0:2])
        elif order == 1:
            out[line] = p[:, 2:4] - p[:, 0:2]
        else:
            out[line] = 0.0
    cub = kind == CUBIC
    if cub.any():
        p = params[cub]
        tt = t[cub, None]
        p0, p1, p2, p3 = p[:, 0:2], p[:, 2:4], p[:, 4:6], p[:, 6:8]
        u = 1.0 - tt
        if order == 0:
            out[cub] = u**3 * p0 + 3 * u * u * tt * p1 + 3 * u * tt * tt * p2 + tt**3 * p3
        elif order == 1:
            out[cub] = 3 * (u * u * (p1 - p0) + 2 * u * tt * (p2 - p1) + tt * tt * (p3 - p2))
        else:
            out[cub] = 6 * (u * (p2 - 2 * p1 + p0) + tt * (p3 - 2 * p2 + p1))
    arc = kind == ARC
    if arc.any():
        p = params[arc]
        dth = p[:, 7]
        th = p[:, 6] + t[arc] * dth
        if order == 0:
            cs = np.stack((np.cos(th), np.sin(th)), axis=1)
            base = p[:, 0:2]
        elif order == 1:
            cs = np.stack((-np.sin(th), np.cos(th)), axis=1) * dth[:, None]
            base = 0.0
        else:
            cs = -np.stack((np.cos(th), np.sin(th)), axis=1) * (dth * dth)[:, None]
            base = 0.0
        m = p[:, 2:6].reshape(-1, 2, 2)
        out[arc] = base + np.einsum("nij,nj->ni", m, cs)
    return out


def start_points(kind: NDArray[np.int8], params: FloatArray) -> FloatArray:
    return evaluate(kind, params, np.zeros(kind.shape[0]))


def end_points(kind: NDArray[np.int8], params: FloatArray) -> FloatArray:
    return evaluate(kind, params, np.ones(kind.shape[0]))


def piece_counts(kind: NDArray[np.int8], params: FloatArray, tol_mm: float) -> IntArray:
    """Number of equal-parameter chords per primitive so every chord is within `tol_mm` of
    its curve piece.

    Bound: for a C² curve C(t) and its linear interpolant L on [t_a, t_a + h],
    ‖C(t) − L(t)‖ ≤ h²/8 · max‖C''‖ (the vector form of the interpolation error bound, from
    C − L = ∫ G(t, s) C''(s) ds with G ≤ 0 and ∫|G| ≤ h²/8). C(t) and L(t) are paired points,
    so the Hausdorff distance between chord and curve piece is within the same bound.
    - cubic: C'' is linear in t, so max‖C''‖ = max(‖C''(0)‖, ‖C''(1)‖), C''(0) = 6(p0−2p1+p2)
    - arc: C''(θ) = −M·u(θ), ‖C''‖ ≤ σ_max(M) per rad², so with t-steps h: h²Δθ²σ/8 ≤ tol
    - line: one chord (exact).
    n = ⌈sqrt(max‖C''‖ / (8·tol))⌉.
    """
    n = np.ones(kind.shape[0], dtype=np.int64)
    cub = kind == CUBIC
    if cub.any():
        p = params[cub]
        d0 = 6 * np.hypot(*(p[:, 0:2] - 2 * p[:, 2:4] + p[:, 4:6]).T)
        d1 = 6 * np.hypot(*(p[:, 2:4] - 2 * p[:, 4:6] + p[:, 6:8]).T)
        n[cub] = np.maximum(1, np.ceil(np.sqrt(np.maximum(d0, d1) / (8.0 * tol_mm))))
    arc = kind == ARC
    if arc.any():
        p = params[arc]
        m = p[:, 2:6].reshape(-1, 2, 2)
        sig = np.linalg.svd(m, compute_uv=False)[:, 0]
        n[arc] = np.maximum(1, np.ceil(np.abs(p[:, 7]) * np.sqrt(sig / (8.0 * tol_mm))))
    return n


@dataclass(frozen=True)
class Polylines:
    """Flattened strokes: vertices (M, 2) mm, CSR `offsets` (S+1,), and for each vertex the
    primitive it lies on (`prim`) and its parameter `t` there (vertex 0 of a stroke: the
    stroke's first primitive at t = 0). The chord v → v+1 lies on primitive prim[v+1] and
    spans t ∈ [t0[v+1], t[v+1]] (`t0`)."""

    points: FloatArray
    offsets: IntArray
    prim: IntArray
    t: FloatArray
    t0: FloatArray
    stroke: IntArray  # stroke index of each polyline (into the Drawing's strokes)


#: Primitives flattened at a time (bounds the per-vertex temporaries of `flatten`).
FLATTEN_BLOCK = 1 << 16


def flatten(drawing: Drawing, tol_mm: float, max_points: int | None = None) -> Polylines:
    """Flatten every stroke into a polyline whose chords are within `tol_mm` of the curves
    (bound in `piece_counts`), vectorised over blocks of primitives (each primitive's
    vertices depend on it alone, so blocks give the same arrays as one pass). More than
    `max_points` vertices is an `InputError`, raised before they are computed."""
    kind, params = drawing.kind, drawing.params
    nprim = kind.shape[0]
    if nprim == 0:
        z = np.zeros(0, dtype=np.int64)
        return Polylines(np.zeros((0, 2)), np.zeros(1, dtype=np.int64), z, np.zeros(0),
                         np.zeros(0), z)
    n = piece_counts(kind, params, tol_mm)
    first = np.ones(nprim, dtype=bool)
    first[1:] = drawing.stroke[1:] != drawing.stroke[:-1]
    # Each primitive contributes n points (t = 1/n … 1); each stroke also its start point.
    counts = n + first
    start_of = np.cumsum(counts) - counts
    total = int(start_of[-1] + counts[-1])
    if max_points is not None and total > max_points:
        raise InputError(f"flattened within {tol_mm:g} mm, the curves have {total:,} points, "
                         f"more than the limit {max_points:,} (4 × --max-segments); raise "
                         "--max-segments or the tolerance if the machine has the memory",
                         drawing.file)
    pts = np.empty((total, 2))
    prim_out = np.empty(total, dtype=np.int64)
    t_out = np.empty(total)
    t0_out = np.empty(total)
    for i in range(0, nprim, FLATTEN_BLOCK):
        c = counts[i:i + FLATTEN_BLOCK]
        v0 = int(start_of[i])
        v1 = v0 + int(c.sum())
        prim = np.repeat(np.arange(i, i + c.shape[0]), c)
        local = np.arange(v0, v1) - np.repeat(start_of[i:i + FLATTEN_BLOCK], c)
        j = local + 1 - np.repeat(first[i:i + FLATTEN_BLOCK], c)  # 0: the stroke's start
        nn = np.repeat(n[i:i + FLATTEN_BLOCK], c)
        t = j / nn
        pts[v0:v1] = evaluate(kind[prim], params[prim], t)
        t0_out[v0:v1] = np.where(j > 0, (j - 1) / nn, 0.0)
        t_out[v0:v1] = t
        prim_out[v0:v1] = prim
    starts = start_of[first]
    offsets = np.append(starts, total).astype(np.int64)
    return Polylines(pts, offsets, prim_out, t_out, t0_out,
                     drawing.stroke[first].astype(np.int64))


def nearest_distance(kind: NDArray[np.int8], params: FloatArray, q: FloatArray,
                     t_guess: FloatArray, iterations: int = 3) -> FloatArray:
    """Distance from q[i] to primitive i.

    Lines: exact (projection clamped to the segment). Curves: Newton's method on
    f(t) = (C(t) − q)·C'(t) from t_guess, t clamped to [0, 1] — always an upper bound of the
    true distance (a distance to a point on the curve; the best iterate is kept)."""
    out = np.empty(q.shape[0])
    line = kind == LINE
    if line.any():
        p = params[line]
        a, d = p[:, 0:2], p[:, 2:4] - p[:, 0:2]
        rel = q[line] - a
        dd = np.einsum("ij,ij->i", d, d)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.clip(np.nan_to_num(np.einsum("ij,ij->i", rel, d) / dd), 0.0, 1.0)
        out[line] = np.hypot(*(rel - u[:, None] * d).T)
    cur = ~line
    if cur.any():
        k, p, qq = kind[cur], params[cur], q[cur]
        t = np.clip(np.asarray(t_guess, dtype=np.float64)[cur], 0.0, 1.0)
        best = np.hypot(*(evaluate(k, p, t) - qq).T)
        for _ in range(iterations):
            c = evaluate(k, p, t)
            d1 = evaluate(k, p, t, 1)
            d2 = evaluate(k, p, t, 2)
            r = c - qq
            f = np.einsum("ij,ij->i", r, d1)
            fp = np.einsum("ij,ij->i", d1, d1) + np.einsum("ij,ij->i", r, d2)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(fp > 0, f / fp, 0.0)
            t = np.clip(t - np.nan_to_num(step), 0.0, 1.0)
            best = np.minimum(best, np.hypot(*(evaluate(k, p, t) - qq).T))
        out[cur] = best
    return out


def read_source(source: str | Path | bytes, file: str | None, default: str) -> tuple[bytes, str]:
    """The bytes of a drawing given as a path or as bytes, and the name errors should use."""
    if isinstance(source, bytes):
        return source, file or default
    name = file or str(source)
    try:
        return Path(source).read_bytes(), name
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror or e}", name) from e
