"""The protocol contract: settings ($$, $n=v), homing ($H) and the alarms that lock.

Each test runs against ``fivebar-mock://`` and against the firmware in simavr (see
conftest.py) and must pass on both; shared helpers are in contract_helpers.py.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from contract_devices import Device
from contract_helpers import DOC_DEFAULTS, assert_nothing_executed, idle, poll, replies_to

from fivebar_host import protocol
from fivebar_host.protocol import AlarmPush, ErrorReply, Ok, SettingLine

# ------------------------------------------------------------------ settings, homing, alarms


def test_settings_listing_and_change(device: Device) -> None:
    s = device.session
    got = replies_to(device, b"$$\n", 1)
    assert got[-1] == Ok()
    assert got[:-1] == [SettingLine(i, v) for i, v in enumerate(DOC_DEFAULTS)]
    assert s.send("$0=1234") == Ok()
    assert s.send("$10=-77") == Ok()
    got = replies_to(device, b"$$\n", 1)
    assert got[0] == SettingLine(0, 1234) and got[10] == SettingLine(10, -77)
    s.realtime(protocol.RT_RESET)  # settings survive a reset
    s.wait_banner()
    assert replies_to(device, b"$$\n", 1)[0] == SettingLine(0, 1234)
    assert_nothing_executed(device)


def test_homing_finds_the_switches(open_device: Callable[..., Device]) -> None:
    dev = open_device(endstops=(-300, -120))
    s = dev.session
    for line in ("$7=1", "$8=4000", "$9=50", "$10=1000", "$11=-7"):
        assert s.send(line) == Ok()
    assert s.status().homed is False
    assert s.send("$H") == Ok()
    r = s.status()
    assert (r.state, r.a, r.b, r.homed) == ("Idle", 1000, -7, True)
    assert s.send("G1 A1010 P10000") == Ok()
    r = idle(dev)
    assert r.a == 1010
    done = dev.executed()
    assert done.steps == (300 + 50 + 10, 120 + 50)
    assert done.net == (-300 + 50 + 10, -120 + 50)


def test_homing_failure_raises_an_alarm_that_locks(device: Device) -> None:
    s = device.session
    for line in ("$7=1", "$8=40000", "$12=100", "G92 A500 B500"):
        assert s.send(line) == Ok()
    assert idle(device).homed
    got = replies_to(device, b"$H\n", 1)
    assert got == [AlarmPush(31), ErrorReply(31)]
    r = s.status()
    # the seek counts from 0: the position (and H) are unknown after a failed homing
    assert (r.state, r.detail, r.a, r.b, r.homed) == ("Alarm", 31, -100, -100, False)
    for line in ("G1 A0 P100000", "G90", "M3 S1", "G92 A0", "M17"):
        assert s.send(line) == ErrorReply(14), line
    for line in ("", "$I", "M110", "$0=20000"):
        assert s.send(line) == Ok(), line
    s.realtime(protocol.RT_RESET)  # a reset keeps the alarm
    s.wait_banner()
    assert s.status().state == "Alarm"
    assert s.send("$X") == Ok()
    r = s.status()
    assert (r.state, r.a) == ("Idle", -100)
    assert s.send("G1 A0 B0 P100000") == Ok()
    idle(device)
    done = device.executed()
    assert done.steps == (200, 200) and done.net == (0, 0)


def test_hold_during_homing_aborts_it(open_device: Callable[..., Device]) -> None:
    dev = open_device(endstops=(-100000, -100000))
    s = dev.session
    for line in ("$7=1", "$8=1000", "$12=100000"):
        assert s.send(line) == Ok()
    dev.port.write(b"$H\n")
    r = poll(dev, lambda r: r.state == "Home" and r.a < -20, what="homing under way")
    s.realtime(protocol.RT_HOLD)
    assert s.read_reply() == ErrorReply(32)
    assert AlarmPush(32) in s.messages
    r = s.status()
    assert (r.state, r.detail) == ("Alarm", 32)
    time.sleep(0.02)
    assert s.status().a == r.a
    done = dev.executed()
    assert done.net == (r.a, r.b)


def test_endstop_outside_homing_raises_alarm_30(open_device: Callable[..., Device]) -> None:
    dev = open_device(endstops=(-100, None))
    s = dev.session
    for line in ("$7=1", "M3 S255", "G1 A-500 P100000"):
        assert s.send(line) == Ok()
    r = poll(dev, lambda r: r.state == "Alarm", what="Alarm")
    assert (r.detail, r.laser, r.queued, r.a) == (30, 0, 0, -100)  # stopped on the switch
    assert AlarmPush(30) in s.messages
    assert s.send("G1 A0 P100000") == ErrorReply(14)
    assert s.send("$X") == Ok()
    assert s.status().state == "Idle"
    # away from the pressed switch is allowed: that is how a machine is freed
    assert s.send("G1 A0 P100000") == Ok()
    r = idle(dev)
    assert (r.state, r.a) == ("Idle", 0)
    done = dev.executed()
    assert done.steps == (200, 0) and done.laser_periods == 2  # M3 is modal


def test_stepping_into_a_pressed_switch_alarms_at_once(open_device: Callable[..., Device]
                                                       ) -> None:
    dev = open_device(endstops=(0, None))  # pressed from power-on
    s = dev.session
    assert s.send("$7=1") == Ok()
    assert s.send("G1 A20 P100000") == Ok()  # away: allowed
    idle(dev)
    assert s.send("G1 A-30 P100000") == Ok()  # back: pressed again at 0
    r = poll(dev, lambda r: r.state == "Alarm", timeout=3.0, what="Alarm")
    assert (r.detail, r.a) == (30, 0)
    assert s.send("$X") == Ok()
    assert s.send("G1 A-5 P100000") == Ok()  # still pressed: alarm at the first step
    r = poll(dev, lambda r: r.state == "Alarm", timeout=3.0, what="Alarm")
    assert (r.detail, r.a) == (30, -1)
    assert dev.executed().steps == (20 + 20 + 1, 0)
