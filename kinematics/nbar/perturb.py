"""Input link perturbation (Sec. 3.1, Eqs. 10–22) as rigid motions linear in two numbers.

An input moves the joints of its link by a rigid motion that depends on one input value u:
- planar revolute input: rotation by Δ = u − u0 about the fixed pivot c, points by
  T⁻¹RT (Eqs. 10–11) and lines by (T⁻¹RT)⁻ᵀ (Eq. 12);
- planar prismatic input: translation by Δ along the fixed line (a, b, c), points by
  Δ·(b, −a)/√(a² + b²) (Eq. 13), lines by the offset change of Eq. 14;
- spherical revolute input: rotation by Δ about the axis through the fixed joint and the centre
  (Eqs. 15–20); spherical prismatic input: rotation about the pole of the fixed plane
  (Eqs. 21–22). Eq. 15 builds that rotation as Rx⁻¹Ry⁻¹RzRyRx, undefined when the axis is the
  x axis (m = n = 0); Rodrigues' formula below is the same matrix (shown in the tests) with no
  such gap.
Each motion is applied to the *initial* coordinates with the total Δ: rotations about one fixed
axis (and translations along one line) compose additively, so this equals the paper's
step-by-step perturbation without accumulating round-off. Every such motion is affine in
(cos Δ − 1, sin Δ), respectively in Δ, so all driven coordinates are x_d = x_d0 + B·f(u).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray

MotionKind = Literal["rotate-plane", "translate-plane", "rotate-sphere", "actuator"]


def rotation_about_axis(axis: FloatArray, angle: float) -> FloatArray:
    """Right-handed rotation by `angle` about the unit direction of `axis` (Rodrigues).

    Equal to Eq. 15 [R]_(l,m,n) = Rx⁻¹ Ry⁻¹ Rz Ry Rx wherever that is defined.
    """
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx),
                      dtype=np.float64)


def planar_rotation(pivot: FloatArray, angle: float) -> FloatArray:
    """Homogeneous 3×3 matrix T⁻¹RT of Eqs. 10–11: rotation by `angle` about `pivot`."""
    c, s = math.cos(angle), math.sin(angle)
    px, py = float(pivot[0]), float(pivot[1])
    return np.array([[c, -s, px - c * px + s * py],
                     [s, c, py - s * px - c * py],
                     [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class Motion:
    """How one input moves: its kind, the input value u0 of the initial configuration, and
    where its coefficients sit in f (rotations take two columns, translations one; an
    actuator owns the squared-length entry `column` of S instead)."""

    kind: MotionKind
    value0: float
    column: int


@dataclass(frozen=True, eq=False)
class InputBasis:
    """Driven coordinates as x_d(u) = x0 + basis·f(u) and actuator entries S(u) = u²."""

    x0: FloatArray
    basis: FloatArray
    motions: tuple[Motion, ...]
    n_f: int
    n_act: int

    def coefficients(self, u: FloatArray) -> FloatArray:
        """f(u): (cos Δ − 1, sin Δ) per rotation, Δ per translation, Δ = u − u0."""
        f = np.empty(self.n_f)
        for mo, ui in zip(self.motions, u, strict=True):
            d = float(ui) - mo.value0
            if mo.kind == "actuator":
                continue
            if mo.kind == "translate-plane":
                f[mo.column] = d
            else:
                sh = math.sin(0.5 * d)
                f[mo.column] = -2.0 * sh * sh
                f[mo.column + 1] = math.sin(d)
        return f

    def coefficients_batch(self, u: FloatArray) -> FloatArray:
        """f(u) for many input rows (S, n_in) → (S, n_f)."""
        uu = np.atleast_2d(np.asarray(u, dtype=np.float64))
        f = np.zeros((uu.shape[0], self.n_f))
        for j, mo in enumerate(self.motions):
            d = uu[:, j] - mo.value0
            if mo.kind == "translate-plane":
                f[:, mo.column] = d
            elif mo.kind != "actuator":
                sh = np.sin(0.5 * d)
                f[:, mo.column] = -2.0 * sh * sh
                f[:, mo.column + 1] = np.sin(d)
        return f

    def driven_batch(self, u: FloatArray) -> FloatArray:
        """Driven coordinates (S, n_d) for input rows (S, n_in)."""
        return np.asarray(self.x0 + self.coefficients_batch(u) @ self.basis.T, dtype=np.float64)

    def actuators_batch(self, u: FloatArray) -> FloatArray:
        """Squared actuator lengths (S, n_act) for input rows (S, n_in)."""
        uu = np.atleast_2d(np.asarray(u, dtype=np.float64))
        cols = [j for j, mo in enumerate(self.motions) if mo.kind == "actuator"]
        return np.asarray(uu[:, cols] ** 2, dtype=np.float64)

    def entries_batch(self, u: FloatArray) -> FloatArray:
        """x's input-driven entries [x_d, S] (S, n_d + n_act) for input rows (S, n_in)."""
        return np.concatenate((self.driven_batch(u), self.actuators_batch(u)), axis=1)

    def entries(self, u: FloatArray) -> FloatArray:
        """x's input-driven entries [x_d, S] at input values u."""
        return np.concatenate((self.driven(u), self.actuators(u)))

    def driven(self, u: FloatArray) -> FloatArray:
        """Driven coordinates x_d at input values u."""
        return np.asarray(self.x0 + self.basis @ self.coefficients(u), dtype=np.float64)

    def actuators(self, u: FloatArray) -> FloatArray:
        """Squared actuator lengths S at input values u."""
        s = np.empty(self.n_act)
        for mo, ui in zip(self.motions, u, strict=True):
            if mo.kind == "actuator":
                s[mo.column] = float(ui) ** 2
        return s

    @cached_property
    def _along_map(self) -> tuple[FloatArray, FloatArray]:
        """(c0, M) with [x_d, S, ẋ_d, Ṡ] = c0 + M·[f, ḟ, S, Ṡ]: `along` in one product."""
        nd, nf, na = self.x0.size, self.n_f, self.n_act
        mat = np.zeros((2 * (nd + na), 2 * (nf + na)))
        mat[:nd, :nf] = self.basis
        mat[nd: nd + na, 2 * nf: 2 * nf + na] = np.eye(na)
        mat[nd + na: 2 * nd + na, nf: 2 * nf] = self.basis
        mat[2 * nd + na:, 2 * nf + na:] = np.eye(na)
        c0 = np.zeros(2 * (nd + na))
        c0[:nd] = self.x0
        return c0, mat

    def along(self, u: FloatArray, d: FloatArray) -> tuple[FloatArray, FloatArray]:
        """([x_d, S], d/dt [x_d, S]) at input values u moving as u + t·d: `driven`,
        `actuators` and `derivatives`·d in one product (the fold solve needs all of them
        every iteration)."""
        nf, na = self.n_f, self.n_act
        e = [0.0] * (2 * (nf + na))
        for mo, ui, di in zip(self.motions, u.tolist(), d.tolist(), strict=True):
            if mo.kind == "actuator":
                e[2 * nf + mo.column] = ui * ui
                e[2 * nf + na + mo.column] = 2.0 * ui * di
                continue
            dl = ui - mo.value0
            if mo.kind == "translate-plane":
                e[mo.column] = dl
                e[nf + mo.column] = di
            else:
                sh, sn, cs = math.sin(0.5 * dl), math.sin(dl), math.cos(dl)
                e[mo.column] = -2.0 * sh * sh
                e[mo.column + 1] = sn
                e[nf + mo.column] = -sn * di
                e[nf + mo.column + 1] = cs * di
        c0, mat = self._along_map
        out = c0 + mat @ np.array(e)
        k = out.size // 2
        return out[:k], out[k:]

    def taylor(self, u: FloatArray, d: FloatArray, order: int) -> FloatArray:
        """Taylor coefficients (order + 1, n_d + n_act) of [x_d, S] along u + t·d in t:
        row k is (1/k!) dᵏ/dtᵏ at t = 0 (the k-th derivative of cos θ is cos(θ + kπ/2))."""
        nf, na = self.n_f, self.n_act
        f = np.zeros((order + 1, nf))
        s = np.zeros((order + 1, na))
        for mo, ui, di in zip(self.motions, u.tolist(), d.tolist(), strict=True):
            if mo.kind == "actuator":  # S = (u + t·d)²
                s[0, mo.column] = ui * ui
                s[1, mo.column] = 2.0 * ui * di
                s[2, mo.column] = di * di
                continue
            dl = ui - mo.value0
            if mo.kind == "translate-plane":
                f[0, mo.column] = dl
                f[1, mo.column] = di
                continue
            fac = 1.0
            for k in range(order + 1):
                fac = fac * di / k if k else 1.0
                f[k, mo.column] = fac * math.cos(dl + 0.5 * k * math.pi)
                f[k, mo.column + 1] = fac * math.sin(dl + 0.5 * k * math.pi)
            f[0, mo.column] -= 1.0
        out = np.empty((order + 1, self.x0.size + na))
        np.matmul(f, self.basis.T, out=out[:, : self.x0.size])
        out[0, : self.x0.size] += self.x0
        out[:, self.x0.size:] = s
        return out

    def derivatives(self, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(∂x_d/∂u (n_d, n_in), ∂S/∂u (n_act, n_in)) at input values u."""
        n_in = len(self.motions)
        df = np.zeros((self.n_f, n_in))
        ds = np.zeros((self.n_act, n_in))
        for j, (mo, ui) in enumerate(zip(self.motions, u, strict=True)):
            d = float(ui) - mo.value0
            if mo.kind == "actuator":
                ds[mo.column, j] = 2.0 * float(ui)
            elif mo.kind == "translate-plane":
                df[mo.column, j] = 1.0
            else:
                df[mo.column, j] = -math.sin(d)
                df[mo.column + 1, j] = math.cos(d)
        return np.asarray(self.basis @ df, dtype=np.float64), ds


def motion_columns(kind: MotionKind, coords: FloatArray, is_line: bool, axis: FloatArray
                   ) -> FloatArray:
    """Basis columns (3, 1 or 2) for one driven primitive's stored coordinates.

    rotate-plane: axis is the pivot (x, y); translate-plane: the unit direction (ux, uy);
    rotate-sphere: the unit rotation axis.
    """
    v = np.asarray(coords, dtype=np.float64)
    if kind == "rotate-plane":
        cx, cy = float(axis[0]), float(axis[1])
        if is_line:
            a, b = v[0], v[1]
            cos_col = [a, b, -(a * cx + b * cy)]
            sin_col = [-b, a, -(-b * cx + a * cy)]
        else:
            dx, dy = v[0] - cx, v[1] - cy
            cos_col = [dx, dy, 0.0]
            sin_col = [-dy, dx, 0.0]
        return np.array([cos_col, sin_col]).T
    if kind == "translate-plane":
        ux, uy = float(axis[0]), float(axis[1])
        col = [0.0, 0.0, -(v[0] * ux + v[1] * uy)] if is_line else [ux, uy, 0.0]
        return np.array([col]).T
    k = np.asarray(axis, dtype=np.float64)
    return np.array([v - (k @ v) * k, np.cross(k, v)]).T


def build_basis(coords: FloatArray, is_line: NDArray[np.bool_], driven: NDArray[np.bool_],
                owner: NDArray[np.intp], motions: tuple[Motion, ...],
                axes: tuple[FloatArray, ...], n_f: int) -> InputBasis:
    """Assemble x0 and the basis for the driven coordinates in flat (primitive-major) order.

    driven is the (n, 3) mask of driven coordinates, owner[i] the input moving primitive i.
    """
    rows = np.flatnonzero(driven.ravel())
    x0 = coords.ravel()[rows].copy()
    basis = np.zeros((rows.size, n_f))
    for r, flat in enumerate(rows):
        i, c = divmod(int(flat), 3)
        j = int(owner[i])
        mo = motions[j]
        cols = motion_columns(mo.kind, coords[i], bool(is_line[i]), axes[j])
        basis[r, mo.column:mo.column + cols.shape[1]] = cols[c]
    n_act = sum(1 for mo in motions if mo.kind == "actuator")
    return InputBasis(x0, basis, motions, n_f, n_act)
