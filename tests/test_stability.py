"""Stability where methods fail: one test per failure mode the stability map and the
approaches of `python -m benchmarks.speed_accuracy` found (docs/performance.md, section 5),
each asserting the documented behaviour at that place — an error, a refusal, or a bounded
error. References are the closed-form formulas evaluated in long double
(benchmarks/kinematics.py's bare formulas with np.longdouble input).

Machines: SYM is the bundled profile's geometry (a = 60, b = 90, w = 40 mm; b1 + b2 exceeds
a1 + a2 + w, so it has no Mode 1a, but b1 = b2 gives Mode 1b: coincident elbows); SHORT has
70 mm floating links and therefore a Mode 1a singularity (the links stretched into one line).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.approx import fit_linear, forward_table, inverse_table  # noqa: E402
from benchmarks.kinematics import bare_forward, bare_inverse  # noqa: E402
from kinematics.fivebar import FiveBar, Reason, UnreachableError  # noqa: E402
from kinematics.nbar import (  # noqa: E402
    Status,
    fivebar_mechanism,
    simulate,
    validate_fivebar_path,
)

SYM = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
SHORT = FiveBar(60.0, 70.0, 60.0, 70.0, 40.0)
MODE = "+-"
DELTAS = 10.0 ** -np.arange(1.0, 12.5, 0.5)  # 0.1 mm … 1e-12 mm
LD = np.longdouble


def ld_forward(fb: FiveBar, th: np.ndarray, sign: float | np.ndarray) -> np.ndarray:
    s = np.broadcast_to(np.asarray(sign, dtype=LD), (th.shape[0],))
    with np.errstate(invalid="ignore"):
        return np.asarray(bare_forward(fb, th.astype(LD), s))


def ld_inverse(fb: FiveBar, p: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.asarray(bare_inverse(fb, p.astype(LD), 1.0, -1.0))


def dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.asarray(a, dtype=LD) - np.asarray(b, dtype=LD)
    return np.sqrt((d * d).sum(axis=1)).astype(float)


def reach_ray(fb: FiveBar, folded: bool, phi_deg: float, deltas: np.ndarray) -> np.ndarray:
    """Points δ inside arm 1's outer reach circle (stretched) or outside its inner one
    (folded), along the ray from M1 at angle φ."""
    radius = abs(fb.a1 - fb.b1) + deltas if folded else fb.a1 + fb.b1 - deltas
    u = np.array([math.cos(math.radians(phi_deg)), math.sin(math.radians(phi_deg))])
    return np.asarray(radius[:, None] * u)


def coincidence(fb: FiveBar, assembly: str = "+") -> tuple[np.ndarray, np.ndarray]:
    """θ_X where R1 = R2 = X (upper intersection of the elbow circles, b1 = b2) and a joint
    direction v = (σ1/a1, σ2/a2) along which θ_X + δ·v stays in working mode +-, in
    `assembly`, ≥ 10° from type 1: the elbows part by ~δ mm (Mode 1b approach)."""
    xa = (fb.w ** 2 + fb.a1 ** 2 - fb.a2 ** 2) / (2 * fb.w)
    x = np.array([xa, math.sqrt(fb.a1 ** 2 - xa ** 2)])
    tx = np.array([math.atan2(x[1], x[0]), math.atan2(x[1], x[0] - fb.w)])
    for s1 in (1.0, -1.0):
        for s2 in (1.0, -1.0):
            v = np.array([s1 / fb.a1, s2 / fb.a2])
            th = tx + DELTAS[:, None] * v
            fw = fb.forward_batch(th, assembly)
            if not fw.valid.all():
                continue
            modes = fb.mode_of(fw.points, th)
            m = np.abs(fb.singularity_margins(th, fw.points))
            if (modes == [1, -1]).all() and m[:, :2].min() > math.radians(10.0):
                return tx, v
    raise AssertionError("no Mode 1b approach in mode +-")


def mode_1a_approach(fb: FiveBar, th1: float, deltas: np.ndarray) -> np.ndarray:
    """Motor angles with θ1 fixed and |R1R2| = b1 + b2 − δ (δ < 0: the links cannot meet),
    on the branch of R2 that keeps working mode +-."""
    r1 = np.array([fb.a1 * math.cos(th1), fb.a1 * math.sin(th1)])
    d = np.array([fb.w, 0.0]) - r1
    dn = float(np.hypot(*d))
    length = fb.b1 + fb.b2 - deltas
    along = (dn * dn + length ** 2 - fb.a2 ** 2) / (2 * dn * dn)
    k = (length + fb.a2 + dn) * (length + fb.a2 - dn) * (length - fb.a2 + dn) * (
        -length + fb.a2 + dn)
    across = np.sqrt(k) / (2 * dn * dn)
    r2 = r1 + along[:, None] * d - across[:, None] * np.array([-d[1], d[0]])
    return np.stack((np.full(deltas.size, th1), np.arctan2(r2[:, 1], r2[:, 0] - fb.w)), 1)


# ============================================================================ closed form
@pytest.mark.parametrize(("folded", "phi"), [(False, 80.0), (True, 100.0)],
                         ids=["stretched", "folded"])
def test_closed_inverse_stays_exact_up_to_a_reach_circle_then_refuses(folded: bool,
                                                                      phi: float) -> None:
    """Type 1 (an arm stretched or folded): θ has a square-root branch point there, yet the
    factored Heron form keeps the answer exact to rounding down to 1e-12 mm from the circle;
    1e-9 mm past it the single-point call raises UnreachableError with the excess."""
    p = reach_ray(SYM, folded, phi, DELTAS)
    res = SYM.inverse_batch(p, MODE)
    assert res.valid.all()
    sign = SYM.assembly_of(res.angles, p).astype(float)
    pen = dist(ld_forward(SYM, res.angles, sign), p)
    assert pen.max() < 1e-11
    ang = np.abs(res.angles - ld_inverse(SYM, p).astype(float))
    assert ang.max() < 1e-9
    beyond = reach_ray(SYM, folded, phi, np.array([-1e-9]))[0]
    with pytest.raises(UnreachableError) as ei:
        SYM.inverse(beyond, MODE)
    assert ei.value.reason == (Reason.INSIDE_REACH_1 if folded else Reason.BEYOND_REACH_1)
    assert ei.value.excess_mm == pytest.approx(1e-9, rel=0.05)


def test_closed_forward_near_coincident_elbows_errs_only_as_the_problem_does() -> None:
    """Mode 1b (b1 = b2, elbows δ apart): P's direction is that of R2 − R1, known to
    ~a·ε/δ, so the float64 answer drifts from the long-double one like 1/δ — past 1e-6 mm
    within ~1e-7 mm of the coincidence. That is the problem's conditioning, not the
    algorithm's: rounding the motor angles alone (one ulp) moves the exact P as much."""
    tx, v = coincidence(SYM)
    th = tx + DELTAS[:, None] * v
    p = np.asarray(SYM.forward_batch(th, "+").points)
    err = dist(p, ld_forward(SYM, th, 1.0))
    ulp = th * (1.0 + np.finfo(float).eps)
    sensitivity = dist(ld_forward(SYM, ulp, 1.0), ld_forward(SYM, th, 1.0))
    assert (err <= 100.0 * sensitivity + 1e-13).all()
    assert (err * DELTAS).max() < 1e-11  # mm²: the 1/δ growth, bounded
    assert err[DELTAS >= 1e-3].max() < 1e-9
    # exactly coincident elbows raise DegenerateError (tests/test_fivebar.py holds that case)


def test_closed_forward_stays_exact_up_to_mode_1a_then_refuses() -> None:
    """Mode 1a (floating links stretched into one line): P has a square-root branch point
    (its error grows like 1/√δ, within what one ulp of the motor angles does to the exact
    P) and stays below 1e-6 mm down to δ = 1e-12 mm; 1e-9 mm past it the links cannot
    meet: UnreachableError."""
    th = mode_1a_approach(SHORT, 1.9, DELTAS)
    res = SHORT.forward_batch(th, "+")
    assert res.valid.all()
    err = dist(res.points, ld_forward(SHORT, th, 1.0))
    ulp = th * (1.0 + np.finfo(float).eps)
    sensitivity = dist(ld_forward(SHORT, ulp, 1.0), ld_forward(SHORT, th, 1.0))
    assert (err <= 100.0 * sensitivity + 1e-13).all()  # grows like 1/√δ, as the problem
    assert err[DELTAS >= 1e-6].max() < 1e-9 and err.max() < 1e-6
    past = mode_1a_approach(SHORT, 1.9, np.array([-1e-9]))[0]
    with pytest.raises(UnreachableError) as ei:
        SHORT.forward(past, "+")
    assert ei.value.reason == Reason.ELBOWS_TOO_FAR


# ============================================================================ n-bar solver
def test_nbar_approaching_a_reach_circle_stays_bounded() -> None:
    """Type 1 is no singularity of the forward problem: the continuation follows the arm to
    1e-12 mm of full stretch with the error of its residual tolerance."""
    p = reach_ray(SYM, False, 80.0, DELTAS)
    th = np.asarray(SYM.inverse_batch(p, MODE).angles)
    sim = simulate(fivebar_mechanism(SYM, th[0], "+"), th)
    assert sim.completed
    assert dist(sim.path("P"), ld_forward(SYM, th, 1.0)).max() < 1e-7


def test_nbar_approaching_mode_1a_has_bounded_error_then_reports_the_limit() -> None:
    """Near Mode 1a a residual ε moves P by ~√(ε·L): the error grows to ~√tolerance·size
    (bounded) and where the Jacobian turns singular the solver reports a motion limit;
    it never answers 1e-3 mm past the singularity, where the links cannot meet."""
    th = mode_1a_approach(SHORT, 1.9, DELTAS)
    mech = fivebar_mechanism(SHORT, th[0], "+")
    tol = mech.settings.tolerance
    sim = simulate(mech, th)
    solved = np.isin(sim.status, (Status.OK, Status.SUBDIVIDED))
    err = dist(sim.path("P")[solved], ld_forward(SHORT, th[solved], 1.0))
    assert err.max() < 10.0 * math.sqrt(tol) * (SHORT.b1 + SHORT.b2)
    assert np.nanmax(sim.residual[solved]) <= tol
    if not solved.all():
        k = int(np.flatnonzero(~solved)[0])
        assert sim.status[k] == Status.LIMIT and sim.limits
        assert all(s == Status.UNREACHED for s in sim.status[k + 1:])
    past = mode_1a_approach(SHORT, 1.9, np.array([-1e-3]))
    sim2 = simulate(mech, np.vstack((th[:8], past)))
    assert sim2.status[-1] in (Status.LIMIT, Status.UNREACHED)
    assert sim2.limits and "limit" in str(sim2.limits[0])


def test_nbar_step_passing_coincident_elbows_refuses_rather_than_answers_wrong() -> None:
    """Found by the stability map: a 0.05 rad joint step (the largest of a job segment) that
    passes ~0.02 mm from coincident elbows. P swings round the elbows faster than the
    continuity guard accepts, so the solver reports a motion limit ("no continuous
    solution") although the closed form answers there; never a wrong point. The job's
    n-bar second opinion then reports the row as unsolved or agrees with the closed form."""
    target = np.array([1.21966872, 1.92075066])
    home = np.radians([120.0, 60.0])
    start = target + 0.05 * (home - target) / np.hypot(*(home - target))
    line = start + np.linspace(0.0, 1.0, 401)[:, None] * (target - start)
    r1, r2 = SYM.elbows(line)
    assert np.hypot(*(r2 - r1).T).min() < 0.05  # the place: elbows nearly coincide
    closed = SYM.forward_batch(np.stack((start, target)), "+")
    assert closed.valid.all()
    sim = simulate(fivebar_mechanism(SYM, start, "+"), np.stack((start, target)))
    if sim.status[-1] == Status.LIMIT:
        assert "continuous" in sim.limits[0].reason
        # validation (its own tighter tolerance) either reports the row unsolved or agrees
        report = validate_fivebar_path(SYM, np.stack((start, target)), "+")
        assert (not report.valid[-1] and report.max_deviation == math.inf) or (
            report.max_deviation < 1e-6)
    else:  # a solver that gets through must land on the closed-form point
        assert np.hypot(*(sim.path("P")[-1] - closed.points[1])) < 1e-6


def test_nbar_through_coincident_elbows_keeps_p_continuous_and_validation_sees_it() -> None:
    """Exactly through R1 = R2 (b1 = b2) P is free on a circle: the continuation keeps it
    continuous, which lands on the other assembly sign past the coincidence, while the
    closed form in the job's assembly jumps to the far side. Either the solver refuses
    (motion limit) or validation against the closed form reports the disagreement."""
    tx, v = coincidence(SYM)
    s = np.concatenate((DELTAS, [0.0, -1e-9]))
    th = tx + s[:, None] * v
    sim = simulate(fivebar_mechanism(SYM, th[0], "+"), th)
    if not sim.completed:
        assert sim.limits
        return
    p = sim.path("P")
    assert np.hypot(*(p[-1] - p[-3])) < 1e-3  # continuous through the coincidence
    report = validate_fivebar_path(SYM, th, "+")
    assert report.max_deviation > 1.0  # the far-side jump is reported, not hidden


# ============================================================================ approximations
def test_linear_approximation_refuses_outside_and_misses_the_tolerance_inside() -> None:
    """Eq. 25/26 fitted on a page: refuses outside its box and out of reach (0.0, never
    NaN); inside, its error is the fit's residual — bounded, but far above a plotter's
    tolerance (the transform is linear, the kinematics are not)."""
    xs, ys = np.meshgrid(np.linspace(-20.0, 60.0, 25), np.linspace(95.0, 135.0, 15))
    page = np.stack((xs.ravel(), ys.ravel()), axis=1)
    lin = fit_linear(SYM, MODE, page, "similarity")
    r = lin.inverse(page)
    assert r.valid.all()
    exact = np.asarray(SYM.inverse_batch(page, MODE).angles)
    assert np.abs(r.values - exact).max() <= lin.max_rad * (1 + 1e-9)
    pen = dist(ld_forward(SYM, r.values, 1.0), page)
    assert pen.max() > 0.05
    out = lin.inverse([[200.0, 0.0], [20.0, 60.0], [-60.0, 120.0]])  # far, unreachable, off-box
    assert not out.valid.any() and (out.values == 0.0).all()
    fwd = lin.forward([[0.0, 3.0], [2.0, 1.0]])  # out of its angle box / links cannot meet
    assert not fwd.valid[0] and np.isfinite(fwd.values).all()


def test_table_refuses_cells_at_a_reach_circle_and_estimates_the_error_next_to_it() -> None:
    """Inverse table near type 1: a cell with a node out of reach is refused; in the cells
    next to the circle the error grows (square-root branch point) and the build-time
    estimate tracks it; the margin guard refuses the whole band."""
    box = (-110.0, 150.0, -150.0, 150.0)
    tab = inverse_table(SYM, MODE, box, 256, centre=(20.0, 114.0))
    p = reach_ray(SYM, False, 80.0, DELTAS)
    r = tab(p)
    refused = ~r.valid
    assert refused[DELTAS < 1e-3].all()
    ok = r.valid
    if ok.any():
        pen = dist(ld_forward(SYM, r.values[ok], 1.0), p[ok])
        assert (pen <= 1.05 * tab.error_estimate(p[ok]) + 1e-12).all()
    guarded = inverse_table(SYM, MODE, box, 256, centre=(20.0, 114.0),
                            min_margins=(math.radians(5.0), math.radians(15.0)))
    assert not guarded(p).valid.any()
    assert np.isfinite(r.values).all() and (r.values[refused] == 0.0).all()


def test_table_near_type_2_escapes_its_estimate_and_the_margin_guard_refuses() -> None:
    """Near coincident elbows (Mode 1b) any angle error moves the pen far: an unguarded
    inverse table answers with pen errors far beyond its sampled cell estimate (a point
    singularity inside a cell escapes sampling). With the profile's margins as guard every
    such point is refused. Forward tables near Mode 1a: cells past the singularity have
    nodes without a solution and are refused; the guard refuses the band before it."""
    box = (-110.0, 150.0, -150.0, 150.0)
    tx, v = coincidence(SYM)
    th = tx + DELTAS[:, None] * v
    p = np.asarray(SYM.forward_batch(th, "+").points)
    tab = inverse_table(SYM, MODE, box, 128, centre=(20.0, 114.0))
    r = tab(p)
    assert r.valid.any()
    pen = dist(ld_forward(SYM, r.values[r.valid], 1.0), p[r.valid])
    assert (pen > 10.0 * tab.error_estimate(p[r.valid])).any()
    margins = (math.radians(5.0), math.radians(15.0))
    guarded = inverse_table(SYM, MODE, box, 128, centre=(20.0, 114.0), min_margins=margins)
    assert not guarded(p).valid.any()
    # forward table of the short-link machine across Mode 1a
    jbox = (1.0, 2.8, -1.0, 1.0)
    th1a = mode_1a_approach(SHORT, 1.9, np.concatenate((DELTAS, [-1e-3, -1.0])))
    ftab = forward_table(SHORT, "+", jbox, 128)
    fr = ftab(th1a)
    assert not fr.valid[-2:].any()  # past the singularity: no answer exists, none given
    fg = forward_table(SHORT, "+", jbox, 128, min_margins=margins)
    assert not fg(th1a).valid.any()
