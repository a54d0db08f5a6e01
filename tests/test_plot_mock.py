"""`fivebar plot --port` against the mock device: streaming, faults, resume, bad use.

The mock's named machine keeps the physical motor positions and a ledger of every block it
executed across reconnects, so "nothing lost, nothing doubled" is checked on what the motors
did, not on what the host believes.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host import wire
from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, Job, compile_job
from fivebar_host.config import load_profile
from fivebar_host.controllers.fivebar.kept import kept_resume_segment
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices import mock
from fivebar_host.program import Program
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import SendError
from fivebar_host.run.moves import build_program
from fivebar_host.run.resume import ResumePoint, resume_path

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(autouse=True)
def _clean_machines(clean_mock: None) -> None:
    """Every test here starts and ends with no named mock machine left over."""


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


def planned_steps(path: Path) -> np.ndarray:
    """Sum of |steps| per motor over all the job's segments, travel included."""
    job = compile_job(path, load_profile(), CompileOptions(validate=False))
    return np.asarray(np.abs(np.diff(job.steps, axis=0)).sum(axis=0))


def all_steps(m: mock.Machine) -> np.ndarray:
    """Sum of |steps| per motor the machine issued, laser on or off."""
    tot = np.zeros(2, dtype=np.int64)
    for e in m.ledger:
        if e.kind == "G1":
            tot += np.abs(np.asarray(e.steps))
    return tot


def drawn_steps(m: mock.Machine) -> np.ndarray:
    """Sum of |steps| per motor the machine issued with the laser on."""
    tot = np.zeros(2, dtype=np.int64)
    for e in m.ledger:
        if e.kind == "G1" and e.power > 0:
            tot += np.abs(np.asarray(e.steps))
    return tot


def url(name: str, extra: str = "", speed: float = 20) -> str:
    return f"fivebar-mock://?machine={name}&speed={speed:g}" + (f"&{extra}" if extra else "")


def test_plot_completes_and_draws_exactly_the_plan(drawing: Path) -> None:
    code, out = run("plot", str(drawing), "--port", url("ok"), "--laser", "--yes")
    assert code == 0, out
    assert "done: " in out
    m = mock.machine("ok")
    assert m.phys == [0, 0]  # jobs end at the homed pose
    assert m.laser == 0
    assert np.array_equal(drawn_steps(m), planned_draw_steps(drawing))
    assert not resume_path(drawing).exists()
    # Reopening resets the controller, which keeps its position: no question this time.
    code, out = run("plot", str(drawing), "--port", url("ok"), "--laser")
    assert code == 0, out
    assert "home pose" not in out
    m.power_cut()  # a power-on forgets it: asked again (no terminal: refused)
    code, out = run("plot", str(drawing), "--port", url("ok"), "--laser")
    assert code == 3 and "position unknown" in out


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


def wait_stopped(m: mock.Machine) -> None:
    """Wait until a controller cut off from its host has run out its queue."""
    deadline = time.monotonic() + 10.0
    while m.port is not None and m.port.snapshot().state == "Run":
        assert time.monotonic() < deadline
        time.sleep(0.02)


def resume_and_check(drawing: Path, m: mock.Machine, name: str, profile: Path | None = None
                     ) -> str:
    """`plot --resume` to its end: exit 0, machine home, laser off, resume file gone."""
    extra = ["--config", str(profile)] if profile is not None else []
    code, out = run("plot", str(drawing), "--port", url(name), "--laser", "--yes", "--resume",
                    *extra)
    assert code == 0, out
    assert m.phys == [0, 0] and m.laser == 0
    assert not resume_path(drawing).exists()
    return out


# The faults count wire lines: the job here is about 270 segments in about 90 lines (G6 packing,
# docs/protocol.md 6.3), so line 50 is mid-job; each test asserts the fault fired mid-job.
@pytest.mark.parametrize(("fault", "word"), [
    ("error_on=15", "refused: error:11"),
    ("stall_after=12&watchdog=0", "went silent"),  # no watchdog: the reply timeout
    ("stall_after=12", "the firmware restarted"),  # the watchdog reset it (protocol 9)
    ("reset_after=18", "the firmware restarted"),
])
def test_fault_then_resume_completes_exactly(drawing: Path, quick_profile: Path, fault: str,
                                             word: str) -> None:
    """The position is read after the fault: at once when the controller answers, from the
    record it kept across its restart after a reset or a stall (reset by its watchdog, or
    rebooted through DTR when it has none)."""
    code, out = run("plot", str(drawing), "--port", url("f", fault), "--laser", "--yes",
                    "--config", str(quick_profile))
    assert code == 3, out
    assert word in out and "resume file" in out
    m = mock.machine("f")
    assert m.laser == 0
    rp = ResumePoint.load(resume_path(drawing))
    assert rp.position is not None and not rp.has_stream
    assert f"stopped at A = {rp.position[0]}, B = {rp.position[1]} steps" in out
    if fault.startswith(("stall", "reset")):
        assert "kept its position and its last executed line" in out
    if "watchdog=0" in fault:
        assert "rebooted through DTR: laser off" in out
    assert 0 < rp.next_segment < rp.segments
    resume_and_check(drawing, m, "f", quick_profile)
    assert np.array_equal(drawn_steps(m), planned_draw_steps(drawing))  # nothing lost/doubled
    assert np.array_equal(all_steps(m), planned_steps(drawing))  # no travel back either


@pytest.mark.parametrize("wait", [True, False])
def test_disconnect_then_resume_reads_the_kept_record(drawing: Path, wait: bool) -> None:
    """The link breaks: the position is not known yet. Reopening the port resets the
    controller, which keeps its position and last executed line; --resume maps them back to
    the exact segment — after the queue ran out, or mid-segment when the reopen cut it."""
    # At real speed the queue still runs when the resume reopens the port at once.
    code, out = run("plot", str(drawing), "--port",
                    url("d", "disconnect_after=18", speed=20 if wait else 1), "--laser",
                    "--yes")
    assert code == 3, out
    assert "device gone" in out and "resume file" in out
    assert "position not known yet" in out and "--resume reads them from it" in out
    rp = ResumePoint.load(resume_path(drawing))
    assert rp.position is None and rp.has_stream and 0 < rp.next_segment < rp.segments
    assert rp.sent_segment is not None and rp.sent_segment > rp.next_segment
    m = mock.machine("d")
    if wait:  # the cut-off firmware runs out its queue
        wait_stopped(m)
        assert m.laser == 0  # the queue ran empty: laser off without the host
    out = resume_and_check(drawing, m, "d")
    assert "resume point read from the controller" in out
    assert np.array_equal(drawn_steps(m), planned_draw_steps(drawing))
    if not wait:
        cut = [e for e in m.ledger if e.stopped == "reboot"]
        assert len(cut) == 1 and cut[0].kind == "G1" and 0 < cut[0].fraction < 1
    assert np.array_equal(all_steps(m), planned_steps(drawing))  # no travel back either


@pytest.mark.parametrize("fault", ["power_cut_after=18", "disconnect_after=18"])
def test_power_lost_falls_back_to_the_last_confirmed_segment(drawing: Path,
                                                             fault: str) -> None:
    """A controller that lost power (H:0) kept nothing: home, resume after the last
    segment a status report confirmed, and say how many may be drawn twice."""
    code, out = run("plot", str(drawing), "--port", url("p", fault), "--laser", "--yes")
    assert code == 3, out
    m = mock.machine("p")
    if fault.startswith("power_cut"):
        assert "the firmware restarted" in out and "position unknown" in out
        assert "H:0" in out and "may be drawn twice" in out
        assert m.laser == 0
    else:
        wait_stopped(m)
        m.power_cut()  # between the fault and the resume
    rp = ResumePoint.load(resume_path(drawing))
    assert rp.position is None and rp.sent_segment is not None
    assert 0 < rp.next_segment < rp.segments  # the fault fired mid-job
    m.phys = [0, 0]  # the user puts the arms at the home pose
    code, out = run("home", "--port", url("p"), "--yes")  # ... and says so
    assert code == 0 and "homed" in out, out
    out = resume_and_check(drawing, m, "p")
    n = rp.sent_segment - rp.next_segment
    assert f"up to {n} segments after it may be drawn twice" in out and n > 0
    assert "the last a status report confirmed" in out
    assert np.all(drawn_steps(m) >= planned_draw_steps(drawing))  # nothing lost


@pytest.mark.parametrize("fault", ["power_cut_after=18", "disconnect_after=18"])
def test_resume_yes_after_a_power_loss_is_refused(drawing: Path, fault: str) -> None:
    """Issue 16.2: `--yes` never stands in for a homing or for a person's word that the arms
    were placed after a power loss. The resume refuses, exits 3, says what to do, and
    nothing is sent; after `fivebar home` it proceeds."""
    code, out = run("plot", str(drawing), "--port", url("q", fault), "--laser", "--yes")
    assert code == 3, out
    m = mock.machine("q")
    wait_stopped(m)
    if fault.startswith("disconnect"):
        m.power_cut()
    rp_before = resume_path(drawing).read_text()
    phys, ledger = list(m.phys), len(m.ledger)
    code, out = run("plot", str(drawing), "--port", url("q"), "--laser", "--yes", "--resume")
    assert code == 3, out
    assert "lost power" in out and "--yes does not answer" in out, out
    assert f"fivebar home --port {url('q')}" in out, out
    assert m.phys == phys and len(m.ledger) == ledger  # no step, no line after the refusal
    assert m.laser == 0 and resume_path(drawing).read_text() == rp_before
    m.phys = [0, 0]  # the person puts the arms at the home pose ...
    code, out = run("home", "--port", url("q"), "--yes")  # ... and says so
    assert code == 0, out
    out = resume_and_check(drawing, m, "q")
    assert np.all(drawn_steps(m) >= planned_draw_steps(drawing))


def test_kept_record_of_another_stream_falls_back(drawing: Path) -> None:
    """Between the fault and the resume, another session moved the arms: the controller's
    record is not the interrupted stream's, so the resume starts from the last confirmed
    segment, from the position the controller knows, and says so."""
    code, _ = run("plot", str(drawing), "--port", url("k", "disconnect_after=18"), "--laser",
                  "--yes")
    assert code == 3
    m = mock.machine("k")
    wait_stopped(m)
    with Link.open(url("k")) as link:
        link.command("G91")
        link.command("G1 A-30 B20 P300000")
        link.wait_idle(10.0)
    out = resume_and_check(drawing, m, "k")
    assert "does not belong to the interrupted job" in out
    assert "may be drawn twice" in out
    assert np.all(drawn_steps(m) >= planned_draw_steps(drawing))


def test_resume_of_another_job_is_refused(drawing: Path) -> None:
    code, _ = run("plot", str(drawing), "--port", url("x", "error_on=10"), "--laser", "--yes")
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
    ("/dev/ttyDOES-NOT-EXIST", "no such port: is the board plugged in?"),
    ("loop://", "no fivebar firmware banner"),
    ("fivebar-mock://?proto=9", "speaks protocol 9"),
    ("fivebar-mock://?bogus=1", "bogus"),
])
def test_bad_ports(drawing: Path, quick_profile: Path, port: str, message: str) -> None:
    code, out = run("plot", str(drawing), "--port", port, "--yes", "--config", str(quick_profile))
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


# ------------------------------------------------------------------ resume points, kept records


def test_old_resume_files_read_without_stream_info(tmp_path: Path) -> None:
    old = tmp_path / "old.json"
    old.write_text('{"drawing": "d.svg", "fingerprint": "f", "next_segment": 3, '
                   '"position": null, "reason": "disconnect", "segments": 9}')
    rp = ResumePoint.load(old)
    assert (rp.next_segment, rp.position, rp.has_stream, rp.sent_segment) == (3, None, False,
                                                                              None)
    full = ResumePoint("d.svg", "f", 3, None, "r", 9, 5, 40, 0, (1, -2), True, 7)
    full.save(tmp_path / "new.json")
    assert ResumePoint.load(tmp_path / "new.json") == full and full.has_stream
    bad = tmp_path / "bad.json"
    bad.write_text(old.read_text().replace('"segments": 9', '"segments": 9, "laser": "yes"'))
    with pytest.raises(SendError, match=r"bad\.json: unreadable resume file: laser"):
        ResumePoint.load(bad)


def _stream() -> tuple[Job, Program, int]:
    job = compile_job(EXAMPLES / "simple.svg", load_profile(), CompileOptions(validate=False))
    return job, build_program(job, load_profile(), True, 0, job.steps[0]), 7


def _status(done: int, a: int, b: int, homed: bool = True) -> StatusReport:
    return StatusReport("Idle", None, a, b, 0, done, 0, 0, 0, homed)


def test_kept_record_maps_onto_the_stream_exactly() -> None:
    job, prog, first = _stream()
    k = 40
    line = first + int(np.flatnonzero(prog.segment == k)[0])  # the line of segment k
    s0, s1 = job.steps[k + 1], job.steps[k + 2]
    mid = (s0 + (s1 - s0) // 2).tolist()  # segment k + 1 cut half-way
    start = job.steps[0]
    assert kept_resume_segment(prog, first, 0, start, _status(line, *mid), 30) == (k + 1, "")
    assert kept_resume_segment(prog, first, 0, start, _status(line, *s0.tolist()), 30) == (
        k + 1, "")
    assert kept_resume_segment(prog, first, 0, start, _status(first - 1, *start.tolist()),
                               0) == (0, "")
    off = [mid[0] + 5, mid[1]]
    assert "not on the stream's path" in kept_resume_segment(
        prog, first, 0, start, _status(line, *off), 30)[1]
    assert "H:0" in kept_resume_segment(prog, first, 0, start,
                                        _status(line, *mid, homed=False), 30)[1]
    assert "fewer than the 50" in kept_resume_segment(prog, first, 0, start,
                                                      _status(line, *mid), 50)[1]
    assert "not one of the stream's lines" in kept_resume_segment(
        prog, first, 0, start, _status(first + len(prog), *mid), 0)[1]


def test_a_segment_whose_steps_are_all_issued_is_not_drawn_again() -> None:
    """Cut after its last step but before its time was over, a segment is finished by a
    minimal laser-off line at its end, not redrawn after a travel back."""
    job, _, _ = _stream()
    k = 40
    prog = build_program(job, load_profile(), True, k, job.steps[k + 1])
    bodies = wire.bodies(prog)
    first_g1 = next(b for b in bodies if b.startswith("G1"))
    a, b = job.steps[k + 1].tolist()
    assert first_g1 == f"G1 A{a} B{b} P100 S0"
    assert prog.segment[bodies.index(first_g1)] == k
    assert sum(1 for x in bodies if x.startswith("G1")) == job.n_segments - k


def test_positions_are_shown_in_steps_and_mm() -> None:
    """The home pose of configs/default.toml (θ = 120°, 60°; a = 60, b = 90, w = 40 mm) puts
    the pen at x = 20, y = 60 sin 60° + √(90² − 50²) = 126.79 mm (worked by hand); a 5 mm jog
    in x shows x 25.0 mm."""
    code, out = run("status", "--port", url("pos"))
    assert code == 0 and "A = 0 steps, B = 0 steps (position unknown: not homed)" in out, out
    code, out = run("home", "--port", url("pos"), "--yes")
    assert code == 0 and "homed: A = 0 steps, B = 0 steps (x 20.0 mm, y 126.8 mm)" in out, out
    code, out = run("jog", "--port", url("pos"), "--dx", "5")
    assert code == 0 and "(x 25.0 mm, y 126.8 mm)" in out, out
    code, out = run("status", "--port", url("pos"))
    assert code == 0 and out.startswith("Idle: A = ") and "(x 25.0 mm, y 126.8 mm)" in out


def _most_segments_within(job: Job, plan_s: float) -> int:
    """The most segments of `job` that finish within `plan_s` of planned time."""
    end_s = np.cumsum(job.duration_us) * 1e-6
    return int((np.searchsorted(end_s, end_s + plan_s, side="right")
                - np.arange(end_s.size)).max())


def test_progress_lines_without_a_terminal(drawing: Path) -> None:
    """In a log file: a progress line at least every 10 % (percent, segment n/m, time left),
    not nothing between "plotting" and "done"."""
    speed = 5
    code, out = run("plot", str(drawing), "--port", url("log", speed=speed), "--yes")
    assert code == 0, out
    lines = [ln for ln in out.splitlines() if ln.startswith("plotting: ")]
    pct = [int(ln.split()[1].rstrip("%")) for ln in lines]
    # no gap wider than the pace allows: 10 % plus what finishes between two status reports
    # (the link polls every 50 ms, twice that allowed here; at `speed` × the plan's pace)
    job = compile_job(drawing, load_profile(), CompileOptions(validate=False))
    per_poll = _most_segments_within(job, 2 * 0.05 * speed) / job.n_segments
    widest = 10 + 100 * per_poll + 1
    assert pct == sorted(pct) and pct[0] <= widest and pct[-1] >= 100 - widest, out
    assert len(lines) >= int(100 // widest) - 1, out  # as many lines as such gaps need
    assert max(np.diff([0, *pct, 100])) <= widest
    assert all("segment " in ln and "elapsed" in ln and "left" in ln for ln in lines)
    assert "done: " in out.splitlines()[-1] and "(x 20.0 mm, y 126.8 mm)" in out
