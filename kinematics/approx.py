"""Approximate five-bar kinematics, kept to measure them against the closed form (issue 7).

Three families, all pure numpy and vectorised, each with inverse (point → motor angles) and
forward (motor angles → point) maps:

- `LinearApprox` — the thesis' linear transform (Gamble 2020, Sec. 5.2): Eq. 25

      [θ1, θ2']ᵀ ≈ B·(R(γ)·[x, y]ᵀ + [A1, A2]ᵀ),     R(γ) the rotation by γ,

  and its algebraic inverse, Eq. 26, [x, y]ᵀ ≈ R(γ)ᵀ·([θ1, θ2']ᵀ/B − A), as forward
  kinematics. The thesis measures θ2 as the interior angle at M2 from the direction M2→M1, so
  θ2' = π − θ2 in this project's convention (ARCHITECTURE.md); with that, the least-squares fit
  over the default machine's page region lands on γ = 135°, the rotation the thesis read off its
  Fig. 25. γ, A1, A2, B are fitted by linear least squares on c = B·cos γ, s = B·sin γ, B·A
  (`form="similarity"`, 4 parameters as in Eq. 25); `form="affine"` frees the 2×2 matrix (6
  parameters), the best any linear map can do.
- `TiledLinear` — the same fit per region: the domain box is cut into tiles and each tile gets
  its own Eq. 25 (similarity) or affine map, fitted to the closed form on a sub-grid of the tile.
  Inverse tiles live in the (x, y) box, forward tiles in the (θ1, θ2) box.
- `LookupTable` — the closed form sampled on a regular grid, read back by bilinear or bicubic
  (Keys/Catmull–Rom, a = −½) interpolation.

Documented behaviour where they fail (tests/test_stability.py holds each case):

- every map returns an `Approximation` (values + `valid` mask); invalid rows hold 0.0, never NaN;
- outside the domain box a point is refused; so is any point the closed form would refuse:
  inverse maps check both reach annuli (|a_i − b_i| ≤ |P − M_i| ≤ a_i + b_i), forward maps the
  elbow distance (|b1 − b2| ≤ |R1 − R2| ≤ b1 + b2) — two cheap distance tests, so an
  approximation never answers where no answer exists;
- tiles refuse the whole tile, tables the whole cell (the interpolation stencil: 2×2 nodes
  bilinear, 4×4 bicubic), when a sample or node of it has no closed-form answer (out of reach;
  with `assembly` given, the other assembly), or when its angles jump by more than π (the ±π
  seam: inverse tables keep one continuous branch, unwrapped about the angles at a `centre`);
- inside, the error is not checked per point (that would cost the closed form itself): each
  tile and cell stores the largest *pen* error (mm) measured against the closed form at build
  time on sub-samples (`error` / `cell_error`; for inverse maps: where the approximate angles put
  the pen), and `max_error` refuses tiles/cells above it. This is an estimate from samples, not
  a proof: a point singularity inside a cell escapes it. `min_margins` (type 1, type 2) refuses
  tiles/cells with a sample or node that close to a singularity, as the job's pose checks
  do; margins are continuous, so a fine enough grid then keeps singular points out of every
  usable cell. The error grows near type-1 singularities for inverse maps (θ has a square-root
  branch point at the reach circles) and near type-2 singularities for both (P has one where
  the floating links align, and there any angle error moves the pen far): where the closed
  form's derivative blows up, any interpolant's error does.

The benchmark (`python -m benchmarks.speed_accuracy`) charts time per point against error for
all of them; the job pipeline uses none, see docs/performance.md for why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.fivebar import WORKING_MODES, FiveBar

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.intp]
Box = tuple[float, float, float, float]  # (u_min, u_max, v_min, v_max)
Form = Literal["similarity", "affine"]
Kind = Literal["inverse", "forward"]
Order = Literal["linear", "cubic"]

__all__ = [
    "Approximation",
    "LinearApprox",
    "LookupTable",
    "TiledLinear",
    "assemblable",
    "fit_linear",
    "forward_table",
    "forward_tiles",
    "inverse_table",
    "inverse_tiles",
    "reachable",
    "to_thesis",
]


@dataclass(frozen=True)
class Approximation:
    """Result of an approximate map: values (N, 2) (rad for inverse, mm for forward) and a
    `valid` mask (N,); rows that are not valid hold 0.0."""

    values: FloatArray
    valid: BoolArray


# ----------------------------------------------------------------------------- helpers
def _as_rows(values: ArrayLike, what: str) -> FloatArray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape == (2,):
        arr = arr.reshape(1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{what} must have shape (2,) or (N, 2); got {arr.shape}")
    return arr


def _check_box(box: Box) -> Box:
    u0, u1, v0, v1 = (float(b) for b in box)
    if not (math.isfinite(u0 + u1 + v0 + v1) and u1 > u0 and v1 > v0):
        raise ValueError(f"box must be finite (u_min, u_max, v_min, v_max) with max > min; "
                         f"got {box!r}")
    return (u0, u1, v0, v1)


def _in_box(q: FloatArray, box: Box) -> BoolArray:
    u0, u1, v0, v1 = box
    return np.asarray((q[:, 0] >= u0) & (q[:, 0] <= u1) & (q[:, 1] >= v0) & (q[:, 1] <= v1),
                      dtype=bool)


def reachable(fb: FiveBar, points: FloatArray) -> BoolArray:
    """True where both reach annuli contain the point: the closed form's inverse exists in
    every working mode (boundary included). Two squared distances, no square root."""
    x, y = points[:, 0], points[:, 1]
    c1 = x * x + y * y
    c2 = (x - fb.w) ** 2 + y * y
    (lo1, hi1), (lo2, hi2) = fb.reach
    ok = (c1 <= hi1 * hi1) & (c1 >= lo1 * lo1) & (c2 <= hi2 * hi2) & (c2 >= lo2 * lo2)
    return np.asarray(ok & np.isfinite(c1 + c2), dtype=bool)


def assemblable(fb: FiveBar, angles: FloatArray) -> BoolArray:
    """True where the floating links can meet: |b1 − b2| ≤ |R1 − R2| ≤ b1 + b2 (the closed
    form's forward kinematics exist, in both assemblies)."""
    dx = fb.w + fb.a2 * np.cos(angles[:, 1]) - fb.a1 * np.cos(angles[:, 0])
    dy = fb.a2 * np.sin(angles[:, 1]) - fb.a1 * np.sin(angles[:, 0])
    lsq = dx * dx + dy * dy
    hi = fb.b1 + fb.b2
    lo = fb.b1 - fb.b2
    ok = (lsq <= hi * hi) & (lsq >= lo * lo) & (lsq > 0.0)
    return np.asarray(ok & np.isfinite(lsq), dtype=bool)


def to_thesis(angles: FloatArray) -> FloatArray:
    """Motor angles in the thesis' convention: θ1 unchanged, θ2' = π − θ2 (the interior
    angle at M2 measured from M2→M1, Sec. 2). The map is its own inverse."""
    out = np.array(angles, dtype=np.float64, copy=True)
    out[..., 1] = math.pi - out[..., 1]
    return out


def _unwrap_about(theta: FloatArray, ref: FloatArray) -> FloatArray:
    """Angles shifted by multiples of 2π into (ref − π, ref + π], per column."""
    return np.asarray(ref + np.mod(theta - ref + math.pi, 2.0 * math.pi) - math.pi,
                      dtype=np.float64)


def _closed_inverse(fb: FiveBar, mode: str, pts: FloatArray) -> tuple[FloatArray, BoolArray]:
    res = fb.inverse_batch(pts, mode)
    return np.asarray(res.angles), np.asarray(res.valid)


def _closed_forward(fb: FiveBar, assembly: str, th: FloatArray) -> tuple[FloatArray, BoolArray]:
    res = fb.forward_batch(th, assembly)
    return np.asarray(res.points), np.asarray(res.valid)


def _same_branch_inverse(fb: FiveBar, mode: str, assembly: str | None, pts: FloatArray,
                         th: FloatArray) -> BoolArray:
    """True where the exact pose (pts, th) has the assembly sign `assembly` (None: any)."""
    if assembly is None:
        return np.ones(pts.shape[0], dtype=bool)
    sign = 1 if assembly == "+" else -1
    return np.asarray(fb.assembly_of(th, pts) == sign, dtype=bool)


def _check_mode(mode: str) -> None:
    if mode not in WORKING_MODES:
        raise ValueError(f"working mode must be one of {', '.join(WORKING_MODES)}; got {mode!r}")


def _check_assembly(assembly: str) -> None:
    if assembly not in ("+", "-"):
        raise ValueError(f"assembly must be '+' or '-'; got {assembly!r}")


def _lsq_maps(u: FloatArray, y: FloatArray, form: Form) -> tuple[FloatArray, FloatArray]:
    """Least-squares linear maps y ≈ M·u + c for T independent sample sets.

    u, y: (T, S, 2). Returns M (T, 2, 2), c (T, 2). `similarity` restricts M to B·R(γ)
    (Eq. 25: M = [[c, −s], [s, c]]); `affine` leaves M free. Solved per set on the normal
    equations of coordinates centred and scaled per set, so tiny tiles stay well conditioned.
    """
    if form not in ("similarity", "affine"):
        raise ValueError(f"form must be 'similarity' or 'affine'; got {form!r}")
    mu = u.mean(axis=1, keepdims=True)
    sc = np.sqrt(((u - mu) ** 2).sum(axis=2).mean(axis=1, keepdims=True))[..., None]
    sc = np.where(sc > 0, sc, 1.0)
    z = (u - mu) / sc  # (T, S, 2), zero mean, unit RMS radius
    t, s = z.shape[0], z.shape[1]
    ones = np.ones((t, s))
    if form == "affine":
        x = np.stack((z[..., 0], z[..., 1], ones), axis=2)  # (T, S, 3)
        xtx = np.einsum("tsi,tsj->tij", x, x)
        xty = np.einsum("tsi,tsk->tik", x, y)
        coef = np.linalg.solve(xtx, xty)  # (T, 3, 2)
        mz = np.transpose(coef[:, :2, :], (0, 2, 1))  # y = mz·z + c0
        c0 = coef[:, 2, :]
    else:
        zeros = np.zeros((t, s))
        # rows for y0: [z0, −z1, 1, 0]·[c, s, a0, a1]; for y1: [z1, z0, 0, 1].
        r0 = np.stack((z[..., 0], -z[..., 1], ones, zeros), axis=2)
        r1 = np.stack((z[..., 1], z[..., 0], zeros, ones), axis=2)
        x = np.concatenate((r0, r1), axis=1)  # (T, 2S, 4)
        rhs = np.concatenate((y[..., 0], y[..., 1]), axis=1)  # (T, 2S)
        xtx = np.einsum("tsi,tsj->tij", x, x)
        xty = np.einsum("tsi,ts->ti", x, rhs)
        p = np.linalg.solve(xtx, xty[..., None])[..., 0]  # (T, 4)
        mz = np.empty((t, 2, 2))
        mz[:, 0, 0] = p[:, 0]
        mz[:, 0, 1] = -p[:, 1]
        mz[:, 1, 0] = p[:, 1]
        mz[:, 1, 1] = p[:, 0]
        c0 = p[:, 2:4]
    m = mz / sc  # back to raw coordinates: y = m·(u − mu) + c0
    c = c0 - np.einsum("tij,tj->ti", m, mu[:, 0, :])
    return np.asarray(m, dtype=np.float64), np.asarray(c, dtype=np.float64)


# ----------------------------------------------------------------------------- Eq. 25 / 26
@dataclass(frozen=True, eq=False)
class LinearApprox:
    """The thesis' linear approximation fitted to a machine (Sec. 5.2, Eqs. 25–26).

    θ' = M·p + c with θ' = `to_thesis`(θ) and M = B·R(γ), c = B·A for the `similarity` form;
    `box` / `angle_box` bound the fitted points / angles (the domains of `inverse` /
    `forward`); `rms_rad` and `max_rad` are the fit's angle residuals on its own samples.
    """

    fb: FiveBar
    mode: str
    assembly: str
    form: Form
    matrix: FloatArray
    offset: FloatArray
    box: Box
    angle_box: Box
    rms_rad: float
    max_rad: float

    @property
    def gamma(self) -> float:
        """Rotation γ of Eq. 25, rad (similarity form only)."""
        self._need_similarity()
        return math.atan2(float(self.matrix[1, 0]), float(self.matrix[0, 0]))

    @property
    def scale(self) -> float:
        """Scale factor B of Eq. 25, rad/mm (similarity form only)."""
        self._need_similarity()
        return math.hypot(float(self.matrix[0, 0]), float(self.matrix[1, 0]))

    @property
    def shift(self) -> tuple[float, float]:
        """Shift (A1, A2) of Eq. 25, mm (similarity form only)."""
        b = self.scale
        return (float(self.offset[0]) / b, float(self.offset[1]) / b)

    def _need_similarity(self) -> None:
        if self.form != "similarity":
            raise ValueError("γ, A and B exist for the similarity form (Eq. 25) only")

    def inverse(self, points: ArrayLike) -> Approximation:
        """Eq. 25: motor angles (N, 2) rad (this project's convention) for points (N, 2) mm.
        Refused outside `box` and where the point is out of reach."""
        p = _as_rows(points, "points")
        th = p @ self.matrix.T + self.offset
        th[:, 1] = math.pi - th[:, 1]
        ok = _in_box(p, self.box) & reachable(self.fb, p)
        th[~ok] = 0.0
        return Approximation(th, ok)

    def forward(self, angles: ArrayLike) -> Approximation:
        """Eq. 26: points (N, 2) mm for motor angles (N, 2) rad — the algebraic inverse of the
        fitted Eq. 25, as the thesis proposes. Refused outside `angle_box` and where the
        floating links cannot meet."""
        th = _as_rows(angles, "angles")
        tt = to_thesis(th)
        inv = np.linalg.inv(self.matrix)
        p = (tt - self.offset) @ inv.T
        ok = _in_box(th, self.angle_box) & assemblable(self.fb, th)
        p[~ok] = 0.0
        return Approximation(np.asarray(p, dtype=np.float64), ok)


def fit_linear(fb: FiveBar, mode: str, points: ArrayLike,
               form: Form = "similarity") -> LinearApprox:
    """Fit Eq. 25 by least squares to the closed-form inverse at `points` (N ≥ 3, mm).

    Every point must be reachable in `mode` and all must share one assembly sign (the
    forward map, Eq. 26, is then read in that assembly); otherwise ValueError.
    """
    _check_mode(mode)
    p = _as_rows(points, "points")
    if p.shape[0] < 3:
        raise ValueError(f"need at least 3 points to fit; got {p.shape[0]}")
    th, ok = _closed_inverse(fb, mode, p)
    if not ok.all():
        bad = p[int(np.flatnonzero(~ok)[0])]
        raise ValueError(f"point ({bad[0]:.6g}, {bad[1]:.6g}) mm is not reachable in mode "
                         f"{mode}: fit only on the workspace")
    asm = fb.assembly_of(th, p)
    if not (np.all(asm > 0) or np.all(asm < 0)):
        raise ValueError("the points straddle the type-2 singularity (both assembly signs): "
                         "Eq. 26 needs one assembly")
    tt = to_thesis(th)
    tt = _unwrap_about(tt, tt[0])
    m, c = _lsq_maps(p[None], tt[None], form)
    resid = p @ m[0].T + c[0] - tt
    box = (float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()),
           float(p[:, 1].max()))
    abox = (float(th[:, 0].min()), float(th[:, 0].max()), float(th[:, 1].min()),
            float(th[:, 1].max()))
    return LinearApprox(fb, mode, "+" if asm[0] > 0 else "-", form, m[0], c[0], box, abox,
                        float(np.sqrt(np.mean(resid ** 2))), float(np.abs(resid).max()))


# ----------------------------------------------------------------------------- grids
@dataclass(frozen=True)
class _Grid:
    """A regular grid of nx × ny nodes over a box (node (j, i) at (u0 + i·hu, v0 + j·hv))."""

    box: Box
    nx: int
    ny: int

    @property
    def hu(self) -> float:
        return (self.box[1] - self.box[0]) / (self.nx - 1)

    @property
    def hv(self) -> float:
        return (self.box[3] - self.box[2]) / (self.ny - 1)

    def nodes(self) -> FloatArray:
        u = np.linspace(self.box[0], self.box[1], self.nx)
        v = np.linspace(self.box[2], self.box[3], self.ny)
        uu, vv = np.meshgrid(u, v)
        return np.stack((uu.ravel(), vv.ravel()), axis=1)

    def locate(self, q: FloatArray, ncu: int, ncv: int
               ) -> tuple[IntArray, IntArray, FloatArray, FloatArray, BoolArray]:
        """Cell indices (i, j) in [0, ncu) × [0, ncv), local coordinates (fu, fv) and the
        inside-the-box mask for query points q (N, 2)."""
        fu = (q[:, 0] - self.box[0]) * (1.0 / self.hu)
        fv = (q[:, 1] - self.box[2]) * (1.0 / self.hv)
        inside = (fu >= 0.0) & (fu <= self.nx - 1) & (fv >= 0.0) & (fv <= self.ny - 1)
        with np.errstate(invalid="ignore"):
            i = np.clip(np.floor(fu), 0, ncu - 1).astype(np.intp)
            j = np.clip(np.floor(fv), 0, ncv - 1).astype(np.intp)
        i[~inside] = 0
        j[~inside] = 0
        return i, j, fu - i, fv - j, np.asarray(inside, dtype=bool)


def _exact(fb: FiveBar, kind: Kind, mode_or_asm: str, q: FloatArray,
           page_assembly: str | None, min_margins: tuple[float, float] = (0.0, 0.0)
           ) -> tuple[FloatArray, BoolArray]:
    """Closed-form values at q for building/checking an approximation: inverse (angles of
    points, restricted to one assembly if given) or forward (points of angles). With
    `min_margins` = (type 1, type 2) in rad, poses closer than that to a singularity
    (`FiveBar.singularity_margins`, magnitudes) count as having no value."""
    if kind == "inverse":
        th, ok = _closed_inverse(fb, mode_or_asm, q)
        ok &= _same_branch_inverse(fb, mode_or_asm, page_assembly, q, th)
        vals, pts, ang = th, q, th
    else:
        vals, ok = _closed_forward(fb, mode_or_asm, q)
        pts, ang = vals, q
    m1, m2 = min_margins
    if (m1 > 0.0 or m2 > 0.0) and ok.any():
        m = np.abs(fb.singularity_margins(ang, pts))
        ok &= (m[:, 0] >= m1) & (m[:, 1] >= m1) & (m[:, 2] >= m2)
    return vals, ok


def _pen_error(fb: FiveBar, kind: Kind, q: FloatArray, approx: FloatArray,
               exact: FloatArray) -> FloatArray:
    """Pen error (mm) of approximate answers at inputs q: for forward maps the distance to the
    exact point; for inverse maps the distance from q to where the approximate angles put the
    pen (closed-form forward kinematics in the exact pose's own assembly), inf if they put it
    nowhere. Angle errors are thereby weighed by the machine's sensitivity, which is what a
    tolerance in mm needs (near a type-2 singularity a tiny angle error moves the pen far)."""
    if kind == "forward":
        return np.asarray(np.hypot(*(approx - exact).T), dtype=np.float64)
    asm = fb.assembly_of(exact, q).astype(np.float64)
    asm[asm == 0] = 1.0
    fw = fb.forward_batch(approx, asm)
    e = np.hypot(*(np.asarray(fw.points) - q).T)
    return np.asarray(np.where(fw.valid, e, np.inf), dtype=np.float64)


# ----------------------------------------------------------------------------- tiles
@dataclass(frozen=True, eq=False)
class TiledLinear:
    """Per-region linear maps: the box is cut into tiles_u × tiles_v tiles, each with its own
    y ≈ M·u + c (Eq. 25 form or affine) fitted to the closed form on a sub-grid of the tile.

    `ok` (tv, tu) marks usable tiles; `error` (tv, tu) is the largest error measured on the
    tile's fit samples (rad for inverse, mm for forward).
    """

    fb: FiveBar
    kind: Kind
    mode: str
    assembly: str
    form: Form
    grid: _Grid
    matrix: FloatArray  # (tv, tu, 2, 2)
    offset: FloatArray  # (tv, tu, 2)
    ok: BoolArray
    error: FloatArray

    @property
    def tiles(self) -> tuple[int, int]:
        """(tiles along u, tiles along v)."""
        return (self.grid.nx - 1, self.grid.ny - 1)

    def __call__(self, q_in: ArrayLike) -> Approximation:
        """Evaluate at points (inverse) or angles (forward), (N, 2)."""
        q = _as_rows(q_in, "input")
        tu, tv = self.tiles
        i, j, _, _, inside = self.grid.locate(q, tu, tv)
        m = self.matrix[j, i]
        c = self.offset[j, i]
        y = np.einsum("nij,nj->ni", m, q if self.kind == "inverse" else to_thesis(q)) + c
        ok = inside & self.ok[j, i]
        if self.kind == "inverse":
            y[:, 1] = math.pi - y[:, 1]
            ok &= reachable(self.fb, q)
        else:
            ok &= assemblable(self.fb, q)
        y[~ok] = 0.0
        return Approximation(np.asarray(y, dtype=np.float64), np.asarray(ok, dtype=bool))


def _tiles(fb: FiveBar, kind: Kind, key: str, box: Box, tiles: int | tuple[int, int],
           samples: int, form: Form, max_error: float, page_assembly: str | None,
           min_margins: tuple[float, float] = (0.0, 0.0)) -> TiledLinear:
    box = _check_box(box)
    tu, tv = (tiles, tiles) if isinstance(tiles, int) else tiles
    if tu < 1 or tv < 1 or samples < 2:
        raise ValueError(f"need ≥ 1 tile per axis and ≥ 2 samples per tile axis; got "
                         f"{tiles!r}, {samples}")
    grid = _Grid(box, tu + 1, tv + 1)
    # Sub-grid of samples x samples per tile (tile edges included), (T, S, 2).
    f = np.linspace(0.0, 1.0, samples)
    fu, fv = np.meshgrid(f, f)
    loc = np.stack((fu.ravel(), fv.ravel()), axis=1)
    ii, jj = np.meshgrid(np.arange(tu), np.arange(tv))
    corner = np.stack((box[0] + ii.ravel() * grid.hu, box[2] + jj.ravel() * grid.hv), axis=1)
    u = corner[:, None, :] + loc[None, :, :] * np.array([grid.hu, grid.hv])
    flat = u.reshape(-1, 2)
    y, valid = _exact(fb, kind, key, flat, page_assembly, min_margins)
    if kind == "forward":
        u = to_thesis(u)  # fit P against θ' = (θ1, π − θ2), the variables of Eq. 26
    n_t, n_s = u.shape[0], u.shape[1]
    y = y.reshape(n_t, n_s, 2)
    valid = valid.reshape(n_t, n_s)
    if kind == "inverse":
        y = to_thesis(y)
        y = _unwrap_about(y, y[:, :1, :])
    ok = np.asarray(valid.all(axis=1), dtype=bool)
    if kind == "inverse":
        ok &= ~(np.ptp(y, axis=1) > math.pi).any(axis=1)  # the ±π seam runs through the tile
    yfit = np.where(ok[:, None, None], y, u)  # dummy well-posed data for refused tiles
    m, c = _lsq_maps(u, yfit, form)
    pred = np.einsum("tij,tsj->tsi", m, u) + c[:, None, :]
    if kind == "inverse":  # back to this project's angles, then to pen error
        pe = _pen_error(fb, kind, flat, to_thesis(pred).reshape(-1, 2),
                        to_thesis(y).reshape(-1, 2))
    else:
        pe = _pen_error(fb, kind, flat, pred.reshape(-1, 2), y.reshape(-1, 2))
    err = np.where(ok, pe.reshape(n_t, n_s).max(axis=1), np.inf)
    ok &= err <= max_error
    return TiledLinear(fb, kind, key if kind == "inverse" else "",
                       key if kind == "forward" else (page_assembly or ""), form, grid,
                       m.reshape(tv, tu, 2, 2), c.reshape(tv, tu, 2), ok.reshape(tv, tu),
                       err.reshape(tv, tu))


def inverse_tiles(fb: FiveBar, mode: str, box: Box, tiles: int | tuple[int, int],
                  form: Form = "similarity", samples: int = 8, max_error: float = math.inf,
                  assembly: str | None = None,
                  min_margins: tuple[float, float] = (0.0, 0.0)) -> TiledLinear:
    """Eq. 25 fitted per tile over an (x, y) box (mm) in working mode `mode`.

    A tile is refused if any of its samples is out of reach (or, with `assembly`, in the other
    assembly), if its angles span the ±π seam, or if the pen error of its fit on its samples
    exceeds `max_error` mm, or if a sample is closer than `min_margins` = (type 1, type 2)
    rad to a singularity.
    """
    _check_mode(mode)
    if assembly is not None:
        _check_assembly(assembly)
    return _tiles(fb, "inverse", mode, box, tiles, samples, form, max_error, assembly,
                  min_margins)


def forward_tiles(fb: FiveBar, assembly: str, box: Box, tiles: int | tuple[int, int],
                  form: Form = "affine", samples: int = 8,
                  max_error: float = math.inf,
                  min_margins: tuple[float, float] = (0.0, 0.0)) -> TiledLinear:
    """Per-tile linear forward maps over a (θ1, θ2) box (rad) in assembly `assembly`; a tile
    is refused where a sample has no forward solution or its pen error exceeds `max_error` mm.
    (Forward tiles map θ' = (θ1, π − θ2) to P; the similarity form is Eq. 26 per tile.)"""
    _check_assembly(assembly)
    return _tiles(fb, "forward", assembly, box, tiles, samples, form, max_error, None,
                  min_margins)


# ----------------------------------------------------------------------------- tables
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
    grid: _Grid
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

    def _raw(self, q: FloatArray) -> tuple[FloatArray, BoolArray, IntArray]:
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
        q = _as_rows(q_in, "input")
        y, ok, _ = self._raw(q)
        if self.kind == "inverse":
            ok &= reachable(self.fb, q)
        else:
            ok &= assemblable(self.fb, q)
        y[~ok] = 0.0
        return Approximation(y, ok)

    def error_estimate(self, q_in: ArrayLike) -> FloatArray:
        """The build-time error of the cell holding each query (inf where refused)."""
        q = _as_rows(q_in, "input")
        _, ok, cell = self._raw(q)
        return np.asarray(np.where(ok, self.cell_error.ravel()[cell], np.inf), dtype=np.float64)


def _table(fb: FiveBar, kind: Kind, key: str, box: Box, n: int | tuple[int, int],
           order: Order, max_error: float, page_assembly: str | None,
           centre: ArrayLike | None = None,
           min_margins: tuple[float, float] = (0.0, 0.0)) -> LookupTable:
    box = _check_box(box)
    nx, ny = (n, n) if isinstance(n, int) else n
    if order not in ("linear", "cubic"):
        raise ValueError(f"order must be 'linear' or 'cubic'; got {order!r}")
    if min(nx, ny) < (4 if order == "cubic" else 2):
        raise ValueError(f"a {order} table needs ≥ {4 if order == 'cubic' else 2} nodes per "
                         f"axis; got {nx} × {ny}")
    g = _Grid(box, nx, ny)
    nodes = g.nodes()
    vals, node_ok = _exact(fb, kind, key, nodes, page_assembly, min_margins)
    if kind == "inverse" and node_ok.any():
        # One continuous branch of the angles: unwrapped into (θc − π, θc + π] about the
        # angles θc at `centre` (default: the valid node nearest the box centre), so the seam
        # lies where an elbow points away from where it points at the centre. A stencil
        # that still jumps by > π there is refused below.
        if centre is not None:
            c = np.asarray(centre, dtype=np.float64).reshape(1, 2)
            th_c, ok_c = _closed_inverse(fb, key, c)
            if not ok_c[0]:
                raise ValueError(f"centre {c[0].tolist()} mm is not reachable in mode {key}")
            ref = th_c[0]
        else:
            mid = np.array([0.5 * (box[0] + box[1]), 0.5 * (box[2] + box[3])])
            dist = np.where(node_ok, np.hypot(*(nodes - mid).T), np.inf)
            ref = vals[int(np.argmin(dist))]
        vals = _unwrap_about(vals, ref)
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
        exact, eok = _exact(fb, kind, key, sub, page_assembly)
        e = _pen_error(fb, kind, sub, approx, exact)
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
    _check_mode(mode)
    if assembly is not None:
        _check_assembly(assembly)
    return _table(fb, "inverse", mode, box, n, order, max_error, assembly, centre,
                  min_margins)


def forward_table(fb: FiveBar, assembly: str, box: Box, n: int | tuple[int, int],
                  order: Order = "linear", max_error: float = math.inf,
                  min_margins: tuple[float, float] = (0.0, 0.0)) -> LookupTable:
    """Forward kinematics of assembly `assembly` tabulated on n × n nodes over a (θ1, θ2)
    box (rad). Cells whose build-time error exceeds `max_error` mm are refused, and so are
    cells with a node closer than `min_margins` = (type 1, type 2) rad to a singularity."""
    _check_assembly(assembly)
    return _table(fb, "forward", assembly, box, n, order, max_error, None, None, min_margins)
