"""Link-length design: search (a1, b1, a2, b2, w) for a five-bar that carries a page.

Thesis Sec. 7.3 leaves the choice of link lengths to the builder; `fivebar design` searches
them. Thousands of random geometries are screened at once by a vectorised, trigonometry-free
page check (`_screen`), and only the best few are verified with the exact point test of the
safe region (`kinematics.workspace.point_safety`) and scored on a dense grid. Pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kinematics.arrays import BoolArray, FloatArray
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace import (
    Limits,
    NoSafeRegionError,
    PageStats,
    Rect,
    default_resolution,
    page_stats,
    point_safety,
)

__all__ = ["DesignCandidate", "DesignResult", "design_search"]


@dataclass(frozen=True)
class DesignCandidate:
    """One verified design: geometry, where the page goes, and its figures over the page.

    `score` = worst |μ − 90°| / 50° + worst sensitivity / page diagonal (mm/rad per mm): a
    transmission angle at the thesis' recommended limit weighs as much as a pen that moves one
    page diagonal per radian of the worst motor. Lower is better."""

    geometry: FiveBar
    page: Rect
    mode: str
    stats: PageStats
    score: float


@dataclass(frozen=True)
class DesignResult:
    """Outcome of `design_search`: the best verified candidates (best first) and counts."""

    candidates: list[DesignCandidate]
    evaluated: int
    feasible: int
    verified: int


def _sample_designs(rng: np.random.Generator, n: int, diag: float,
                    motor_spacing: float | tuple[float, float] | None,
                    symmetric_fraction: float) -> FloatArray:
    """Random candidate link lengths (n, 5) = (a1, b1, a2, b2, w), mm, scaled to the page
    diagonal: a ∈ [0.3, 1.5]·D, b ∈ [0.5, 2.5]·D, w ∈ [0.05, 1]·D (or the given spacing).
    A fraction are mirror-symmetric (a1 = a2, b1 = b2), the usual build."""
    a1 = rng.uniform(0.3, 1.5, n) * diag
    b1 = rng.uniform(0.5, 2.5, n) * diag
    a2 = rng.uniform(0.3, 1.5, n) * diag
    b2 = rng.uniform(0.5, 2.5, n) * diag
    sym = rng.random(n) < symmetric_fraction
    a2[sym] = a1[sym]
    b2[sym] = b1[sym]
    if motor_spacing is None:
        w = rng.uniform(0.05, 1.0, n) * diag
    elif isinstance(motor_spacing, tuple):
        w = rng.uniform(motor_spacing[0], motor_spacing[1], n)
    else:
        w = np.full(n, float(motor_spacing))
    return np.stack((a1, b1, a2, b2, w), axis=1)


def _arm(dx: FloatArray, dy: FloatArray, a: FloatArray, b: FloatArray,
         s: float) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """Broadcasting inverse of one arm (motor at the origin of dx, dy), Eq. 18 without arccos:
    returns θ, the elbow offset (ex, ey) = R − M and validity. |(dx·C − s·dy·√K, dy·C +
    s·dx·√K)| = 2a·c², so the elbow needs no trigonometry."""
    csq = dx * dx + dy * dy
    c = np.sqrt(csq)
    k = (a + b + c) * (a + b - c) * (a - b + c) * (b - a + c)
    ok = (k >= 0.0) & (csq > 0.0)
    rk = s * np.sqrt(np.maximum(k, 0.0))
    cc = csq + a * a - b * b
    vx = dx * cc - dy * rk
    vy = dy * cc + dx * rk
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = 1.0 / (2.0 * np.where(csq > 0, csq, 1.0))
    return np.arctan2(vy, vx), vx * inv, vy * inv, ok


def _limits_ok(th: FloatArray, lo: float, hi: float) -> BoolArray:
    t = lo + np.mod(th - lo, 2.0 * math.pi)
    return np.asarray((t <= hi + 1e-12) | (t - lo >= 2.0 * math.pi - 1e-12), dtype=bool)


def _screen(geo: FloatArray, x: FloatArray, y: FloatArray, mode: str, min1: float,
            min2: float, limits: Limits | None) -> tuple[BoolArray, FloatArray, FloatArray]:
    """Vectorised page check. geo (C, 5); x, y (C, K, P): P samples of K placements per
    candidate. Returns feasible (C, K), worst |μ − 90°| (C, K), worst |∂P/∂θ_i| (C, K)."""
    a1, b1, a2, b2, w = (geo[:, i, None, None] for i in range(5))
    s1 = 1.0 if mode[0] == "+" else -1.0
    s2 = 1.0 if mode[1] == "+" else -1.0
    th1, e1x, e1y, ok1 = _arm(x, y, a1, b1, s1)
    th2, e2x, e2y, ok2 = _arm(x - w, y, a2, b2, s2)
    ok = ok1 & ok2
    # Floating links f_i = P − R_i; transmission angle μ_i between (M_i − R_i) and f_i.
    f1x, f1y = x - e1x, y - e1y
    f2x, f2y = x - w - e2x, y - e2y
    mu1 = np.arctan2(np.abs(-e1x * f1y + e1y * f1x), -e1x * f1x - e1y * f1y)
    mu2 = np.arctan2(np.abs(-e2x * f2y + e2y * f2x), -e2x * f2x - e2y * f2y)
    half = 0.5 * math.pi
    ok &= (np.minimum(mu1, math.pi - mu1) >= min1) & (np.minimum(mu2, math.pi - mu2) >= min1)
    # Type 2: signed angle between the lines of b1 and b2 (Eq. det A = cross(f1, f2)).
    det = f1x * f2y - f1y * f2x
    psi = np.arctan2(det, np.abs(f1x * f2x + f1y * f2y))
    ok &= np.abs(psi) >= min2
    if limits is not None:
        ok &= _limits_ok(th1, float(limits[0][0]), float(limits[0][1]))
        ok &= _limits_ok(th2, float(limits[1][0]), float(limits[1][1]))
    feas = ok.all(axis=2)
    same = (np.sign(psi) == np.sign(psi[..., :1])).all(axis=2)
    feas &= same
    # |J col i| = |B_ii|·b_j/|det A| with B_ii = cross(R_i − M_i, P − R_i).
    with np.errstate(divide="ignore", invalid="ignore"):
        bb1 = np.abs(e1x * f1y - e1y * f1x)
        bb2 = np.abs(e2x * f2y - e2y * f2x)
        sens = np.maximum(bb1 * b2, bb2 * b1) / np.abs(det)
    mudev = np.maximum(np.abs(mu1 - half), np.abs(mu2 - half))
    return feas, mudev.max(axis=2), np.where(ok, sens, np.inf).max(axis=2)


def _score(mu_dev_rad: FloatArray | float, sens: FloatArray | float,
           diag: float) -> FloatArray | float:
    """`DesignCandidate.score`: worst |μ − 90°| / 50° + worst sensitivity / page diagonal."""
    return mu_dev_rad / math.radians(50.0) + sens / diag


@dataclass(frozen=True)
class _Ask:
    """What a design must do: carry a page_w × page_h mm page (diagonal `diag`) in working
    mode `mode` with both singularity margins and the joint limits."""

    page_w: float
    page_h: float
    diag: float
    mode: str
    min1: float
    min2: float
    limits: Limits | None


def _unit_samples() -> tuple[FloatArray, FloatArray]:
    """Unit samples on [-1, 1]²: a 7 × 5 interior grid plus 32 edge points."""
    gx, gy = np.meshgrid(np.linspace(-1, 1, 7), np.linspace(-1, 1, 5))
    t = np.linspace(-1, 1, 9)[1:-1]
    ux = np.concatenate([gx.ravel(), t, t, -np.ones(8), np.ones(8)])
    uy = np.concatenate([gy.ravel(), -np.ones(7), np.ones(7), np.linspace(-1, 1, 8),
                         np.linspace(-1, 1, 8)])
    return ux, uy


_UNIT_X, _UNIT_Y = _unit_samples()
#: The 4 corners and 4 edge midpoints of [-1, 1]², for the cheap first rejection.
_QUICK_X = np.array([-1.0, 1.0, -1.0, 1.0, 0.0, 0.0, -1.0, 1.0])
_QUICK_Y = np.array([-1.0, -1.0, 1.0, 1.0, -1.0, 1.0, 0.0, 0.0])
#: Page placements: centre x = w/2 + shift·D, bottom edge at a fraction of the free reach.
_SHIFTS = np.array([-0.15, 0.0, 0.15])
_FRACS = np.linspace(0.0, 1.0, 12)


def _placements(g: FloatArray, ask: _Ask) -> tuple[FloatArray, FloatArray, FloatArray,
                                                   FloatArray]:
    """The 3 × 12 page placements of each candidate g (C, 5): centres pcx, pcy (C, 36) and
    the half sizes hw, hh (C,) of the page grown by three cells of `default_resolution`."""
    reach = np.minimum(g[:, 0] + g[:, 1], g[:, 2] + g[:, 3])
    ext = np.maximum(g[:, 0] + g[:, 1], g[:, 2] + g[:, 3]) * 2.0 + g[:, 4]
    grow = 3.0 * ext / 400.0  # three cells of `default_resolution`
    hw = 0.5 * ask.page_w + grow
    hh = 0.5 * ask.page_h + grow
    cx = 0.5 * g[:, 4, None] + (_SHIFTS * ask.diag)[None, :]          # (C, 3)
    y0 = _FRACS[None, :] * np.maximum(reach - 2 * hh, 0.0)[:, None]  # (C, 12)
    cy = y0 + hh[:, None]
    pcx = np.repeat(cx, _FRACS.size, axis=1)                         # (C, 36)
    pcy = np.tile(cy, (1, _SHIFTS.size))
    return pcx, pcy, hw, hh


def _screen_chunk(g: FloatArray, ask: _Ask) -> tuple[FloatArray, FloatArray]:
    """Best screened score (C,) and page centre (C, 2) of each candidate g (C, 5); inf where
    no placement passes."""
    pcx, pcy, hw, hh = _placements(g, ask)
    # Quick rejection on the 4 corners and 4 edge midpoints, then the full sample set
    # only for the placements that survive (most candidates fail on reach).
    x = pcx[:, :, None] + _QUICK_X[None, None, :] * hw[:, None, None]
    y = pcy[:, :, None] + _QUICK_Y[None, None, :] * hh[:, None, None]
    quick, _, _ = _screen(g, x, y, ask.mode, ask.min1, ask.min2, ask.limits)
    ci, ki = np.nonzero(quick)
    score = np.full(quick.shape, np.inf)
    if ci.size:
        xs_ = pcx[ci, ki][:, None, None] + _UNIT_X[None, None, :] * hw[ci, None, None]
        ys_ = pcy[ci, ki][:, None, None] + _UNIT_Y[None, None, :] * hh[ci, None, None]
        feas, mudev, sens = _screen(g[ci], xs_, ys_, ask.mode, ask.min1, ask.min2, ask.limits)
        score[ci, ki] = np.where(feas[:, 0], _score(mudev[:, 0], sens[:, 0], ask.diag), np.inf)
    k = np.argmin(score, axis=1)
    rows = np.arange(g.shape[0])
    return score[rows, k], np.stack((pcx[rows, k], pcy[rows, k]), axis=1)


def _verify(geo: FloatArray, centre: FloatArray, ask: _Ask,
            rad_per_step: float) -> DesignCandidate | None:
    """The exact check of one screened candidate: the page grown by three grid cells must be
    safe on a dense sample (one assembly sign), scored by `page_stats`; None if it fails."""
    a1, b1, a2, b2, w = (float(v) for v in geo)
    try:
        fb = FiveBar(a1, b1, a2, b2, w)
    except ValueError:
        return None
    res = default_resolution(fb)
    cx, cy = centre
    pw, ph = ask.page_w, ask.page_h
    page = Rect(float(cx) - 0.5 * pw, float(cy) - 0.5 * ph, pw, ph)
    grown = Rect(page.x0 - 3 * res, page.y0 - 3 * res, pw + 6 * res, ph + 6 * res)
    pts = grown.sample(res, res / 4.0)
    try:
        st = page_stats(fb, ask.mode, page, rad_per_step)
    except NoSafeRegionError:
        return None
    if not point_safety(fb, ask.mode, pts, ask.min1, ask.min2, ask.limits,
                        assembly=st.assembly).all():
        return None
    total = float(_score(st.worst_mu_dev_rad, st.worst_sens_mm_per_rad, ask.diag))
    return DesignCandidate(fb, page, ask.mode, st, total)


def design_search(page_w: float, page_h: float, mode: str, min_type1_rad: float,
                  min_type2_rad: float, limits_rad: Limits | None, rad_per_step: float, *,
                  n_candidates: int = 10_000, motor_spacing: float | tuple[float, float] |
                  None = None, seed: int = 0, top: int = 5, symmetric_fraction: float = 0.5,
                  chunk: int = 256) -> DesignResult:
    """Search link lengths (a1, b1, a2, b2, w) for a five-bar that carries a `page_w` × `page_h`
    mm page inside its safe workspace (thesis Sec. 7.3), ranked by `DesignCandidate.score`.

    1. `n_candidates` random geometries (`_sample_designs`); for each, 3 × 12 placements of
       the page (centre x = w/2 + {−0.15, 0, 0.15}·D, bottom edge y from 0 up to the reach),
       all above the motor axis. The page is grown by three grid cells of the `workspace`
       command's default grid so that its grid search is sure to find it again.
    2. Vectorised screen: corners and edge midpoints first (cheap rejection), then 7 × 5
       interior + 32 edge samples: reach, joint limits, both margins, one assembly sign; the
       best feasible placement per candidate by score.
    3. The best screened candidates are verified by the exact point test on a dense sample
       of the grown page (`Rect.sample` at one grid cell) and re-scored on a dense grid;
       the first `top` that pass are returned.
    """
    if not (page_w > 0 and page_h > 0):
        raise ValueError(f"page size must be positive; got {page_w} x {page_h}")
    if mode not in WORKING_MODES:
        raise ValueError(f"working mode must be one of {', '.join(WORKING_MODES)}; got {mode!r}")
    ask = _Ask(page_w, page_h, math.hypot(page_w, page_h), mode, min_type1_rad, min_type2_rad,
               limits_rad)
    rng = np.random.default_rng(seed)
    geo = _sample_designs(rng, n_candidates, ask.diag, motor_spacing, symmetric_fraction)
    best_score = np.full(n_candidates, np.inf)
    best_place = np.zeros((n_candidates, 2))
    for c0 in range(0, n_candidates, chunk):
        best_score[c0:c0 + chunk], best_place[c0:c0 + chunk] = _screen_chunk(
            geo[c0:c0 + chunk], ask)
    feasible = np.flatnonzero(np.isfinite(best_score))
    order = feasible[np.argsort(best_score[feasible])]
    out: list[DesignCandidate] = []
    verified = 0
    for idx in order[: max(10 * top, 50)]:
        cand = _verify(geo[idx], best_place[idx], ask, rad_per_step)
        if cand is None:
            continue
        verified += 1
        out.append(cand)
        if len(out) >= top:
            break
    out.sort(key=lambda d: d.score)
    return DesignResult(out, n_candidates, int(feasible.size), verified)
