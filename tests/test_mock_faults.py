"""``fivebar-mock://`` URL options: each fault does what the docs say, and nothing else.

The protocol behaviour of the mock is checked against the real firmware by
tests/contract/; these tests cover what only the mock has: URL parsing, fault injection,
time scaling, the ledger, named machines, and pyserial's timeout semantics.
"""

from __future__ import annotations

import threading
import time

import pytest
import serial

from fivebar_host import protocol, wire
from fivebar_host.devices import mock, urls
from fivebar_host.devices.mock import MockSerial, MockURLError, parse_mock_url
from fivebar_host.protocol import Banner, ErrorReply, Message, Ok, StatusReport

BANNER = "fivebar 1.1.0 proto:4 rx:255 queue:16 line:128"


def open_mock(options: str = "", timeout: float | None = 0.2) -> MockSerial:
    """Open ``fivebar-mock://?<options>`` through pyserial and read the boot banner."""
    urls.register()
    port = serial.serial_for_url(f"fivebar-mock://?{options}", timeout=timeout)
    assert isinstance(port, MockSerial)
    assert port.readline().decode().rstrip() == port.firmware.banner_text()  # type: ignore[union-attr]
    return port


def messages(port: MockSerial, wait: float = 0.0) -> list[Message]:
    """Every line the device has sent so far (after ``wait`` seconds), decoded."""
    if wait:
        time.sleep(wait)
    out = []
    while port.in_waiting:
        out.append(protocol.parse_message(port.readline().decode()))
    return out


def reply(port: MockSerial, line: str | bytes) -> Message:
    """Send one line and return its reply (``ok`` / ``error``), skipping other messages."""
    port.write(line if isinstance(line, bytes) else protocol.encode_line(line))
    while True:
        raw = port.readline()
        assert raw, "no reply before the timeout"
        msg = protocol.parse_message(raw.decode())
        if protocol.is_reply(msg):
            return msg


def status(port: MockSerial) -> StatusReport:
    port.write(b"?")
    while True:
        msg = protocol.parse_message(port.readline().decode())
        if isinstance(msg, StatusReport):
            return msg


@pytest.fixture(autouse=True)
def _clean_machines() -> None:
    mock.forget_machines()


# --------------------------------------------------------------------------- registration, URL


def test_register_is_idempotent_and_serves_the_scheme() -> None:
    urls.register()
    urls.register()
    assert serial.protocol_handler_packages.count("fivebar_host.devices") == 1
    port = serial.serial_for_url("fivebar-mock://", timeout=0.2)
    assert isinstance(port, MockSerial)
    assert port.readline() == (BANNER + "\r\n").encode()
    port.close()
    with pytest.raises(ValueError, match="protocol 'nosuch-mock' not known"):
        serial.serial_for_url("nosuch-mock://")


@pytest.mark.parametrize(
    ("url", "named"),
    [
        ("fivebar-mock://?speeed=1", "speeed"),
        ("fivebar-mock://?speed=1&bogus", "bogus"),
        ("fivebar-mock://?speed=-1", "speed"),
        ("fivebar-mock://?drop=1.5", "drop"),
        ("fivebar-mock://?corrupt=x", "corrupt"),
        ("fivebar-mock://?endstops=5", "endstops"),
        ("fivebar-mock://?error_code=30", "error_code"),
        ("fivebar-mock://?error_on=0", "error_on"),
        ("fivebar-mock://?rx=abc", "rx"),
        ("fivebar-mock://?queue=0", "queue"),
        ("fivebar-mock://?speed=1&speed=2", "speed"),
        ("fivebar-mock://somewhere", "somewhere"),
    ],
)
def test_bad_options_raise_value_error_naming_them(url: str, named: str) -> None:
    with pytest.raises(ValueError, match=named):
        parse_mock_url(url)
    urls.register()
    with pytest.raises(MockURLError, match=named) as info:
        serial.serial_for_url(url)
    assert isinstance(info.value, ValueError) and isinstance(info.value, serial.SerialException)


def test_options_parse() -> None:
    o = parse_mock_url("fivebar-mock://?speed=0&drop=0.01&corrupt=0.02&seed=7"
                       "&disconnect_after=9&reset_after=8&error_on=3&error_code=9"
                       "&stall_after=6&endstops=-300,&rx=64&queue=8&line=40&version=2.0"
                       "&proto=3&machine=m&watchdog=120")
    assert (o.speed, o.drop, o.corrupt, o.seed, o.watchdog) == (0.0, 0.01, 0.02, 7, 120)
    assert (o.disconnect_after, o.reset_after, o.error_on, o.error_code, o.stall_after) == (
        9, 8, 3, 9, 6)
    assert o.endstops == (-300, None)
    assert (o.rx, o.queue, o.line, o.version, o.proto, o.machine) == (64, 8, 40, "2.0", 3, "m")
    assert parse_mock_url("fivebar-mock://") == mock.MockOptions()


# --------------------------------------------------------------------------- sizes, banner


def test_sizes_and_version_options_change_the_device() -> None:
    port = open_mock("rx=64&queue=4&line=40&version=9.9&proto=3&speed=1")
    assert reply(port, "$I") == Ok()
    assert messages(port) == []
    assert reply(port, b"G1 P1000 " + b"A1" * 16 + b"\n") == ErrorReply(2)  # 41 > line:40
    for _ in range(4):  # one runs, three wait: the queue's 4 slots
        assert reply(port, "G1 P1000000") == Ok()
    port.write(b"G1 P1000\n")  # needs a slot: waits
    port.write(b"G1 P1000000\n" * 6)  # 72 bytes > rx:64
    assert messages(port, 0.01) == []
    port.write(b"?")
    (st,) = messages(port)
    assert isinstance(st, StatusReport) and st.queued == 3
    port.write(b"\x18")
    assert messages(port) == [Banner("9.9", 3, 64, 4, 40)]


# --------------------------------------------------------------------------- time


def test_speed_scales_motion_time() -> None:
    port = open_mock("speed=1")
    assert reply(port, "G1 A1000 P300000") == Ok()  # 0.3 s at real speed
    time.sleep(0.12)
    mid = status(port)
    assert mid.state == "Run" and 0 < mid.a < 1000
    time.sleep(0.35)
    assert (status(port).state, status(port).a) == ("Idle", 1000)
    port.close()

    fast = open_mock("speed=0")
    assert reply(fast, "G1 A1000 P100000000") == Ok()  # 100 s, executed at once
    time.sleep(0.03)  # the queue still waits 20 ms (wall clock) before it starts
    st = status(fast)
    assert (st.state, st.a, st.done_line) == ("Idle", 1000, 1)


def test_laser_timeout_runs_in_wall_time_whatever_the_speed() -> None:
    port = open_mock("speed=100")
    for line in ("$6=100", "M3 S255", "G1 P100000000"):  # 100 s: 1 s of wall time
        assert reply(port, line) == Ok()
    time.sleep(0.05)
    assert status(port).laser == 255
    time.sleep(0.12)  # silence since the last byte: the `?` 50 ms ago + 120 ms > 100 ms
    st = status(port)
    assert (st.state, st.detail, st.laser) == ("Hold", 1, 0)


# --------------------------------------------------------------------------- faults


def _reply_or_none(port: MockSerial) -> Message | None:
    """The next reply, or None when none comes before the port's timeout."""
    while True:
        raw = port.readline()
        if not raw:
            return None
        msg = protocol.parse_message(raw.decode())
        if protocol.is_reply(msg):
            return msg


def send_reliably(port: MockSerial, body: str, n: int) -> int:
    """Send-and-wait with resend, as a correct host does; returns the errors seen."""
    data = protocol.encode_line(body, n)
    errors = 0
    for _ in range(100):
        port.write(data)
        msg = _reply_or_none(port)
        if msg == Ok():
            return errors
        errors += 1
        if msg is None:  # its newline was lost: the resend merges with it and fails the CRC
            continue
        assert isinstance(msg, ErrorReply)
        if msg.resend is None:
            # It lost both its N and its '*': taken as an unnumbered line, counted and
            # refused.  Resume the job the error held and set the counter back.
            port.write(protocol.RT_RESUME)
            while _reply_or_none(port) != Ok():
                port.write(protocol.encode_line("M110", n - 1))
            continue
        if msg.code == 9 and msg.resend == n + 1:
            return errors  # accepted earlier: the reply waited for was the merged line's
        assert msg.resend == n, msg
    raise AssertionError(f"line {n} never accepted")


@pytest.mark.parametrize("fault", ["drop=0.01&seed=2", "corrupt=0.01&seed=1",
                                   "drop=0.005&corrupt=0.005&seed=3"])
def test_line_noise_is_absorbed_by_checksums_and_resend(fault: str) -> None:
    port = open_mock(f"{fault}&speed=0", timeout=0.02)
    moves = [(7 * i % 23 - 11, 5 * i % 17 - 8) for i in range(150)]
    errors = sum(send_reliably(port, wire.g1(a, b, 1000), n)
                 for n, (a, b) in enumerate([(0, 0), *moves], start=1))
    assert errors >= 5, "the fault never fired"
    time.sleep(0.05)
    port.write(b"?")
    ledger = port.ledger
    g1 = [e for e in ledger if e.kind == "G1"]
    assert [e.line for e in g1] == list(range(1, len(moves) + 2)), "a line lost or run twice"
    assert sum(e.steps[0] for e in g1) == moves[-1][0]
    assert sum(e.steps[1] for e in g1) == moves[-1][1]


def test_seed_makes_the_faults_reproducible() -> None:
    def run(seed: int) -> list[Message]:
        port = open_mock(f"corrupt=0.05&drop=0.05&seed={seed}&speed=0")
        port.write(b"".join(protocol.encode_line(f"G1 A{i} P1000", i + 1) for i in range(8)))
        time.sleep(0.03)
        got = messages(port)
        port.close()
        return got

    first = run(1)
    assert any(m != Ok() for m in first)
    assert run(1) == first
    assert run(2) != first


def test_drop_everything_keeps_real_time_bytes() -> None:
    port = open_mock("drop=1")
    port.write(b"G1 A10 P1000\nG90\n")
    assert messages(port, 0.03) == []
    st = status(port)  # `?` is never dropped
    assert (st.accepted_line, st.a) == (0, 0)


def test_disconnect_after_n_lines() -> None:
    port = open_mock("disconnect_after=3&speed=0")
    assert reply(port, "M3 S9") == Ok()
    assert reply(port, "G1 A10 P1000") == Ok()
    with pytest.raises(serial.SerialException, match="disconnect"):
        port.write(b"G1 A30 P1000\nG1 A40 P1000\n")
    for call in (lambda: port.read(1), lambda: port.write(b"?"), lambda: port.in_waiting):
        with pytest.raises(serial.SerialException):
            call()
    time.sleep(0.03)  # the device runs on: the two queued moves execute
    g1 = [e for e in port.ledger if e.kind == "G1"]
    assert [(e.line, e.end, e.power, e.complete) for e in g1] == [
        (2, (10, 0), 9, True), (3, (30, 0), 9, True)]
    port.close()


def _reset_mid_segment(fault: str) -> tuple[MockSerial, StatusReport]:
    """Numbered lines 1-6 (a G92, one short and one long segment with the laser on), the
    fault firing after line 6 while line 5 runs; returns the port and the status after it."""
    port = open_mock(f"{fault}=6&speed=10")
    for n, line in enumerate(("$0=1234", "M3 S255", "G92 A10 B-5", "G1 A110 P100000",
                              "G1 A1110 B95 P1000000"), start=1):
        assert reply(port, protocol.encode_line(line, n)) == Ok()
    time.sleep(0.05)  # line 5 runs (0.1 s at speed 10)
    # line 6, then the reset; line 7 is lost with the rest of the write
    port.write(protocol.encode_line("G1 A2110 P1000000", 6) + protocol.encode_line("G90", 7))
    assert messages(port) == [Ok(), Banner("1.1.0", protocol.PROTOCOL_VERSION, 255, 16, 128)]
    assert messages(port, 0.03) == []
    entries = [e for e in port.ledger if e.kind == "G1"]
    assert [e.line for e in entries] == [4, 5]
    assert entries[1].stopped == ("reboot" if fault == "reset_after" else "power-cut")
    assert 0 < entries[1].fraction < 1
    assert port.machine.laser == 0
    return port, status(port)


def _after_boot_as_at_power_on(port: MockSerial, st: StatusReport) -> None:
    """Everything but position, H and Ln done restarts as at power-on."""
    assert (st.state, st.queued, st.accepted_line, st.laser, st.underruns) == (
        "Idle", 0, 0, 0, 0)
    port.write(protocol.encode_line("$$"))
    assert port.readline().decode().rstrip() == "$0=20000"  # settings at their boot values
    assert reply(port, b"") == Ok()  # the rest of the listing, then its ok
    assert reply(port, "G1 P10000") == Ok()  # unnumbered: numbered mode ended
    time.sleep(0.05)
    assert port.ledger[-1].power == 0  # M5 again: the laser stays off


def test_reset_after_n_lines_keeps_position_h_and_done() -> None:
    """A reset with the RAM powered keeps A, B, H and Ln done (docs/protocol.md 7)."""
    port, st = _reset_mid_segment("reset_after")
    part = port.ledger[-1]
    assert (st.a, st.b) == part.end and 110 < st.a < 1110  # exact, part-way along line 5
    assert (st.done_line, st.homed) == (4, True)  # the line before the interrupted one
    _after_boot_as_at_power_on(port, st)


def test_power_cut_after_n_lines_loses_everything() -> None:
    port, st = _reset_mid_segment("power_cut_after")
    physical = port.firmware.physical()  # type: ignore[union-attr]
    assert physical == tuple(port.machine.phys) and 100 < physical[0] < 1100
    assert (st.a, st.b, st.done_line, st.homed) == (0, 0, 0, False)
    _after_boot_as_at_power_on(port, st)


def test_dtr_reset_keeps_position_h_and_done_while_ctrl_x_zeroes_ln() -> None:
    port = open_mock("speed=0")
    for n, line in enumerate(("G92 A7 B8", "G1 A20 B-3 P10000", "G90"), start=1):
        assert reply(port, protocol.encode_line(line, n)) == Ok()
    time.sleep(0.03)
    assert status(port).done_line == 2
    port.dtr = False
    port.dtr = True
    assert messages(port) == [Banner("1.1.0", protocol.PROTOCOL_VERSION, 255, 16, 128)]
    st = status(port)
    assert (st.a, st.b, st.homed, st.done_line, st.accepted_line) == (20, -3, True, 2, 0)
    port.write(b"\x18")
    assert messages(port) == [Banner("1.1.0", protocol.PROTOCOL_VERSION, 255, 16, 128)]
    st = status(port)
    assert (st.a, st.b, st.homed, st.done_line, st.accepted_line) == (20, -3, True, 0, 0)


def test_error_on_line_k_refuses_it_like_the_firmware() -> None:
    port = open_mock("error_on=3&speed=10")
    assert reply(port, "G90") == Ok()
    assert reply(port, "G1 A10 P100000") == Ok()
    assert reply(port, "G1 A20 P100000") == ErrorReply(11)  # refused: soft limit
    st = status(port)
    assert (st.state, st.detail, st.accepted_line) == ("Hold", 2, 3)  # job held, line counted
    port.write(b"~")
    time.sleep(0.05)
    st = status(port)
    assert (st.state, st.a) == ("Idle", 10)
    assert [e.line for e in port.ledger if e.kind == "G1"] == [2]


def test_error_on_with_a_resend_code() -> None:
    port = open_mock("error_on=2&error_code=8&speed=0")
    assert reply(port, protocol.encode_line("G90", 1)) == Ok()
    assert reply(port, protocol.encode_line("G1 A5 P1000", 2)) == ErrorReply(8, resend=2)
    assert status(port).accepted_line == 1  # not accepted
    assert reply(port, protocol.encode_line("G1 A5 P1000", 2)) == Ok()  # line 3 of the port
    time.sleep(0.03)
    assert status(port).a == 5


def test_stall_after_n_lines_freezes_everything_until_dtr_reset() -> None:
    port = open_mock("stall_after=4&speed=1&watchdog=0")  # no watchdog: the hang lasts
    assert reply(port, "G92 A5") == Ok()
    assert reply(port, "M3 S200") == Ok()
    assert reply(port, "G1 A1000 P1000000") == Ok()
    time.sleep(0.05)  # the move runs
    assert reply(port, "G90") == Ok()  # answered, then the device hangs
    port.write(b"?G90\n!\x18")
    assert port.read(100) == b""  # no status, no reply, no banner
    frozen = port.ledger[-1]
    time.sleep(0.3)  # longer than the watchdog would take
    assert port.ledger[-1] == frozen and frozen.fraction < 1
    assert port.machine.laser == 200  # a hung controller keeps its pins
    port.dtr = False
    port.dtr = True  # the Uno's auto-reset
    assert port.readline() == (BANNER + "\r\n").encode()
    assert port.machine.laser == 0 and port.ledger[-1].stopped == "reboot"
    # the .noinit record survived the hang: where the motors froze, H, the G92's line done
    st = status(port)
    assert (st.a, st.b, st.homed, st.done_line) == (*frozen.end, True, 1)
    assert reply(port, "G90") == Ok()


def test_the_watchdog_resets_a_hung_device_laser_off_within_its_timeout() -> None:
    """docs/protocol.md section 9: the firmware's watchdog resets it 256 ms after a hang
    (laser off first), and it boots with its .noinit record, as after a DTR reset."""
    port = open_mock("stall_after=4&speed=1", timeout=1.0)
    assert port.options.watchdog == 256
    assert reply(port, "G92 A5") == Ok()
    assert reply(port, "M3 S200") == Ok()
    assert reply(port, "G1 A1000 P1000000") == Ok()
    time.sleep(0.05)  # the move runs
    assert reply(port, "G90") == Ok()  # answered, then the device hangs
    fw = port.firmware
    assert fw is not None and fw.hung_at is not None
    hung_at = fw.hung_at
    port.write(b"?G91\n")  # lost: the firmware hangs
    frozen = port.ledger[-1]
    assert port.machine.laser == 200  # still on: a hung controller keeps its pins
    assert port.readline() == (BANNER + "\r\n").encode()  # the watchdog's reset
    (t_off, power), = [e for e in port.machine.laser_log if e[0] >= hung_at]
    laser_off_s = t_off - hung_at
    print(f"\nmock: laser off {laser_off_s * 1000:.1f} ms after the hang")
    assert power == 0 and 0.256 - 1e-9 <= laser_off_s < 0.2561 and laser_off_s <= 0.5
    cut = port.ledger[-1]
    assert (cut.line, cut.stopped, cut.end) == (frozen.line, "watchdog", frozen.end)
    assert cut.fraction < 1  # the motors stopped where the hang froze them
    st = status(port)
    assert (st.state, st.a, st.b, st.homed, st.done_line, st.accepted_line, st.laser) == (
        "Idle", *frozen.end, True, 1, 0, 0)
    assert reply(port, "G90") == Ok()  # it runs again; each fault fires once
    time.sleep(0.3)
    assert reply(port, "G1 A5 P100000") == Ok()


def test_stall_after_zero_is_a_device_that_never_answers() -> None:
    urls.register()
    port = serial.serial_for_url("fivebar-mock://?stall_after=0&watchdog=0", timeout=0.05)
    assert port.readline() == (BANNER + "\r\n").encode()  # the banner came before the hang
    port.write(b"$I\n?")
    assert port.read(10) == b""


def test_stall_after_zero_with_the_watchdog_answers_after_its_reset() -> None:
    urls.register()
    port = serial.serial_for_url("fivebar-mock://?stall_after=0", timeout=1.0)
    assert port.readline() == (BANNER + "\r\n").encode()  # the banner came before the hang
    port.write(b"$I\n")  # lost
    assert port.readline() == (BANNER + "\r\n").encode()  # the watchdog's reset
    port.write(b"$I\n")
    assert port.read_until(b"ok\r\n") == (BANNER + "\r\nok\r\n").encode()


# --------------------------------------------------------------------------- ledger, machines


def test_ledger_records_every_block() -> None:
    port = open_mock("speed=0")
    for line in ("M3 S50", "G1 A10 B-4 P1000", "G92 A100", "M18", "M17", "G1 A90 P1000 S60",
                 "M5", "G1 B0 P1000"):
        assert reply(port, line) == Ok()
    time.sleep(0.03)
    got = [(e.kind, e.line, e.start, e.end, e.steps, e.power, e.duration_us, e.fraction)
           for e in port.ledger]
    assert got == [
        ("G1", 2, (0, 0), (10, -4), (10, -4), 50, 1000, 1.0),
        ("G92", 3, (10, -4), (100, -4), (0, 0), 0, 0, 1.0),
        ("M18", 4, (100, -4), (100, -4), (0, 0), 0, 0, 1.0),
        ("M17", 5, (100, -4), (100, -4), (0, 0), 0, 0, 1.0),
        ("G1", 6, (100, -4), (90, -4), (-10, 0), 60, 1000, 1.0),
        ("G1", 8, (90, -4), (90, 0), (0, 4), 0, 1000, 1.0),
    ]
    assert all(e.boot == 1 and e.stopped is None for e in port.ledger)
    assert [p for _, p in port.machine.laser_log] == [0, 50, 0, 60, 0]


def test_ledger_shows_the_running_block_and_a_hold() -> None:
    port = open_mock("speed=1")
    assert reply(port, "G1 A1000 P200000") == Ok()
    time.sleep(0.08)
    port.write(b"!")
    entry = port.ledger[-1]
    assert entry.stopped is None and 0.1 < entry.fraction < 0.9
    assert entry.end[0] == status(port).a
    time.sleep(0.05)
    assert port.ledger[-1].fraction == entry.fraction  # frozen while held
    port.write(b"~")
    time.sleep(0.25)
    assert port.ledger[-1].complete and port.ledger[-1].end == (1000, 0)


def test_named_machine_survives_reopen_and_is_busy_while_open() -> None:
    port = open_mock("machine=m1&speed=0&endstops=-50,-10")
    assert reply(port, "G1 A-30 P10000") == Ok()
    time.sleep(0.03)
    with pytest.raises(serial.SerialException, match="busy"):
        serial.serial_for_url("fivebar-mock://?machine=m1")
    port.close()
    again = open_mock("machine=m1&speed=0&endstops=-50,-10")  # a DTR reset: position kept
    st = status(again)
    assert (st.a, st.homed, st.done_line) == (-30, False, 1)
    for line in ("$7=1", "$9=5", "$12=1000"):
        assert reply(again, line) == Ok()
    assert reply(again, "$H") == Ok()  # the switch is 20 steps away now, not 50
    kinds = [(e.boot, e.kind, e.steps) for e in mock.machine("m1").ledger]
    assert kinds == [(1, "G1", (-30, 0)), (2, "home-seek", (-20, -10)),
                     (2, "home-pulloff", (5, 5)), (2, "home-set", (0, 0))]
    assert mock.machine("m1").phys == [-45, -5]
    again.close()


def test_power_cut_of_a_named_machine_between_opens_and_while_open() -> None:
    mock.machine("never-opened").power_cut()  # nothing to cut yet
    port = open_mock("machine=pc&speed=0")
    assert reply(port, "G92 A100 B100") == Ok()
    assert reply(port, "G1 A130 P10000") == Ok()
    time.sleep(0.03)
    port.close()
    mock.machine("pc").power_cut()
    again = open_mock("machine=pc&speed=0")  # powered up: nothing kept
    st = status(again)
    assert (st.a, st.b, st.homed, st.done_line) == (0, 0, False, 0)
    assert mock.machine("pc").phys == [30, 0]  # the motors stayed where they were
    assert reply(again, "G92 A5 B6") == Ok()
    assert reply(again, "M3 S90") == Ok()
    assert reply(again, "G1 A1005 P1000000") == Ok()  # 100 s at speed 0: at once
    assert reply(again, "G1 A2005 P100000000") == Ok()
    time.sleep(0.05)
    mock.machine("pc").power_cut()  # while open: it boots again at once, as at power-on
    assert messages(again) == [Banner("1.1.0", protocol.PROTOCOL_VERSION, 255, 16, 128)]
    st = status(again)
    assert (st.a, st.b, st.homed, st.done_line, st.laser) == (0, 0, False, 0, 0)
    assert mock.machine("pc").laser == 0
    assert [e.boot for e in mock.machine("pc").ledger if e.kind == "G1"] == [1, 2, 2]
    again.close()


# --------------------------------------------------------------------------- pyserial semantics


def test_timeouts_follow_pyserial() -> None:
    port = open_mock("speed=10", timeout=0)
    assert port.read(10) == b""  # non-blocking
    port.timeout = 0.1
    t0 = time.monotonic()
    assert port.read(10) == b""
    assert 0.09 <= time.monotonic() - t0 < 0.5
    port.timeout = None  # blocks until the bytes come: the reply to a line that waits
    for _ in range(16):
        assert reply(port, "G1 P100000") == Ok()  # 10 ms each at speed 10
    port.write(b"G1 P100000\n")
    t0 = time.monotonic()
    assert port.read(4) == b"ok\r\n"
    assert 0.002 < time.monotonic() - t0 < 1.0
    result: list[bytes] = []
    reader = threading.Thread(target=lambda: result.append(port.read(1000)))
    reader.start()
    time.sleep(0.02)
    port.cancel_read()
    reader.join(1.0)
    assert result == [b""]
    port.close()
    with pytest.raises(serial.PortNotOpenError):
        port.read(1)


def test_reset_input_buffer_discards_unread_output() -> None:
    port = open_mock()
    port.write(b"$I\n$$\n")
    assert port.in_waiting > 0
    port.reset_input_buffer()
    assert port.in_waiting == 0
    port.reset_output_buffer()
    assert port.out_waiting == 0
