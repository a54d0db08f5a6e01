"""The pen on an extension of distal link 1 (kinematics.extension) against independent checks:
the link lengths of the solved pose, the IK∘FK round trip, a pose worked by hand, finite
differences of the forward kinematics, and the general n-bar solver (which shares no code)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kinematics.extension import ExtendedFiveBar
from kinematics.fivebar import WORKING_MODES, FiveBar, UnreachableError
from kinematics.nbar import validate_fivebar_path
from kinematics.workspace import point_safety, type2_traces

#: Plotclock's arms (configs/plotclock.toml): 35 mm servo horns, 45 mm links, servos 25 mm
#: apart, the pen 13.2 mm off the joint, 45.4° off the straight line.
PLOTCLOCK = ExtendedFiveBar(35.0, 45.025, 35.0, 45.0, 25.0, 13.2, math.radians(45.4))
STRAIGHT = ExtendedFiveBar(60.0, 90.0, 60.0, 90.0, 40.0, 25.0, 0.0)
GEOMS = [PLOTCLOCK, STRAIGHT, ExtendedFiveBar(55.0, 80.0, 65.0, 85.0, 42.0, 20.0, -0.7)]


def _cloud(fb: FiveBar, n: int = 3000) -> np.ndarray:
    rng = np.random.default_rng(7)
    hi = fb.reach[0][1]
    return np.stack((rng.uniform(-hi, fb.w + hi, n), rng.uniform(-hi, hi, n)), axis=1)


@pytest.mark.parametrize("fb", GEOMS)
@pytest.mark.parametrize("mode", WORKING_MODES)
def test_inverse_satisfies_every_link_and_round_trips(fb: ExtendedFiveBar, mode: str) -> None:
    """Every solved pose has the stated link lengths and the rigid pen triangle (checked on
    the points, not through Eq. X1), the asked working mode, and forward kinematics in the
    pose's assembly mode returns the point."""
    pts = _cloud(fb)
    inv = fb.inverse_batch(pts, mode)
    assert inv.valid.sum() > 300
    th, p = inv.angles[inv.valid], pts[inv.valid]
    r1, r2 = fb.elbows(th)
    j = fb.joints(th, p)
    length = lambda u, v: np.hypot(*(u - v).T)  # noqa: E731
    assert np.abs(length(r1, np.zeros(2)) - fb.a1).max() < 1e-9
    assert np.abs(length(r2, np.array([fb.w, 0.0])) - fb.a2).max() < 1e-9
    assert np.abs(length(j, r1) - fb.b1).max() < 1e-9
    assert np.abs(length(j, r2) - fb.b2).max() < 1e-9
    assert np.abs(length(p, j) - fb.extension).max() < 1e-9
    # The extension's direction: angle of J→P from R1→J is γ.
    u, v = j - r1, p - j
    ang = np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], (u * v).sum(axis=1))
    if fb.extension > 0:
        assert np.abs(ang - fb.extension_angle).max() < 1e-9
    signs = [1 if c == "+" else -1 for c in mode]
    assert (fb.mode_of(p, th) == signs).all()
    asm = fb.assembly_of(th, p).astype(float)
    fw = fb.forward_batch(th, asm)
    assert fw.valid.all()
    assert np.abs(fw.points - p).max() < 1e-8


def test_a_pose_worked_by_hand() -> None:
    """a = 30, b = 50, w = 40, θ = (90°, 90°): R1 = (0, 30), R2 = (40, 30), J = (20, 30 + h)
    with h = √(50² − 20²); a straight 10 mm extension puts P at J + (J − R1)/5, a 90° one at
    J + 10·(−h, 20)/50."""
    h = math.sqrt(2500.0 - 400.0)
    j = np.array([20.0, 30.0 + h])
    for gamma, pen in ((0.0, j + np.array([20.0, h]) / 5.0),
                       (math.pi / 2, j + 10.0 * np.array([-h, 20.0]) / 50.0)):
        fb = ExtendedFiveBar(30.0, 50.0, 30.0, 50.0, 40.0, 10.0, gamma)
        got = fb.forward(np.radians([90.0, 90.0]), "+")
        assert np.allclose(got, pen, atol=1e-12)
        mode = "".join("+" if s > 0 else "-" for s in
                       fb.mode_of(pen, np.radians([90.0, 90.0]))[0])
        assert np.allclose(fb.inverse(pen, mode), np.radians([90.0, 90.0]), atol=1e-12)


def test_no_extension_is_the_plain_five_bar() -> None:
    plain = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
    ext = ExtendedFiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
    pts = _cloud(plain, 500)
    a, b = plain.inverse_batch(pts, "+-"), ext.inverse_batch(pts, "+-")
    assert (a.valid == b.valid).all() and (a.reason == b.reason).all()
    assert np.abs(a.angles - b.angles).max() < 1e-12
    th, p = a.angles[a.valid], pts[a.valid]
    assert np.abs(plain.singularity_margins(th, p) - ext.singularity_margins(th, p)).max() < 1e-12
    assert np.abs(plain.jacobian(th, p) - ext.jacobian(th, p)).max() < 1e-9


@pytest.mark.parametrize("fb", GEOMS)
def test_jacobian_is_the_derivative_of_forward_kinematics(fb: ExtendedFiveBar) -> None:
    """J = A⁻¹B against central differences of FK (relative error, away from singularities)."""
    pts = _cloud(fb, 600)
    inv = fb.inverse_batch(pts, "+-")
    th, p = inv.angles[inv.valid], pts[inv.valid]
    keep = np.abs(fb.singularity_margins(th, p)).min(axis=1) > math.radians(5)
    th, p = th[keep], p[keep]
    asm = fb.assembly_of(th, p).astype(float)
    jac = fb.jacobian(th, p)
    h = 1e-6
    for k in range(2):
        e = np.eye(2)[k] * h
        fd = (fb.forward_batch(th + e, asm).points - fb.forward_batch(th - e, asm).points) / (2 * h)
        scale = np.abs(jac[:, :, k]).max(axis=1)
        assert (np.abs(fd - jac[:, :, k]).max(axis=1) / scale).max() < 1e-6


def test_singularities_of_the_extension() -> None:
    """Arm 1 stretched onto the pen (|P| = a1 + d) is arm 1's type-1 singularity, not
    a1 ∥ b1; the type-2 singularity is b1 ∥ b2 at the joint wherever the pen is."""
    fb = PLOTCLOCK
    d = fb.pen_link
    # Arm 1 stretched onto the pen: θ1 is the pen's direction.
    phi = math.radians(80.0)
    p = (fb.a1 + d) * np.array([math.cos(phi), math.sin(phi)])
    th = fb.inverse(p, "+-")
    assert th[0] == pytest.approx(phi, abs=1e-6)
    m = fb.singularity_margins(th, p)[0]
    assert abs(m[0]) < 1e-6 and abs(m[1]) > 0.05
    _, b = fb.jacobians(th, p)
    assert abs(b[0, 0, 0]) < 1e-6 * fb.a1 * d
    # The links b1 and b2 in one line: elbows b1 + b2 apart.
    th1 = math.radians(150.0)
    r1 = fb.a1 * np.array([math.cos(th1), math.sin(th1)])
    span = fb.b1 + fb.b2 - 1e-8  # a hair inside, so the pose exists after rounding
    # R2 on the circle about M2 at distance `span` from R1 (bisection on θ2).
    lo, hi = math.radians(0.0), math.radians(90.0)
    dist = lambda t: math.hypot(fb.w + fb.a2 * math.cos(t) - r1[0],  # noqa: E731
                                fb.a2 * math.sin(t) - r1[1]) - span
    assert dist(lo) * dist(hi) < 0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if dist(mid) * dist(lo) > 0 else (lo, mid)
    pose = np.array([[th1, lo if dist(lo) <= 0 else hi]])
    fw = fb.forward_batch(pose, "+")
    assert fw.valid.all()
    m2 = fb.singularity_margins(pose, fw.points)[0, 2]
    assert abs(m2) < 1e-3
    a, _ = fb.jacobians(pose, fw.points)
    assert abs(np.linalg.det(a[0])) < 1e-3 * fb.b1 * fb.b2
    assert abs(fb.singularity_margins(pose, fw.points)[0, 0]) > 0.05  # arm 1 is not


def test_type2_traces_are_type2_singular() -> None:
    fb = PLOTCLOCK
    for tr in type2_traces(fb, n=360):
        for mode in set(tr.modes.tolist()) - {""}:
            pts = tr.points[tr.modes == mode]
            inv = fb.inverse_batch(pts, mode)
            m = fb.singularity_margins(inv.angles[inv.valid], pts[inv.valid])
            assert inv.valid.mean() > 0.9
            assert np.abs(m[:, 2]).max() < 1e-6


@pytest.mark.parametrize("fb", GEOMS)
def test_nbar_solver_agrees_along_a_circle(fb: ExtendedFiveBar) -> None:
    """The n-bar solver carries the rigid link R1–J–P by itself (a ternary link) and follows
    a drawn circle; its pen path equals the closed form's."""
    cloud = _cloud(fb, 4000)
    safe = cloud[point_safety(fb, "+-", cloud, math.radians(10), math.radians(20),
                              assembly="+")]
    t = np.linspace(0.0, 2 * math.pi, 240)
    ring = 0.05 * fb.reach[0][1] * np.stack((np.cos(t), np.sin(t)), axis=1)
    order = np.argsort(np.hypot(*(safe - safe.mean(axis=0)).T))
    centre = next(c for c in safe[order]
                  if point_safety(fb, "+-", c + ring, math.radians(5), math.radians(10),
                                  assembly="+").all())
    pts = centre + ring
    inv = fb.inverse_batch(pts, "+-")
    assert inv.valid.all()
    report = validate_fivebar_path(fb, inv.angles, "+")
    assert report.valid.all() and report.simulation.completed
    # The solver stops at a relative residual of 1e-12; through the pen's lever that is
    # nanometres at most, a million times below a step's motion.
    assert report.max_deviation < 1e-8
    assert np.abs(report.nbar_points - pts).max() < 1e-8


def test_unreachable_names_the_arm_and_the_joint() -> None:
    fb = PLOTCLOCK
    with pytest.raises(UnreachableError, match=r"\|P − M1\|"):
        fb.inverse(np.array([0.0, 200.0]), "+-")
    with pytest.raises(ValueError, match="extension"):
        ExtendedFiveBar(30.0, 50.0, 30.0, 50.0, 40.0, -1.0, 0.0)
    with pytest.raises(ValueError, match="elbow R1"):
        ExtendedFiveBar(30.0, 50.0, 30.0, 50.0, 40.0, 50.0, math.pi)
