"""The paper's examples (configs/mechanisms/*.toml): counts, rigidity, sphere, completion.

Rigidity is measured here, independently of the solver's constraint selection: for every link
and every pair of its joints (not only the 2k − 3 pairs the solver keeps), the distance between
points, the signed distance of a point from a line or plane, and the angle between lines or
planes, at every solved step, against the initial configuration.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from kinematics.nbar import Mechanism, Simulation, Status, parse_mechanism, simulate, sweep

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"
ALL = sorted(p.stem for p in MECH.glob("*.toml"))


@cache
def load(name: str) -> Mechanism:
    return parse_mechanism((MECH / f"{name}.toml").read_text())


@cache
def run(name: str) -> Simulation:
    return sweep(load(name))


def pair_metric(mech: Mechanism, coords: np.ndarray, a: str, b: str) -> np.ndarray:
    """Metric of joints a, b over all rows: distance, point–line distance or angle (rad)."""
    ia, ib = mech.index(a), mech.index(b)
    la, lb = mech.joints[ia].is_line, mech.joints[ib].is_line
    d = mech.dim
    if not la and not lb:
        return np.asarray(np.linalg.norm(coords[:, ia, :d] - coords[:, ib, :d], axis=1))
    if la and lb:
        u, v = coords[:, ia, :d], coords[:, ib, :d]
        cos = np.sum(u * v, axis=1)
        sin = (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] if d == 2
               else np.linalg.norm(np.cross(u, v), axis=1))
        return np.asarray(np.arctan2(sin, cos))
    p, ln = (ib, ia) if la else (ia, ib)
    n = coords[:, ln, :d]
    off = coords[:, ln, 2] if d == 2 else 0.0
    return np.asarray((np.sum(coords[:, p, :d] * n, axis=1) + off) / np.linalg.norm(n, axis=1))


@pytest.mark.parametrize("name", ALL)
def test_rigidity_is_preserved_at_every_step(name: str) -> None:
    """Every pairwise link metric equals its initial value to 1e-9 (lengths relative to the
    mechanism size) at every solved step."""
    mech, sim = load(name), run(name)
    solved = sim.solved
    assert solved.sum() >= 50
    c = sim.coords[solved]
    worst = 0.0
    for link in mech.links:
        for a, b in itertools.combinations(link.joints, 2):
            m = pair_metric(mech, c, a, b)
            is_angle = mech.joints[mech.index(a)].is_line and mech.joints[mech.index(b)].is_line
            scale = 1.0 if is_angle else max(mech.size, 1.0)
            worst = max(worst, float(np.max(np.abs(m - m[0]))) / scale)
    assert worst < 1e-9


@pytest.mark.parametrize("name", ALL)
def test_every_step_meets_the_residual_tolerance(name: str) -> None:
    sim = run(name)
    assert np.all(sim.residual[sim.solved] <= load(name).settings.tolerance)
    assert np.all(sim.iterations >= 0)


@pytest.mark.parametrize("name", ["spherical_rrpr", "spherical_watt1"])
def test_spherical_joints_stay_on_the_unit_sphere(name: str) -> None:
    mech, sim = load(name), run(name)
    pts = [i for i, j in enumerate(mech.joints) if not j.is_line]
    r = np.linalg.norm(sim.coords[sim.solved][:, pts, :], axis=2)
    assert np.abs(r - 1.0).max() < 1e-9
    planes = [i for i, j in enumerate(mech.joints) if j.is_line]
    n = np.linalg.norm(sim.coords[sim.solved][:, planes, :], axis=2)
    assert np.abs(n - 1.0).max() < 1e-9


@pytest.mark.parametrize("name", ["fourbar_crank_rocker", "stephenson2", "theo_jansen",
                                  "spherical_rrpr", "five_ss", "fivebar_robot"])
def test_example_completes_its_180_steps(name: str) -> None:
    sim = run(name)
    assert sim.completed and len(sim.status) == 181 and not sim.limits


@pytest.mark.parametrize("name", ["fourbar_crank_rocker", "stephenson2", "theo_jansen",
                                  "spherical_rrpr"])
def test_full_input_turn_closes_the_curve(name: str) -> None:
    """180 steps of 2π/180 are one input turn: the mechanism is back where it started (a
    silent branch change on the way would leave it elsewhere)."""
    sim = run(name)
    assert sim.inputs[-1, 0] - sim.inputs[0, 0] == pytest.approx(2 * math.pi)
    assert np.abs(sim.coords[-1] - sim.coords[0]).max() < 1e-9


def test_equation_counts_match_the_paper() -> None:
    """Sec. 4: state dimensions and equations per example, by kind."""
    expected = {
        # name: (unknowns, {kind: rows})
        "stephenson2": (11, {"RR": 5, "RP": 5, "NORM": 1}),  # 10 rigidity + Eq. 8
        "theo_jansen": (11, {"RR": 7, "RP": 3, "NORM": 1}),  # 10 rigidity + Eq. 8
        "spherical_rrpr": (6, {"RR": 1, "RP": 3, "NORM": 1, "SPHERE": 1}),  # 4 + Eq. 9 + 8
        "spherical_watt1": (12, {"RR": 8, "SPHERE": 4}),  # 8 rigidity + 4 unit sphere
        "five_ss": (18, {"RR": 17, "ACT": 1}),  # 5 binary + 12 coupler + actuator
        "fourbar_crank_rocker": (4, {"RR": 4}),
        "fivebar_robot": (2, {"RR": 2}),
    }
    for name, (n_u, kinds) in expected.items():
        mech = load(name)
        assert mech.system.n_u == n_u, name
        assert dict(Counter(c.kind for c in mech.constraints)) == kinds, name


def test_five_ss_actuator_and_coupler() -> None:
    """5-SS: the actuator length |J7 − J1| follows the input exactly; the coupler's 12 rows
    (3k − 6 for k = 6) keep all 15 of its distances."""
    mech, sim = load("five_ss"), run("five_ss")
    length = np.linalg.norm(sim.path("J7") - sim.path("J1"), axis=1)
    assert np.abs(length - sim.inputs[:, 0]).max() < 1e-9 * mech.size
    assert sim.inputs[-1, 0] - sim.inputs[0, 0] == pytest.approx(1.8)
    coupler = [c for c in mech.constraints if c.link == "L6"]
    assert len(coupler) == 12


def test_watt1_has_a_limited_input_range_traced_both_ways() -> None:
    """With Table 4's data the Watt-I input link cannot turn fully: the file asks to reverse at
    the limit, and both extremes are reported (open curve, fewer than 180 points, as the
    paper says of open-loop curves)."""
    sim = run("spherical_watt1")
    assert [lim.kind for lim in sim.limits] == ["limit", "limit"]
    assert sim.status[-1] == Status.LIMIT and sim.reversed_at is not None
    lo, hi = sorted(lim.reached[0] for lim in sim.limits)
    assert math.degrees(hi) == pytest.approx(97.06, abs=0.05)
    assert math.degrees(lo) == pytest.approx(-43.37, abs=0.05)
    assert len(sim.status) < 180


def test_watt1_return_after_the_limit_matches_solving_every_row() -> None:
    """Back from the first limit the sweep replays the states it solved on the way out and
    then continues past the start: every row after the reversal equals an independent
    `simulate` over the same inputs (each row solved by Newton from its neighbour)."""
    sim = run("spherical_watt1")
    mech = sim.mechanism
    r0 = sim.reversed_at
    assert r0 is not None
    back = np.arange(r0 + 1, len(sim.status) - 1)  # after the turn, before the second limit
    assert np.any(sim.inputs[back, 0] < sim.inputs[0, 0])  # it went past the start
    ref = simulate(mech, sim.inputs[back, 0])
    assert ref.completed
    assert np.abs(ref.coords - sim.coords[back]).max() < 1e-9 * mech.size


def test_rounded_spherical_tables_are_projected_and_reported() -> None:
    """Table 2 points are off the unit sphere by up to 0.3 %: projected, listed."""
    mech = load("spherical_rrpr")
    assert any("J2: projected onto the unit sphere" in a for a in mech.adjustments)
    assert np.allclose(np.linalg.norm(mech.coords0, axis=1), 1.0, atol=1e-15)


def test_five_ss_table_misprint_is_caught() -> None:
    """Table 5 as printed lists J10 twice in L6: the loader refuses it by name."""
    text = (MECH / "five_ss.toml").read_text().replace(
        '"J9", "J10", "J11"]', '"J9", "J10", "J10"]')
    from kinematics.nbar import MechanismError

    with pytest.raises(MechanismError, match=r"L6.*J10.*twice"):
        parse_mechanism(text)
