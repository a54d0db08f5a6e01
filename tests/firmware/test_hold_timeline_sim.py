"""Feed holds land anywhere in the step timeline, and every resume continues it in place.

The firmware freezes the step timer at a hold and re-arms it at the resume, the cycles the
next step had left kept.  A resume whose compare was written after the timer had already
passed it waited a whole timer period (65,536 cycles, 4.1 ms): a hold landing within a few
dozen cycles of a step did that (the step due at the hold, its compare flag already set), and
in a raster scan the burn then ran 4.1 ms ahead of the arms for the rest of the row (the GRBL
bridge's feed-hold test, ~1 run in 30).  Many holds at random instants in a fast move make
such a landing certain; the pin trace then shows every resume against the DDA schedule.
"""

from __future__ import annotations

import itertools
import random
from collections.abc import Iterator
from pathlib import Path

import pytest

from fivebar_host import protocol, wire
from fivebar_host.devices import sim
from fivebar_host.devices.simtimers import late_compares
from fivebar_host.protocol import Ok

pytestmark = pytest.mark.sim

F_CPU = 16_000_000
#: A: 16,000 steps in 0.5 s (500 cycles apart), B: 2,500 (3,200 apart), back and forth.
STEPS_A, STEPS_B, P_US = 16_000, 2_500, 500_000
SEGMENTS = 8
#: Cycles a resume may add to the held time: the re-arm's margin and the interrupts' entry.
RESUME_SLACK = 1_000


def ideal_a(segments: int) -> list[int]:
    """Motor A's DDA step times from the job's start: floor((2k-1)C/2n) in each segment."""
    c = P_US * F_CPU // 1_000_000
    return [j * c + ((2 * k - 1) * c) // (2 * STEPS_A)
            for j in range(segments) for k in range(1, STEPS_A + 1)]


@pytest.fixture
def device(build: sim.BuildPaths, tmp_path: Path) -> Iterator[sim.SimDevice]:
    """The firmware in the emulator with its compare writes logged to tmp_path/timers.log."""
    emu = sim.Emulator(build.elf, build.harness, tmp_path / "fw.trace",
                       extra=["-D", str(tmp_path / "timers.log")])
    dev = sim.boot(emu, tmp_path / "fw.trace", 10.0)
    yield dev
    dev.close()


def test_every_resume_continues_the_held_timeline(device: sim.SimDevice,
                                                  tmp_path: Path) -> None:
    session = device.session
    assert session.send("$0=40000") == Ok()  # 40,000 steps/s
    assert session.send("M3 S200") == Ok()
    for j in range(SEGMENTS):
        out = j % 2 == 0  # absolute targets: out and back
        assert session.send(wire.g1(STEPS_A * out, STEPS_B * out, P_US)) == Ok()
    rng = random.Random(7)
    pairs = 0
    while session.status().state != "Idle":
        for _ in range(20):
            device.emulator.byte_at(protocol.RT_HOLD[0], rng.randint(1, 5_000))
            device.emulator.byte_at(protocol.RT_RESUME[0], rng.randint(2_000, 20_000))
            pairs += 1
    done = session.wait_idle()
    assert (done.a, done.b) == (0, 0)
    trace = device.finish()
    late = late_compares(tmp_path / "timers.log")
    assert not late, f"{len(late)} compares armed behind the timer: {late[:5]}"
    steps = [s.cycle for s in trace.steps("A")]
    assert len(steps) == SEGMENTS * STEPS_A
    writes = [c for c, _ in trace.pin("lwrite")]
    ideal = ideal_a(SEGMENTS)
    resid = [t - i for t, i in zip(steps, ideal, strict=True)]
    holds = 0
    for k, (r0, r1) in enumerate(itertools.pairwise(resid), start=1):
        jump = r1 - r0
        if jump < 2_000:
            assert abs(jump) < 200, f"step {k} of A moved {jump} cycles off its schedule"
            continue
        # holds between steps k-1 and k: the laser's off and on writes bound each
        inside = [c for c in writes if steps[k - 1] < c < steps[k]]
        assert inside and len(inside) % 2 == 0, (
            f"a gap of {jump} cycles before step {k} of A with no whole hold in it")
        held = sum(on - off for off, on in zip(inside[::2], inside[1::2], strict=True))
        n = len(inside) // 2
        assert 0 <= jump - held <= n * RESUME_SLACK, (
            f"the resume after {n} hold(s) before step {k} of A lost {jump - held} cycles "
            f"(held {held} cycles)")
        holds += n
    print(f"{pairs} holds sent, {holds} inside the move, every resume within "
          f"{RESUME_SLACK} cycles of its schedule")
    assert holds >= 20, f"only {holds} of {pairs} holds landed in the move"
