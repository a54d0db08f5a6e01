"""Feed holds at random instants of a raster job change nothing of where its power changes.

A hold freezes the step timeline and the pixel timeline together (the laser off while held)
and the resume restarts both where they stood, so holds anywhere — inside a pixel, between a
step and the change next to it, while the pixel timeline waits for the host's next line —
must leave every power change after the same steps of each motor.  `fivebar plot` engraves
a grey patch on the firmware in the emulator twice: once as it is, once while another
thread holds and resumes it at random cycles (fbsim's `byte` command; from its first step
on, since the host refuses to start on a held machine).  Each power change is the firmware's
write of the laser's register (the trace's `lwrite`), placed by the step edges of each motor
before it; the second run must have the first run's changes in order, each within a step,
plus the holds' own.  (The dose per pixel is no measure here: `raster.dose` places the
laser's pulses between two step edges at constant speed, which a hold between them breaks.)
Before the resume re-armed its compares 256 cycles on (board_avr_step.c `RESUME_CYCLES`), a
pixel change due within ~150 cycles of a hold waited a whole timer period: measured on that
firmware, a change 3 steps late and a compare written behind the timer.
"""

from __future__ import annotations

import random
import re
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from fivebar_host import protocol
from fivebar_host.cli import main
from fivebar_host.devices import sim
from fivebar_host.devices.simtimers import late_compares
from fivebar_host.devices.simtrace import read_trace
from kinematics.arrays import IntArray

pytestmark = pytest.mark.sim


def _hold_at_random(emu: sim.Emulator, trace: Path, done: threading.Event,
                    held: list[int]) -> None:
    """From the job's first step until `done`: hold after 50k-300k cycles of running (most
    pixels, 5 ms each, see none), resume 2k-20k cycles later."""
    while not done.is_set():
        emu.control("flush")
        if re.search(r"step[AB] 1", trace.read_text()):
            break
        time.sleep(0.02)
    rng = random.Random(5)
    while not done.is_set():
        emu.byte_at(protocol.RT_HOLD[0], rng.randint(50_000, 300_000))
        emu.byte_at(protocol.RT_RESUME[0], rng.randint(2_000, 20_000))
        held.append(1)


def _engrave(build: sim.BuildPaths, img: Path, tmp: Path, holds: bool) -> tuple[IntArray, int]:
    """Plot `img` on a new emulated machine: per laser write, the steps of A and B before
    it (N, 2), and how many holds were sent; no compare was armed behind the timer."""
    tmp.mkdir()
    trace = tmp / "pins.trace"
    emu = sim.Emulator(build.elf, build.harness, trace, extra=["-D", str(tmp / "timers.log")])
    pty = emu.start()
    done, held = threading.Event(), []
    th = threading.Thread(target=_hold_at_random, args=(emu, trace, done, held), daemon=True)
    try:
        if holds:
            th.start()
        res = CliRunner().invoke(main, ["plot", str(img), "--laser", "--width", "6mm", "--yes",
                                        "--preview", str(tmp / "p.png"), "--port", pty])
    finally:
        done.set()
        if holds:
            th.join(10)
        emu.stop()
    assert res.exit_code == 0, res.output
    late = late_compares(tmp / "timers.log")
    assert not late, f"{len(late)} compares armed behind the timer: {late[:5]}"
    tr = read_trace(trace)
    writes = np.array([c for c, _ in tr.pin("lwrite")], dtype=np.int64)
    counts = [np.searchsorted(np.array([s.cycle for s in tr.steps(m)]), writes)
              for m in ("A", "B")]
    return np.stack(counts, axis=1).astype(np.int64), len(held)


def test_holds_anywhere_in_a_raster_leave_every_power_change_in_place(
        build: sim.BuildPaths, tmp_path: Path) -> None:
    img = tmp_path / "grey.png"
    a = np.full((8, 30), 128, dtype=np.uint8)
    a[:, 10:20] = 64  # power changes inside every line
    Image.fromarray(a).save(img)
    ref, _ = _engrave(build, img, tmp_path / "plain", holds=False)
    got, holds = _engrave(build, img, tmp_path / "held", holds=True)
    assert holds >= 20, f"only {holds} holds"
    assert len(ref) >= 40  # the scans' changes, their ends, the job's start and end
    j = 0
    for i, want in enumerate(ref):
        # the holds' own writes (off, then on again) come in between
        while j < len(got) and np.abs(got[j] - want).max() > 1:
            assert not (got[j] > want + 1).any(), (
                f"power change {i} of {len(ref)}, after A {want[0]} and B {want[1]} steps "
                f"without holds, came after {got[j].tolist()} with them")
            j += 1
        assert j < len(got), f"power change {i} of {len(ref)} never came with holds"
        j += 1
    print(f"{holds} holds; the {len(ref)} power changes each within a step of their place")
