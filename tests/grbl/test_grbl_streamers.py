"""Real streamers through `fivebar bridge` to the emulated firmware (docs/grbl.md, issue 35):

- GRBL's own `stream.py` (converted to Python 3: `stream_py.py`) closes the port right after
  the last `ok`; the bridge finishes what it received, as GRBL does: every step of
  `drawing.nc` is drawn, the executed path within the tolerance plus one step quantum.
- A character-counting sender's "done" (its last `ok`, as bCNC and grbl-streamer show 100 %)
  comes no earlier than the last 15 moves of motion: at that moment the pen is on one of the
  file's last 16 motion lines (found from the machine's own position, not the bridge's
  count).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from grbl_client import GrblClient, mpos
from grbl_support import ORIGIN, Running, start_bridge, stop_bridge
from test_grbl_sender import DRAWING, TOLERANCE, distance_to, reference_path

from fivebar_host.bridge.controller import OK_WINDOW
from fivebar_host.compile.steps import step_angles, step_quantum_mm
from fivebar_host.config import load_profile
from fivebar_host.devices.simtrace import read_trace
from fivebar_host.report.text.executed import merge_axes

STREAM_PY = Path(__file__).resolve().parent / "stream_py.py"
LINES = [s for s in DRAWING.read_text().splitlines() if s]


def _unlock(run: Running) -> None:
    c = run.client()
    assert c.command("$X")[1] == "ok"
    c.close()


def _wait_idle(run: Running, timeout: float = 300.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if run.core.grbl_state() == "Idle" and run.core.machine.idle:
            return
        time.sleep(0.05)
    raise TimeoutError(run.core.grbl_state())


def _executed(run: Running) -> tuple[np.ndarray, float]:
    """The laser-on pen points of the recorded steps and the step quantum bound."""
    assert run.trace is not None
    tr = read_trace(run.trace)
    t, track = merge_axes(tr.positions("A"), tr.positions("B"))
    on = np.array([tr.laser_on_at(int(c)) for c in t])
    prof = load_profile()
    mot = prof.motors
    th = step_angles(track, mot.home_rad, mot.steps_per_rev)
    fk = prof.geometry.forward_batch(th, prof.kinematics.assembly)
    quantum = step_quantum_mm(prof.geometry.jacobian(th[on], fk.points[on]),
                              mot.rad_per_step).max()
    return fk.points[on & fk.valid], float(quantum)


@pytest.mark.sim
def test_stream_py_closes_after_the_last_ok_and_the_job_finishes(
        tmp_path: Path, sim_build: object) -> None:
    run = start_bridge("sim", tmp_path, laser=True, pty=True, realtime=True)
    try:
        _unlock(run)
        t0 = time.monotonic()
        out = subprocess.run([sys.executable, str(STREAM_PY), str(DRAWING),
                              str(tmp_path / "grbl-tty"), "-q"], stdin=subprocess.DEVNULL,
                             capture_output=True, text=True, timeout=300)
        closed_at = time.monotonic()
        assert out.returncode == 0, out.stderr
        assert "G-code streaming finished!" in out.stdout
        left = run.core.grbl_state()
        _wait_idle(run)
        tail = time.monotonic() - closed_at
    finally:
        stop_bridge(run)
    pts, quantum = _executed(run)
    ref = reference_path(LINES)
    dev = distance_to(pts, ref)
    refp = np.concatenate(ref)[::20]
    gaps = [np.hypot(*(pts[None] - r[:, None]).transpose(2, 0, 1)).min(1).max()
            for r in np.array_split(refp, max(1, refp.shape[0] // 256))]
    print(f"stream.py closed the port {closed_at - t0:.1f} s in, the bridge {left} then; "
          f"motion went on {tail:.1f} s to the end; executed deviation {dev.max():.4f} mm "
          f"(bound {TOLERANCE} + {quantum:.4f}), largest gap {max(gaps):.3f} mm")
    assert dev.max() <= TOLERANCE + quantum
    assert max(gaps) < 0.5  # every part of the drawing was drawn: the job finished


def _motion_lines() -> list[tuple[int, np.ndarray]]:
    """(index among the file's lines, sampled machine-mm points) of each motion line."""
    out = []
    x = y = 0.0
    for i, raw in enumerate(LINES):
        words = {w[0]: float(w[1:]) for w in raw.split() if w[0] in "GXY"}
        if "X" in words or "Y" in words:
            nx, ny = words.get("X", x), words.get("Y", y)
            seg = np.linspace([x, y], [nx, ny], 50) + np.array(ORIGIN)
            out.append((i, seg))
            x, y = nx, ny
    return out


def _lines_left(report: str) -> int:
    """How many motion lines of the file the pen has still to run, from its position (the
    last line it is on, within 0.1 mm; arcs taken as their chords are close enough here)."""
    p = np.array(mpos(report)[:2])
    moves = _motion_lines()
    on = [k for k, (_, seg) in enumerate(moves) if np.hypot(*(seg - p).T).min() < 0.6]
    assert on, report
    return len(moves) - 1 - max(on)


@pytest.mark.sim
def test_a_senders_done_comes_with_the_last_15_moves(tmp_path: Path,
                                                     sim_build: object) -> None:
    run = start_bridge("sim", tmp_path, laser=True, realtime=True)
    try:
        c: GrblClient = run.client()
        assert c.command("$X")[1] == "ok"
        t0 = time.monotonic()
        replies = c.stream(LINES)
        done_at = time.monotonic()
        report = c.status()
        ahead = run.core.moves_acked - run.core.machine.moves_done
        _wait_idle(run)
        end = time.monotonic()
        c.close()
    finally:
        stop_bridge(run)
    assert replies == ["ok"] * len(LINES)
    left = _lines_left(report)
    print(f"the sender's done at {done_at - t0:.1f} s of a {end - t0:.1f} s job: the pen on "
          f"the file's motion line {left} from the end, {ahead} accepted moves not yet run "
          f"(window {OK_WINDOW})")
    assert ahead <= OK_WINDOW
    assert left <= OK_WINDOW + 1
