"""Backlash on the host's own moves (issue 38): the travel back to a resume point and a jog
end with each motor's slack taken up the way the next move needs (run/moves.py
`slack_travel`), so a resumed drawing on a true machine with 8 steps of slack per motor
is drawn within the bound, whatever state the slack was left in by the fault.

The true machine is Eq. B1 (`compile.backlash.play`) driven through every move of the
program `build_program` makes for the resume; the pen points of its joints are measured
against the drawing by the executed-path report (`executed_path`) on the joints' steps."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_backlash import LASH, SQUARE, _profile

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, Job, compile_job
from fivebar_host.compile.backlash import play
from fivebar_host.config import Profile, load_profile
from fivebar_host.devices import mock
from fivebar_host.program import Kind, Program
from fivebar_host.report.text.executed import executed_path, ledger_track
from fivebar_host.run import moves
from fivebar_host.run.resume import ResumePoint, resume_path


def _joints_after(prog: Program, pos: np.ndarray, start_slack: tuple[int, int]
                  ) -> np.ndarray:
    """The true machine's joint steps after every move of `prog` from counts `pos`."""
    return play(_counts(prog, pos), (LASH, LASH), start_slack)


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


def _counts(prog: Program, pos: np.ndarray) -> np.ndarray:
    """The motor counts (E, 2) a program passes through from `pos`: `pos`, then its moves."""
    mv = prog.kind == Kind.MOVE
    return np.concatenate((pos[None, :], np.stack((prog.a[mv], prog.b[mv]), axis=1)))


def _target_offsets(job: Job, prof: Profile, counts: np.ndarray, joints: np.ndarray, k: int
                    ) -> np.ndarray:
    """Pen offset (mm) of the true joints from the planned joints at every target of the
    job from k on, where the motor counts reach that target (in order)."""
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
    off = _target_offsets(job, prof, _counts(fixed, home), _joints_after(fixed, home, (0, 0)),
                          k)
    assert off.max() == 0.0  # with the take-up: every target exactly where planned
    monkeypatch.setattr(moves, "slack_travel",
                        lambda p, asm, s, e, _slack, what: moves.travel(p, asm, s, e, what))
    plain = moves.build_program(job, prof, False, k, home)
    off = _target_offsets(job, prof, _counts(plain, home), _joints_after(plain, home, (0, 0)),
                          k)
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


def _fault_and_resume(tmp_path: Path, name: str) -> tuple[Job, Profile, int, np.ndarray]:
    """examples/square.gcode plotted on a mock machine with 8 steps of real slack a motor,
    its power cut mid-job, the arms put back at the home pose by hand, `fivebar home`, then
    `plot --resume`: the job, the profile, the segment the resume started at and the motor
    counts of the resumed run (the mock's ledger after the homing)."""
    cfg = tmp_path / "lash.toml"
    cfg.write_text(f"[motors]\nbacklash_steps = [{LASH}, {LASH}]\n")
    drawing = tmp_path / "square.gcode"
    shutil.copy(SQUARE, drawing)
    url = f"fivebar-mock://?machine={name}&speed=20&backlash={LASH},{LASH}"
    run = CliRunner().invoke
    res = run(main, ["plot", str(drawing), "--config", str(cfg), "--port",
                     f"{url}&power_cut_after=12", "--yes"], catch_exceptions=False)
    assert res.exit_code == 3 and "the firmware restarted" in res.output, res.output
    k = ResumePoint.load(resume_path(drawing)).next_segment
    m = mock.machine(name)
    m.phys = [0, 0]  # the person puts the arms at the home pose ...
    res = run(main, ["home", "--config", str(cfg), "--port", url, "--yes"])
    assert res.exit_code == 0, res.output  # ... and says so
    n0 = len(m.ledger)
    res = run(main, ["plot", str(drawing), "--config", str(cfg), "--port", url, "--yes",
                     "--resume"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    prof = load_profile(cfg)
    job = compile_job(drawing, prof, CompileOptions())
    _, counts = ledger_track(m.ledger[n0:])
    assert (counts[0] == 0).all() and 0 < k < job.n_segments
    return job, prof, k, counts


@pytest.mark.parametrize("start_slack", [(0, 0), (LASH, LASH)])
def test_fault_and_resume_on_a_machine_with_backlash(tmp_path: Path,
                                                     start_slack: tuple[int, int]) -> None:
    """The whole resume on the mock: the resumed drawing within tolerance + step quantum,
    whichever way the slack was left when the arms were put back by hand."""
    mock.forget_machines()
    job, prof, k, counts = _fault_and_resume(tmp_path, "lashres")
    joints = play(counts, (LASH, LASH), start_slack)
    dev, done = _drawn_deviation(job, prof, k, joints)
    assert done == job.n_segments
    assert 0.0 < dev <= job.tolerance_mm + job.step_quantum_mm, dev
    assert _target_offsets(job, prof, counts, joints, k).max() == 0.0
    mock.forget_machines()


def test_fault_and_resume_without_the_take_up_is_off(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The same resume with the travel back of before (no take-up): over the bound."""
    monkeypatch.setattr(moves, "slack_travel",
                        lambda p, asm, s, e, _slack, what: moves.travel(p, asm, s, e, what))
    mock.forget_machines()
    job, prof, k, counts = _fault_and_resume(tmp_path, "lashres0")
    off = _target_offsets(job, prof, counts, play(counts, (LASH, LASH), (0, 0)), k)
    assert off.max() > 2 * (job.tolerance_mm + job.step_quantum_mm), off.max()
    mock.forget_machines()
