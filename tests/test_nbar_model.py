"""Mechanism files: n-ary link reduction, adjustments of rounded data, and clear refusals."""

from __future__ import annotations

import copy
import itertools
import math
import tomllib
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from kinematics.nbar import MechanismError, build_mechanism, parse_mechanism, sweep

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"


def spec_of(name: str) -> dict[str, Any]:
    return tomllib.loads((MECH / f"{name}.toml").read_text())


def test_nary_planar_link_gives_2k_minus_3_independent_rows() -> None:
    """A pentagonal plate (k = 5) on a crank and a rocker: 7 rows for the plate, rank full."""
    plate = [[0.0, 1.0], [4.0, 4.0], [3.0, 6.0], [1.5, 5.0], [2.5, 3.2]]
    spec = {
        "mechanism": {"name": "plate", "kind": "planar", "ground": "G"},
        "joints": {"O": {"type": "revolute", "at": [0.0, 0.0]},
                   "D": {"type": "revolute", "at": [4.0, 0.0]},
                   **{f"P{i}": {"type": "revolute", "at": p} for i, p in enumerate(plate)}},
        "links": {"G": ["O", "D"], "crank": ["O", "P0"], "rocker": ["P1", "D"],
                  "plate": [f"P{i}" for i in range(5)]},
        "inputs": [{"link": "crank", "joint": "O"}],
    }
    mech = build_mechanism(spec)
    rows = [c for c in mech.constraints if c.link == "plate"]
    assert len(rows) == 2 * 5 - 3
    sim = sweep(mech, steps=60)
    assert sim.completed
    for a, b in itertools.combinations(range(5), 2):
        d = np.linalg.norm(sim.path(f"P{a}") - sim.path(f"P{b}"), axis=1)
        assert np.abs(d - d[0]).max() < 1e-9


def test_line_in_a_ternary_link_is_fixed_by_two_point_distances() -> None:
    """Stephenson-II L2 = {J2, J3 (line), J4}: one RR row and two RP rows (2k − 3 = 3)."""
    mech = parse_mechanism((MECH / "stephenson2.toml").read_text())
    kinds = Counter(c.kind for c in mech.constraints if c.link == "L2")
    assert kinds == {"RR": 1, "RP": 2}
    l5 = Counter(c.kind for c in mech.constraints if c.link == "L5")
    assert l5 == {"RR": 1, "RP": 2}  # J5, J6 keep their distances to the fixed line J7


def test_collinear_ternary_link_is_refused_with_a_reason() -> None:
    spec = spec_of("fourbar_crank_rocker")
    spec["joints"]["J5"]["at"] = [8.0, 7.0]  # on the line J2 (0, 1) – J3 (4, 4)
    with pytest.raises(MechanismError, match=r"L2: joint J\d .*collinear"):
        build_mechanism(spec)


def test_coplanar_spatial_point_is_refused() -> None:
    spec = spec_of("five_ss")
    j6, j7, j8 = (np.array(spec["joints"][k]["at"]) for k in ("J6", "J7", "J8"))
    spec["joints"]["J11"]["at"] = (j6 + 0.3 * (j7 - j6) + 0.4 * (j8 - j6)).tolist()
    for k in ("J9", "J10"):
        spec["joints"][k]["at"] = (j6 + 0.2 * (j7 - j6) + 0.7 * (j8 - j6) + (
            0.1 if k == "J9" else -0.3) * (j7 - j8)).tolist()
    with pytest.raises(MechanismError, match="coplanar"):
        build_mechanism(spec)


def test_spherical_point_far_off_the_sphere_is_refused() -> None:
    spec = spec_of("spherical_rrpr")
    spec["joints"]["J5"]["at"] = [0.5, -0.21, 0.95]
    with pytest.raises(MechanismError, match=r"J5.*not on the unit sphere"):
        build_mechanism(spec)


def test_lines_are_normalised_without_moving_them() -> None:
    mech = parse_mechanism((MECH / "stephenson2.toml").read_text())
    j3 = mech.coords0[mech.index("J3")]
    raw = np.array([-0.17, 0.98, -4.28])
    assert math.hypot(*j3[:2]) == pytest.approx(1.0)
    assert np.allclose(j3, raw / math.hypot(*raw[:2]))


@pytest.mark.parametrize(("edit", "match"), [
    (lambda s: s["mechanism"].update(kind="cylindrical"), "kind"),
    (lambda s: s["mechanism"].update(ground="L9"), "ground"),
    (lambda s: s["joints"]["J2"].update(at=[1.0]), "J2.at"),
    (lambda s: s["joints"]["J2"].update(colour="red"), "unknown key"),
    (lambda s: s["links"].update(L2=["J2", "J9"]), "unknown joint 'J9'"),
    (lambda s: s["links"].pop("L3"), "J4 belong to no link|degree"),
    (lambda s: s["inputs"][0].update(joint="J2"), "must be fixed"),
    (lambda s: s["inputs"][0].update(link="L6"), "moving link"),
    (lambda s: s.update(inputs=[]), "at least one input"),
    (lambda s: s["simulation"].update(steps=0), "steps"),
    (lambda s: s["inputs"][0].update(initial=0.3), "disagrees"),
])
def test_bad_files_are_refused_by_name(edit: Any, match: str) -> None:
    spec = copy.deepcopy(spec_of("stephenson2"))
    edit(spec)
    with pytest.raises(MechanismError, match=match):
        build_mechanism(spec)


def test_missing_link_leaves_a_free_joint() -> None:
    """Without the rocker the four-bar's J3 can move with the crank held: refused, counted."""
    spec = spec_of("fourbar_crank_rocker")
    spec["links"]["L3"] = ["J3"]
    with pytest.raises(MechanismError, match="degree"):
        build_mechanism(spec)


def test_singular_initial_pose_is_refused() -> None:
    """A four-bar drawn at its folded pose (J2, J3, J1 collinear): Jacobian singular."""
    spec = spec_of("fourbar_crank_rocker")
    spec["inputs"] = [{"link": "L3", "joint": "J4"}]
    psi = 2 * math.pi / 3
    j3 = [4 + 4 * math.cos(psi), 4 * math.sin(psi)]
    spec["joints"]["J3"]["at"] = j3
    spec["joints"]["J2"]["at"] = (np.array(j3) * -0.25).tolist()  # crank folded under coupler
    spec["joints"]["J5"]["at"] = [1.0, 2.0]
    with pytest.raises(MechanismError, match="singular"):
        build_mechanism(spec)


def test_spatial_input_must_be_an_actuator_and_actuator_needs_a_step() -> None:
    spec = spec_of("five_ss")
    spec["inputs"] = [{"actuator": ["J1", "J7"]}]
    with pytest.raises(MechanismError, match="explicit step"):
        build_mechanism(spec)
    spec["inputs"] = [{"link": "L1", "joint": "J1"}]
    with pytest.raises(MechanismError, match="actuator"):
        build_mechanism(spec)


def test_not_toml_is_refused() -> None:
    with pytest.raises(MechanismError, match="TOML"):
        parse_mechanism("[mechanism\nkind = planar")


def test_inputs_moving_a_link_apart_are_refused() -> None:
    """A link joining a fixed joint to a joint another input drives cannot stay rigid."""
    spec = spec_of("fivebar_robot")
    spec["links"]["strut"] = ["M1", "R2"]
    with pytest.raises(MechanismError, match=r"strut.*cannot move"):
        build_mechanism(spec)
