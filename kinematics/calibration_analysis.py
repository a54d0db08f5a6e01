"""What a calibration fit means: identifiability, outliers and the drawing-shape error.

- Identifiability (`weak_combinations`): with the paper's placement unknown the seven machine
  parameters are nearly dependent (the default pattern's scaled Jacobian has a condition
  number of ~10^4). The placement is a nuisance, so it is projected out first (the Schur
  complement: J_m' = (I − Q_p·Q_pᵀ)·J_m with Q_p an orthonormal basis of the placement
  columns, whence Cov(machine) = s²·(J_m'ᵀJ_m')⁻¹ exactly). The SVD of J_m' in "mm units"
  (home angles as arc length at the elbow, a_k·h_k) names the combinations: the right
  singular vector v_k of singular value S_k is a combination vᵀz whose standard deviation is
  s / S_k (I1).
- Outliers (`studentized`): per mark, the externally studentized residual
  t_i = |r_i| / (s_(i)·√(1 − h_i)), with h_i the mean leverage of the mark's two rows of the
  hat matrix H = J(JᵀJ)⁻¹Jᵀ and s_(i)² = (|r|² − |r_i|²/(1 − h_i)) / (dof − 2) the residual
  variance without mark i (O1). Under the model t_i² is about χ²(2), so t_i > 4 happens with
  probability e⁻⁸ ≈ 3·10⁻⁴ per mark.
- Drawing-shape error (`shape_errors`): what matters to a user is not the parameters but where
  the machine draws. A profile `used` commands, for an intended point p, the angles
  IK_used(p); the machine `true` turns them, relative to the same homed pose, into
  q = FK_true(h_true + IK_used(p) − h_used) (S1). The shape error is |Rot(φ*)·q + t* − p|
  after the rigid alignment (φ*, t*) that fits the whole region best in least squares
  (the paper may sit anywhere) (S2). Step quantisation is left out: it is the same for any
  profile.

Pure numpy, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kinematics.arrays import BoolArray, FloatArray
from kinematics.calibration import (
    MACHINE_NAMES,
    N_PARAMS,
    FitResult,
    MachineParams,
    MarkData,
    jacobian,
    rigid_fit,
    rotation,
)
from kinematics.workspace import safe_mask, workspace_bounds
from kinematics.workspace.region import Limits

#: Outlier threshold on the externally studentized residual (O1).
OUTLIER_T = 4.0


@dataclass(frozen=True)
class Combination:
    """A parameter combination the marks determine poorly: coefficients per machine
    parameter (lengths per mm, home angles per degree) and its standard deviation, mm."""

    coefficients: dict[str, float]
    std_mm: float

    def describe(self) -> str:
        """E.g. 'b1 + 0.93·b2 − 0.88·w + 0.64·h1[°]'."""
        parts: list[str] = []
        for name, c in sorted(self.coefficients.items(), key=lambda kv: -abs(kv[1])):
            label = f"{name}[°]" if name.startswith("h") else name
            mag = "" if abs(abs(c) - 1.0) < 5e-3 else f"{abs(c):.2f}·"
            sign = "−" if c < 0 else "+"
            parts.append(f"{sign} {mag}{label}" if parts else
                         f"{'−' if c < 0 else ''}{mag}{label}")
        return " ".join(parts)


def machine_block(res: FitResult) -> tuple[FloatArray, FloatArray]:
    """J_m' (the machine columns with the placement projected out) and the mm-unit scale of
    each machine parameter (1 for lengths, a_k for home angle k) (I1)."""
    jm, jp = res.jac[:, :7], res.jac[:, 7:]
    qp, _ = np.linalg.qr(jp)
    proj = jm - qp @ (qp.T @ jm)
    m = res.machine
    unit = np.array([1.0, 1.0, 1.0, 1.0, 1.0, m.a1, m.a2])
    return proj, unit


def condition_number(res: FitResult) -> float:
    """Condition number of the column-normalised Jacobian of all ten parameters."""
    jac = res.jac
    scale = np.sqrt(np.sum(jac * jac, axis=0))
    sv = np.linalg.svd(jac / np.where(scale > 0, scale, 1.0), compute_uv=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf


def weak_combinations(res: FitResult, count: int = 3, min_coef: float = 0.1) -> list[Combination]:
    """The `count` machine-parameter combinations with the largest standard deviations (I1),
    each normalised so its largest coefficient (mm units) is 1; terms below `min_coef` are
    dropped from the description."""
    proj, unit = machine_block(res)
    _, sv, vt = np.linalg.svd(proj / unit, full_matrices=False)
    out: list[Combination] = []
    for k in range(len(sv) - 1, max(len(sv) - 1 - count, -1), -1):
        v = vt[k]
        big = float(np.max(np.abs(v)))
        v = v / big
        if v[np.argmax(np.abs(v))] < 0:
            v = -v
        std = res.sigma / (float(sv[k]) * big) if sv[k] > 0 else math.inf
        coefs: dict[str, float] = {}
        for i, name in enumerate(MACHINE_NAMES):
            if abs(v[i]) < min_coef:
                continue
            # z_i = unit_i · x_i; per degree for the home angles.
            coefs[name] = float(v[i] * (unit[i] * math.pi / 180.0 if i >= 5 else 1.0))
        out.append(Combination(coefs, std))
    return out


def studentized(res: FitResult) -> FloatArray:
    """Externally studentized residual per mark (N,) (O1)."""
    jac = res.jac
    q, _ = np.linalg.qr(jac)
    lev = np.sum(q * q, axis=1).reshape(-1, 2).mean(axis=1)
    r2 = np.sum(res.residual_after ** 2, axis=1)
    one_minus = np.maximum(1.0 - lev, 1e-12)
    ss = float(r2.sum())
    s_i2 = np.maximum((ss - r2 / one_minus) / max(res.dof - 2, 1), 1e-30)
    return np.asarray(np.sqrt(r2 / (s_i2 * one_minus)), dtype=np.float64)


# ----------------------------------------------------------------- drawing-shape error
def drawn_points(true: MachineParams, used: MachineParams, points: FloatArray, mode: str,
                 assembly: str) -> FloatArray:
    """Where the machine `true` puts the pen when profile `used` commands `points` (S1);
    NaN rows where either cannot."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    inv = used.fivebar().inverse_batch(pts, mode)
    th = inv.angles - np.asarray(used.home_rad) + np.asarray(true.home_rad)
    fwd = true.fivebar().forward_batch(th, assembly)
    q = fwd.points.copy()
    q[~(inv.valid & fwd.valid)] = np.nan
    return q


def align(drawn: FloatArray, intended: FloatArray) -> FloatArray:
    """Error vectors (N, 2) of `drawn` after its best rigid alignment onto `intended` (S2),
    over the rows where both are finite (NaN elsewhere)."""
    ok = np.all(np.isfinite(drawn), axis=1) & np.all(np.isfinite(intended), axis=1)
    out = np.full(drawn.shape, np.nan)
    if ok.sum() < 2:
        return out
    phi, t = rigid_fit(drawn[ok], intended[ok])
    out[ok] = drawn[ok] @ rotation(phi).T + t - intended[ok]
    return out


def shape_errors(true: MachineParams, used: MachineParams, points: FloatArray, mode: str,
                 assembly: str) -> FloatArray:
    """Drawing-shape error (N,) mm of profile `used` on machine `true` over `points`,
    after the best rigid alignment of the whole set (S1, S2); NaN where undefined."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    e = align(drawn_points(true, used, pts, mode, assembly), pts)
    return np.asarray(np.hypot(e[:, 0], e[:, 1]), dtype=np.float64)


def predicted_shape_std(res: FitResult, points: FloatArray, mode: str, assembly: str,
                        h: float = 1e-6) -> FloatArray:
    """1σ (N,) mm of the fitted profile's own shape error over `points`, propagated from the
    machine covariance: the error is linear in small parameter errors, so with D the
    (2N, 7) derivative of the aligned drawing (finite differences, step h in mm units),
    Cov = D·C·Dᵀ and the per-point σ is √trace of its 2×2 block."""
    fitted = res.machine
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    base = fitted.vector()
    unit = np.array([1.0, 1.0, 1.0, 1.0, 1.0, fitted.a1, fitted.a2])
    cols = []
    for i in range(7):
        x = base.copy()
        x[i] += h / unit[i]
        cols.append(align(drawn_points(MachineParams.from_vector(x), fitted, pts, mode,
                                       assembly), pts).ravel() / (h / unit[i]))
    d = np.stack(cols, axis=1)
    cov = res.covariance[:7, :7]
    if not np.all(np.isfinite(cov)):
        return np.full(pts.shape[0], math.inf)
    var = np.einsum("ij,jk,ik->i", d, cov, d).reshape(-1, 2).sum(axis=1)
    return np.asarray(np.sqrt(np.maximum(var, 0.0)), dtype=np.float64)


# ----------------------------------------------------------------- the region
@dataclass(frozen=True)
class SafeGrid:
    """The safe region as a grid: coordinates xs (nx,), ys (ny,) mm and mask (ny, nx) of the
    largest 4-connected safe component."""

    xs: FloatArray
    ys: FloatArray
    mask: BoolArray

    def points(self) -> FloatArray:
        """The safe grid nodes (M, 2) mm."""
        gx, gy = np.meshgrid(self.xs, self.ys)
        return np.stack((gx[self.mask], gy[self.mask]), axis=1)

    def eroded(self, radius_mm: float) -> SafeGrid:
        """Nodes whose whole disc of `radius_mm` is safe (disc sampled on the grid)."""
        pitch = float(self.xs[1] - self.xs[0])
        k = math.ceil(radius_mm / pitch)
        out = self.mask.copy()
        ny, nx = self.mask.shape
        padded = np.zeros((ny + 2 * k, nx + 2 * k), dtype=bool)
        padded[k:k + ny, k:k + nx] = self.mask
        for dj in range(-k, k + 1):
            for di in range(-k, k + 1):
                if (di * di + dj * dj) * pitch * pitch <= radius_mm * radius_mm:
                    out &= padded[k + dj:k + dj + ny, k + di:k + di + nx]
        return SafeGrid(self.xs, self.ys, out)


def safe_grid(m: MachineParams, mode: str, min_type1_rad: float, min_type2_rad: float,
              limits_rad: Limits | None, assembly: str, pitch_mm: float = 1.0) -> SafeGrid:
    """The largest connected safe component (`kinematics.workspace.point_safety`) of machine
    `m` in `mode`, sampled every `pitch_mm`."""
    fb = m.fivebar()
    x0, x1, y0, y1 = workspace_bounds(fb)
    xs = np.arange(math.floor(x0), x1 + pitch_mm, pitch_mm)
    ys = np.arange(math.floor(y0), y1 + pitch_mm, pitch_mm)
    mask = safe_mask(fb, mode, xs, ys, min_type1_rad, min_type2_rad, limits_rad,
                     assembly=assembly)
    return SafeGrid(xs, ys, _largest_component(mask))


def _largest_component(mask: BoolArray) -> BoolArray:
    """The largest 4-connected component of `mask` (label by iterative min-propagation)."""
    if not mask.any():
        return mask
    ny, nx = mask.shape
    big = ny * nx + 1
    lab = np.where(mask, np.arange(ny * nx).reshape(ny, nx), big)
    while True:
        new = lab.copy()
        new[1:, :] = np.minimum(new[1:, :], lab[:-1, :])
        new[:-1, :] = np.minimum(new[:-1, :], lab[1:, :])
        new[:, 1:] = np.minimum(new[:, 1:], lab[:, :-1])
        new[:, :-1] = np.minimum(new[:, :-1], lab[:, 1:])
        new = np.where(mask, new, big)
        if np.array_equal(new, lab):
            break
        lab = new
    vals, counts = np.unique(lab[mask], return_counts=True)
    return np.asarray(lab == vals[np.argmax(counts)], dtype=bool)


def spread_points(candidates: FloatArray, n: int) -> FloatArray:
    """`n` of the candidate points (M, 2) spread over them by farthest-point sampling,
    starting from the candidate farthest from their centroid: the first picks are the
    region's extremes, so its edges are covered, the rest fill the largest gaps."""
    if n > candidates.shape[0]:
        raise ValueError(f"cannot pick {n} points from {candidates.shape[0]} candidates")
    c = candidates.mean(axis=0)
    first = int(np.argmax(np.sum((candidates - c) ** 2, axis=1)))
    chosen = [first]
    dist = np.sum((candidates - candidates[first]) ** 2, axis=1)
    for _ in range(n - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.sum((candidates - candidates[k]) ** 2, axis=1))
    return np.asarray(candidates[chosen], dtype=np.float64)


# ----------------------------------------------------------------- where to put the marks
def design_marks(nominal: MachineParams, candidates: FloatArray, n: int, seeds: int,
                 rad_per_step: float, mode: str, assembly: str,
                 min_spacing_mm: float = 0.0) -> FloatArray:
    """`n` mark positions (n, 2) among `candidates`: `seeds` by `spread_points` (the
    region's extremes first), then greedily the candidate whose predicted position is least
    certain given the marks so far, tr(J_c·(JᵀJ)⁻¹·J_cᵀ) — the sequential D-optimal design
    (each pick maximises the determinant gain of JᵀJ), which puts the remaining marks where
    the fit would otherwise extrapolate: along the region's edges. No two marks are closer
    than `min_spacing_mm` (ValueError when the candidates run out)."""
    cand = np.asarray(candidates, dtype=np.float64).reshape(-1, 2)
    first = spread_points(cand, min(seeds, n))
    sel = [int(np.argmin(np.sum((cand - p) ** 2, axis=1))) for p in first]
    inv = nominal.fivebar().inverse_batch(cand, mode)
    st = (inv.angles - np.asarray(nominal.home_rad)) / rad_per_step
    data = MarkData(st, np.zeros_like(st), rad_per_step, assembly)
    jc = jacobian(np.concatenate((nominal.vector(), [0.0, 0.0, 0.0])), data).reshape(-1, 2,
                                                                                     N_PARAMS)
    while len(sel) < n:
        j = jc[sel].reshape(-1, N_PARAMS)
        m = np.linalg.pinv(j.T @ j)
        var = np.einsum("nij,jk,nik->n", jc, m, jc)
        for k in sel:
            var[np.sum((cand - cand[k]) ** 2, axis=1) < min_spacing_mm ** 2] = -1.0
        var[sel] = -1.0
        if var.max() < 0.0:
            raise ValueError(f"no room for {n} marks {min_spacing_mm:g} mm apart")
        sel.append(int(np.argmax(var)))
    return np.asarray(cand[sel], dtype=np.float64)
