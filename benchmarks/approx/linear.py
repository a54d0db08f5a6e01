"""The thesis' linear approximation (Gamble 2020, Sec. 5.2, Eqs. 25–26) and the same fit
per tile.

`fit_linear` fits Eq. 25, θ' ≈ B·R(γ)·p + B·A, by least squares to the closed form over a
set of points (`form="similarity"`, 4 parameters) or frees the 2×2 matrix (`form="affine"`,
6 parameters); its `forward` is the algebraic inverse, Eq. 26. `inverse_tiles` /
`forward_tiles` cut a box into tiles and fit one such map per tile, each tile refused where a
sample has no closed-form answer, spans the ±π seam or misses `max_error`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from benchmarks.approx.common import (
    Approximation,
    Box,
    Form,
    Grid,
    Kind,
    as_rows,
    assemblable,
    check_assembly,
    check_box,
    check_inverse_args,
    check_mode,
    closed_inverse,
    exact_values,
    in_box,
    pen_error,
    reachable,
    to_thesis,
    unwrap_about,
)
from kinematics.arrays import BoolArray, FloatArray
from kinematics.fivebar import FiveBar


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
        p = as_rows(points, "points")
        th = p @ self.matrix.T + self.offset
        th[:, 1] = math.pi - th[:, 1]
        ok = in_box(p, self.box) & reachable(self.fb, p)
        th[~ok] = 0.0
        return Approximation(th, ok)

    def forward(self, angles: ArrayLike) -> Approximation:
        """Eq. 26: points (N, 2) mm for motor angles (N, 2) rad — the algebraic inverse of the
        fitted Eq. 25, as the thesis proposes. Refused outside `angle_box` and where the
        floating links cannot meet."""
        th = as_rows(angles, "angles")
        tt = to_thesis(th)
        inv = np.linalg.inv(self.matrix)
        p = (tt - self.offset) @ inv.T
        ok = in_box(th, self.angle_box) & assemblable(self.fb, th)
        p[~ok] = 0.0
        return Approximation(np.asarray(p, dtype=np.float64), ok)


def fit_linear(fb: FiveBar, mode: str, points: ArrayLike,
               form: Form = "similarity") -> LinearApprox:
    """Fit Eq. 25 by least squares to the closed-form inverse at `points` (N ≥ 3, mm).

    Every point must be reachable in `mode` and all must share one assembly sign (the
    forward map, Eq. 26, is then read in that assembly); otherwise ValueError.
    """
    check_mode(mode)
    p = as_rows(points, "points")
    if p.shape[0] < 3:
        raise ValueError(f"need at least 3 points to fit; got {p.shape[0]}")
    th, ok = closed_inverse(fb, mode, p)
    if not ok.all():
        bad = p[int(np.flatnonzero(~ok)[0])]
        raise ValueError(f"point ({bad[0]:.6g}, {bad[1]:.6g}) mm is not reachable in mode "
                         f"{mode}: fit only on the workspace")
    asm = fb.assembly_of(th, p)
    if not (np.all(asm > 0) or np.all(asm < 0)):
        raise ValueError("the points straddle the type-2 singularity (both assembly signs): "
                         "Eq. 26 needs one assembly")
    tt = to_thesis(th)
    tt = unwrap_about(tt, tt[0])
    m, c = _lsq_maps(p[None], tt[None], form)
    resid = p @ m[0].T + c[0] - tt
    box = (float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()),
           float(p[:, 1].max()))
    abox = (float(th[:, 0].min()), float(th[:, 0].max()), float(th[:, 1].min()),
            float(th[:, 1].max()))
    return LinearApprox(fb, mode, "+" if asm[0] > 0 else "-", form, m[0], c[0], box, abox,
                        float(np.sqrt(np.mean(resid ** 2))), float(np.abs(resid).max()))


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
    grid: Grid
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
        q = as_rows(q_in, "input")
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
    box = check_box(box)
    tu, tv = (tiles, tiles) if isinstance(tiles, int) else tiles
    if tu < 1 or tv < 1 or samples < 2:
        raise ValueError(f"need ≥ 1 tile per axis and ≥ 2 samples per tile axis; got "
                         f"{tiles!r}, {samples}")
    grid = Grid(box, tu + 1, tv + 1)
    # Sub-grid of samples x samples per tile (tile edges included), (T, S, 2).
    f = np.linspace(0.0, 1.0, samples)
    fu, fv = np.meshgrid(f, f)
    loc = np.stack((fu.ravel(), fv.ravel()), axis=1)
    ii, jj = np.meshgrid(np.arange(tu), np.arange(tv))
    corner = np.stack((box[0] + ii.ravel() * grid.hu, box[2] + jj.ravel() * grid.hv), axis=1)
    u = corner[:, None, :] + loc[None, :, :] * np.array([grid.hu, grid.hv])
    flat = u.reshape(-1, 2)
    y, valid = exact_values(fb, kind, key, flat, page_assembly, min_margins)
    if kind == "forward":
        u = to_thesis(u)  # fit P against θ' = (θ1, π − θ2), the variables of Eq. 26
    n_t, n_s = u.shape[0], u.shape[1]
    y = y.reshape(n_t, n_s, 2)
    valid = valid.reshape(n_t, n_s)
    if kind == "inverse":
        y = to_thesis(y)
        y = unwrap_about(y, y[:, :1, :])
    ok = np.asarray(valid.all(axis=1), dtype=bool)
    if kind == "inverse":
        ok &= ~(np.ptp(y, axis=1) > math.pi).any(axis=1)  # the ±π seam runs through the tile
    yfit = np.where(ok[:, None, None], y, u)  # dummy well-posed data for refused tiles
    m, c = _lsq_maps(u, yfit, form)
    pred = np.einsum("tij,tsj->tsi", m, u) + c[:, None, :]
    if kind == "inverse":  # back to this project's angles, then to pen error
        pe = pen_error(fb, kind, flat, to_thesis(pred).reshape(-1, 2),
                        to_thesis(y).reshape(-1, 2))
    else:
        pe = pen_error(fb, kind, flat, pred.reshape(-1, 2), y.reshape(-1, 2))
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
    check_inverse_args(mode, assembly)
    return _tiles(fb, "inverse", mode, box, tiles, samples, form, max_error, assembly,
                  min_margins)


def forward_tiles(fb: FiveBar, assembly: str, box: Box, tiles: int | tuple[int, int],
                  form: Form = "affine", samples: int = 8,
                  max_error: float = math.inf,
                  min_margins: tuple[float, float] = (0.0, 0.0)) -> TiledLinear:
    """Per-tile linear forward maps over a (θ1, θ2) box (rad) in assembly `assembly`; a tile
    is refused where a sample has no forward solution or its pen error exceeds `max_error` mm.
    (Forward tiles map θ' = (θ1, π − θ2) to P; the similarity form is Eq. 26 per tile.)"""
    check_assembly(assembly)
    return _tiles(fb, "forward", assembly, box, tiles, samples, form, max_error, None,
                  min_margins)

