"""The Taylor series of a branch (`FastPath.taylor`, the predictor of a sweep's first block),
checked against states solved independently by `simulate` and against the input motion's own
series (`InputBasis.taylor`) evaluated exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kinematics.nbar import parse_mechanism, simulate, sweep
from kinematics.nbar.fast import TAYLOR, FastPath
from kinematics.nbar.results import Status
from kinematics.nbar.tracker import Tracker

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"
NAMES = sorted(p.stem for p in MECH.glob("*.toml"))


@pytest.mark.parametrize("name", NAMES)
def test_input_series_equals_the_motion(name: str) -> None:
    """Σ e_k tᵏ reproduces [x_d, S] at u + t·d to rounding for |t| up to a large step."""
    basis = parse_mechanism((MECH / f"{name}.toml").read_text()).basis
    u = np.array([m.value0 for m in basis.motions]) + 0.3
    d = np.linspace(0.05, -0.04, len(basis.motions))
    coef = basis.taylor(u, d, 12)
    for t in (0.0, 0.5, -1.0, 2.0):
        series = (t ** np.arange(13)) @ coef
        np.testing.assert_allclose(series, basis.entries(u + t * d), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_branch_series_matches_independent_solutions(name: str) -> None:
    """Coefficients from one Jacobian, order by order, give the states `simulate` solves at
    fractions of an input step (error of the order of the neglected terms), and the first
    coefficient is the tangent q' = −J⁻¹Φ_u along the step."""
    mech = parse_mechanism((MECH / f"{name}.toml").read_text())
    if mech.overdetermined:
        pytest.skip("least-squares mechanisms are not predicted by the series")
    tr = Tracker(mech, mech.settings)
    d = mech.step
    coef = FastPath(tr).taylor(tr.q, tr.u, d).copy()
    assert coef.shape == (TAYLOR + 1, mech.system.n_u)
    np.testing.assert_array_equal(coef[0], mech.q0)
    np.testing.assert_allclose(coef[1], tr.tangent()[0] @ d, rtol=0, atol=1e-12)
    ts = np.array([0.25, 0.5, 1.0, 2.0])
    sim = simulate(mech, mech.input0 + ts[:, None] * d, tolerance=1e-13)
    assert sim.completed
    solved = sim.coords.reshape(len(ts), -1)[:, mech.system.unknown_flat]
    series = (ts[:, None] ** np.arange(TAYLOR + 1)) @ coef
    err = np.linalg.norm(series - solved, axis=1)
    size = max(mech.size, 1.0)
    assert err[0] < 1e-11 * size and err[1] < 1e-9 * size
    # Each doubling of t multiplies the truncation error by about 2^(TAYLOR+1) at most.
    assert err[-1] < 1e-5 * size


def test_first_block_from_the_series_is_accepted_in_one_pass() -> None:
    """The four-bar's first twelve steps come from the series in one batched Newton step and
    equal `simulate` solving each of those inputs afresh."""
    mech = parse_mechanism((MECH / "fourbar_crank_rocker.toml").read_text())
    sim = sweep(mech, steps=12)
    assert sim.completed and (sim.status == Status.OK).all()
    assert (sim.iterations[1:] == 1).all()
    ref = simulate(mech, sim.inputs, tolerance=1e-13)
    np.testing.assert_allclose(sim.coords, ref.coords, rtol=0, atol=1e-9)
