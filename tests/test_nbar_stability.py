"""Where plain Newton–Raphson fails: each case ends in a documented outcome.

- a motion limit (the Jacobian turns singular at a rocker's extreme): reported as LIMIT with the
  input value, never passed through; `reverse_at_limit` traces the whole range;
- a step large enough that Newton from the previous state lands on another branch: the step is
  subdivided and the result stays on the branch (reference: an independent scipy continuation
  of the loop equations in 1° steps);
- rounded data of an over-constrained linkage: reported as INCONSISTENT at the first step.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.optimize import fsolve

from kinematics.nbar import Status, build_mechanism, parse_mechanism, simulate, sweep
from kinematics.nbar.system import newton

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"
PSI_MAX = 2.0 * math.acos(4.0 / 8.0)  # rocker angle where |J3 − J1| = coupler − crank = 4
PSI_MIN = 2.0 * math.acos(6.0 / 8.0)  # … = coupler + crank = 6


def rocker_driven() -> Any:
    """The Sec. 4.1 four-bar driven at its rocker (J4): the rocker angle ψ of J3 about J4
    satisfies |J3 − J1| = 8 cos(ψ/2) ∈ [4, 6], so ψ ∈ [82.82°, 120°]."""
    spec = tomllib.loads((MECH / "fourbar_crank_rocker.toml").read_text())
    spec["inputs"] = [{"link": "L3", "joint": "J4", "step": math.radians(0.7)}]
    return build_mechanism(spec)


def crank_pin(psi: float) -> np.ndarray:
    """Analytic J2 for rocker angle ψ: circle(J1, 1) ∩ circle(J3, 5), J2 left of J1→J3."""
    j3 = np.array([4.0 + 4.0 * math.cos(psi), 4.0 * math.sin(psi)])
    d = float(np.linalg.norm(j3))
    a = (1.0 - 25.0 + d * d) / (2 * d)
    h = math.sqrt(max(1.0 - a * a, 0.0))
    e = j3 / d
    return np.asarray(a * e + h * np.array([-e[1], e[0]]))


def test_motion_limit_is_reported_with_its_input_value() -> None:
    mech = rocker_driven()
    psi = math.pi / 2 + math.radians(0.7) * np.arange(60)  # up to 131.3°, past the limit
    sim = simulate(mech, psi)
    k = int(np.argmax(psi > PSI_MAX))
    assert not sim.completed
    assert all(s in (Status.OK, Status.SUBDIVIDED) for s in sim.status[:k])
    assert sim.status[k] == Status.LIMIT
    assert all(s == Status.UNREACHED for s in sim.status[k + 1:])
    assert np.isnan(sim.coords[k + 1:]).all()
    (lim,) = sim.limits
    assert lim.kind == "limit" and lim.row == k
    assert lim.reached[0] < PSI_MAX and PSI_MAX - lim.reached[0] < 1e-6
    assert lim.failed[0] > lim.reached[0] and lim.requested[0] == psi[k]
    assert "singular" in lim.reason and "motion limit" in str(lim)
    # The LIMIT row holds the extreme configuration, at the input value reached, intact.
    assert sim.inputs[k, 0] == lim.reached[0]
    j1, j2, j3 = (sim.path(n)[k] for n in ("J1", "J2", "J3"))
    assert np.hypot(*(j2 - j1)) == pytest.approx(1.0, abs=1e-9)
    assert np.hypot(*(j3 - j2)) == pytest.approx(5.0, abs=1e-9)
    assert np.hypot(*(j3 - j1)) == pytest.approx(4.0, abs=1e-5)  # folded at the limit
    for r in range(k):
        assert np.abs(sim.path("J2")[r] - crank_pin(float(psi[r]))).max() < 1e-9


def test_reverse_at_limit_traces_the_whole_rocker_range() -> None:
    mech = rocker_driven()
    sim = sweep(mech, steps=200, reverse_at_limit=True)
    assert [lim.kind for lim in sim.limits] == ["limit", "limit"]
    top, bottom = sim.limits
    assert abs(top.reached[0] - PSI_MAX) < 1e-6 and abs(bottom.reached[0] - PSI_MIN) < 1e-6
    assert sim.reversed_at == top.row and sim.status[-1] == Status.LIMIT
    assert sim.inputs[:, 0].max() == top.reached[0] and sim.inputs[:, 0].min() == bottom.reached[0]
    inner = [r for r, s in enumerate(sim.status) if s != Status.LIMIT]
    for r in inner:
        assert np.abs(sim.path("J2")[r] - crank_pin(float(sim.inputs[r, 0]))).max() < 1e-9
    assert np.nanmax(sim.residual) <= 1e-10


# ------------------------------------------------------------------------ branch flip
def stephenson_reference(angles: np.ndarray) -> np.ndarray:
    """Independent continuation of Table 1: the 11 loop equations written from the link list
    (distances, point-line distances, Eq. 8), solved by scipy's fsolve in 1° steps from the
    table configuration. Returns the states [J3 (a, b, c), J4, J5, J6, J8] at `angles`
    (absolute angle of J2 about J1, increasing from the table's)."""
    spec = tomllib.loads((MECH / "stephenson2.toml").read_text())
    jt = spec["joints"]
    p = {k: np.array(v["at"], dtype=float) for k, v in jt.items() if "at" in v}
    line3 = np.array(jt["J3"]["line"], dtype=float)
    line3 /= math.hypot(*line3[:2])
    line7 = np.array(jt["J7"]["line"], dtype=float)

    def pl(x: np.ndarray, ln: np.ndarray) -> float:
        return float((ln[0] * x[0] + ln[1] * x[1] + ln[2]) / math.hypot(ln[0], ln[1]))

    def dist(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.hypot(*(a - b)))

    def metrics(j2: np.ndarray, z: np.ndarray) -> np.ndarray:
        l3, j4, j5, j6, j8 = z[0:3], z[3:5], z[5:7], z[7:9], z[9:11]
        return np.array([dist(j2, j4), pl(j2, l3), pl(j4, l3), pl(j6, l3), dist(j4, j5),
                         dist(j4, j8), dist(j5, j8), dist(j5, j6), pl(j5, line7),
                         pl(j6, line7), l3[0] ** 2 + l3[1] ** 2])

    z = np.concatenate((line3, p["J4"], p["J5"], p["J6"], p["J8"]))
    j1, j20 = p["J1"], p["J2"]
    target = metrics(j20, z)
    theta0 = math.atan2(*(j20 - j1)[::-1])

    def j2_at(th: float) -> np.ndarray:
        c, s = math.cos(th - theta0), math.sin(th - theta0)
        d = j20 - j1
        return np.asarray(j1 + np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]]))

    out = []
    th = theta0
    for goal in angles:
        while th < goal - 1e-12:
            th = min(th + math.radians(1.0), float(goal))
            sol, _, ok, msg = fsolve(lambda v, t=th: metrics(j2_at(t), v) - target, z,
                                     full_output=True, xtol=1e-13)
            assert ok == 1, msg
            assert np.abs(sol - z).max() < 0.2  # 1° steps: a continuous branch
            z = sol
        out.append(z.copy())
    return np.array(out)


def test_large_step_that_invites_a_branch_flip_is_subdivided() -> None:
    """Stephenson-II from its state at +204°: Newton from there, for one 84° step, converges
    to another assembly; the solver subdivides and stays on the branch."""
    mech = parse_mechanism((MECH / "stephenson2.toml").read_text())
    u0, step = mech.input0[0], math.radians(2.0)
    fine = u0 + step * np.arange(103)
    jump = fine[-1] + math.radians(84.0)
    sim = simulate(mech, np.append(fine, jump))
    ref = stephenson_reference(np.array([fine[-1], jump]))
    unknown = mech.system.unknown_flat
    states = sim.coords.reshape(len(sim.status), -1)[:, unknown]
    assert np.abs(states[-2] - ref[0]).max() < 1e-8

    # The step does invite a flip: plain Newton (Algorithm 1) from the previous state.
    sys = mech.system
    x = sys.new_x()
    x[sys.n_u: sys.n_u + sys.n_d] = mech.basis.driven(np.array([jump]))
    plain = newton(sys, x, states[-2], 1e-10, 60, monotone=False)
    assert plain.converged and np.abs(plain.q - ref[1]).max() > 0.1

    assert sim.status[-1] == Status.SUBDIVIDED and sim.substeps[-1] > 1
    assert np.abs(states[-1] - ref[1]).max() < 1e-8


# ------------------------------------------------------------------- inconsistent data
def test_rounded_data_of_an_overconstrained_linkage_is_reported_inconsistent() -> None:
    """A double parallelogram (three parallel cranks) is mobile only if its cranks are exactly
    equal and parallel. Printed to two decimals — pivot O3 = (1.503, −1.497) → (1.50, −1.50),
    tip T3 = O3 + (1.004, 1.996) → (2.51, 0.50) — crank 3 is (1.01, 2.00), crank 1 (1.00,
    2.00): the redundant equations admit no motion. Outcome: INCONSISTENT at the first step,
    with the reason, and no made-up states."""
    spec = {
        "mechanism": {"name": "double parallelogram (rounded)", "kind": "planar",
                      "ground": "G"},
        "joints": {"O1": {"type": "revolute", "at": [0.0, 0.0]},
                   "O2": {"type": "revolute", "at": [3.0, 0.0]},
                   "O3": {"type": "revolute", "at": [1.50, -1.50]},
                   "T1": {"type": "revolute", "at": [1.00, 2.00]},
                   "T2": {"type": "revolute", "at": [4.00, 2.00]},
                   "T3": {"type": "revolute", "at": [2.51, 0.50]}},
        "links": {"G": ["O1", "O2", "O3"], "c1": ["O1", "T1"], "c2": ["O2", "T2"],
                  "c3": ["O3", "T3"], "coupler": ["T1", "T2", "T3"]},
        "inputs": [{"link": "c1", "joint": "O1"}],
    }
    mech = build_mechanism(spec)  # it loads: the initial pose satisfies its own metrics
    assert mech.overdetermined
    sim = sweep(mech)
    assert sim.status_names == ["ok", "inconsistent"]
    (lim,) = sim.limits
    assert lim.kind == "inconsistent" and "over-constrained" in lim.reason
    assert "inconsistent constraints" in str(lim)
    assert np.isnan(sim.coords[1]).all()
    sim2 = simulate(mech, mech.input0[0] + np.radians([0.0, 1.0, 2.0]))
    assert sim2.status_names == ["ok", "inconsistent", "unreached"]
    assert sim2.limits[0].kind == "inconsistent" and sim2.limits[0].row == 1


def test_sweep_with_large_steps_stays_on_the_branch() -> None:
    """A sweep of Stephenson-II in 84° steps (the fast sweep path): every row on the branch
    of the independent continuation, the large steps subdivided where needed."""
    mech = parse_mechanism((MECH / "stephenson2.toml").read_text())
    sim = sweep(mech, steps=5, step=math.radians(84.0))
    assert sim.completed
    ref = stephenson_reference(sim.inputs[1:, 0])
    states = sim.coords.reshape(len(sim.status), -1)[:, mech.system.unknown_flat]
    assert np.abs(states[1:] - ref).max() < 1e-8
    assert (sim.status[1:] == Status.SUBDIVIDED).any()
