"""The pen servo's contract (docs/protocol.md 6.2, 8 `$14`, 9), on the mock and the firmware.

Each test runs against ``fivebar-mock://`` and the firmware in simavr (conftest.py): the
pen commands and their replies, the queued pen block that no step of the next segment may
enter before its move and settle time are over, and the park (pen up) at a hold (lowered
again, and waited for, before ``~`` resumes), a reset, a power-on and host silence.
"""

from __future__ import annotations

import time

from contract_devices import Device
from contract_helpers import dtr_reset, idle, poll

from fivebar_host import protocol
from fivebar_host.protocol import ErrorReply, Ok

UP, DOWN = 1800, 1000


def setup_pen(dev: Device) -> None:
    """`$14=UP`: the pen servo is set up and parked up at once."""
    assert dev.session.send(f"$14={UP}") == Ok()
    assert dev.session.status().pen == UP


def test_pen_commands_and_their_errors(device: Device) -> None:
    s = device.session
    assert s.status().pen == 0  # no pen set up: no pulses
    assert s.send("M280 S1000") == ErrorReply(19)  # NO_PEN
    assert s.send("$14=499") == ErrorReply(7)
    assert s.send("$14=2501") == ErrorReply(7)
    setup_pen(device)
    for bad, code in (("M280 S499", 7), ("M280 S2501", 7), ("M280 S1000 R-1", 7),
                      ("M280 S1000 D10001", 7), ("M280 R10", 6), ("M280 S1000 P5", 5),
                      ("M3 S300", 7)):
        assert s.send(bad) == ErrorReply(code), bad
    s.realtime(protocol.RT_RESET)  # error replies held nothing: the queue was empty
    s.wait_banner()
    assert s.status().pen == UP
    assert device.executed().steps == (0, 0)


def test_no_step_before_the_pen_has_had_its_time(device: Device) -> None:
    s = device.session
    setup_pen(device)
    assert s.stream(["M280 S1000 R200 D100", "G1 A50 P20000"], numbered_from=2) == [Ok()] * 2
    seen = []

    def check(r: protocol.StatusReport) -> bool:
        seen.append((r.pen, r.a))
        return r.state == "Idle" and r.queued == 0

    r = poll(device, check, what="the pen block and the segment done")
    assert (r.pen, r.a, r.done_line) == (DOWN, 50, 3)
    moving = [a for pen, a in seen if pen != DOWN]
    assert moving and all(a == 0 for a in moving), seen  # no step while the pulse moves
    assert any(UP > pen > DOWN for pen, _ in seen) or device.kind == "sim"
    assert device.executed().steps == (50, 0)


def test_a_hold_parks_the_pen_and_resume_lowers_it_first(device: Device) -> None:
    s = device.session
    setup_pen(device)
    for line in ("M280 S1000 D400", "G1 A100 P2000000"):
        assert s.send(line) == Ok()
    r = poll(device, lambda r: r.a > 0, what="the segment running")
    s.realtime(protocol.RT_HOLD)
    held = s.status()
    assert (held.state, held.pen) == ("Hold", UP)
    s.realtime(protocol.RT_RESUME)
    r = s.status()
    assert (r.state, r.pen, r.a) == ("Hold", DOWN, held.a)  # waits the pen's 400 ms
    r = poll(device, lambda r: r.state == "Run", what="resumed once the pen is down")
    r = idle(device)
    assert (r.a, r.pen) == (100, DOWN)
    assert device.executed().steps == (100, 0)


def test_reset_power_on_and_silence_park_the_pen(device: Device) -> None:
    s = device.session
    setup_pen(device)
    assert s.send("M280 S1000") == Ok()
    poll(device, lambda r: r.pen == DOWN, what="pen down")
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    assert s.status().pen == UP  # Ctrl-X
    assert s.send("M280 S1000") == Ok()
    poll(device, lambda r: r.pen == DOWN, what="pen down")
    dtr_reset(device)
    assert s.status().pen == UP  # a reset that keeps the RAM
    device.power_cut()
    r = s.status()
    assert (r.pen, r.homed) == (UP, False)  # $14 is kept in the EEPROM
    for line in ("$6=100", "M280 S1000"):
        assert s.send(line) == Ok()
    poll(device, lambda r: r.pen == DOWN, what="pen down")
    time.sleep(0.5)  # silence: > 100 ms in both the emulator's and the mock's clock
    r = s.status()
    assert (r.state, r.pen) == ("Idle", UP)  # an idle machine only parks the pen
    assert device.executed().steps == (0, 0)
