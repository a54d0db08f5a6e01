"""Lookup tables: the closed form sampled on a regular grid and read back by bilinear or
bicubic (Keys/Catmull–Rom, a = −½) interpolation, for inverse (x, y → angles) and forward
(angles → x, y) kinematics.

Each cell stores the largest pen error measured against the closed form at build time on
sub-samples; `max_error` and `min_margins` refuse cells, and a stencil that would straddle
the ±π seam is refused too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from benchmarks.approx.common import (
    Approximation,
    Box,
    Grid,
    Kind,
    Order,
    as_rows,
    assemblable,
    check_assembly,
    check_box,
    check_inverse_args,
    closed_inverse,
    exact_values,
    pen_error,
    reachable,
    unwrap_about,
)
from kinematics.arrays import BoolArray, FloatArray, IndexArray
from kinematics.fivebar import FiveBar


#: Catmull–Rom / Keys (a = −½) weights of the 4 taps at offsets −1, 0, 1, 2 for fraction t.
def _keys_weights(t: FloatArray) -> FloatArray:
    t2 = t * t
    t3 = t2 * t
    return np.stack((-0.5 * t3 + t2 - 0.5 * t,
                     1.5 * t3 - 2.5 * t2 + 1.0,
                     -1.5 * t3 + 2.0 * t2 + 0.5 * t,
                     0.5 * t3 - 0.5 * t2), axis=1)


@dataclass(frozen=True, eq=False)
class LookupTable:
    """The closed form sampled on an nx × ny grid over a box and read back by interpolation.

    `values` (ny·nx, 2) node values (angles unwrapped so a stencil never straddles the ±π
    seam — stencils that would are refused); `cell_ok` (ny−1, nx−1) usable cells; `cell_error`
    the largest pen error (mm) measured against the closed form at build time on sub-samples
    of each cell (centre and edge midpoints; bicubic also the quarter points; inf where
    refused).
    """

    fb: FiveBar
    kind: Kind
    mode: str
    assembly: str
    order: Order
    grid: Grid
    values: FloatArray
    cell_ok: BoolArray
    cell_error: FloatArray

    @property
    def size(self) -> tuple[int, int]:
        """(nodes along u, nodes along v)."""
        return (self.grid.nx, self.grid.ny)

    @property
    def nbytes(self) -> int:
        """Memory held by the table's arrays, bytes."""
        return int(self.values.nbytes + self.cell_ok.nbytes + self.cell_error.nbytes)

    def _raw(self, q: FloatArray) -> tuple[FloatArray, BoolArray, IndexArray]:
        """Interpolated values, ok mask (in box and usable cell) and flat cell index."""
        g = self.grid
        nx = g.nx
        i, j, fu, fv, inside = g.locate(q, nx - 1, g.ny - 1)
        cell = j * (nx - 1) + i
        ok = inside & self.cell_ok.ravel()[cell]
        v = self.values
        k = j * nx + i
        if self.order == "linear":
            v00 = v[k]
            v01 = v[k + 1]
            v10 = v[k + nx]
            v11 = v[k + nx + 1]
            a = v00 + fu[:, None] * (v01 - v00)
            b = v10 + fu[:, None] * (v11 - v10)
            y = a + fv[:, None] * (b - a)
        else:
            # 4 × 4 stencil from node (i−1, j−1); refused cells at the rim are clamped here.
            wu = _keys_weights(fu)
            wv = _keys_weights(fv)
            base = np.clip(k - nx - 1, 0, v.shape[0] - 3 * nx - 4)
            y = np.zeros((q.shape[0], 2))
            for r in range(4):
                row = np.zeros((q.shape[0], 2))
                for c in range(4):
                    row += wu[:, c, None] * v[base + r * nx + c]
                y += wv[:, r, None] * row
        return y, np.asarray(ok, dtype=bool), cell

    def __call__(self, q_in: ArrayLike) -> Approximation:
        """Interpolate at points (inverse: (x, y) mm → angles rad) or angles (forward)."""
        q = as_rows(q_in, "input")
        y, ok, _ = self._raw(q)
        if self.kind == "inverse":
            ok &= reachable(self.fb, q)
        else:
            ok &= assemblable(self.fb, q)
        y[~ok] = 0.0
        return Approximation(y, ok)

    def error_estimate(self, q_in: ArrayLike) -> FloatArray:
        """The build-time error of the cell holding each query (inf where refused)."""
        q = as_rows(q_in, "input")
        _, ok, cell = self._raw(q)
        return np.asarray(np.where(ok, self.cell_error.ravel()[cell], np.inf), dtype=np.float64)


def _table(fb: FiveBar, kind: Kind, key: str, box: Box, n: int | tuple[int, int],
           order: Order, max_error: float, page_assembly: str | None,
           centre: ArrayLike | None = None,
           min_margins: tuple[float, float] = (0.0, 0.0)) -> LookupTable:
    box = check_box(box)
    nx, ny = (n, n) if isinstance(n, int) else n
    if order not in ("linear", "cubic"):
        raise ValueError(f"order must be 'linear' or 'cubic'; got {order!r}")
    if min(nx, ny) < (4 if order == "cubic" else 2):
        raise ValueError(f"a {order} table needs ≥ {4 if order == 'cubic' else 2} nodes per "
                         f"axis; got {nx} × {ny}")
    g = Grid(box, nx, ny)
    nodes = g.nodes()
    vals, node_ok = exact_values(fb, kind, key, nodes, page_assembly, min_margins)
    if kind == "inverse" and node_ok.any():
        # One continuous branch of the angles: unwrapped into (θc − π, θc + π] about the
        # angles θc at `centre` (default: the valid node nearest the box centre), so the seam
        # lies where an elbow points away from where it points at the centre. A stencil
        # that still jumps by > π there is refused below.
        if centre is not None:
            c = np.asarray(centre, dtype=np.float64).reshape(1, 2)
            th_c, ok_c = closed_inverse(fb, key, c)
            if not ok_c[0]:
                raise ValueError(f"centre {c[0].tolist()} mm is not reachable in mode {key}")
            ref = th_c[0]
        else:
            mid = np.array([0.5 * (box[0] + box[1]), 0.5 * (box[2] + box[3])])
            dist = np.where(node_ok, np.hypot(*(nodes - mid).T), np.inf)
            ref = vals[int(np.argmin(dist))]
        vals = unwrap_about(vals, ref)
    vals[~node_ok] = 0.0
    vg = vals.reshape(ny, nx, 2)
    okg = node_ok.reshape(ny, nx)
    # A cell is usable if its whole stencil is valid and spans less than π in angle.
    if order == "linear":
        stencil = [(0, 0), (0, 1), (1, 0), (1, 1)]
        lo_j, hi_j, lo_i, hi_i = 0, ny - 1, 0, nx - 1
    else:
        stencil = [(r, c) for r in range(-1, 3) for c in range(-1, 3)]
        lo_j, hi_j, lo_i, hi_i = 1, ny - 2, 1, nx - 2
    cell_ok = np.zeros((ny - 1, nx - 1), dtype=bool)
    sl = (slice(lo_j, hi_j), slice(lo_i, hi_i))
    acc = np.ones((hi_j - lo_j, hi_i - lo_i), dtype=bool)
    vmin = np.full((hi_j - lo_j, hi_i - lo_i, 2), np.inf)
    vmax = np.full((hi_j - lo_j, hi_i - lo_i, 2), -np.inf)
    for dj, di in stencil:
        win = (slice(lo_j + dj, hi_j + dj), slice(lo_i + di, hi_i + di))
        acc &= okg[win]
        vmin = np.minimum(vmin, vg[win])
        vmax = np.maximum(vmax, vg[win])
    if kind == "inverse":
        acc &= ((vmax - vmin) < math.pi).all(axis=2)
    cell_ok[sl] = acc
    tab = LookupTable(fb, kind, key if kind == "inverse" else "",
                      key if kind == "forward" else (page_assembly or ""), order, g,
                      np.ascontiguousarray(vals), cell_ok, np.zeros((ny - 1, nx - 1)))
    # Build-time error per cell. Bilinear: for a locally quadratic map the error vector is
    # bilinear in (s(1 − s), t(1 − t)) ∈ [0, ¼]², so its norm peaks at a corner of that
    # square — the cell centre or an edge midpoint: those five samples. Bicubic: the quarter
    # points too.
    pts5 = [[0.5, 0.5], [0.5, 0.0], [1.0, 0.5], [0.5, 1.0], [0.0, 0.5]]
    quarters = [[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]]
    loc = np.array(pts5 + (quarters if order == "cubic" else [])) * np.array([g.hu, g.hv])
    cj, ci = np.nonzero(cell_ok)
    corner = np.stack((box[0] + ci * g.hu, box[2] + cj * g.hv), axis=1)
    sub = (corner[:, None, :] + loc[None]).reshape(-1, 2)
    err = np.full((ny - 1, nx - 1), np.inf)
    if sub.size:
        approx, aok, _ = tab._raw(sub)
        exact, eok = exact_values(fb, kind, key, sub, page_assembly)
        e = pen_error(fb, kind, sub, approx, exact)
        # A sub-sample without an exact answer inside a usable cell: the closed form refuses
        # there too (dead-zone arc through the cell); `__call__` refuses it by its reach test.
        e = np.where(aok & eok, e, 0.0).reshape(-1, loc.shape[0]).max(axis=1)
        err[cj, ci] = e
    cell_ok &= err <= max_error
    err[~cell_ok] = np.inf
    return LookupTable(fb, kind, tab.mode, tab.assembly, order, g, tab.values, cell_ok, err)


def inverse_table(fb: FiveBar, mode: str, box: Box, n: int | tuple[int, int],
                  order: Order = "linear", max_error: float = math.inf,
                  assembly: str | None = None, centre: ArrayLike | None = None,
                  min_margins: tuple[float, float] = (0.0, 0.0)) -> LookupTable:
    """Inverse kinematics of working mode `mode` tabulated on n × n nodes over an (x, y) box
    (mm). With `assembly`, nodes of the other assembly count as missing (the table then never
    interpolates across the type-2 curve). Cells whose build-time pen error exceeds
    `max_error` mm are refused, and so are cells with a node closer than `min_margins` =
    (type 1, type 2) rad to a singularity. `centre` (mm) places the angles' ±π seam."""
    check_inverse_args(mode, assembly)
    return _table(fb, "inverse", mode, box, n, order, max_error, assembly, centre,
                  min_margins)


def forward_table(fb: FiveBar, assembly: str, box: Box, n: int | tuple[int, int],
                  order: Order = "linear", max_error: float = math.inf,
                  min_margins: tuple[float, float] = (0.0, 0.0)) -> LookupTable:
    """Forward kinematics of assembly `assembly` tabulated on n × n nodes over a (θ1, θ2)
    box (rad). Cells whose build-time error exceeds `max_error` mm are refused, and so are
    cells with a node closer than `min_margins` = (type 1, type 2) rad to a singularity."""
    check_assembly(assembly)
    return _table(fb, "forward", assembly, box, n, order, max_error, None, None, min_margins)
