"""Backlash: the slack model (compile.backlash.play), the take-up segments the compiler
inserts at reversals, and a true machine with 8 steps of slack per motor on the mock drawing
the square and the circle (the pattern of UGS's backlash work, examples/square.gcode) within
the bound with compensation and beyond it without."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, Job, compile_job
from fivebar_host.compile.backlash import play
from fivebar_host.config import ConfigError, Profile, load_profile, merged_document, parse_profile
from fivebar_host.devices import mock
from fivebar_host.devices.mock.options import parse_mock_url
from fivebar_host.report.text.executed import executed_path, ledger_track

ROOT = Path(__file__).resolve().parent.parent
SQUARE = ROOT / "examples" / "square.gcode"
LASH = 8


@pytest.fixture(autouse=True)
def _clean_machines() -> Iterator[None]:
    mock.forget_machines()
    yield
    mock.forget_machines()


def _profile(lash: int) -> Profile:
    prof = load_profile(None)
    return dataclasses.replace(prof, motors=dataclasses.replace(
        prof.motors, backlash_steps=(lash, lash)))


def test_play_follows_the_motor_after_the_slack() -> None:
    """One motor, B = 3, from j = m = 0: up 5 (the first 3 are slack), down 2 (slack), down
    4 (1 of slack left, then 3 of motion), up 1 (slack)."""
    m = np.array([[0, 0], [5, 0], [3, 0], [-1, 0], [0, 0]])
    j = play(m, (3, 0))
    assert j[:, 0].tolist() == [0, 2, 2, -1, -1]
    assert (j[:, 1] == 0).all()
    # started with the slack taken up upward (m − j = 3): going up moves the joint at once
    assert play(m, (3, 0), (3, 0))[:, 0].tolist() == [-3, 2, 2, -1, -1]


def test_take_up_segments_hold_the_joint_and_move_only_the_reversing_motor() -> None:
    job = compile_job(SQUARE, _profile(LASH), CompileOptions())
    plain = compile_job(SQUARE, _profile(0), CompileOptions())
    assert job.slack.shape == job.steps.shape and not plain.slack.shape[0]
    # The model of the machine driven by the counts puts every joint where the job says.
    assert (play(job.steps, (LASH, LASH)) == job.joint_steps).all()
    joint_moves = np.diff(job.joint_steps, axis=0)
    motor_moves = np.diff(job.steps.astype(np.int64), axis=0)
    take = (joint_moves == 0).all(axis=1) & (motor_moves != 0).any(axis=1)
    assert take.sum() >= 4  # a square and a circle reverse each motor several times
    # Pieces of one take-up add up to ±B per motor; between take-ups the slack is B or 0.
    assert job.slack.min() >= 0 and job.slack.max() <= LASH
    assert set(np.unique(job.slack[1:][~take]).tolist()) <= {0, LASH}
    # The job ends with the slack taken up downward, as the next one assumes at home.
    assert (job.slack[-1] == 0).all() and (job.steps[-1] == job.joint_steps[-1]).all()
    assert np.abs(motor_moves[take]).max() <= LASH
    # A take-up keeps the pen's state: drawing take-ups stay drawing (no pen lift); a laser
    # is at power 0 while it stands still there.
    assert job.pen_downs == plain.pen_downs
    assert job.draw[take].any() and (job.power[take] == 0).all()
    assert (job.power[job.draw & ~take] > 0).all()
    assert job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
    # The take-ups cost little time (8 steps each at the joint limits).
    assert float(job.duration_us[take].sum()) * 1e-6 < 0.05 * plain.total_time_s


def _executed_deviation(tmp_path: Path, compensate: bool) -> tuple[float, Job]:
    """Plot the square and the circle on a mock machine with 8 steps of real slack per motor
    and measure where it drew (executed-path report)."""
    cfg = tmp_path / "lash.toml"
    cfg.write_text(f"[motors]\nbacklash_steps = [{LASH if compensate else 0}, "
                   f"{LASH if compensate else 0}]\n")
    url = f"fivebar-mock://?machine=lash{int(compensate)}&speed=0&backlash={LASH},{LASH}"
    res = CliRunner().invoke(main, ["plot", str(SQUARE), "--config", str(cfg), "--port", url,
                                    "--yes"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    prof = load_profile(cfg)
    job = compile_job(SQUARE, prof, CompileOptions())
    m = mock.machine(f"lash{int(compensate)}")
    t, track = ledger_track(m.ledger)
    ex = executed_path(job, prof, t, track, backlash=m.backlash)
    assert ex.segments_completed == job.n_segments
    return ex.max_deviation_mm, job


def test_true_backlash_drawn_within_the_bound_only_with_compensation(tmp_path: Path) -> None:
    with_comp, job = _executed_deviation(tmp_path, True)
    without, _ = _executed_deviation(tmp_path, False)
    bound = job.tolerance_mm + job.step_quantum_mm
    assert with_comp <= bound
    # 8 steps of 12800 per turn on 60 mm arms move the pen by some 0.2 mm: well over.
    assert without > 2 * bound


def test_backlash_options_are_checked() -> None:
    assert parse_mock_url("fivebar-mock://?backlash=8,3").backlash == (8, 3)
    with pytest.raises(ValueError, match="backlash"):
        parse_mock_url("fivebar-mock://?backlash=8")
    doc, _ = merged_document(None)
    doc["motors"]["backlash_steps"] = [2.5, 0]
    with pytest.raises(ConfigError, match="whole steps"):
        parse_profile(doc, "x.toml")
    doc["motors"]["backlash_steps"] = [-1, 0]
    with pytest.raises(ConfigError, match="backlash_steps"):
        parse_profile(doc, "x.toml")


def test_the_grbl_bridge_takes_up_slack_too() -> None:
    """The bridge's online compiler (GRBL senders' streams): a square drawn move by move gets
    take-ups at its reversals, and every batch ends with the slack taken up downward, so its
    counts are the joints' steps where the next batch starts."""
    from fivebar_host.compile.incremental import OnlineCompiler

    prof = _profile(LASH)
    oc = OnlineCompiler(prof, "+-", 0.05, laser=True)
    th0 = oc.angles_of_steps(0, 0)
    start = oc.point_of(th0)
    assert start is not None
    x, y = start
    corners = [(x + 10, y - 10), (x + 10, y - 30), (x - 10, y - 30), (x - 10, y - 10),
               (x + 10, y - 10)]
    moves, th, pt = [], th0, start
    for c in corners:
        m = oc.solve(th, pt, [c], rapid=False, draw=True, feed_mm_s=20.0, power=200,
                     dynamic=False, arc=False)
        assert m is not None
        moves.append(m)
        th, pt = m.th[-1], (float(m.pts[-1, 0]), float(m.pts[-1, 1]))
    batch = oc.plan(th0, start, moves)
    prog = batch.program
    counts = np.concatenate(([[0, 0]], prog.positions((0, 0))[prog.is_motion]))
    joint = play(counts, (LASH, LASH))
    # The batch ends with the slack taken down: the counts are the joints' steps there.
    assert batch.end_steps == tuple(joint[-1].tolist()) == tuple(counts[-1].tolist())
    take = (np.diff(joint, axis=0) == 0).all(axis=1) & (np.diff(counts, axis=0) != 0).any(axis=1)
    assert take.sum() >= 2
