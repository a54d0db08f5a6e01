"""The protocol contract: moves, G92, the step rate and soft limits, laser power, and the
real-time bytes (hold, resume, Ctrl-X), with exact step counts checked on the pins.

Each test runs against ``fivebar-mock://`` and against the firmware in simavr (see
conftest.py) and must pass on both; shared helpers are in contract_helpers.py.
"""

from __future__ import annotations

import time

import pytest
from contract_devices import Device
from contract_helpers import assert_nothing_executed, idle, poll

from fivebar_host import protocol
from fivebar_host.protocol import ErrorReply, Ok

# --------------------------------------------------------------------------- motion


def test_absolute_and_relative_moves_step_exactly(device: Device) -> None:
    lines = ["G90", "G1 A300 B-200 P20000", "G91", "G1 A-100 B50 P20000",
             "G1 A-100 B50 P20000 S0", "G90", "G1 A0 B100 P20000", "G1 P5000"]
    assert all(r == Ok() for r in device.session.stream(lines))
    report = idle(device)
    assert (report.a, report.b) == (0, 100)
    assert report.underruns == 1
    done = device.executed()
    assert done.steps == (300 + 100 + 100 + 100, 200 + 50 + 50 + 200)
    assert done.net == (0, 100)


def test_g92_sets_the_position_without_steps(device: Device) -> None:
    s = device.session
    assert s.stream(["G1 A100 B20 P10000", "G92 A1000 B-5", "G1 A1010 P10000",
                     "G92 B7", "G91", "G1 B3 P10000"]) == [Ok()] * 6
    report = idle(device)
    assert (report.a, report.b, report.done_line) == (1010, 10, 6)
    done = device.executed()
    assert done.steps == (110, 23) and done.net == (110, 23)


def test_step_rate_limit_follows_setting_0(device: Device) -> None:
    s = device.session
    assert s.send("G91") == Ok()
    assert s.send("G1 A20 P1000") == Ok()  # 20 steps in 1 ms = 20000/s: the default limit
    idle(device)  # (an error while a block is queued would hold it)
    assert s.send("G1 A41 P2000") == ErrorReply(12)  # 32000 // 41 = 780 < 800 cycles
    assert s.send("$0=1000") == Ok()
    assert s.send("G1 A30 P10000") == ErrorReply(12)  # 3000/s > 1000/s
    assert s.send("G1 A30 P30000") == Ok()
    report = idle(device)
    assert report.a == 50
    assert device.executed().steps == (50, 0)


def test_soft_limits_follow_settings(device: Device) -> None:
    s = device.session
    for line in ("$1=-50", "$2=50", "$3=-10", "$4=10"):
        assert s.send(line) == Ok()
    assert s.send("G1 A51 P100000") == ErrorReply(11)
    assert s.send("G1 B-11 P100000") == ErrorReply(11)
    assert s.send("G1 A50 B-10 P100000") == Ok()
    idle(device)
    assert s.send("$5=0") == Ok()
    assert s.send("G1 A200 P100000") == Ok()
    report = idle(device)
    assert (report.a, report.b) == (200, -10)
    assert device.executed().steps == (200, 10)


def test_laser_power_per_segment_in_status(device: Device) -> None:
    s = device.session
    lines = ["M3 S128", "G1 P1000000", "M5", "G1 P1000000", "M3", "G1 A10 P200000 S77",
             "G1 P200000"]
    assert s.stream(lines, numbered_from=1) == [Ok()] * len(lines)
    # the block running is the one after the last done line; it runs (not waiting for the
    # start) when the queue holds one block fewer than the blocks left
    left = {0: 4, 2: 3, 4: 2, 6: 1}
    power = {0: 128, 2: 0, 4: 77, 6: 77}  # M5 spares the running segment; S77 is modal
    seen: dict[int, set[int]] = {}
    while True:
        r = s.status()
        if r.state == "Idle" and r.queued == 0:
            break
        if r.state == "Run" and r.queued == left[r.done_line] - 1:
            seen.setdefault(r.done_line, set()).add(r.laser)
        time.sleep(0.002)
    assert {0, 2} <= seen.keys(), seen  # the 1 s segments were certainly seen
    for done_line, lasers in seen.items():
        assert lasers == {power[done_line]}, (done_line, lasers)
    done = device.executed()
    assert done.laser_on_s == pytest.approx(1.0 + 0.2 + 0.2, abs=0.01)
    assert done.laser_periods == 2


def test_status_fields_are_one_instant(device: Device) -> None:
    """`Ln` done and `L` in one report are read at one instant (protocol section 7).

    Rounds of short blocks, each with its own power, polled throughout: whenever the laser
    is on, the power shown is that of the first block after the one `Ln` says is done.
    Reading the fields one by one, a block switch between the two reads shows the next
    block's power.
    """
    s = device.session
    assert s.send("M3") == Ok()  # line 1
    n, rounds, first = device.banner.queue, 50, 2
    checked = done = 0
    # at least `rounds` rounds, more (up to 4×) until enough reports were checked: how many
    # polls land on a running block depends on how busy the machine is, not on the firmware
    while done < rounds or (checked < rounds // 4 and done < 4 * rounds):
        done += 1
        power = {first + i: 1 + (first + i) % 250 for i in range(n)}
        lines = [f"G1 P1000 S{power[k]}" for k in sorted(power)]
        assert s.stream(lines, numbered_from=first) == [Ok()] * n
        while (r := s.status()).state != "Idle" or r.queued:
            if r.laser:
                running = min(k for k in power if k > r.done_line)
                assert r.laser == power[running], r
                checked += 1
        first += n
    assert checked >= rounds // 4, checked  # the check really ran


# --------------------------------------------------------------------------- real-time bytes


def test_hold_freezes_and_resume_continues_exactly(device: Device) -> None:
    s = device.session
    assert s.send("M3 S200") == Ok()
    assert s.send("G1 A2000 B-1000 P2000000") == Ok()
    poll(device, lambda r: r.a >= 200, what="A >= 200")
    s.realtime(protocol.RT_HOLD)
    held = s.status()
    assert (held.state, held.detail, held.laser) == ("Hold", 0, 0)
    assert 200 <= held.a < 2000
    time.sleep(0.05)
    again = s.status()
    assert (again.a, again.b, again.state) == (held.a, held.b, "Hold"), "moved while held"
    s.realtime(protocol.RT_HOLD)  # a second hold changes nothing
    s.realtime(protocol.RT_RESUME)
    done_report = idle(device)
    assert (done_report.a, done_report.b) == (2000, -1000)
    done = device.executed()
    assert done.steps == (2000, 1000)
    assert done.laser_periods == 2  # off during the hold, on again after it
    assert done.laser_on_s == pytest.approx(2.0, abs=0.01)


def test_hold_when_idle_keeps_the_queue_from_starting(device: Device) -> None:
    s = device.session
    s.realtime(protocol.RT_HOLD)
    assert s.stream(["G1 A10 P10000", "G1 A20 P10000"]) == [Ok(), Ok()]
    time.sleep(0.05)
    r = s.status()
    assert (r.state, r.detail, r.queued, r.a) == ("Hold", 0, 2, 0)
    s.realtime(protocol.RT_RESUME)
    r = idle(device)
    assert r.a == 20
    assert device.executed().steps == (20, 0)


def test_reset_stops_clears_and_keeps_position(device: Device) -> None:
    s = device.session
    assert s.stream(["G91", "M3 S255", "G1 A4000 P2000000", "G1 A4000 P2000000"],
                    numbered_from=1) == [Ok()] * 4
    poll(device, lambda r: r.a >= 300, what="A >= 300")
    s.realtime(protocol.RT_RESET)
    assert s.wait_banner() == device.banner
    r = s.status()
    assert (r.state, r.queued, r.laser, r.done_line, r.accepted_line, r.underruns) == (
        "Idle", 0, 0, 0, 0, 0)
    stopped_at = r.a
    assert 300 <= stopped_at < 4000
    time.sleep(0.05)
    assert s.status().a == stopped_at, "motion after reset"
    # modal state is back to boot values: G90 (absolute), M5 (laser off)
    assert s.send("G1 A10 P1000000 S255") == Ok()
    r = idle(device)
    assert (r.a, r.laser) == (10, 0)
    done = device.executed()
    assert done.steps == (stopped_at + stopped_at - 10, 0)
    assert done.laser_periods == 1  # only before the reset


def test_reset_discards_a_partial_line(device: Device) -> None:
    s = device.session
    device.port.write(b"G1 A99 P10000")
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    assert s.send("G90") == Ok()
    assert s.status().accepted_line == 1
    assert_nothing_executed(device)
