"""Input perturbation against the paper's Eqs. 10–22 written out literally.

The solver moves driven joints by x_d = x_d0 + B·f(u) (Rodrigues for the sphere); here the same
motions are rebuilt from the paper's matrices: T⁻¹RT (Eqs. 10–11), its inverse transpose for
lines (Eq. 12), the translations of Eqs. 13–14 and Rx⁻¹Ry⁻¹RzRyRx (Eqs. 15–18) applied as in
Eqs. 19–22, step by step as the paper perturbs.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from kinematics.nbar import Mechanism, build_mechanism, parse_mechanism
from kinematics.nbar.perturb import planar_rotation, rotation_about_axis

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"
RNG = np.random.default_rng(7)


def eq15(axis: np.ndarray, theta: float) -> np.ndarray:
    """[R]_(l,m,n) = Rx⁻¹ Ry⁻¹ Rz Ry Rx with the matrices of Eqs. 16–18 (unit axis)."""
    l, m, n = axis / np.linalg.norm(axis)
    s = math.hypot(m, n)
    rx = np.array([[1, 0, 0], [0, n / s, -m / s], [0, m / s, n / s]])
    ry = np.array([[s, 0, -l], [0, 1, 0], [l, 0, s]])
    rz = np.array([[math.cos(theta), -math.sin(theta), 0],
                   [math.sin(theta), math.cos(theta), 0], [0, 0, 1]])
    return np.asarray(np.linalg.inv(rx) @ np.linalg.inv(ry) @ rz @ ry @ rx)


def eq10_matrix(pivot: np.ndarray, theta: float) -> np.ndarray:
    """T⁻¹ R T with T the translation by −pivot (Eq. 11)."""
    t = np.array([[1, 0, -pivot[0]], [0, 1, -pivot[1]], [0, 0, 1.0]])
    r = np.array([[math.cos(theta), -math.sin(theta), 0],
                  [math.sin(theta), math.cos(theta), 0], [0, 0, 1.0]])
    return np.asarray(np.linalg.inv(t) @ r @ t)


def test_rodrigues_equals_eq15() -> None:
    """The rotation used for spherical inputs is the paper's Eq. 15 matrix."""
    for _ in range(50):
        axis = RNG.normal(size=3)
        theta = float(RNG.uniform(-4, 4))
        np.testing.assert_allclose(rotation_about_axis(axis, theta), eq15(axis, theta),
                                   atol=1e-13)


def test_rodrigues_covers_the_x_axis_where_eq15_is_undefined() -> None:
    """Eq. 16 divides by √(m² + n²): the x axis is a gap there, not for Rodrigues."""
    r = rotation_about_axis(np.array([1.0, 0.0, 0.0]), 0.5)
    np.testing.assert_allclose(r @ [0, 1, 0], [0, math.cos(0.5), math.sin(0.5)], atol=1e-15)
    with np.errstate(divide="ignore", invalid="ignore"):
        assert not np.all(np.isfinite(eq15(np.array([1.0, 0.0, 0.0]), 0.5)))


def test_planar_rotation_is_eq10() -> None:
    pivot = np.array([0.7, -1.2])
    np.testing.assert_allclose(planar_rotation(pivot, 0.9), eq10_matrix(pivot, 0.9),
                               atol=1e-14)


def _driven(mech: Mechanism, u: np.ndarray) -> np.ndarray:
    return mech.coords_batch(mech.q0[None], np.atleast_1d(u)[None])[0]


def test_planar_revolute_input_moves_points_by_eq10_and_lines_by_eq12() -> None:
    """A slotted input link: its pin by T⁻¹RT, its slot line by (T⁻¹RT)⁻ᵀ (Eq. 12)."""
    spec = {
        "mechanism": {"name": "slotted input", "kind": "planar", "ground": "G"},
        "joints": {"C": {"type": "revolute", "at": [0.0, 0.0]},
                   "E": {"type": "revolute", "at": [1.0, 2.0]},
                   "S": {"type": "prismatic", "line": [1.0, -0.2, 0.3]},
                   "O": {"type": "revolute", "at": [0.5, -3.0]},
                   "A": {"type": "revolute", "at": [-0.3, 0.9]}},
        "links": {"G": ["C", "O"], "in": ["C", "E", "S"], "block": ["A", "S"],
                  "crank": ["O", "A"]},
        "inputs": [{"link": "in", "joint": "C"}],
    }
    mech = build_mechanism(spec)
    c0 = mech.coords0
    u0 = mech.input0[0]
    assert u0 == pytest.approx(math.atan2(2.0, 1.0))
    for dth in (0.1, -2.0, 3.5):
        c = _driven(mech, u0 + dth)
        m = eq10_matrix(c0[mech.index("C"), :2], dth)
        np.testing.assert_allclose(c[mech.index("E")], m @ c0[mech.index("E")], atol=1e-14)
        line = np.linalg.inv(m).T @ c0[mech.index("S")]
        np.testing.assert_allclose(c[mech.index("S")], line, atol=1e-14)


def test_planar_prismatic_input_moves_points_by_eq13_and_lines_by_eq14() -> None:
    """A slider on the fixed line G carrying a point B and an inclined line S."""
    spec = {
        "mechanism": {"name": "slider", "kind": "planar", "ground": "ground"},
        "joints": {"O": {"type": "revolute", "at": [0.0, 0.0]},
                   "G": {"type": "prismatic", "line": [0.3, 1.0, 0.5]},
                   "B": {"type": "revolute", "at": [3.0, -1.4]},
                   "S": {"type": "prismatic", "line": [1.0, 1.0, 0.4]},
                   "A": {"type": "revolute", "at": [0.6, 0.8]}},
        "links": {"ground": ["O", "G"], "slider": ["G", "B", "S"], "coupler": ["B", "A"],
                  "crank": ["O", "A"]},
        "inputs": [{"link": "slider", "joint": "G", "step": 0.05}],
    }
    mech = build_mechanism(spec)
    assert mech.inputs[0].kind == "prismatic" and mech.input0[0] == 0.0
    raw_g = np.array([0.3, 1.0, 0.5])
    a1, b1 = raw_g[:2]
    b0 = mech.coords0[mech.index("B")]
    s0 = mech.coords0[mech.index("S")]
    for d in (0.2, -1.5):
        c = _driven(mech, np.array(d))
        eq13 = b0 + np.array([b1 / math.hypot(a1, b1) * d, -a1 / math.hypot(a1, b1) * d, 0.0])
        np.testing.assert_allclose(c[mech.index("B")], eq13, atol=1e-14)
        a2, b2, c2 = s0
        eq14 = np.array([a2, b2, c2 + (a1 * b2 - a2 * b1) / math.hypot(a1, b1) * d])
        np.testing.assert_allclose(c[mech.index("S")], eq14, atol=1e-14)


def test_spherical_revolute_input_is_eq19_applied_step_by_step() -> None:
    """Spherical RRPR: J2 turned about the axis through J1, as the paper does it, in 90
    perturbations of 2° (Eq. 19) — equal to our single rotation by the total angle."""
    mech = parse_mechanism((MECH / "spherical_rrpr.toml").read_text())
    j1 = mech.coords0[mech.index("J1")]
    p = mech.coords0[mech.index("J2")].copy()
    step = math.radians(2.0)
    r = eq15(j1, step)
    for _ in range(90):
        p = r @ p
    c = _driven(mech, np.array(90 * step))
    np.testing.assert_allclose(c[mech.index("J2")], p, atol=1e-13)


def test_spherical_prismatic_input_is_eq21_about_the_pole() -> None:
    """Watt-I: the input link slides along the great circle of J1 = rotation about its pole."""
    mech = parse_mechanism((MECH / "spherical_watt1.toml").read_text())
    pole = mech.coords0[mech.index("J1")]
    assert mech.inputs[0].kind == "prismatic"
    for th in (0.3, -1.1):
        c = _driven(mech, np.array(th))
        r = eq15(pole, th)
        for j in ("J2", "J3"):
            np.testing.assert_allclose(c[mech.index(j)], r @ mech.coords0[mech.index(j)],
                                       atol=1e-13)
        assert c[mech.index("J1")] == pytest.approx(pole)


def test_input_derivatives_match_finite_differences() -> None:
    """∂x_d/∂u (used for the tangent predictor) against central differences."""
    for name in ("stephenson2", "spherical_watt1", "fivebar_robot", "five_ss"):
        mech = parse_mechanism((MECH / f"{name}.toml").read_text())
        u = mech.input0 + 0.37
        dxd, ds = mech.basis.derivatives(u)
        h = 1e-6
        for j in range(len(mech.inputs)):
            e = np.zeros_like(u)
            e[j] = h
            fd = (mech.basis.driven(u + e) - mech.basis.driven(u - e)) / (2 * h)
            np.testing.assert_allclose(dxd[:, j], fd, rtol=1e-7, atol=1e-9)
            fds = (mech.basis.actuators(u + e) - mech.basis.actuators(u - e)) / (2 * h)
            np.testing.assert_allclose(ds[:, j], fds, rtol=1e-7, atol=1e-9)


def test_motion_along_a_direction_is_the_position_and_its_rate() -> None:
    """`along(u, d)` (the fold solve's one-pass evaluation) equals `driven`/`actuators` at u
    and the central difference of both along d."""
    for name in ("stephenson2", "spherical_watt1", "fivebar_robot", "five_ss"):
        basis = parse_mechanism((MECH / f"{name}.toml").read_text()).basis
        u = np.array([m.value0 for m in basis.motions]) + 0.37
        d = np.linspace(0.5, -0.8, len(basis.motions))
        pos, rate = basis.along(u, d)
        np.testing.assert_allclose(pos, np.concatenate((basis.driven(u), basis.actuators(u))),
                                   rtol=0, atol=1e-15)
        h = 1e-6
        up, dn = u + h * d, u - h * d
        fd = (np.concatenate((basis.driven(up), basis.actuators(up)))
              - np.concatenate((basis.driven(dn), basis.actuators(dn)))) / (2 * h)
        np.testing.assert_allclose(rate, fd, rtol=1e-7, atol=1e-9)
