"""The protocol contract (docs/protocol.md), checked on the mock and on the real firmware.

Each test runs against ``fivebar-mock://`` and against the firmware in simavr (see
conftest.py) and must pass on both: the mock is only useful while it answers like the
firmware.  Besides the replies, every test checks what was physically executed — step
pulses and laser output — so "no motion after refused input" and "exact step counts" are
checked on the pins, not only in status reports.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest
from contract_devices import Device

from fivebar_host import protocol
from fivebar_host.protocol import (
    AlarmPush,
    Banner,
    ErrorReply,
    Message,
    Ok,
    SettingLine,
    StatusReport,
)

#: Boot values of the settings, docs/protocol.md section 8.
DOC_DEFAULTS = [20000, -100000, 100000, -100000, 100000, 1, 2000, 0, 2000, 100, 0, 0, 20000, 0,
                0]


def poll(dev: Device, until: Callable[[StatusReport], bool], timeout: float = 10.0,
         what: str = "the expected state") -> StatusReport:
    """Poll ``?`` until ``until(report)``; fail with the last report after ``timeout``."""
    deadline = time.monotonic() + timeout
    report = dev.session.status()
    while not until(report):
        if time.monotonic() > deadline:
            pytest.fail(f"{dev.kind}: never reached {what}; last status {report}")
        time.sleep(0.002)
        report = dev.session.status()
    return report


def idle(dev: Device) -> StatusReport:
    """Wait until Idle with an empty queue."""
    return poll(dev, lambda r: r.state == "Idle" and r.queued == 0, what="Idle")


def replies_to(dev: Device, data: bytes, count: int) -> list[Message]:
    """Write ``data`` at once and collect ``count`` replies plus anything between them."""
    dev.port.write(data)
    got: list[Message] = []
    while sum(isinstance(m, Ok | ErrorReply) for m in got) < count:
        got.append(dev.session.read_message())
    return got


def assert_nothing_executed(dev: Device) -> None:
    """No motion, no laser; the device still answers."""
    report = dev.session.status()
    assert (report.state, report.a, report.b, report.queued, report.laser) == (
        "Idle", 0, 0, 0, 0)
    assert dev.session.send("M110") == Ok()  # accepted in any mode; ends numbered mode
    assert dev.session.send("$I") == Ok()
    done = dev.executed()
    assert done.steps == (0, 0), f"{dev.kind}: motors stepped after refused input"
    assert done.laser_periods == 0


# --------------------------------------------------------------------------- banner, replies


def test_banner_and_info(device: Device) -> None:
    b = device.banner
    assert (b.version, b.proto, b.rx, b.queue, b.line_max) == (
        "1.0.0", protocol.PROTOCOL_VERSION, 128, 16, 80)
    device.port.write(b"$I\n")
    assert device.session.read_message() == b
    assert device.session.read_reply() == Ok()


def test_one_reply_per_line_in_order(device: Device) -> None:
    lines = [
        b"G90",  # ok
        b"G5",  # error:4
        b"$I",  # banner, ok
        b"M3 S10",  # ok
        b"G1 A10",  # error:6 (no P)
        b"G90 A1",  # error:5
        b"M5\r",  # ok (\r dropped)
        b"",  # ok
        b"  ; only a comment",  # ok
        b"g91",  # ok (case-insensitive)
        b"G1A5B-5P10000S0;tight",  # ok: queued
    ]
    data = b"\n".join(lines) + b"\n"
    assert len(data) <= device.banner.rx
    got = replies_to(device, data, len(lines))
    assert got == [
        Ok(), ErrorReply(4), device.banner, Ok(), Ok(), ErrorReply(6), ErrorReply(5), Ok(), Ok(),
        Ok(), Ok(), Ok(),
    ]
    report = idle(device)
    assert (report.a, report.b) == (5, -5)
    assert (report.done_line, report.accepted_line) == (11, 11)  # lines without N count
    assert device.executed().net == (5, -5)


# --------------------------------------------------------------------------- error codes

_BAD_LINES: list[tuple[int, list[bytes]]] = [
    (1, [b"\x01\x02\xfe\xff\x80 G1 A10 P1000", b"G1 A10 P10000\x7f"]),
    (2, [b"G1 P1000 " + b"A1" * 60]),
    (3, [b"G1 A1.5 P10000", b"G1 A12# P10000", b"G", b"$5=x"]),
    (4, [b"G5 A10 P1000", b"M999", b"X10", b"$Q", b"$", b"G70000"]),
    (5, [b"G90 A1", b"G1 A1 A2 P10000", b"G1 A1 P10000 G1", b"M5 S1", b"$I x", b"$5=1x"]),
    (6, [b"G1 A10", b"G92", b"$5"]),
    (7, [b"G1 A100000001 P1000", b"G1 A10 P99", b"G1 A10 P1000 S256", b"M3 S300",
         b"G1 A99999999999 P1000", b"$5=2", b"$0=0", b"G92 A-100000001"]),
    (11, [b"G1 A200000 P10000000", b"G1 B-100001 P10000000"]),
    (12, [b"G1 A1000 P1000", b"G1 B-21 P1000"]),
    (16, [b"$H"]),
    (17, [b"$15=1", b"$99=0", b"$300=1"]),
]


@pytest.mark.parametrize(("code", "lines"), _BAD_LINES, ids=[f"error{c}" for c, _ in _BAD_LINES])
def test_bad_input_is_refused_without_motion(device: Device, code: int, lines: list[bytes]
                                             ) -> None:
    for line in lines:
        assert device.session.send_raw(line + b"\n") == ErrorReply(code), line
    assert_nothing_executed(device)


def test_framing_errors_ask_for_resend(device: Device) -> None:
    s = device.session
    good = protocol.encode_line("G1 A10 P10000", line_number=1)
    assert s.send_raw(good.replace(b"A10", b"A90")) == ErrorReply(8, resend=1)  # CRC mismatch
    # the checksum field of G90 is *56831/3
    for bad in (b"G90*56831", b"G90*56831/", b"G90*56831/4", b"G90*56831/2", b"G90*56830/3",
                b"G90*65536/3", b"G90*056831/3", b"G90*56831/03", b"G90*12x/3",
                b"G90*56831/3x", b"G90*", b"G90*/3", b"G90*56831 /3"):
        assert s.send_raw(bad + b"\n") == ErrorReply(8, resend=1), bad
    assert s.send_raw(b"N1 G90\n") == ErrorReply(10, resend=1)  # number without checksum
    assert s.send("G90", line_number=2) == ErrorReply(9, resend=1)  # gap
    assert s.send("G90", line_number=1) == Ok()
    assert s.send("G90", line_number=1) == ErrorReply(9, resend=2)  # repeat
    assert s.send_raw(b"N2# G90" + protocol.checksum_field(b"N2# G90") + b"\n") == (
        ErrorReply(3))  # malformed N: refused, not accepted
    assert s.status().accepted_line == 1
    assert_nothing_executed(device)


def test_line_counter_rules(device: Device) -> None:
    s = device.session
    assert s.send("G90") == Ok()  # implicit 1
    assert s.send("G5") == ErrorReply(4)  # refused but accepted: implicit 2
    assert s.send_raw(protocol.encode_line("G90", checksum=True)) == Ok()  # implicit 3
    assert s.send("G90", line_number=4) == Ok()
    assert s.status().accepted_line == 4
    assert s.send("M110", line_number=100) == Ok()
    assert s.status().accepted_line == 100
    assert s.send("G90", line_number=101) == Ok()
    assert s.send("M110") == Ok()  # without N: counter to 0
    assert s.send("G90", line_number=1) == Ok()
    assert_nothing_executed(device)


def test_after_a_numbered_line_every_line_must_be_numbered(device: Device) -> None:
    # Strict framing (docs/protocol.md 5.2): a numbered line that lost both its "N<n> " and
    # its "*<crc>" to line noise must not run as an unnumbered line.
    s = device.session
    got = replies_to(device, b"$I\n", 1)  # a host that does not number lines yet
    assert got == [device.banner, Ok()]
    assert s.send("G91", line_number=2) == Ok()
    for line in (b"G1 A50 P10000\n", protocol.encode_line("G1 A50 P10000", checksum=True),
                 b"\n", b"$I\n", b"G5\n", b"M110 A1\n"):
        assert s.send_raw(line) == ErrorReply(10, resend=3), line  # refused, not executed
    r = s.status()
    assert (r.state, r.a, r.accepted_line) == ("Idle", 0, 2)
    assert s.send("G1 A7 P10000", line_number=3) == Ok()
    assert idle(device).a == 7
    assert s.send("M110", line_number=10) == Ok()  # a numbered M110 keeps numbered mode
    assert s.send("G90") == ErrorReply(10, resend=11)
    assert s.send("M110") == Ok()  # a plain M110 ends it
    assert s.send("G90") == Ok()
    assert s.send("G91", line_number=2) == Ok()
    assert s.send("G90") == ErrorReply(10, resend=3)
    s.realtime(protocol.RT_RESET)  # so does a reset
    s.wait_banner()
    assert s.send("G90") == Ok()
    r = idle(device)
    assert (r.a, r.b, r.accepted_line) == (7, 0, 1)
    assert device.executed().steps == (7, 0)


def test_the_first_numbered_line_losing_its_n_and_star_asks_for_resend(device: Device
                                                                       ) -> None:
    # docs/protocol.md 5.2 step 5: before numbered mode begins, a line that lost its "N" and
    # its "*" is refused as well.  N1 G1 A10 P1000*13217/15 without both bytes used to be
    # answered error:4 and counted as line 1, so the host's N2 was taken next: line 1 lost.
    s = device.session
    line = protocol.encode_line("G1 A10 P1000", line_number=1)
    assert line == b"N1 G1 A10 P1000*13217/15\n"
    damaged = line.replace(b"N", b"").replace(b"*", b"")
    assert damaged == b"1 G1 A10 P100013217/15\n"  # fuzz/corpus/regress_first_line_lost_n_star
    assert s.send_raw(damaged) == ErrorReply(10, resend=1)
    # the N replaced by a ';' (a comment line), or by a 'G'; the '*' by a ';' or lost
    for noisy in (b";1 G1 A10 P100013217/15\n", b"G1 G1 A10 P100013217/15\n",
                  b"1 G1 A10 P1000;13217/15\n", b" 1 G1 A10 P1000 13217/15 \n"):
        assert s.send_raw(noisy) == ErrorReply(10, resend=1), noisy
    assert s.status().accepted_line == 0  # none of them was accepted
    assert s.send_raw(line) == Ok()  # the resend
    assert s.send("G1 A0 P1000", line_number=2) == Ok()
    r = idle(device)
    assert (r.a, r.done_line, r.accepted_line) == (0, 2, 2)
    assert s.send("M110") == Ok()
    # the rule's documented cost, for other senders (protocol.encode_line never puts a
    # comment in a line)
    assert s.send_raw(b"G90 ; 1/2\n") == ErrorReply(10, resend=1)
    assert s.send_raw(b"G90 ; 1 of 2\n") == Ok()
    assert device.executed().steps == (20, 0)  # line 1 ran once, then line 2


def test_realtime_bytes_inside_a_line_are_not_part_of_it(device: Device) -> None:
    got = replies_to(device, b"G1 A1?0 P1!~0000\n", 1)
    assert isinstance(got[0], StatusReport)
    assert got[1:] == [Ok()]
    report = idle(device)
    assert (report.a, report.b) == (10, 0)
    assert device.executed().net == (10, 0)


def test_motors_off_refuses_motion(device: Device) -> None:
    s = device.session
    assert s.send("M18") == Ok()
    idle(device)
    assert s.send("G1 A10 P10000") == ErrorReply(15)
    assert s.send("G1 P10000") == Ok()  # a dwell needs no motors
    idle(device)
    assert s.send("M17") == Ok()
    assert s.send("G1 A10 P10000") == Ok()
    report = idle(device)
    assert (report.a, report.state) == (10, "Idle")
    assert device.executed().steps == (10, 0)


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


def dtr_reset(dev: Device) -> None:
    """Pulse DTR as ``Link.hardware_reset`` does (an Uno's auto-reset) and read the banner."""
    dev.port.dtr = False
    dev.port.dtr = True
    assert dev.session.wait_banner() == dev.banner


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
    lines = ["G91", "M3 S0"] + [protocol.g1(a, b, p, sv) for a, b, p, sv in segments]
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


# ------------------------------------------------------------------ queue and receive buffer


def fill_queue(dev: Device, p_us: int = 1_000_000) -> int:
    """Take every queue slot with dwells (streamed: fast); return the lines sent.

    The banner's ``queue:`` counts the block executing as well: once one runs,
    ``queue - 1`` wait (``Q:`` counts only those).
    """
    n = dev.banner.queue
    assert dev.session.stream([f"G1 P{p_us}"] * n) == [Ok()] * n
    r = dev.session.status()
    assert (r.state, r.queued, r.done_line) == ("Run", n - 1, 0)
    return n


def test_a_line_needing_a_queue_slot_waits_unanswered(device: Device) -> None:
    s = device.session
    sent = fill_queue(device)
    got = replies_to(device, b"G1 P1000\nG90\n?", 0)
    while not any(isinstance(m, StatusReport) for m in got):
        got.append(s.read_message())
    assert not any(isinstance(m, Ok | ErrorReply) for m in got), got
    report = next(m for m in got if isinstance(m, StatusReport))
    # the waiting line is accepted (its number counted) but not queued; no block finished yet
    assert (report.queued, report.accepted_line, report.done_line) == (
        device.banner.queue - 1, sent + 1, 0)
    assert s.read_reply() == Ok()  # once the first dwell ends
    assert s.read_reply() == Ok()  # G90 behind it
    assert s.status().done_line >= 1
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    assert device.executed().steps == (0, 0)


def test_receive_overflow_is_reported_on_the_next_line(device: Device) -> None:
    s = device.session
    fill_queue(device)
    device.port.write(b"G1 P1000\n")  # waits for a slot; the main loop stops reading
    flood = b"G1 P1000000\n" * 12  # 144 bytes > rx: the last 16 are lost
    assert len(flood) > device.banner.rx
    device.port.write(flood)
    assert s.read_reply() == Ok()  # the waiting line, once a block ends
    assert s.read_reply() == ErrorReply(18)
    r = s.status()
    assert (r.state, r.detail, r.laser) == ("Hold", 2, 0)  # an error holds a running job
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    assert device.executed().steps == (0, 0)


def test_overflow_is_reported_before_line_too_long(device: Device) -> None:
    # A line that lost bytes to the overflow and is too long gets error:18: the overflow
    # is reported on the next line handled (docs/protocol.md section 4).
    s = device.session
    fill_queue(device)
    device.port.write(b"G1 P1000\n")  # waits for a slot
    device.port.write(b"G1 P1000 " + b"A1" * 70)  # 149 bytes, no newline: 21 lost
    assert s.read_reply() == Ok()  # a slot frees; the 128 bytes go into the line: too long
    device.port.write(b"\n")
    assert s.read_reply() == ErrorReply(18)
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    assert device.executed().steps == (0, 0)


def test_reset_discards_a_line_waiting_for_a_slot(device: Device) -> None:
    # Ctrl-X's mo_stop() frees a slot: the waiting line must not take it (no 'ok' before
    # the banner) and the queue must not start again (no laser flash).  The firmware
    # checks for a pending reset in the critical sections that use a slot or start the
    # queue; firmware/tests/unit_tests.c delivers the Ctrl-X at every point of a pass.
    s = device.session
    assert s.send("M3 S255") == Ok()
    fill_queue(device)
    device.port.write(b"G1 P1000 S255\n")  # received before the Ctrl-X: discarded, no reply
    time.sleep(0.02)
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    assert not any(isinstance(m, Ok | ErrorReply) for m in s.messages), s.messages
    r = s.status()
    assert (r.state, r.queued, r.laser) == ("Idle", 0, 0)
    time.sleep(0.02)
    assert device.executed().laser_periods == 1  # no flash after the reset


# --------------------------------------------------------------------------- errors while running


def test_errors_hold_a_running_job_but_resend_requests_do_not(device: Device) -> None:
    s = device.session
    assert s.send("M3 S255") == Ok()
    assert s.send("G1 A1000 P1000000") == Ok()
    poll(device, lambda r: r.a > 0, what="moving")
    assert s.send_raw(b"G90*1/3\n") == ErrorReply(8, resend=3)
    assert s.status().state == "Run"
    assert s.send("$0=100") == ErrorReply(13)  # settings need an idle machine
    r = s.status()
    assert (r.state, r.detail, r.laser) == ("Hold", 2, 0)
    s.realtime(protocol.RT_RESUME)
    r = idle(device)
    assert r.a == 1000
    done = device.executed()
    assert done.steps == (1000, 0) and done.laser_periods == 2


def test_lines_merged_by_a_lost_newline_ask_for_resend_without_holding_the_job(
        device: Device) -> None:
    """A lost newline merges two numbered lines.  Short enough or too long for the line
    buffer, the merged line is refused with ``error:8`` and a resend (docs/protocol.md 5.2,
    steps 2 and 3), so a running job goes on; both lines are then sent again."""
    s = device.session
    assert s.send("M3 S255", line_number=1) == Ok()
    assert s.send("G1 A1000 P1000000", line_number=2) == Ok()
    poll(device, lambda r: r.a > 0, what="moving")
    widest = protocol.encode_line(protocol.g1(-100_000_000, -100_000_000, 100_000_000, 255), 3)
    merged = widest[:-1] + protocol.encode_line("G1 A1010 P10000", 4)
    assert len(merged) - 1 > device.banner.line_max
    assert s.send_raw(merged) == ErrorReply(8, resend=3)
    short = protocol.encode_line("G90", 3)[:-1] + protocol.encode_line("G90", 4)
    assert len(short) - 1 <= device.banner.line_max
    assert s.send_raw(short) == ErrorReply(8, resend=3)
    r = s.status()
    assert (r.state, r.accepted_line) == ("Run", 2)
    assert s.send("G90", line_number=3) == Ok()
    assert s.send("G1 A1010 P10000", line_number=4) == Ok()
    r = idle(device)
    assert (r.a, r.accepted_line) == (1010, 4)
    assert device.executed().steps == (1010, 0)


def test_laser_silence_holds_the_job(device: Device) -> None:
    s = device.session
    for line in ("$6=100", "M3 S255", "G1 P10000000"):
        assert s.send(line) == Ok()
    time.sleep(0.5)  # silence: > 100 ms in both the emulator's and the mock's clock
    r = s.status()
    assert (r.state, r.detail, r.laser) == ("Hold", 1, 0)
    s.realtime(protocol.RT_RESET)
    s.wait_banner()
    assert device.executed().laser_periods == 1


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


def test_banner_is_the_only_message_on_boot(device: Device) -> None:
    assert device.session.messages == []
    assert isinstance(device.banner, Banner)
    assert device.port.in_waiting == 0
