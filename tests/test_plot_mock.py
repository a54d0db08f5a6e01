"""`fivebar plot --port` against the mock device: streaming, faults, resume, bad use.

The mock's named machine keeps the physical motor positions and a ledger of every block it
executed across reconnects, so "nothing lost, nothing doubled" is checked on what the motors
did, not on what the host believes.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.job import CompileOptions, compile_job
from fivebar_host.sender import ResumePoint, resume_path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(autouse=True)
def _clean_machines() -> Iterator[None]:
    mock.forget_machines()
    yield
    mock.forget_machines()


@pytest.fixture
def profile_path(tmp_path: Path) -> Path:
    """The default profile with a 1 s reply timeout, so a silent device is found quickly."""
    text = (Path(__file__).resolve().parent.parent / "configs" / "default.toml").read_text()
    p = tmp_path / "quick.toml"
    p.write_text(text.replace("reply_timeout_s = 10.0", "reply_timeout_s = 1.0")
                 .replace("banner_timeout_s = 5.0", "banner_timeout_s = 1.0"))
    return p


@pytest.fixture
def drawing(tmp_path: Path) -> Path:
    """A private copy of the simple example (its resume file lands beside it)."""
    dst = tmp_path / "simple.svg"
    shutil.copy(EXAMPLES / "simple.svg", dst)
    return dst


def run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return res.exit_code, res.output


def planned_draw_steps(path: Path) -> np.ndarray:
    """Sum of |steps| per motor over the job's drawing segments."""
    job = compile_job(path, load_profile(), CompileOptions(validate=False))
    d = np.abs(np.diff(job.steps, axis=0))[job.draw]
    return np.asarray(d.sum(axis=0))


def drawn_steps(m: mock.Machine) -> np.ndarray:
    """Sum of |steps| per motor the machine issued with the laser on."""
    tot = np.zeros(2, dtype=np.int64)
    for e in m.ledger:
        if e.kind == "G1" and e.power > 0:
            tot += np.abs(np.asarray(e.steps))
    return tot


def url(name: str, extra: str = "") -> str:
    return f"fivebar-mock://?machine={name}&speed=20" + (f"&{extra}" if extra else "")


def test_plot_completes_and_draws_exactly_the_plan(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port", url("ok"), "--laser", "--yes")
    assert code == 0, out
    assert "done: " in out
    m = mock.machine("ok")
    assert m.phys == [0, 0]  # jobs end at the homed pose
    assert m.laser == 0
    assert np.array_equal(drawn_steps(m), planned_draw_steps(drawing))
    assert not resume_path(drawing).exists()


def test_pen_plot_never_powers_the_output(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port", url("pen"), "--yes")
    assert code == 0, out
    m = mock.machine("pen")
    assert all(p == 0 for _, p in m.laser_log)
    assert all(e.power == 0 for e in m.ledger)


def test_lost_and_corrupted_bytes_are_absorbed_by_resends(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port",
                    url("noisy", "drop=0.003&corrupt=0.003&seed=3"), "--laser", "--yes")
    assert code == 0, out
    resends = int(out.split(" resends")[0].rsplit(",", 1)[1])
    assert resends > 0
    m = mock.machine("noisy")
    assert np.array_equal(drawn_steps(m), planned_draw_steps(drawing))
    assert m.phys == [0, 0]


@pytest.mark.parametrize(("fault", "word"), [
    ("error_on=60", "refused: error:11"),
    ("stall_after=150", "went silent"),
])
def test_fault_then_resume_completes_exactly(drawing: Path, profile_path: Path, fault: str,
                                             word: str) -> None:
    code, out = run("plot", str(drawing), "--port", url("f", fault), "--laser", "--yes",
                    "--config", str(profile_path))
    assert code == 3, out
    assert word in out
    assert "resume file" in out
    m = mock.machine("f")
    assert m.laser == 0
    rp = ResumePoint.load(resume_path(drawing))
    if rp.position is not None:
        assert f"A = {rp.position[0]}, B = {rp.position[1]}" in out
    else:  # the device hung: position unknown; the arms are put home by hand
        assert "position unknown" in out
    assert 0 < rp.next_segment < rp.segments
    if rp.position is None:
        m.phys = [0, 0]
    code, out = run("plot", str(drawing), "--port", url("f"), "--laser", "--yes", "--resume",
                    "--config", str(profile_path))
    assert code == 0, out
    assert m.phys == [0, 0]
    assert m.laser == 0
    drawn = drawn_steps(m)
    plan = planned_draw_steps(drawing)
    if rp.position is not None:
        assert np.array_equal(drawn, plan)  # nothing lost, nothing doubled
    else:
        assert np.all(drawn >= plan)  # nothing lost
    assert not resume_path(drawing).exists()


def test_disconnect_mid_job_reports_and_resumes(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port", url("d", "disconnect_after=70"),
                    "--laser", "--yes")
    assert code == 3, out
    assert "device gone" in out and "resume file" in out
    rp = ResumePoint.load(resume_path(drawing))
    assert rp.position is None and rp.next_segment > 0
    m = mock.machine("d")
    # The cut-off firmware runs out its queue; the user waits for the arms to stop.
    deadline = time.monotonic() + 10.0
    while m.port is not None and m.port.snapshot().state == "Run":
        assert time.monotonic() < deadline
        time.sleep(0.02)
    assert m.laser == 0  # the queue ran empty: laser off without the host
    m.phys = [0, 0]  # the user puts the arms at the home pose
    code, out = run("plot", str(drawing), "--port", url("d"), "--laser", "--yes", "--resume")
    assert code == 0, out
    assert np.all(drawn_steps(m) >= planned_draw_steps(drawing))
    assert m.phys == [0, 0] and m.laser == 0


def test_reset_mid_job_says_position_unknown(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port", url("r", "reset_after=90"), "--laser",
                    "--yes")
    assert code == 3, out
    assert "restarted" in out and "position unknown" in out
    m = mock.machine("r")
    assert m.laser == 0
    m.phys = [0, 0]
    code, out = run("plot", str(drawing), "--port", url("r"), "--laser", "--yes", "--resume")
    assert code == 0, out
    assert np.all(drawn_steps(m) >= planned_draw_steps(drawing))


def test_resume_of_another_job_is_refused(drawing: Path) -> None:
    code, _ = run("plot", str(drawing), "--port", url("x", "error_on=40"), "--laser", "--yes")
    assert code == 3
    code, out = run("plot", str(drawing), "--port", url("x"), "--laser", "--yes", "--resume",
                    "--scale", "0.5")
    assert code == 3 and "different job" in out


def test_resume_without_file(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port", url("y"), "--yes", "--resume")
    assert code == 3 and "no resume file" in out


def test_no_confirmation_without_terminal(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port", url("z"))
    assert code == 3 and "position unknown" in out
    assert mock.machine("z").ledger == []  # nothing moved


@pytest.mark.parametrize(("port", "message"), [
    ("/dev/ttyDOES-NOT-EXIST", "cannot open the port"),
    ("loop://", "no fivebar firmware banner"),
    ("fivebar-mock://?proto=9", "speaks protocol 9"),
    ("fivebar-mock://?bogus=1", "bogus"),
])
def test_bad_ports(drawing: Path, profile_path: Path, port: str, message: str) -> None:
    code, out = run("plot", str(drawing), "--port", port, "--yes", "--config", str(profile_path))
    assert code == 3, out
    assert message in out


def test_busy_port(drawing: Path) -> None:
    import serial

    from fivebar_host.devices import urls

    urls.register()
    first = serial.serial_for_url(url("busy"), timeout=0.1)
    try:
        code, out = run("plot", str(drawing), "--port", url("busy"), "--yes")
    finally:
        first.close()
    assert code == 3 and "busy" in out.lower()


def test_frame_jog_home(drawing: Path) -> None:
    code, out = run("home", "--port", url("h"), "--yes")
    assert code == 0, out
    code, out = run("frame", str(drawing), "--port", url("h"), "--yes")
    assert code == 0, out
    m = mock.machine("h")
    assert m.phys == [0, 0] and all(e.power == 0 for e in m.ledger)
    assert len(m.ledger) > 20
    code, out = run("jog", "--port", url("h"), "--yes", "--motor", "A", "--steps", "200")
    assert code == 0, out
    assert m.phys == [200, 0]
    code, out = run("jog", "--port", url("h"), "--yes", "--dx", "500")
    assert code == 3 and "out of reach" in out
    assert m.phys == [200, 0]  # refused: nothing moved
