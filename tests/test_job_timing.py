"""Timing of whole compiled jobs, from rest to rest, measured on what the firmware receives:
each `G1 A B P` runs at a constant step rate for P µs (docs/protocol.md 6.1), so the joint
velocity is a staircase ω_k = Δθ_k / P_k. Every step of it — out of standstill at the start,
into standstill at the end, at every pen switch and between any two segments — must stay
within the junction jump, and the pen's path speed within what `max_joint_rad_s2` allows
between the junctions' caps (compile.staircase module doc, checked by
tests/staircase_reference.py); speeds within `max_joint_rad_s` and the feeds."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from staircase_reference import staircase_reference

from fivebar_host import protocol
from fivebar_host.compile import CompileOptions, compile_job, encode_lines
from fivebar_host.compile.planner import JUNCTION_JUMP_RAD_S
from fivebar_host.config import load_profile

ROOT = Path(__file__).resolve().parent.parent
PROF = load_profile()
UNDERSIDE = load_profile(ROOT / "configs" / "underside.toml")
CASES = [
    ("fivebar_text.svg", PROF, CompileOptions(), False),
    ("simple.svg", PROF, CompileOptions(tolerance_mm=0.2), False),
    ("mode_change.gcode", PROF, CompileOptions(origin_mm=(0.0, 0.0), mode="auto"), False),
    ("underside_machine_coords.gcode", UNDERSIDE,
     CompileOptions(origin_mm=(0.0, 0.0), mode="++"), True),
]


def _staircase(lines: list[str], steps_per_rev: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From firmware lines (absolute G90): per segment the joint velocity (rad/s) and the
    duration (s), and after which segments the tool switches (M3/M5, or a new power S)."""
    pos = np.zeros(2)
    w, t, switch = [], [], []
    power = None
    for ln in lines:
        if ln.startswith(("M3", "M4", "M5")) and t:
            switch[-1] = True
        if not ln.startswith("G1 "):
            continue
        words = {x[0]: int(x[1:]) for x in ln.split()[1:]}
        new = np.array([words["A"], words["B"]], dtype=float)
        if power is not None and words["S"] != power and t:
            switch[-1] = True
        power = words["S"]
        dt = words["P"] * 1e-6
        w.append((new - pos) * (2 * math.pi / steps_per_rev) / dt)
        t.append(dt)
        switch.append(False)
        pos = new
    return np.array(w), np.array(t), np.array(switch)


@pytest.mark.parametrize(("name", "prof", "opts", "laser"), CASES,
                         ids=[c[0] for c in CASES])
def test_joint_speed_and_acceleration_limits_from_rest_to_rest(name: str, prof, opts,  # type: ignore[no-untyped-def]
                                                                laser: bool) -> None:
    job = compile_job(ROOT / "examples" / name, prof, opts)
    w, t, switch = _staircase(encode_lines(job, prof, laser=laser), prof.motors.steps_per_rev)
    assert w.shape[0] == job.n_segments
    jump, alpha = JUNCTION_JUMP_RAD_S, prof.motion.max_joint_rad_s2
    slack = 1 + 1e-9
    assert switch[:-1].sum() >= 2  # the jobs do switch the tool
    # the jump at every boundary and out of and into standstill (job start and end, both
    # sides of every tool switch); the path speed's acceleration between the junctions' caps
    worst_jump, worst_acc = staircase_reference(w * t[:, None], t * 1e6, switch, alpha, jump,
                                                job.length_mm)
    assert worst_jump <= slack and worst_acc <= 1 + 1e-6
    # speeds, feeds, and the firmware's shortest segment
    assert np.abs(w).max() <= prof.motion.max_joint_rad_s * slack
    feed = np.where(job.draw, prof.motion.draw_feed_mm_s, prof.motion.travel_feed_mm_s)
    if name.endswith(".svg"):  # SVG has no F words: the profile's feeds apply
        assert (job.length_mm / t / feed).max() <= slack
    assert (job.duration_us >= protocol.P_MIN_US).all()
    # still within tolerance + one step quantum (cutting ramps into pieces moves nothing)
    assert job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm


def test_first_segment_no_longer_jumps_from_standstill() -> None:
    """The defect this timing fixes: the first segment started at ~1.2 rad/s from rest."""
    job = compile_job(ROOT / "examples" / "fivebar_text.svg", PROF)
    th = np.diff(job.steps[:2], axis=0)[0] * (2 * math.pi / job.steps_per_rev)
    w0 = np.abs(th).max() / (job.duration_us[0] * 1e-6)
    assert w0 <= JUNCTION_JUMP_RAD_S
    # and the ramp is really used: the job reaches well above the jump later on
    w = np.abs(np.diff(job.steps, axis=0)).max(axis=1) * (2 * math.pi / job.steps_per_rev)
    assert (w / (job.duration_us * 1e-6)).max() > 3 * JUNCTION_JUMP_RAD_S
