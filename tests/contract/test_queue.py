"""The protocol contract: the block queue and the receive buffer (waiting lines,
overflow), and errors that arrive while a job runs.

Each test runs against ``fivebar-mock://`` and against the firmware in simavr (see
conftest.py) and must pass on both; shared helpers are in contract_helpers.py.
"""

from __future__ import annotations

import time

from contract_devices import Device
from contract_helpers import fill_queue, idle, poll, replies_to

from fivebar_host import protocol, wire
from fivebar_host.protocol import ErrorReply, Ok, StatusReport

# ------------------------------------------------------------------ queue and receive buffer



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
    flood = b"G1 P1000000\n" * (device.banner.rx // 12 + 2)  # > rx: the last bytes are lost
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
    long = b"G1 P1000 " + b"A1" * (device.banner.rx // 2 + 10)  # no newline: > rx, some lost
    assert len(long) > device.banner.rx > device.banner.line_max
    device.port.write(long)
    assert s.read_reply() == Ok()  # a slot frees; the rx bytes go into the line: too long
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
    widest = protocol.encode_line(wire.g1(-100_000_000, -100_000_000, 100_000_000, 255), 3)
    widest4 = protocol.encode_line(wire.g1(-100_000_000, -100_000_000, 100_000_000, 255), 4)
    merged = widest[:-1] + widest4[:-1] + protocol.encode_line("G1 A1010 P10000", 5)
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
