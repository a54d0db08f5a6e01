"""Backlash on the host's own moves (issue 38): the travel back to a resume point and a jog
end with each motor's slack taken up the way the next move needs (run/moves.py
`slack_travel`), so a resumed drawing on a true machine with 8 steps of slack per motor
is drawn within the bound, whatever state the slack was left in by the fault.

The true machine is Eq. B1 (`compile.backlash.play`) driven through every move of the
program `build_program` makes for the resume; the pen points of its joints are measured
against the drawing by the executed-path report (`executed_path`) on the joints' steps."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_backlash import LASH, SQUARE, _profile

from fivebar_host.compile import CompileOptions, Job, compile_job
from fivebar_host.compile.backlash import play
from fivebar_host.config import Profile
from fivebar_host.program import Kind, Program
from fivebar_host.report.text.executed import executed_path
from fivebar_host.run import moves


def _joints_after(prog: Program, pos: np.ndarray, start_slack: tuple[int, int]
                  ) -> np.ndarray:
    """The true machine's joint steps after every move of `prog` from counts `pos`."""
    mv = prog.kind == Kind.MOVE
    track = np.concatenate((pos[None, :], np.stack((prog.a[mv], prog.b[mv]), axis=1)))
    return play(track, (LASH, LASH), start_slack)


def _drawn_deviation(job: Job, prof: Profile, k: int, joints: np.ndarray) -> tuple[float, int]:
    """Max deviation of the drawing segments from k on (the report on the joints' steps)."""
    jj = dataclasses.replace(job, steps=job.joint_steps, slack=job.slack[:0])
    flat = dataclasses.replace(prof, motors=dataclasses.replace(prof.motors,
                                                                backlash_steps=(0, 0)))
    ex = executed_path(jj, flat, np.arange(joints.shape[0], dtype=np.float64), joints, k,
                       tuple(int(v) for v in joints[0]))
    return ex.max_deviation_mm, ex.segments_completed


def _resume_segment(job: Job) -> int:
    """A drawing segment mid-job whose slack the travel from home would leave wrong: a motor
    that travels down into it while the job has it taken up upward (or the other way)."""
    js = job.steps
    for k in range(job.n_segments // 3, job.n_segments):
        wrong = (js[k] < 0) & (job.slack[k] > 0) | (js[k] > 0) & (job.slack[k] == 0)
        if job.draw[k] and wrong.any() and np.any(js[k] != js[k + 1]):
            return k
    raise AssertionError("no such segment")


@pytest.mark.parametrize("start_slack", [(0, 0), (LASH, LASH), (LASH, 0)])
def test_resume_travel_takes_the_slack_up(start_slack: tuple[int, int]) -> None:
    prof = _profile(LASH)
    job = compile_job(SQUARE, prof, CompileOptions())
    k = _resume_segment(job)
    home = np.zeros(2, dtype=np.int64)  # re-homed after the fault; slack left anyhow
    prog = moves.build_program(job, prof, False, k, home)
    joints = _joints_after(prog, home, start_slack)
    assert (joints == job.joint_steps[k]).all(axis=1).any()  # the joint reaches the point
    dev, done = _drawn_deviation(job, prof, k, joints)
    assert done == job.n_segments
    assert dev <= job.tolerance_mm + job.step_quantum_mm, dev


def _target_offsets(job: Job, prof: Profile, prog: Program, pos: np.ndarray,
                    joints: np.ndarray, k: int) -> np.ndarray:
    """Pen offset (mm) of the true joints from the planned joints at every target of the
    job from k on, where the program's counts reach that target (in order)."""
    mv = prog.kind == Kind.MOVE
    counts = np.concatenate((pos[None, :], np.stack((prog.a[mv], prog.b[mv]), axis=1)))
    r, got, want = k, [], []
    for i in range(counts.shape[0]):
        while r <= job.n_segments and (counts[i] == job.steps[r]).all():
            got.append(joints[i])
            want.append(job.joint_steps[r])
            r += 1
    assert r == job.n_segments + 1  # every target reached, in order
    rps = 2 * np.pi / job.steps_per_rev
    f = [prof.geometry.forward_batch(np.asarray(job.home_rad) + np.array(x) * rps, "+").points
         for x in (got, want)]
    return np.asarray(np.hypot(*(f[0] - f[1]).T))


def test_without_the_take_up_the_resumed_drawing_is_off(monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    """The same resume with a plain travel back (the code before this fix): the joints
    arrive a motor's slack off the resume point and draw off until that motor reverses."""
    prof = _profile(LASH)
    job = compile_job(SQUARE, prof, CompileOptions())
    k = _resume_segment(job)
    home = np.zeros(2, dtype=np.int64)
    bound = job.tolerance_mm + job.step_quantum_mm
    fixed = moves.build_program(job, prof, False, k, home)
    off = _target_offsets(job, prof, fixed, home, _joints_after(fixed, home, (0, 0)), k)
    assert off.max() == 0.0  # with the take-up: every target exactly where planned
    monkeypatch.setattr(moves, "slack_travel",
                        lambda p, asm, s, e, _slack, what: moves.travel(p, asm, s, e, what))
    plain = moves.build_program(job, prof, False, k, home)
    off = _target_offsets(job, prof, plain, home, _joints_after(plain, home, (0, 0)), k)
    assert off[0] > bound and off.max() > 2 * bound, (off[0], off.max(), bound)


def test_jog_ends_with_the_slack_taken_down() -> None:
    prof = _profile(LASH)
    pos = np.array([0, 0], dtype=np.int64)
    for start_slack in ((0, 0), (LASH, LASH)):
        for motor, steps in (("A", 40), ("A", -40), ("B", 40)):
            prog = moves.jog_program(prof, 1, "+-", pos.tolist(), motor=motor, steps=steps)
            joints = _joints_after(prog, pos, start_slack)
            want = pos.copy()
            want["AB".index(motor)] += steps
            mv = prog.kind == Kind.MOVE
            end = np.array([prog.a[mv][-1], prog.b[mv][-1]])
            assert (end == want).all()  # the counts end on the jog's target …
            assert (joints[-1] == want).all()  # … and so does the joint: slack taken down
