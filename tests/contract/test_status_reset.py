"""The protocol contract: status report fields, what a reset keeps (docs/protocol.md
section 7) and a streamed job with character counting.

Each test runs against ``fivebar-mock://`` and against the firmware in simavr (see
conftest.py) and must pass on both; shared helpers are in contract_helpers.py.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest
from contract_devices import Device
from contract_helpers import dtr_reset, idle, poll, replies_to

from fivebar_host import protocol, wire
from fivebar_host.protocol import Ok, SettingLine

# --------------------------------------------------------------------------- status, streaming


def test_status_report_fields(device: Device) -> None:
    s = device.session
    r = s.status()
    assert (r.state, r.detail, r.a, r.b, r.queued, r.done_line, r.accepted_line, r.laser,
            r.underruns) == ("Idle", None, 0, 0, 0, 0, 0, 0, 0)
    lines = ["G1 A50 P100000", "G1 B-30 P100000", "G92 A0", "M18", "G90"]
    assert s.stream(lines, numbered_from=1) == [Ok()] * 5
    r = s.status()
    assert r.accepted_line == 5
    r = idle(device)
    assert (r.a, r.b, r.done_line, r.accepted_line, r.underruns) == (0, -30, 4, 5, 1)
    assert device.executed().steps == (50, 30)


def test_homed_flag_is_set_by_an_executed_g92_and_kept_by_ctrl_x(
        open_device: Callable[..., Device]) -> None:
    dev = open_device()
    s = dev.session
    assert s.status().homed is False  # power-on: the position is unknown
    s.realtime(protocol.RT_HOLD)  # keeps the G92 in the queue
    assert s.send("G92 A100 B-50") == Ok()
    time.sleep(0.05)
    r = s.status()
    assert (r.state, r.queued, r.a, r.homed) == ("Hold", 1, 0, False)  # queued, not executed
    s.realtime(protocol.RT_RESUME)
    r = idle(dev)
    assert (r.a, r.b, r.homed) == (100, -50, True)
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    r = s.status()
    assert (r.a, r.b, r.homed) == (100, -50, True)  # Ctrl-X keeps the position and H
    dev.power_cut()  # a power-on: the RAM (and the kept record) is lost
    r = s.status()
    assert (r.state, r.a, r.b, r.homed, r.done_line) == ("Idle", 0, 0, False, 0)
    assert dev.executed().steps == (0, 0)


# ------------------------------------------------------------- kept across a reset (section 7)



def test_a_reset_keeps_position_h_and_done_and_restarts_the_rest(device: Device) -> None:
    s = device.session
    lines = ["$9=5", "G92 A1000 B-500", "G91", "G1 A120 B-30 P20000", "G1 A-20 B45 P20000"]
    assert s.stream(lines, numbered_from=1) == [Ok()] * len(lines)
    r = idle(device)
    assert (r.a, r.b, r.homed, r.done_line, r.accepted_line) == (1100, -485, True, 5, 5)
    dtr_reset(device)
    r = s.status()
    assert (r.state, r.a, r.b, r.homed, r.done_line, r.accepted_line, r.queued, r.laser,
            r.underruns) == ("Idle", 1100, -485, True, 5, 0, 0, 0, 0)
    # everything else as at power-on: settings, G90, M5, numbered mode off
    assert replies_to(device, b"$$\n", 1)[9] == SettingLine(9, 100)
    assert s.send("G1 A1000 P20000 S255") == Ok()
    r = idle(device)
    assert (r.a, r.b, r.done_line, r.accepted_line) == (1000, -485, 2, 2)
    done = device.executed()
    assert done.steps == (120 + 20 + 100, 30 + 45) and done.net == (0, 15)
    assert done.laser_periods == 0


def test_a_reset_mid_segment_keeps_the_exact_position_and_the_line_before(
        device: Device) -> None:
    s = device.session
    lines = ["G92 A10 B20", "M3 S255", "G1 A110 B20 P50000", "G1 A1110 B-480 P2000000",
             "G1 A0 P1000000"]
    assert s.stream(lines, numbered_from=1) == [Ok()] * len(lines)
    poll(device, lambda r: r.done_line == 3 and r.a >= 300, what="part-way along line 4")
    dtr_reset(device)
    r = s.status()
    assert (r.state, r.done_line, r.accepted_line, r.homed, r.laser, r.queued) == (
        "Idle", 3, 0, True, 0, 0)
    assert 300 <= r.a < 1110 and -480 < r.b < 20
    time.sleep(0.05)
    assert (s.status().a, s.status().b) == (r.a, r.b), "motion after the reset"
    done = device.executed()
    assert done.net == (r.a - 10, r.b - 20)  # every step issued is in the kept position
    assert done.laser_periods == 1  # off at the reset


def test_a_reset_during_homing_keeps_h_0(open_device: Callable[..., Device]) -> None:
    dev = open_device(endstops=(-100000, -100000))
    s = dev.session
    for line in ("$7=1", "$8=1000", "$12=100000", "G92 A7 B7"):
        assert s.send(line) == Ok()
    assert idle(dev).homed
    dev.port.write(b"$H\n")
    poll(dev, lambda r: r.state == "Home" and r.a < -20, what="homing under way")
    dtr_reset(dev)
    r = s.status()
    # homing cleared H and counts its seek from 0; no alarm survives the reset
    assert (r.state, r.homed, r.done_line) == ("Idle", False, 4)
    assert r.a == r.b < -20
    done = dev.executed()
    assert done.net == (r.a, r.b)


def test_streamed_job_with_character_counting_is_exact(device: Device) -> None:
    segments = [(((i * 37) % 61) - 30, ((i * 53) % 41) - 20, 4000 + 100 * (i % 7), 255 * (i % 2))
                for i in range(100)]
    lines = ["G91", "M3 S0"] + [wire.g1(a, b, p, sv) for a, b, p, sv in segments]
    replies = device.session.stream(lines, rx_size=device.banner.rx, numbered_from=1)
    assert replies == [Ok()] * len(lines)
    r = idle(device)
    want = (sum(a for a, _, _, _ in segments), sum(b for _, b, _, _ in segments))
    assert (r.a, r.b) == want
    assert (r.done_line, r.accepted_line) == (len(lines), len(lines))
    assert r.underruns >= 1
    done = device.executed()
    assert done.net == want
    assert done.steps == (sum(abs(a) for a, _, _, _ in segments),
                          sum(abs(b) for _, b, _, _ in segments))
    burn = sum(p for _, _, p, sv in segments if sv) / 1e6
    assert done.laser_on_s == pytest.approx(burn, abs=0.01)
