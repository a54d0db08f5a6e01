"""The planned job against its continuous profile at sharp junctions (issue 39): a zigzag's
every corner reverses a joint, and the staircase the firmware runs (one constant rate per
segment) lost half the time there — the segment after a reversal ran at a few per cent of
its speed.  The reference is the continuous time-optimal profile under the same limits
(`planner.plan` at the profile's whole acceleration on the job's own segments;
`benchmarks/topp.py` checks it against TOPP-RA: within 0.1 % on these drawings)."""

from __future__ import annotations

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, compile_drawing, planner
from fivebar_host.compile import steps as stepsmod
from fivebar_host.config import load_profile
from fivebar_host.toolpath.svg import read_svg


def _ratio(points: str) -> float:
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="30mm" height="30mm" '
           f'viewBox="0 0 30 30"><polyline fill="none" stroke="black" points="{points}"/>'
           "</svg>").encode()
    prof = load_profile()
    m = prof.motion
    job = compile_drawing(read_svg(svg), prof, CompileOptions(validate=False))
    th = stepsmod.step_angles(job.steps, prof.motors.home_rad, prof.motors.steps_per_rev)
    dq = np.diff(th, axis=0)
    seg = np.flatnonzero((np.abs(dq).max(axis=1) > 0) & job.draw)
    cont = planner.plan(dq[seg], np.maximum(job.length_mm[seg], 1e-6),
                        np.full(seg.size, m.draw_feed_mm_s), m.max_joint_rad_s,
                        m.max_joint_rad_s2, junction_jump_rad_s=m.junction_jump_rad_s)
    return float(job.duration_us[seg].sum()) * 1e-6 / float(cont.duration_s.sum())


@pytest.mark.parametrize(("points", "bound"), [
    # 3 mm teeth at 0.4 mm: 1.99 before, 1.10 with the sharp pieces, 1.011 with pieces of
    # 2 steps (compile.timing.PLAN_MIN_PIECE_STEPS)
    (" ".join(f"{5 + k * 0.4:.2f},{10 + (3 if k % 2 else 0)}" for k in range(40)), 1.03),
    # a five-pointed star: 1.077 before, 1.014, now 1.007
    (" ".join(f"{15 + 10 * np.cos(k * 2.51327):.3f},{15 + 10 * np.sin(k * 2.51327):.3f}"
              for k in range(11)), 1.03),
    # a comb of 0.3 mm teeth: 1.013 before, 1.010, now 1.0096 (too short to cut: GROW_ROOM)
    (" ".join(f"{5 + k * 0.5:.2f},{10 + (0.3 if k % 2 else 0)}" for k in range(40)), 1.03),
])
def test_sharp_corners_near_the_continuous_profile(points: str, bound: float) -> None:
    assert _ratio(points) <= bound
