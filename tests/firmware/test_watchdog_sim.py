"""The hardware watchdog of the real firmware in simavr (docs/protocol.md section 9).

simavr 1.6 emulates the ATmega328P's watchdog (WDTCSR and its timed sequence, WDR, the
128 kHz timeouts, WDRF); the harness turns its reset into a reset that keeps the RAM
(firmware/sim/fbsim.c).  The harness's ``hang`` (the firmware spins with interrupts off),
``spin`` (the main loop spins, interrupts run on) and ``stepoff`` (the step interrupt stops
coming) strike mid-segment with the laser on; the pin trace must show the laser low within
0.5 s of the hang, the watchdog's reset in between, and the firmware back with the position,
``H`` and ``Ln`` done it had.  An idle, held, dwelling or homing machine must never be reset.

``pytest tests/firmware/test_watchdog_sim.py -s`` prints the measured hang-to-laser-off times.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from fivebar_host.devices.sim import SimDevice as Device
from fivebar_host.devices.simtrace import Trace, read_trace
from fivebar_host.protocol import Ok

pytestmark = pytest.mark.sim

F_CPU = 16_000_000
#: The firmware's watchdog timeout: 2^15 cycles of the 128 kHz watchdog oscillator.
WDT_S = 32768 / 128_000
#: What the laser may take from a hang to off (issue 16: within 0.5 s, reboot included).
LIMIT_S = 0.5


def flushed_trace(dev: Device) -> Trace:
    """The pin trace so far (the harness writes it out first)."""
    dev.emulator.control("flush")
    return read_trace(dev.trace_path)


def laser_on_now(trace: Trace) -> bool:
    """Whether the last laser change in the trace left it on."""
    changes = trace.pin("laser")
    return bool(changes) and changes[-1][1] == 1


@pytest.mark.parametrize("fault", ["hang", "spin", "stepoff"])
def test_a_hang_mid_segment_turns_the_laser_off_within_half_a_second(
        device: Device, fault: str) -> None:
    s = device.session
    for line in ("G92 A0 B0", "M3 S255", "G1 A3000 B-1500 P3000000"):
        assert s.send(line) == Ok()
    s.wait_state({"Run"})
    time.sleep(0.05)  # well into the segment
    assert s.status().laser == 255
    device.emulator.control(fault)
    s.wait_banner()  # the watchdog reset the firmware, which booted again
    after = s.status()
    trace = flushed_trace(device)
    (hang, _), = trace.pin(fault)
    wdt = [c for c, _ in trace.pin("wdt")]
    assert len(wdt) == 1 and wdt[0] > hang, "exactly one watchdog reset, after the fault"
    assert trace.laser_on_at(hang - 1), "the laser was on when the firmware hung"
    off = [c for c, level in trace.pin("laser") if level == 0 and c >= hang]
    laser_off_s = (off[0] - hang) / F_CPU
    print(f"\n{fault}: laser off {laser_off_s * 1000:.1f} ms after the hang "
          f"(watchdog reset at {(wdt[0] - hang) / F_CPU * 1000:.1f} ms)")
    assert laser_off_s <= LIMIT_S
    # the watchdog did it, not something earlier: at most its period after the last feed
    assert 0.9 * WDT_S <= laser_off_s <= WDT_S + 0.002
    assert not any(level for c, level in trace.pin("laser") if c > off[0])
    # the .noinit record survived the watchdog reset: the motors' position per the trace
    end = trace.last_cycle() + 1
    assert (after.a, after.b) == (trace.position_at("A", end), trace.position_at("B", end))
    assert 0 < after.a < 3000
    assert (after.state, after.homed, after.done_line, after.accepted_line, after.laser) == (
        "Idle", True, 1, 0, 0)
    if fault == "spin":  # the step interrupt ran on: the steps after the hang are counted
        assert trace.position_at("A", wdt[0]) > trace.position_at("A", hang)
    else:  # no step after the hang
        assert trace.position_at("A", wdt[0]) == trace.position_at("A", hang)
    assert s.send("G1 A0 B0 P1000000") == Ok()  # it runs again
    s.wait_idle()


def test_an_idle_held_dwelling_or_homing_machine_is_never_reset(
        start_device: Callable[..., Device]) -> None:
    dev = start_device(endstop_a=-800, endstop_b=-600)
    s = dev.session
    time.sleep(0.3)  # idle: about 2 s of emulated time, many watchdog periods
    for line in ("$7=1", "$8=1000", "$12=5000", "$H"):  # homing: about 0.8 s
        assert s.send(line) == Ok()
    for line in ("M3 S128", "G1 A100 P1000000", "G1 A200 B100 P400000"):
        assert s.send(line) == Ok()  # a 1 s dwell-like slow move, then a segment
    s.wait_state({"Run"})
    s.realtime(b"!")
    held = s.wait_state({"Hold"})
    time.sleep(0.3)  # held (step timer paused) for well over a watchdog period
    assert s.status() == held
    s.realtime(b"~")
    s.wait_idle()
    assert s.send("G1 P2000000") == Ok()  # a dwell: no step for 2 s
    s.wait_idle()
    trace = flushed_trace(dev)
    assert trace.pin("wdt") == [], "the watchdog reset a healthy firmware"
    assert s.banner is not None and not any(
        type(m).__name__ == "Banner" for m in s.messages), "no reboot"
    assert trace.last_cycle() / F_CPU > 3 * WDT_S
    assert not laser_on_now(trace)
