"""Closed-form five-bar kinematics against independent references.

References: analytic poses worked by hand, a scipy root-find of the loop-closure equations
(brentq per arm for the inverse, fsolve of the two circle equations for the forward), the
thesis' arccos form of Eq. 23, and finite differences of forward kinematics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq, fsolve

from kinematics.fivebar import (
    WORKING_MODES,
    DegenerateError,
    FiveBar,
    Reason,
    UnreachableError,
)

SYM = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)


# ----------------------------------------------------------------------------- analytic
def test_symmetric_machine_point_on_axis() -> None:
    """P on the symmetry axis: θ1 = φ + β and θ2 = π − θ1 in mode +- (hand-worked)."""
    h = 100.0
    p = np.array([20.0, h])
    c = math.hypot(20.0, h)
    phi = math.atan2(h, 20.0)
    beta = math.acos((60.0**2 + c**2 - 90.0**2) / (2 * 60.0 * c))
    th = np.asarray(SYM.inverse(p, "+-"))
    assert th[0] == pytest.approx(phi + beta, abs=1e-14)
    assert th[1] == pytest.approx(math.pi - (phi + beta), abs=1e-14)
    th2 = np.asarray(SYM.inverse(p, "-+"))
    assert th2[0] == pytest.approx(phi - beta, abs=1e-14)
    assert th2[1] == pytest.approx(math.pi - (phi - beta), abs=1e-14)
    # Both elbows outward in +-: R1 left of the axis, R2 right of it, mirror images.
    r1, r2 = SYM.elbows(th)
    assert r1[0, 0] < 20.0 < r2[0, 0]
    assert r1[0, 0] + r2[0, 0] == pytest.approx(40.0, abs=1e-12)


@pytest.mark.parametrize("psi_deg", [-150.0, -30.0, 0.0, 45.0, 90.0, 179.0])
def test_arm_exactly_stretched(psi_deg: float) -> None:
    """P at distance a1+b1 from M1 along ψ: θ1 = ψ in both arm-1 modes, type-1 margin 0."""
    fb = FiveBar(50.0, 70.0, 55.0, 95.0, 30.0)
    psi = math.radians(psi_deg)
    p = np.array([120.0 * math.cos(psi), 120.0 * math.sin(psi)])
    res = fb.inverse_batch(p[None, :], "++")
    if not res.valid[0]:  # the point may be out of arm 2's reach; then it must say so
        assert res.reason[0] in (Reason.BEYOND_REACH_2, Reason.INSIDE_REACH_2)
        return
    for mode in ("++", "-+"):
        th = np.asarray(fb.inverse(p, mode))
        assert math.remainder(th[0] - psi, 2 * math.pi) == pytest.approx(0.0, abs=1e-7)
        m = fb.singularity_margins(th, p)[0]
        assert abs(m[0]) < 1e-7


def test_arm_folded_b_longer_than_a() -> None:
    """Folded arm (c = b − a): the elbow points away from P (β = π)."""
    fb = FiveBar(40.0, 100.0, 40.0, 100.0, 20.0)
    p = np.array([0.0, 60.0])  # |P − M1| = 60 = b1 − a1
    th = np.asarray(fb.inverse(p, "++"))
    assert math.remainder(th[0] + math.pi / 2, 2 * math.pi) == pytest.approx(0.0, abs=1e-7)


# ----------------------------------------------------------------------------- round trips
@st.composite
def geometries(draw: st.DrawFn) -> FiveBar:
    """Random lopsided five-bars whose loop can close."""
    a1 = draw(st.floats(10.0, 200.0))
    a2 = draw(st.floats(10.0, 200.0))
    b1 = draw(st.floats(10.0, 200.0))
    b2 = draw(st.floats(10.0, 200.0))
    w = draw(st.floats(1.0, 0.9 * (a1 + b1 + a2 + b2)))
    try:
        return FiveBar(a1, b1, a2, b2, w)
    except ValueError:
        assume(False)
        raise


def _well_conditioned(fb: FiveBar, th: np.ndarray, p: np.ndarray, min_rad: float) -> np.ndarray:
    m = fb.singularity_margins(th, p)
    return np.all(np.abs(m) > min_rad, axis=1)


@settings(max_examples=60, deadline=None)
@given(geometries(), st.integers(0, 2**31 - 1))
def test_round_trips_all_modes(fb: FiveBar, seed: int) -> None:
    """inverse(forward(θ)) = θ and forward(inverse(p)) = p, all modes and assemblies,
    to 1e-9 relative in the well-conditioned interior."""
    rng = np.random.default_rng(seed)
    th = rng.uniform(-math.pi, math.pi, size=(400, 2))
    scale = fb.a1 + fb.b1 + fb.a2 + fb.b2 + fb.w
    for asm in ("+", "-"):
        fwd = fb.forward_batch(th, asm)
        ok = fwd.valid
        if not ok.any():
            continue
        p = fwd.points[ok]
        t = th[ok]
        modes = fb.mode_of(p, t)
        good = _well_conditioned(fb, t, p, 0.05) & np.all(modes != 0, axis=1)
        assert np.all(fb.assembly_of(t, p) == (1 if asm == "+" else -1))
        for mode in WORKING_MODES:
            sel = good & (modes[:, 0] == (1 if mode[0] == "+" else -1)) & (
                modes[:, 1] == (1 if mode[1] == "+" else -1))
            if not sel.any():
                continue
            inv = fb.inverse_batch(p[sel], mode)
            assert inv.valid.all()
            d = np.abs(np.remainder(inv.angles - t[sel] + math.pi, 2 * math.pi) - math.pi)
            # Angle errors scale like position error / arm length: 1e-9 relative in position.
            assert d.max() < 1e-9 * scale / min(fb.a1, fb.a2)
            back = fb.forward_batch(inv.angles, asm)
            assert back.valid.all()
            assert np.abs(back.points - p[sel]).max() < 1e-9 * scale


# ----------------------------------------------------------------------------- second opinion
def _scipy_inverse_arm(px: float, py: float, mx: float, a: float, b: float,
                       sign: int) -> float:
    """Root of |P − M − a(cos θ, sin θ)|² − b² with the elbow on the requested side."""

    def g(t: float) -> float:
        return (px - mx - a * math.cos(t)) ** 2 + (py - a * math.sin(t)) ** 2 - b * b

    phi = math.atan2(py, px - mx)
    # g is smallest at θ = φ (elbow toward P); the roots lie either side of it within π.
    root = brentq(g, phi, phi + math.pi, xtol=1e-15) if sign > 0 else brentq(
        g, phi - math.pi, phi, xtol=1e-15)
    return float(root)


@pytest.mark.parametrize("mode", WORKING_MODES)
def test_inverse_matches_scipy_root_find(mode: str) -> None:
    fb = FiveBar(55.0, 85.0, 65.0, 100.0, 35.0)
    rng = np.random.default_rng(7)
    pts = rng.uniform([-60, -60], [100, 150], size=(300, 2))
    res = fb.inverse_batch(pts, mode)
    checked = 0
    for p, th, ok in zip(pts, res.angles, res.valid, strict=True):
        c1 = math.hypot(p[0], p[1])
        c2 = math.hypot(p[0] - fb.w, p[1])
        reach = (abs(fb.a1 - fb.b1) < c1 < fb.a1 + fb.b1) and (
            abs(fb.a2 - fb.b2) < c2 < fb.a2 + fb.b2)
        assert ok == reach
        if not ok:
            continue
        s = [1 if ch == "+" else -1 for ch in mode]
        ref1 = _scipy_inverse_arm(p[0], p[1], 0.0, fb.a1, fb.b1, s[0])
        ref2 = _scipy_inverse_arm(p[0], p[1], fb.w, fb.a2, fb.b2, s[1])
        assert math.remainder(th[0] - ref1, 2 * math.pi) == pytest.approx(0.0, abs=1e-8)
        assert math.remainder(th[1] - ref2, 2 * math.pi) == pytest.approx(0.0, abs=1e-8)
        # Mode label, recomputed by hand: elbow left of the chord M_i → P.
        for i, (mx, a, t) in enumerate(((0.0, fb.a1, th[0]), (fb.w, fb.a2, th[1]))):
            rx, ry = mx + a * math.cos(t), a * math.sin(t)
            cross = (p[0] - mx) * ry - p[1] * (rx - mx)
            assert (cross > 0) == (s[i] > 0)
        checked += 1
    assert checked > 50


@pytest.mark.parametrize("asm", ["+", "-"])
def test_forward_matches_scipy_fsolve(asm: str) -> None:
    fb = FiveBar(55.0, 85.0, 65.0, 100.0, 35.0)
    rng = np.random.default_rng(3)
    th = rng.uniform(0.2, 2.9, size=(200, 2))
    res = fb.forward_batch(th, asm)
    r1, r2 = fb.elbows(th)
    checked = 0
    for i in np.flatnonzero(res.valid):
        p = res.points[i]
        if abs(fb.singularity_margins(th[i], p)[0, 2]) < 0.05:
            continue
        # Start from P mirrored a little towards the chord so fsolve must do the work.
        guess = p + rng.normal(0.0, 2.0, 2)

        def eqs(q: np.ndarray, i: int = int(i)) -> list[float]:
            return [float(np.sum((q - r1[i]) ** 2) - fb.b1**2),
                    float(np.sum((q - r2[i]) ** 2) - fb.b2**2)]

        q = fsolve(eqs, guess, xtol=1e-14)
        d = r2[i] - r1[i]
        e = q - r1[i]
        side = d[0] * e[1] - d[1] * e[0]
        if (side > 0) != (asm == "+"):
            continue  # fsolve found the other assembly: no comparison possible
        assert np.abs(q - p).max() < 1e-8
        checked += 1
    assert checked > 50


# ----------------------------------------------------------------------------- measures
def test_transmission_angle_equals_eq23() -> None:
    """μ_i from atan2 equals the thesis' arccos((c² − a² − b²)/(−2ab)) (Eq. 23)."""
    fb = FiveBar(55.0, 85.0, 65.0, 100.0, 35.0)
    rng = np.random.default_rng(11)
    pts = rng.uniform([-60, 20], [100, 150], size=(500, 2))
    res = fb.inverse_batch(pts, "+-")
    p = pts[res.valid]
    mu = fb.transmission_angles(res.angles[res.valid], p)
    c1 = np.hypot(p[:, 0], p[:, 1])
    c2 = np.hypot(p[:, 0] - fb.w, p[:, 1])
    ref1 = np.arccos((c1**2 - fb.a1**2 - fb.b1**2) / (-2 * fb.a1 * fb.b1))
    ref2 = np.arccos((c2**2 - fb.a2**2 - fb.b2**2) / (-2 * fb.a2 * fb.b2))
    assert np.abs(mu[:, 0] - ref1).max() < 1e-7
    assert np.abs(mu[:, 1] - ref2).max() < 1e-7


def test_jacobian_matches_finite_differences() -> None:
    fb = FiveBar(55.0, 85.0, 65.0, 100.0, 35.0)
    th = np.array([[2.0, 0.9], [1.6, 1.2], [2.4, 0.4]])
    p = fb.forward_batch(th, "+").points
    jac = fb.jacobian(th, p)
    h = 1e-6
    for j in range(2):
        dp = np.zeros(2)
        dp[j] = h
        fd = (fb.forward_batch(th + dp, "+").points - fb.forward_batch(th - dp, "+").points) / (
            2 * h)
        assert np.abs(jac[:, :, j] - fd).max() < 1e-5


def test_margins_signs_follow_modes_and_assembly() -> None:
    fb = FiveBar(55.0, 85.0, 65.0, 100.0, 35.0)
    p = np.array([10.0, 110.0])
    for mode in WORKING_MODES:
        th = np.asarray(fb.inverse(p, mode))
        m = fb.singularity_margins(th, p)[0]
        assert np.sign(m[0]) == (1 if mode[0] == "+" else -1)
        assert np.sign(m[1]) == (1 if mode[1] == "+" else -1)
        assert np.sign(m[2]) == fb.assembly_of(th, p)[0]
        assert np.all(np.abs(m) <= math.pi / 2)


# ----------------------------------------------------------------------------- stability
@pytest.mark.parametrize("offset", [0.0, -1e-12, 1e-12])
def test_reach_boundary(offset: float) -> None:
    """Exactly on, 1e-12 inside and 1e-12 beyond arm 1's outer reach: exact or refused."""
    fb = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
    # (90, 120) lies exactly 150 mm from M1 (a 3-4-5 triangle) and 130 mm from M2.
    k = (150.0 + offset) / 150.0
    p = np.array([90.0 * k, 120.0 * k])
    if offset > 0:
        with pytest.raises(UnreachableError) as ei:
            fb.inverse(p, "+-")
        assert ei.value.reason == Reason.BEYOND_REACH_1
        assert ei.value.excess_mm == pytest.approx(1e-12, rel=0.2)
        assert "beyond arm 1's reach" in str(ei.value)
        res = fb.inverse_batch(p[None], "+-")
        assert not res.valid[0] and res.reason[0] == Reason.BEYOND_REACH_1
        assert np.isfinite(res.angles).all()
    else:
        th = np.asarray(fb.inverse(p, "+-"))
        assert np.isfinite(th).all()
        assert th[0] == pytest.approx(math.atan2(120.0, 90.0), abs=2e-6)
        q = np.asarray(fb.forward(th, "+"))
        assert np.abs(q - p).max() < 1e-9


@pytest.mark.parametrize("offset", [0.0, 1e-12, -1e-12])
def test_inner_reach_boundary(offset: float) -> None:
    """Arm 2's dead zone (a2 ≠ b2): on it exact, 1e-12 inside refused with INSIDE_REACH_2."""
    fb = FiveBar(60.0, 90.0, 40.0, 100.0, 80.0)
    p = np.array([80.0, 60.0 + offset])  # |P − M2| = 60 = b2 − a2 (+ offset)
    if offset < 0:
        with pytest.raises(UnreachableError) as ei:
            fb.inverse(p, "++")
        assert ei.value.reason == Reason.INSIDE_REACH_2
        assert "dead zone" in str(ei.value)
    else:
        th = np.asarray(fb.inverse(p, "++"))
        assert np.isfinite(th).all()
        r2 = fb.elbows(th)[1][0]
        assert fb.singularity_margins(th, p)[0, 1] == pytest.approx(0.0, abs=1e-6)
        assert math.hypot(*(p - r2)) == pytest.approx(100.0, abs=1e-9)


def test_type2_singularity_exact() -> None:
    """Floating links collinear (b1 ∥ b2): forward is exact (one double root), margin 0."""
    fb2 = FiveBar(100.0, 50.0, 100.0, 50.0, 100.0)
    th = np.array([math.pi, 0.0])  # R1 = (−100, 0), R2 = (200, 0): 300 apart > 100
    res = fb2.forward_batch(th[None], "+")
    assert not res.valid[0] and res.reason[0] == Reason.ELBOWS_TOO_FAR
    th = np.array([math.pi / 2, math.pi / 2])  # R1 = (0, 100), R2 = (100, 100): exactly b1+b2
    for asm in ("+", "-"):
        p = np.asarray(fb2.forward(th, asm))
        assert p == pytest.approx([50.0, 100.0], abs=1e-12)
    assert fb2.singularity_margins(th, [50.0, 100.0])[0, 2] == pytest.approx(0.0, abs=1e-12)
    assert fb2.assembly_of(th, [50.0, 100.0])[0] == 0


def test_type1_singularity_forward_and_inverse() -> None:
    """Arm 1 stretched: inverse exact (β = 0), forward reproduces P, margin 0, mode 0."""
    fb = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
    p = np.array([150.0 * math.cos(1.2), 150.0 * math.sin(1.2)])
    th = np.asarray(fb.inverse(p, "+-"))
    assert th[0] == pytest.approx(1.2, abs=1e-7)
    assert np.abs(np.asarray(fb.forward(th, "+")) - p).max() < 1e-6


def test_point_at_motor() -> None:
    """P on a motor: with a ≠ b it is inside the dead zone; with a = b, θ is undetermined."""
    with pytest.raises(UnreachableError) as ei:
        SYM.inverse([0.0, 0.0], "+-")
    assert ei.value.reason == Reason.INSIDE_REACH_1
    eq = FiveBar(80.0, 80.0, 80.0, 80.0, 50.0)
    with pytest.raises(DegenerateError) as ei2:
        eq.inverse([50.0, 0.0], "+-")
    assert ei2.value.reason == Reason.AT_MOTOR_2
    res = eq.inverse_batch([[0.0, 0.0], [50.0, 0.0], [25.0, 80.0]], "+-")
    assert list(res.reason) == [Reason.AT_MOTOR_1, Reason.AT_MOTOR_2, Reason.OK]
    assert np.isfinite(res.angles).all()


def test_coincident_elbows_b1_equals_b2() -> None:
    """Mode 1b class I: R1 = R2 exactly with b1 = b2 → DegenerateError, batch never NaN.

    θ = (0, 0) puts R1 = (a1, 0) and R2 = (w + a2, 0) with exact cos/sin; a1 = w + a2.
    """
    fb = FiveBar(100.0, 90.0, 60.0, 90.0, 40.0)
    th = np.array([0.0, 0.0])
    r1, r2 = fb.elbows(th)
    assert np.all(r1 == r2)
    with pytest.raises(DegenerateError, match="Mode 1b") as ei:
        fb.forward(th, "+")
    assert ei.value.reason == Reason.ELBOWS_COINCIDENT
    res = fb.forward_batch(np.array([[0.0, 0.0], [0.3, 0.2]]), "+")
    assert list(res.reason) == [Reason.ELBOWS_COINCIDENT, Reason.OK]
    assert np.isfinite(res.points).all()
    # With b1 ≠ b2 coincident elbows cannot close the loop: a reach error, not a free circle.
    fb2 = FiveBar(100.0, 90.0, 60.0, 95.0, 40.0)
    with pytest.raises(UnreachableError) as ei2:
        fb2.forward(th, "+")
    assert ei2.value.reason == Reason.ELBOWS_TOO_CLOSE


def test_nearly_coincident_elbows_are_flagged_by_the_margin() -> None:
    """Elbows 1e-9 mm apart: P is on both circles and the type-2 margin reports ≈ 0."""
    fb = FiveBar(100.0, 90.0, 60.0, 90.0, 40.0 + 1e-9)
    th = np.array([0.0, 0.0])
    p = np.asarray(fb.forward(th, "+"))
    r1, r2 = fb.elbows(th)
    assert math.hypot(*(p - r1[0])) == pytest.approx(90.0, abs=1e-6)
    assert math.hypot(*(p - r2[0])) == pytest.approx(90.0, abs=1e-6)
    assert abs(fb.singularity_margins(th, p)[0, 2]) < 1e-6


def test_forward_elbows_vertically_aligned() -> None:
    """x_R1 = x_R2 (where the thesis' Eqs. 9–15 divide by zero) is an ordinary pose here."""
    fb = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
    # R1 = (20, h), R2 = (20, −h) with h = √(60² − 20²): θ1 = atan2(h, 20), θ2 = atan2(−h, −20)
    h = math.sqrt(60.0**2 - 20.0**2)
    th = np.array([math.atan2(h, 20.0), math.atan2(-h, -20.0)])
    r1, r2 = fb.elbows(th)
    assert r1[0, 0] == pytest.approx(r2[0, 0], abs=1e-12)
    for asm in ("+", "-"):
        p = np.asarray(fb.forward(th, asm))
        assert math.hypot(*(p - r1[0])) == pytest.approx(90.0, abs=1e-10)
        assert math.hypot(*(p - r2[0])) == pytest.approx(90.0, abs=1e-10)
        assert fb.assembly_of(th, p)[0] == (1 if asm == "+" else -1)


def test_not_finite_and_bad_arguments() -> None:
    res = SYM.inverse_batch([[np.nan, 1.0], [np.inf, 0.0]], "++")
    assert list(res.reason) == [Reason.NOT_FINITE, Reason.NOT_FINITE]
    assert np.isfinite(res.angles).all()
    with pytest.raises(UnreachableError, match="not a finite number"):
        SYM.inverse([np.nan, 1.0], "++")
    with pytest.raises(UnreachableError, match="not a finite number"):
        SYM.forward([np.nan, 1.0], "+")
    with pytest.raises(ValueError, match="working mode"):
        SYM.inverse([20.0, 100.0], "+")
    with pytest.raises(ValueError, match="assembly"):
        SYM.forward([1.0, 1.0], "++")
    with pytest.raises(ValueError, match="shape"):
        SYM.inverse(np.zeros((3, 3)), "++")


@pytest.mark.parametrize(("kwargs", "msg"), [
    ({"a1": 0.0, "b1": 1.0, "a2": 1.0, "b2": 1.0, "w": 1.0}, "a1 must be a positive"),
    ({"a1": 1.0, "b1": -1.0, "a2": 1.0, "b2": 1.0, "w": 1.0}, "b1 must be a positive"),
    ({"a1": 1.0, "b1": 1.0, "a2": 1.0, "b2": 1.0, "w": math.inf}, "w must be a positive"),
    ({"a1": 10.0, "b1": 10.0, "a2": 10.0, "b2": 10.0, "w": 41.0}, "never meet"),
    ({"a1": 1.0, "b1": 1.0, "a2": 10.0, "b2": 100.0, "w": 5.0}, "dead zone"),
])
def test_geometry_validation(kwargs: dict[str, float], msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        FiveBar(**kwargs)


def test_geometry_is_immutable() -> None:
    with pytest.raises(AttributeError):
        SYM.a1 = 3.0  # type: ignore[misc]
