"""LaserGRBL-style raster files through `fivebar bridge` (issue 32): each row of run-length
`G1 X.. S..` moves is recognised as a scanline and burned by the raster machinery at one
speed, the power changing at the file's run boundaries and nowhere else.

The emulator tests stream a small file with a character-counting GRBL sender and measure the
burn from the pin trace (`benchmarks/lasergrbl.py`: step pulses → forward kinematics, the
laser pin's PWM) against the file's own runs — cycle-exact, not real time."""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from grbl_client import GrblClient
from grbl_support import ORIGIN, Running, start_bridge, stop_bridge

from benchmarks import lasergrbl as lg
from fivebar_host.bridge import scanlines
from fivebar_host.compile.incremental import OnlineCompiler, Solved
from fivebar_host.config import load_profile
from fivebar_host.program import Kind
from fivebar_host.raster import trace as rtrace

H = 0.1


def _row_moves(oc: OnlineCompiler, s_row: np.ndarray, y: float, *, dynamic: bool,
               feed: float = 50.0) -> list[Solved]:
    return lg.row_moves(oc, s_row, y, dynamic=dynamic, feed_mm_s=feed)


def test_a_row_of_runs_becomes_one_scanline_with_the_files_powers() -> None:
    prof = load_profile(None)
    oc = OnlineCompiler(prof, "+-", 0.05, True)
    row = lg.image(1, 120, seed=5)[0]
    row[0] = row[-1] = 450  # burned to both ends: the scanline is the whole row
    moves = _row_moves(oc, row, 100.0, dynamic=True)
    found = scanlines.find(moves)
    assert len(found) == 1
    sc = found[0]
    assert (sc.first, sc.end) == (0, len(moves))
    assert sc.pitch == pytest.approx(H, abs=1e-9)
    want = np.rint(255 * row / 1000).astype(np.uint8)  # the file's S, independently
    assert np.array_equal(sc.power, want)
    start = scanlines._steps(oc, oc.checker.inverse(np.array([[-2.0, 100.0]]))[0])
    prog, _ = scanlines.compile_scan(oc, sc, start)
    raster = prog.kind == Kind.RASTER
    assert raster.sum() > 0 and (prog.kind == Kind.MOVE).sum() > 0  # travel, then the scan
    # the G7 runs carry every pixel in order and 0 after the last (at F: M4 scale 1)
    got = np.frombuffer(b"".join(r.powers for r in prog.runs), dtype=np.uint8)
    assert np.array_equal(got, np.concatenate((want, [0])))
    # progress: each piece names a move of the row, never going back
    seg = prog.segment[raster]
    assert seg.min() >= 0 and seg.max() == len(moves) - 1 and (np.diff(seg) >= 0).all()
    # from the overscan start itself: still a target before the first G7 line (a stand)
    over = np.array([prog.a[raster][0], prog.b[raster][0]])
    first_g7 = int(np.flatnonzero(raster)[0])
    at = np.array([prog.a[first_g7 - 1], prog.b[first_g7 - 1]])
    again, _ = scanlines.compile_scan(oc, sc, at)
    assert again.kind[1] == Kind.MOVE and again.p_us[1] == 100
    assert np.array_equal([again.a[1], again.b[1]], at) and not np.array_equal(at, over)


def test_m4_power_is_scaled_once_by_the_scan_speed() -> None:
    prof = load_profile(None)
    oc = OnlineCompiler(prof, "+-", 0.05, True)
    row = np.array([600] * 10 + [300] * 10 + [900] * 10)
    # F far above what the joints allow: the scan runs slower, M4 scales every power by v/F
    moves = _row_moves(oc, row, 100.0, dynamic=True, feed=400.0)
    sc = scanlines.find(moves)[0]
    prog, _ = scanlines.compile_scan(oc, sc, scanlines._steps(oc, moves[0].th[0]))
    got = np.frombuffer(b"".join(r.powers for r in prog.runs), dtype=np.uint8)[:-1]
    assert sc.pitch == pytest.approx(10 * H)  # every run 1 mm: pixels of 1 mm
    base = np.rint(255 * row[::10] / 1000)
    ratio = got / base
    assert ratio.max() < 0.999  # scaled down
    assert np.ptp(ratio) < 0.02  # by one factor (the rounding aside)


def test_moves_that_are_not_a_raster_row_stay_ordinary_moves() -> None:
    prof = load_profile(None)
    oc = OnlineCompiler(prof, "+-", 0.05, True)
    one_power = _row_moves(oc, np.array([450] * 30 + [450] * 20), 100.0, dynamic=False)
    assert scanlines.find(one_power) == []  # one power: a vector line, not a raster
    # a corner: the second run turns
    a = oc.solve(oc.checker.inverse(np.array([[0.0, 100.0]]))[0], (0.0, 100.0), [(2.0, 100.0)],
                 rapid=False, draw=True, feed_mm_s=50.0, power=100, dynamic=False, arc=False)
    assert a is not None
    b = oc.solve(a.th[-1], (2.0, 100.0), [(2.0, 102.0)], rapid=False, draw=True,
                 feed_mm_s=50.0, power=200, dynamic=False, arc=False)
    assert b is not None
    assert scanlines.find([a, b]) == []
    # boundaries on no common pixel grid (0.1 and 0.0137 … mm)
    assert scanlines.pitch(np.array([0.1, 0.2137, 0.3])) is None
    assert scanlines.pitch(np.array([0.3, 0.5, 0.6])) == pytest.approx(0.1)


def _burn(tmp_path: Path, spindle: int, rows: int, cols: int) -> tuple[lg.BurnFigures,
                                                                        list[str]]:
    prof = load_profile(None)
    img = lg.image(rows, cols, seed=11)
    lines, ref = lg.raster_file(img, 1 / H, 3000.0, spindle, (0.0, rows * H), ORIGIN)
    trace = tmp_path / "pins.trace"
    run = lg.stream_file(lines, trace, prof, ORIGIN, realtime=False)
    return lg.burn_figures(trace, prof, ref, run.start), run.log


@pytest.mark.sim
@pytest.mark.parametrize("spindle", [3, 4])
def test_lasergrbl_file_changes_power_at_the_run_boundaries_only(
        tmp_path: Path, sim_build: object, spindle: int) -> None:
    f, log = _burn(tmp_path, spindle, rows=4, cols=150)
    print(f"M{spindle}: {f.line()}")
    assert not [s for s in log if "runs as ordinary" in s]
    assert f.boundaries > 40
    assert f.coverage >= 0.999
    assert f.max_distance_mm <= 0.05
    assert f.inside_changes == 0
    assert f.outside_steps == 0


@pytest.mark.sim
def test_the_check_sees_power_changes_inside_runs_without_scanlines(
        tmp_path: Path, sim_build: object, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same file with the scanlines switched off (every run its own planned move, M4
    power following the planned speed): the trace shows changes inside constant runs, so
    the check above can fail."""
    monkeypatch.setattr(scanlines, "find", lambda chunk: [])
    f, _ = _burn(tmp_path, 4, rows=2, cols=150)
    print(f"without scanlines: {f.line()}")
    assert f.inside_changes > 0


def _stream_in_background(c: GrblClient, lines: list[str]) -> threading.Thread:
    def send() -> None:
        # a reset drops lines: the sender gives up
        with contextlib.suppress(OSError, TimeoutError):
            c.stream(lines, timeout=120)

    th = threading.Thread(target=send, daemon=True)
    th.start()
    return th


def _inside_a_row(run: Running, lo: float, hi: float, timeout: float = 30.0) -> bool:
    """Wait until the machine runs with the pen inside x ∈ (lo, hi) on the image's rows."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        x, y, _ = run.core._mpos()
        if run.core.grbl_state() == "Run" and lo < x < hi and ORIGIN[1] < y < ORIGIN[1] + 0.6:
            return True
        time.sleep(0.005)
    return False


@pytest.mark.sim
def test_a_feed_hold_inside_a_scanline_resumes_the_burn_in_place(
        tmp_path: Path, sim_build: object) -> None:
    """`!` in the middle of a row: Hold:0, the laser off and the pen still while held; `~`
    finishes the file, every run boundary still changes the power where it should, and the
    only changes inside a run are the hold's laser-off and the resume's laser-on, next to
    each other."""
    prof = load_profile(None)
    run = start_bridge("sim", tmp_path, realtime=True)
    img = lg.image(6, 150, seed=11)
    lines, ref = lg.raster_file(img, 1 / H, 3000.0, 4, (0.0, 0.6), ORIGIN)
    try:
        c = run.client()
        start = (run.core.machine.status.a, run.core.machine.status.b)
        assert c.command("$X")[1] == "ok"
        th = _stream_in_background(c, lines)
        assert _inside_a_row(run, ORIGIN[0] + 4.0, ORIGIN[0] + 11.0)
        c.write(b"!")
        time.sleep(0.3)
        assert run.core.grbl_state() == "Hold:0"
        held = run.core._mpos()
        time.sleep(0.3)
        assert run.core._mpos() == held  # still
        assert run.core.machine.status.laser == 0
        c.write(b"~")
        th.join(120)
        assert not th.is_alive()
        c.wait_state("Idle", 60)
        c.close()
    finally:
        stop_bridge(run)
    assert run.trace is not None
    f = lg.burn_figures(run.trace, prof, ref, start)
    print(f"hold and resume: {f.line()}; inside: {f.inside_at}")
    assert f.coverage >= 0.999 and f.max_distance_mm <= 0.05
    assert f.outside_steps == 0
    assert f.inside_changes <= 2
    if f.inside_changes == 2:  # the hold's off and the resume's on, at the same place
        (r0, x0, _), (r1, x1, _) = f.inside_at
        assert r0 == r1 and abs(x0 - x1) <= 0.1


@pytest.mark.sim
def test_a_soft_reset_inside_a_scanline_turns_the_laser_off(
        tmp_path: Path, sim_build: object) -> None:
    """Ctrl-X in the middle of a row: the machine stops with the laser off, the look-ahead is
    dropped, the banner comes, and nothing burns afterwards."""
    run = start_bridge("sim", tmp_path, realtime=True)
    img = lg.image(6, 150, seed=11)
    lines, _ = lg.raster_file(img, 1 / H, 3000.0, 3, (0.0, 0.6), ORIGIN)
    try:
        c = run.client()
        assert c.command("$X")[1] == "ok"
        _stream_in_background(c, lines)
        assert _inside_a_row(run, ORIGIN[0] + 4.0, ORIGIN[0] + 11.0)
        n = len(c.lines)
        c.write(b"\x18")
        c.wait_for(lambda s: s.startswith("Grbl 1.1h"), 10, n)
        time.sleep(0.5)
        assert run.core.grbl_state() == "Idle"
        assert run.core.machine.status.laser == 0
        assert not run.core.pending
        stopped = run.core._mpos()
        time.sleep(0.5)
        assert run.core._mpos() == stopped
        c.close()
    finally:
        stop_bridge(run)
    assert run.trace is not None
    pt = rtrace.read_pins(run.trace)
    rise, fall = rtrace.high_intervals(pt)
    steps = rtrace.motion_of(pt).step_cycles()
    # the laser's last fall comes at the reset, with the last step (within a step's time at
    # F3000, ~0.5 ms): nothing burns after it, though the bridge ran on for a second
    assert rise.size and fall.max() - steps.max() < 0.002 * rtrace.F_CPU
