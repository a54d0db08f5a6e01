"""Singularity traces, transmission angle, error sensitivity and condition number
(kinematics.workspace) against analytic formulas and finite differences of forward kinematics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace import (
    condition_numbers,
    measures,
    perturbation_displacements,
    safe_mask,
    step_quantum,
    type1_circles,
    type2_traces,
)

DEG = math.pi / 180.0
MACHINES = [FiveBar(60.0, 90.0, 60.0, 90.0, 40.0), FiveBar(100.0, 60.0, 90.0, 75.0, 50.0),
            FiveBar(45.0, 120.0, 70.0, 95.0, 80.0)]


def _reachable_points(fb: FiveBar, n: int, seed: int) -> np.ndarray:
    """Random points inside both reach annuli (rejection sampling, away from the circles)."""
    rng = np.random.default_rng(seed)
    (lo1, hi1), (lo2, hi2) = fb.reach
    out = []
    while sum(len(o) for o in out) < n:
        p = rng.uniform(-hi1, fb.w + hi2, size=(4 * n, 2))
        d1 = np.hypot(p[:, 0], p[:, 1])
        d2 = np.hypot(p[:, 0] - fb.w, p[:, 1])
        ok = (d1 > lo1 + 1) & (d1 < hi1 - 1) & (d2 > lo2 + 1) & (d2 < hi2 - 1)
        out.append(p[ok])
    return np.concatenate(out)[:n]


@pytest.mark.parametrize("fb", MACHINES)
@pytest.mark.parametrize("mode", WORKING_MODES)
def test_transmission_angle_is_eq23(fb: FiveBar, mode: str) -> None:
    """μ_i = arccos((c_i² − a_i² − b_i²)/(−2 a_i b_i)) (thesis Eq. 23, law of cosines): the
    transmission angle depends on |P − M_i| only, in every working mode."""
    pts = _reachable_points(fb, 300, 1)
    pm = measures(fb, mode, pts)
    assert pm.valid.all()
    for i, (a, b, mx) in enumerate(((fb.a1, fb.b1, 0.0), (fb.a2, fb.b2, fb.w))):
        c = np.hypot(pts[:, 0] - mx, pts[:, 1])
        eq23 = np.arccos((c * c - a * a - b * b) / (-2.0 * a * b))
        np.testing.assert_allclose(pm.mu[:, i], eq23, atol=1e-9)


@pytest.mark.parametrize("fb", MACHINES)
@pytest.mark.parametrize("mode", WORKING_MODES)
def test_sensitivity_equals_finite_differences_of_forward(fb: FiveBar, mode: str) -> None:
    """∂P/∂θ_i from the Jacobian equals a central difference of the forward kinematics (in the
    point's own assembly mode); the per-motor sensitivity is its norm and has the closed form
    a_i·sin μ_i / |sin ψ|, ψ the angle between b1 and b2."""
    pts = _reachable_points(fb, 200, 2)
    pm = measures(fb, mode, pts)
    # Keep well-conditioned points: central differences need room around the pose.
    good = (np.abs(pm.margins) > 3 * DEG).all(axis=1)
    pts, th = pts[good], pm.angles[good]
    jac, sens = pm.jac[good], pm.sens[good]
    asm = pm.assembly[good].astype(float)
    h = 1e-6
    for i in range(2):
        e = np.zeros(2)
        e[i] = h
        fp = fb.forward_batch(th + e, asm)
        fm = fb.forward_batch(th - e, asm)
        assert fp.valid.all() and fm.valid.all()
        fd = (fp.points - fm.points) / (2 * h)
        np.testing.assert_allclose(jac[:, :, i], fd, rtol=1e-6, atol=1e-5)
        np.testing.assert_allclose(sens[:, i], np.hypot(fd[:, 0], fd[:, 1]), rtol=1e-6)
    psi = pm.margins[good][:, 2]
    mu = pm.mu[good]
    np.testing.assert_allclose(sens[:, 0], fb.a1 * np.sin(mu[:, 0]) / np.abs(np.sin(psi)),
                               rtol=1e-9)
    np.testing.assert_allclose(sens[:, 1], fb.a2 * np.sin(mu[:, 1]) / np.abs(np.sin(psi)),
                               rtol=1e-9)


def test_perturbation_traces_are_forward_kinematics_of_perturbed_angles() -> None:
    """Thesis Sec. 4.1: turn one motor by ±δ, the other fixed; the displacement is the exact
    forward kinematics (not the linearisation), and tends to J·δ as δ → 0."""
    fb = MACHINES[0]
    pts = np.array([[20.0, 120.0], [-10.0, 100.0], [45.0, 130.0]])
    d5 = perturbation_displacements(fb, "+-", pts, 5 * DEG)
    pm = measures(fb, "+-", pts)
    for n in range(3):
        for i in range(2):
            for k, sgn in enumerate((-1.0, 1.0)):
                th = pm.angles[n].copy()
                th[i] += sgn * 5 * DEG
                p = np.asarray(fb.forward(th, "+" if pm.assembly[n] > 0 else "-"))
                np.testing.assert_allclose(d5[n, i, k], p - pts[n], atol=1e-9)
    small = perturbation_displacements(fb, "+-", pts, 1e-7)
    np.testing.assert_allclose(small[:, :, 1, :] / 1e-7,
                               np.transpose(pm.jac, (0, 2, 1)), rtol=1e-5, atol=1e-5)
    # 5° is not small: the exact traces differ from the linear ones by a visible amount.
    lin = np.transpose(pm.jac, (0, 2, 1)) * 5 * DEG
    assert np.abs(d5[:, :, 1, :] - lin).max() > 0.05


def test_step_quantum_matches_jacobian_for_one_step() -> None:
    fb = MACHINES[0]
    rad_per_step = 2 * math.pi / 12800
    pts = _reachable_points(fb, 100, 3)
    q = step_quantum(fb, "+-", pts, rad_per_step)
    pm = measures(fb, "+-", pts)
    ok = np.abs(pm.margins[:, 2]) > 5 * DEG
    np.testing.assert_allclose(q[ok], pm.sens[ok].max(axis=1) * rad_per_step, rtol=2e-3)
    assert np.isnan(step_quantum(fb, "+-", np.array([[500.0, 0.0]]), rad_per_step)).all()


def test_condition_numbers_match_svd() -> None:
    rng = np.random.default_rng(4)
    jac = rng.normal(size=(500, 2, 2))
    s = np.linalg.svd(jac, compute_uv=False)
    np.testing.assert_allclose(condition_numbers(jac), s[:, 0] / s[:, 1], rtol=1e-9)
    sing = np.array([[[1.0, 2.0], [2.0, 4.0]], [[np.inf, 0.0], [0.0, 1.0]]])
    assert np.isinf(condition_numbers(sing)).all()
    rot = np.array([[[0.0, -3.0], [3.0, 0.0]]])
    assert condition_numbers(rot)[0] == pytest.approx(1.0)


@pytest.mark.parametrize("fb", MACHINES)
def test_type2_traces_are_singular_in_their_mode(fb: FiveBar) -> None:
    """Every trace point, solved in the working mode it is labelled with, has b1 ∥ b2 (type-2
    margin 0) and the elbow distance of its kind: b1 + b2 (1a), |b1 − b2| (1b-II), 0 (1b-I)."""
    traces = type2_traces(fb, n=720)
    assert traces
    for tr in traces:
        for m in WORKING_MODES:
            sel = tr.modes == m
            if not sel.any():
                continue
            pts = tr.points[sel]
            th = fb.inverse_batch(pts, m).require(pts)
            assert np.abs(fb.singularity_margins(th, pts)[:, 2]).max() < 1e-7
            r1, r2 = fb.elbows(th)
            dist = np.hypot(*(r2 - r1).T)
            want = {"1a": fb.b1 + fb.b2, "1b-II": abs(fb.b1 - fb.b2), "1b-I": 0.0}[tr.kind]
            np.testing.assert_allclose(dist, want, atol=1e-6)


def test_class_one_circle_of_symmetric_machine() -> None:
    """a1 = a2 = a, b1 = b2 = b: R1 = R2 at (w/2, ±√(a² − w²/4)), and the Mode 1b class I
    trace is the circle of radius b about each (thesis Sec. 1.3.2, Fig. 11)."""
    fb = MACHINES[0]
    circles = [t for t in type2_traces(fb) if t.kind == "1b-I"]
    assert len(circles) == 2
    k = math.sqrt(60.0**2 - 20.0**2)
    centres: list[np.ndarray] = []
    for t in circles:
        c = t.points.mean(axis=0)
        np.testing.assert_allclose(np.hypot(*(t.points - c).T), 90.0, atol=1e-9)
        centres.append(c)
    np.testing.assert_allclose(sorted(centres, key=lambda c: c[1]), [(20.0, -k), (20.0, k)],
                               atol=1e-9)
    assert not any(t.kind == "1a" for t in type2_traces(fb))  # b1 + b2 > a1 + a2 + w


def test_mode_1a_trace_cuts_a_hole() -> None:
    """Short floating links (b < a): the Mode 1a trace is a closed curve in one working mode;
    inside it the assembly sign flips, so the safe region of the outer assembly has a hole."""
    fb = FiveBar(100.0, 60.0, 100.0, 60.0, 50.0)
    loops = [t for t in type2_traces(fb, n=720) if t.kind == "1a"]
    assert loops
    loop = loops[0]
    modes = set(loop.modes.tolist())
    assert len(modes) == 1 and not loop.breaks.any()
    mode = modes.pop()
    top = loop.points[np.argmax(loop.points[:, 1])]
    centre = top - np.array([0.0, 15.0])  # just inside the loop (and outside the dead zones)
    far = top + np.array([0.0, 15.0])
    pm = measures(fb, mode, np.stack((centre, far)))
    assert pm.valid.all() and pm.assembly[0] == -pm.assembly[1]
    outer = "+" if pm.assembly[1] > 0 else "-"
    m = safe_mask(fb, mode, [centre[0], far[0]], [centre[1], far[1]], 0.0, 5 * DEG,
                  assembly=outer)
    assert m[0, 0] == False and m[1, 1] == True  # noqa: E712


def test_type1_circles() -> None:
    fb = FiveBar(60.0, 60.0, 50.0, 80.0, 40.0)
    got = type1_circles(fb)
    assert (1, "stretched", (0.0, 0.0), 120.0) in got
    assert not any(arm == 1 and kind == "folded" for arm, kind, _, _ in got)  # a1 = b1
    assert (2, "folded", (40.0, 0.0), 30.0) in got
