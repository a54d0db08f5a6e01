"""The pen servo's pulses on D12 in simavr while the step generator runs at speed.

The pulse is timed by Timer0's compare B and the frame boundary by the 1 kHz tick
(firmware/fivebar/board_avr.c): these tests read the recorded `pen` pin and check that
every frame is 20 ms apart and every pulse has the commanded width (within EDGE_WAIT_US: an
edge can wait for a step interrupt that starts a segment, ~400 cycles, plus a receive and a
tick interrupt; measured up to 34 us under dense steps, about 3 degrees of an SG90's travel,
nothing a pen lift notices; the steps repeat with the frame here, so the error is the same in
every frame and the median is not exact), across several wraps of the tick
count's low byte (256 ms), with the steps exact at 30 kHz aggregate (1:0.73); the highest
rate, 40 kHz for 300 ms, is the benchmark's (`python benchmarks/firmware.py --pen`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import pytest

from fivebar_host import wire
from fivebar_host.devices.sim import SimDevice as Device
from fivebar_host.protocol import Ok

pytestmark = pytest.mark.sim

F_CPU = 16_000_000
UP, DOWN = 1800, 1000
#: The most a pulse edge may wait behind the other interrupts (module doc), µs.
EDGE_WAIT_US = 40
#: 1:0.73 at 30 kHz aggregate: a step about every 530 cycles, edges often waiting for it
RATE_A, RATE_B = 17_341, 12_659


def test_pulses_keep_width_and_frame_under_dense_steps(start_device: Callable[..., Device]) -> None:
    dev = start_device(realtime=True)
    s = dev.session
    assert s.send("$0=40000") == Ok()  # the step-rate limit, as the benchmark sets it
    assert s.send(f"$14={UP}") == Ok()
    assert s.send(f"M280 S{DOWN}") == Ok()
    s.wait_idle()
    base = s.status().underruns
    p_us = 10_000
    segs = [(RATE_A * p_us // 1_000_000, RATE_B * p_us // 1_000_000) for _ in range(60)]
    lines = ["G91"] + [wire.g1(a, b, p_us) for a, b in segs]
    assert s.stream(lines, numbered_from=4) == [Ok()] * len(lines)
    report = s.wait_idle()
    assert (report.a, report.b) == (sum(a for a, _ in segs), sum(b for _, b in segs))
    assert report.underruns - base == 1, "the queue ran empty mid-job with the servo running"
    trace = dev.finish()
    assert len(trace.steps("A")) == sum(a for a, _ in segs)
    pen = trace.pen_pulses()
    first_step = trace.steps("A")[0].cycle
    during = [(rise, width) for rise, width in pen if rise > first_step]
    assert len(during) >= 600 * 1000 // 20_000 - 2, "frames missing while stepping"
    us = [width * 1_000_000 / F_CPU for _, width in during]
    assert all(abs(u - DOWN) <= EDGE_WAIT_US for u in us), (min(us), max(us))
    gaps = [(b - a) * 1000 / F_CPU for (a, _), (b, _) in itertools.pairwise(pen)]
    assert all(abs(g - 20) <= 0.05 or abs(g - 21) <= 0.05 for g in gaps), (min(gaps), max(gaps))
