"""Planar mechanisms against closed-form solutions worked out independently here.

Circle–circle and line–circle intersections with the assembly branch fixed by the initial
configuration; the coupler point carried by its coordinates in the coupler frame.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from kinematics.nbar import MechanismError, Status, build_mechanism, simulate, sweep

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"


def perp(v: np.ndarray) -> np.ndarray:
    return np.array([-v[1], v[0]])


def circles(c1: np.ndarray, r1: float, c2: np.ndarray, r2: float, side: float) -> np.ndarray:
    """Intersection of two circles on the side `side` (sign of cross(c2 − c1, p − c1))."""
    e = c2 - c1
    d = float(np.linalg.norm(e))
    a = (r1 * r1 - r2 * r2 + d * d) / (2 * d)
    h = math.sqrt(r1 * r1 - a * a)
    return np.asarray(c1 + a * e / d + side * h * perp(e) / d)


def fourbar_spec() -> dict[str, Any]:
    return tomllib.loads((MECH / "fourbar_crank_rocker.toml").read_text())


def analytic_fourbar(theta: float) -> tuple[np.ndarray, np.ndarray]:
    """Crank 1 at (0,0), coupler 5, rocker 4 at (4,0); coupler point C = A + 1.08·(B − A)
    + 0.44·perp(B − A) (its table position (3, 6) in the frame A = (0, 1), B = (4, 4))."""
    a = np.array([math.cos(theta), math.sin(theta)])
    b = circles(a, 5.0, np.array([4.0, 0.0]), 4.0, 1.0)
    v = b - a
    return b, a + 1.08 * v + 0.44 * perp(v)


def test_fourbar_tracer_equals_analytic_solution() -> None:
    """Sec. 4.1 crank-rocker: a full crank turn in 180 steps, B and the tracer to 1e-9."""
    from kinematics.nbar import parse_mechanism

    mech = parse_mechanism((MECH / "fourbar_crank_rocker.toml").read_text())
    # The frame coefficients used by the reference follow from the table by hand:
    # (3, 6) − (0, 1) = 1.08·(4, 3) + 0.44·(−3, 4).
    assert np.allclose(1.08 * np.array([4, 3]) + 0.44 * np.array([-3, 4]), [3, 5])
    sim = sweep(mech)
    assert sim.completed and len(sim.status) == 181
    for k, th in enumerate(sim.inputs[:, 0]):
        b, c = analytic_fourbar(float(th))
        assert np.abs(sim.path("J3")[k] - b).max() < 1e-9
        assert np.abs(sim.path("J5")[k] - c).max() < 1e-9
    assert sim.inputs[-1, 0] - sim.inputs[0, 0] == pytest.approx(2 * math.pi)


def rocker_driven() -> Any:
    spec = fourbar_spec()
    spec["inputs"] = [{"link": "L3", "joint": "J4", "step": math.radians(0.7)}]
    return build_mechanism(spec)


def test_rocker_input_value_is_the_absolute_rocker_angle() -> None:
    mech = rocker_driven()
    assert mech.input0[0] == pytest.approx(math.pi / 2)


def test_slider_crank_driven_at_the_slider() -> None:
    """Prismatic input (Eqs. 13–14 in a mechanism): B slides on y = 0, A closes the loop."""
    spec = {
        "mechanism": {"name": "slider-crank", "kind": "planar", "ground": "ground"},
        "joints": {"O": {"type": "revolute", "at": [0.0, 0.0]},
                   "G": {"type": "prismatic", "line": [0.0, 2.0, 0.0]},
                   "B": {"type": "revolute", "at": [3.5, 0.0]},
                   "A": {"type": "revolute", "at": [0.5, math.sqrt(0.75)]}},
        "links": {"ground": ["O", "G"], "slider": ["G", "B"], "coupler": ["A", "B"],
                  "crank": ["O", "A"]},
        "inputs": [{"link": "slider", "joint": "G", "step": -0.01}],
        "simulation": {"steps": 100},
    }
    mech = build_mechanism(spec)
    length = math.hypot(3.0, math.sqrt(0.75))
    sim = sweep(mech)
    assert sim.completed
    for k, s in enumerate(sim.inputs[:, 0]):
        b = np.array([3.5 + s, 0.0])  # the line's direction (b, −a)/‖·‖ = (1, 0)
        assert np.abs(sim.path("B")[k] - b).max() < 1e-12
        a = circles(np.zeros(2), 1.0, b, length, 1.0)
        assert np.abs(sim.path("A")[k] - a).max() < 1e-9


def test_slotted_link_input_quick_return() -> None:
    """Input link carries a slot line through its pivot C (Eq. 12); the crank pin A of the
    follower crank slides in it: A = slot line ∩ circle(O, 1), branch of the start."""
    spec: dict[str, Any] = {
        "mechanism": {"name": "quick return", "kind": "planar", "ground": "G"},
        "joints": {"C": {"type": "revolute", "at": [0.0, -2.0]},
                   "S": {"type": "prismatic", "line": [1.0, 0.0, 0.0]},
                   "E": {"type": "revolute", "at": [0.0, 3.0]},
                   "O": {"type": "revolute", "at": [0.0, 0.0]},
                   "A": {"type": "revolute", "at": [0.0, 1.0]}},
        "links": {"G": ["C", "O"], "slotted": ["C", "S", "E"], "block": ["A", "S"],
                  "crank": ["O", "A"]},
        "inputs": [{"link": "slotted", "joint": "C", "step": -math.radians(0.5)}],
        "simulation": {"steps": 50},  # the slot meets the crank circle within ±30°
    }
    mech = build_mechanism(spec)
    sim = sweep(mech)
    assert sim.completed
    c = np.array([0.0, -2.0])
    for k, th in enumerate(sim.inputs[:, 0]):
        d = np.array([math.cos(th), math.sin(th)])  # slot direction from C
        # |C + t d| = 1 → t² + 2t (c·d) + |c|² − 1 = 0, far root (the pin starts above O)
        t = -float(c @ d) + math.sqrt(float(c @ d) ** 2 - (float(c @ c) - 1.0))
        assert np.abs(sim.path("A")[k] - (c + t * d)).max() < 1e-9


@pytest.mark.parametrize("tilt_deg", [0.0, 10.0])
def test_scotch_yoke_pp_link(tilt_deg: float) -> None:
    """Yoke = slot line S + guide line G (a PP link), the slot through the crank pin P. A slot
    perpendicular to the guide is held by the cosine form (Eq. 7); a slot at 10° to the guide
    (nearly parallel) by the sine form. Analytic: S passes through P with fixed direction φ."""
    phi = math.radians(tilt_deg) if tilt_deg else math.pi / 2
    theta0 = math.radians(60.0)
    p0 = np.array([math.cos(theta0), math.sin(theta0)])
    normal = np.array([-math.sin(phi), math.cos(phi)])  # slot direction (cos φ, sin φ)
    spec = {
        "mechanism": {"name": "scotch yoke", "kind": "planar", "ground": "ground"},
        "joints": {"O": {"type": "revolute", "at": [0.0, 0.0]},
                   "P": {"type": "revolute", "at": p0.tolist()},
                   "S": {"type": "prismatic",
                         "line": [*normal.tolist(), float(-normal @ p0)]},
                   "G": {"type": "prismatic", "line": [0.0, 1.0, 2.0]}},
        "links": {"ground": ["O", "G"], "crank": ["O", "P"], "block": ["P", "S"],
                  "yoke": ["S", "G"]},
        "inputs": [{"link": "crank", "joint": "O"}],
    }
    mech = build_mechanism(spec)
    kinds = {c.kind for c in mech.constraints}
    assert ("PPsin" in kinds) == bool(tilt_deg) and ("PP" in kinds) != bool(tilt_deg)
    sim = sweep(mech)
    assert sim.completed
    for k, th in enumerate(sim.inputs[:, 0]):
        p = np.array([math.cos(th), math.sin(th)])
        expected = np.array([*normal, -normal @ p])
        got = sim.path("S")[k]
        assert np.abs(got / np.linalg.norm(got[:2]) - expected).max() < 1e-9


def parallelogram(t3: list[float]) -> Any:
    """Double parallelogram: three equal parallel cranks (ground triangle O1 O2 O3, coupler
    triangle T1 T2 T3 = ground + (1, 2)) — over-constrained: 5 equations, 4 unknowns."""
    return build_mechanism({
        "mechanism": {"name": "double parallelogram", "kind": "planar", "ground": "G"},
        "joints": {"O1": {"type": "revolute", "at": [0.0, 0.0]},
                   "O2": {"type": "revolute", "at": [3.0, 0.0]},
                   "O3": {"type": "revolute", "at": [1.5, -1.5]},
                   "T1": {"type": "revolute", "at": [1.0, 2.0]},
                   "T2": {"type": "revolute", "at": [4.0, 2.0]},
                   "T3": {"type": "revolute", "at": t3}},
        "links": {"G": ["O1", "O2", "O3"], "c1": ["O1", "T1"], "c2": ["O2", "T2"],
                  "c3": ["O3", "T3"], "coupler": ["T1", "T2", "T3"]},
        "inputs": [{"link": "c1", "joint": "O1"}],
    })


def test_overconstrained_parallelogram_moves_with_least_squares_steps() -> None:
    """Exact data: Gauss–Newton steps follow the translation T_i = O_i + √5 (cos θ, sin θ)."""
    mech = parallelogram([2.5, 0.5])
    assert mech.system.m == 5 and mech.system.n_u == 4 and mech.overdetermined
    sim = sweep(mech)
    assert sim.completed and np.nanmax(sim.residual) <= 1e-10
    th = sim.inputs[:, 0]
    crank = math.sqrt(5.0) * np.stack((np.cos(th), np.sin(th)), axis=1)
    for name, pivot in (("T2", [3.0, 0.0]), ("T3", [1.5, -1.5])):
        assert np.abs(sim.path(name) - (np.array(pivot) + crank)).max() < 1e-9


def test_explicit_lengths_are_assembled_from_rounded_coordinates() -> None:
    """Stated link lengths with coordinates rounded to 0.01: the loader solves the exact pose
    nearby, records the move, and the motion keeps the stated lengths."""
    spec = fourbar_spec()
    spec["joints"]["J3"]["at"] = [4.01, 3.99]
    spec["links"]["L2"] = ["J2", "J3", "J5"]
    spec["links"]["L3"] = {"joints": ["J3", "J4"], "length": 4.0}
    mech = build_mechanism(spec)
    assert any("assembled" in a for a in mech.adjustments)
    j3 = mech.coords0[mech.index("J3"), :2]
    assert np.hypot(*(j3 - [4.0, 0.0])) == pytest.approx(4.0, abs=1e-10)
    assert np.abs(j3 - [4.01, 3.99]).max() < 0.02
    sim = sweep(mech, steps=30)
    assert sim.completed
    assert np.abs(np.hypot(*(sim.path("J3") - [4.0, 0.0]).T) - 4.0).max() < 1e-9


def test_lengths_that_cannot_close_are_refused() -> None:
    spec = fourbar_spec()
    spec["links"]["L3"] = {"joints": ["J3", "J4"], "length": 20.0}
    with pytest.raises(MechanismError, match="do not assemble"):
        build_mechanism(spec)


def test_simulate_takes_explicit_inputs_and_leads_in() -> None:
    """simulate() from the initial pose to inputs that start elsewhere: the way to the first
    row is solved but not recorded; every row matches the analytic four-bar."""
    from kinematics.nbar import parse_mechanism

    mech = parse_mechanism((MECH / "fourbar_crank_rocker.toml").read_text())
    th = np.linspace(3.0, -2.0, 40)
    sim = simulate(mech, th)
    assert sim.completed and sim.status[0] == Status.OK
    for k, t in enumerate(th):
        assert np.abs(sim.path("J5")[k] - analytic_fourbar(float(t))[1]).max() < 1e-9
