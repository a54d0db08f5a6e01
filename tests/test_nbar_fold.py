"""Motion limits located as folds (turning points) of the solution curve, checked against an
independent computation: scipy's SLSQP maximising (or minimising) the input subject to the
paper's exact constraint equations (`Mechanism.residuals`), started near the reported limit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize

from kinematics.nbar import Mechanism, parse_mechanism, simulate, sweep
from kinematics.nbar.fold import FOLD_REASON

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"


def extreme_input(mech: Mechanism, q: np.ndarray, u: float, sign: float) -> float:
    """The input's extreme value (max for sign = +1, min for −1) on the solution set near
    (q, u), by SLSQP on the exact equations."""
    n = q.size
    scale = max(float(np.max(np.abs(q))), 1.0)

    def cons(z: np.ndarray) -> np.ndarray:
        uu = np.array([[z[n]]])
        c = mech.coords_batch(z[None, :n], uu)
        return np.asarray(mech.residuals(c, uu)[0], dtype=np.float64)

    z0 = np.concatenate((q, [u - sign * 1e-4]))
    res = minimize(lambda z: -sign * z[n], z0, method="SLSQP",
                   constraints=[{"type": "eq", "fun": cons}],
                   options={"ftol": 1e-15, "maxiter": 500})
    assert res.success and np.max(np.abs(cons(res.x))) < 1e-9 * scale
    return float(res.x[n])


def limit_state(mech: Mechanism, coords: np.ndarray) -> np.ndarray:
    return np.asarray(coords.ravel()[mech.system.unknown_flat], dtype=np.float64)


def test_watt1_limits_are_folds_located_to_the_reported_bracket() -> None:
    mech = parse_mechanism((MECH / "spherical_watt1.toml").read_text())
    sim = sweep(mech)
    step = float(abs(mech.step[0]))
    assert len(sim.limits) == 2
    for lim in sim.limits:
        assert FOLD_REASON in lim.reason and "singular" in lim.reason
        reached, failed = float(lim.reached[0]), float(lim.failed[0])
        sign = 1.0 if failed > reached else -1.0
        # The bracket is narrower than the halving search's 2^-max_halvings of a step.
        assert 0.0 < abs(failed - reached) <= 2.0 ** -mech.settings.max_halvings * step
        q = limit_state(mech, sim.coords[lim.row])
        assert sim.residual[lim.row] < 1e-10
        u_star = extreme_input(mech, q, reached, sign)
        # The fold lies inside the bracket (up to SLSQP's own accuracy).
        assert sign * (u_star - reached) > -1e-9
        assert sign * (failed - u_star) > -1e-9
        assert abs(u_star - reached) < 1e-8


def test_fold_on_the_rocker_matches_the_closed_form_limit() -> None:
    """Simulated (not swept) input through the rocker's extreme: the fold bracket contains the
    closed-form limit, and the state reached is on the branch that was being followed."""
    from tests.test_nbar_stability import PSI_MAX, crank_pin, rocker_driven

    mech = rocker_driven()
    psi = np.pi / 2 + np.radians(0.7) * np.arange(60)
    sim = simulate(mech, psi)
    (lim,) = sim.limits
    assert FOLD_REASON in lim.reason
    assert lim.reached[0] < PSI_MAX < lim.failed[0]
    assert lim.failed[0] - lim.reached[0] <= 2.0 ** -24 * np.radians(0.7)
    k = lim.row
    # The branch: J2 on the crank circle matches the closed form just before the limit.
    assert np.abs(sim.path("J2")[k - 1] - crank_pin(float(psi[k - 1]))).max() < 1e-9
    assert np.abs(sim.path("J2")[k] - crank_pin(float(lim.reached[0]))).max() < 1e-4


@pytest.mark.parametrize("halvings", [10, 24])
def test_fold_bracket_follows_max_halvings(halvings: int) -> None:
    mech = parse_mechanism((MECH / "spherical_watt1.toml").read_text())
    sim = sweep(mech, max_halvings=halvings)
    step = float(abs(mech.step[0]))
    for lim in sim.limits:
        assert abs(float(lim.failed[0] - lim.reached[0])) <= 2.0 ** -halvings * step


@pytest.mark.parametrize(("refused", "fold_first"), [(0, True), (2, False), (2, True)])
def test_step_without_a_fold_is_taken_whatever_the_hint(refused: int, fold_first: bool) -> None:
    """`advance` told that a fold is likely (`fold_first`) or that the whole step was refused
    (`refused`) on a step with no fold in it: it still reaches the target, on the branch that
    `simulate` follows (the look-ahead and the skipped attempt only change the order of work)."""
    from kinematics.nbar.results import Status
    from kinematics.nbar.tracker import Tracker

    mech = parse_mechanism((MECH / "fourbar_crank_rocker.toml").read_text())
    tr = Tracker(mech, mech.settings)  # at the initial configuration
    target = mech.input0 + 0.05
    ref = simulate(mech, target[None, :], tolerance=1e-13)
    with np.errstate(all="ignore"):
        st, _, subs, _, _, _ = tr.advance(target, None, refused, fold_first)
    assert st == (Status.SUBDIVIDED if refused else Status.OK)
    assert subs >= 1 and np.array_equal(tr.u, target)
    np.testing.assert_allclose(tr.q, ref.coords[0].ravel()[mech.system.unknown_flat],
                               rtol=0, atol=1e-9)
