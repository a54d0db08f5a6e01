"""The real firmware in simavr, driven through the pty with pyserial.

Each test boots a fresh emulator, talks the protocol of docs/protocol.md and
then checks the recorded pin trace: exact step counts and positions, step
timing against the DDA schedule, segment durations, laser on only in laser
segments, and no motion after refused input.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from fivebar_host import protocol, wire
from fivebar_host.devices.sim import SimDevice as Device
from fivebar_host.devices.simtrace import Trace
from fivebar_host.protocol import AlarmPush, ErrorReply, Ok

pytestmark = pytest.mark.sim

F_CPU = 16_000_000


@dataclass(frozen=True)
class Seg:
    """One commanded relative segment."""

    a: int
    b: int
    p_us: int
    s: int

    @property
    def cycles(self) -> int:
        return self.p_us * F_CPU // 1_000_000


def job_segments() -> list[Seg]:
    """A laser job: travel, burns at several powers, reversals, a dwell."""
    segs = [Seg(300, -200, 20_000, 0)]
    for i in range(24):
        sign = -1 if i % 5 == 4 else 1
        segs.append(Seg(sign * (40 + 7 * i), 25 - 3 * i, 5_000 + 250 * i, 255 if i % 3 else 128))
    segs.append(Seg(0, 0, 8_000, 0))
    segs.append(Seg(-150, 90, 12_000, 0))
    segs.append(Seg(77, 0, 6_000, 255))
    return segs


def ideal_offsets(seg: Seg, axis: int) -> list[int]:
    """DDA step times within a segment: floor((2k-1)C/2n)."""
    n = abs(seg.a if axis == 0 else seg.b)
    return [((2 * k - 1) * seg.cycles) // (2 * n) for k in range(1, n + 1)]


def check_job(trace: Trace, segs: list[Seg]) -> tuple[int, int]:
    """Check counts, schedule and laser against the commanded segments.

    Returns (max step deviation from the schedule, max segment duration error)
    in cycles.  The schedule's origin is fitted from the first step.
    """
    starts = [0]
    for seg in segs:
        starts.append(starts[-1] + seg.cycles)
    worst_dev = 0
    worst_dur = 0
    origin: int | None = None
    for axis, name in enumerate(("A", "B")):
        steps = trace.steps(name)
        want = sum(abs(s.a if axis == 0 else s.b) for s in segs)
        assert len(steps) == want, f"motor {name}: {len(steps)} steps, commanded {want}"
        assert sum(st.direction for st in steps) == sum(s.a if axis == 0 else s.b for s in segs)
        k = 0
        firsts: list[tuple[int, int, int]] = []  # (segment, actual, ideal)
        for j, seg in enumerate(segs):
            d = seg.a if axis == 0 else seg.b
            for i, off in enumerate(ideal_offsets(seg, axis)):
                step = steps[k]
                assert step.direction == (1 if d > 0 else -1), f"{name} segment {j}: direction"
                if origin is None:
                    origin = step.cycle - (starts[j] + off)
                dev = step.cycle - (origin + starts[j] + off)
                worst_dev = max(worst_dev, abs(dev))
                assert abs(dev) <= seg.cycles // 100, (
                    f"{name} segment {j} step {i}: {dev} cycles off the schedule"
                )
                if i == 0:
                    firsts.append((j, step.cycle, starts[j] + off))
                k += 1
        for (j0, t0, i0), (j1, t1, i1) in itertools.pairwise(firsts):
            if j1 == j0 + 1:
                err = (t1 - t0) - (i1 - i0)
                worst_dur = max(worst_dur, abs(err))
                assert abs(err) <= segs[j0].cycles // 100, (
                    f"{name} segment {j0} duration off by {err}"
                )
    assert origin is not None
    # laser: on only inside segments with power, and on through them
    windows = [(origin + starts[j], origin + starts[j + 1]) for j, s in enumerate(segs) if s.s]
    slack = 2000
    intervals = trace.laser_intervals()
    for on, off in intervals:
        assert any(w0 - slack <= on and off <= w1 + slack for w0, w1 in _merge(windows)), (
            f"laser on {on}..{off} outside every laser segment"
        )
    for w0, w1 in windows:
        covered = sum(max(0, min(w1, e) - max(w0, s)) for s, e in intervals)
        assert covered >= (w1 - w0) - 2 * slack, f"laser segment {w0}..{w1} not lit through"
    return worst_dev, worst_dur


def _merge(windows: list[tuple[int, int]]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for w in windows:
        if out and w[0] <= out[-1][1]:
            out[-1] = (out[-1][0], w[1])
        else:
            out.append(w)
    return out


def test_boot_banner_and_info(device: Device) -> None:
    banner = device.session.banner
    assert banner is not None
    assert (banner.proto, banner.rx, banner.queue, banner.line_max) == (
        protocol.PROTOCOL_VERSION, 255, 16, 128)
    device.port.write(b"$I\n")
    assert device.session.read_message() == banner
    assert device.session.read_reply() == Ok()


def test_streamed_job_executes_exactly(start_device: Callable[..., Device]) -> None:
    device = start_device(realtime=True)
    session = device.session
    segs = job_segments()
    lines = ["G91", "M3 S0"] + [wire.g1(s.a, s.b, s.p_us, s.s) for s in segs] + ["G90"]
    replies = session.stream(lines, numbered_from=1)
    assert all(r == Ok() for r in replies), replies
    report = session.wait_idle()
    assert (report.a, report.b) == (sum(s.a for s in segs), sum(s.b for s in segs))
    assert report.done_line == len(lines) - 1  # the last G1
    assert report.underruns == 1, "the queue ran empty during the job"
    trace = device.finish()
    check_job(trace, segs)
    widths = trace.pulse_widths("A") + trace.pulse_widths("B")
    assert min(widths) >= 32, "step pulse shorter than 2 us"
    assert min(trace.dir_setup("A") + trace.dir_setup("B")) >= 11, "dir set < 650 ns before step"


def test_hold_freezes_and_resume_completes(device: Device) -> None:
    session = device.session
    assert session.send("M3 S200") == Ok()
    assert session.send(wire.g1(2000, -1000, 400_000)) == Ok()
    while session.status().a < 200:
        time.sleep(0.005)
    session.realtime(protocol.RT_HOLD)
    held = session.status()
    assert (held.state, held.detail, held.laser) == ("Hold", 0, 0)
    time.sleep(0.05)
    again = session.status()
    assert (again.a, again.b) == (held.a, held.b), "motors moved while held"
    assert 0 < held.a < 2000
    session.realtime(protocol.RT_RESUME)
    done = session.wait_idle()
    assert (done.a, done.b) == (2000, -1000)
    trace = device.finish()
    steps = trace.steps("A")
    assert len(steps) == 2000
    gaps = [(b.cycle - a.cycle, a.cycle, b.cycle) for a, b in itertools.pairwise(steps)]
    gap, hold_start, hold_end = max(gaps)
    assert gap > 20 * 3200, "no pause in the step train"
    for on, off in trace.laser_intervals():
        assert off <= hold_start + 3000 or on >= hold_end - 3000, "laser on during the hold"
    assert trace.laser_on_at(hold_start - 5000) and trace.laser_on_at(hold_end + 5000)


def test_reset_stops_at_once_and_keeps_position(device: Device) -> None:
    session = device.session
    assert session.send("M3 S255") == Ok()
    replies = session.stream([wire.g1(4000 * (i + 1), 0, 400_000) for i in range(4)])
    assert all(r == Ok() for r in replies)
    while session.status().a < 300:
        time.sleep(0.005)
    session.realtime(protocol.RT_RESET)
    session.wait_banner()
    report = session.status()
    assert report.state == "Idle" and report.queued == 0 and report.laser == 0
    time.sleep(0.05)
    assert session.status().a == report.a, "motion after reset"
    assert session.send("$I") == Ok()
    trace = device.finish()
    assert len(trace.steps("A")) == report.a
    last_step = trace.steps("A")[-1].cycle
    assert trace.laser_intervals()[-1][1] <= last_step + 5000, "laser on after reset"


def assert_no_motion_and_alive(device: Device) -> None:
    """After refused input: no queued motion, and the firmware still answers."""
    report = device.session.status()
    assert (report.state, report.a, report.b, report.queued) == ("Idle", 0, 0, 0)
    assert device.session.send("M110") == Ok()  # accepted in any mode; ends numbered mode
    assert device.session.send("$I") == Ok()
    trace = device.finish()
    assert trace.steps("A") == [] and trace.steps("B") == []
    assert trace.laser_intervals() == []


def test_garbage_bytes(device: Device) -> None:
    reply = device.session.send_raw(b"\x01\x02\xfe\xff\x80 G1 A10 P1000\n")
    assert reply == ErrorReply(1)
    assert_no_motion_and_alive(device)


def test_overlong_line(device: Device) -> None:
    reply = device.session.send_raw(b"G1 P1000 " + b"A1" * 60 + b"\n")
    assert reply == ErrorReply(2)
    assert_no_motion_and_alive(device)


@pytest.mark.parametrize("line", ["G5 A10 P1000", "M999", "X10"])
def test_unknown_command(device: Device, line: str) -> None:
    assert device.session.send(line) == ErrorReply(4)
    assert_no_motion_and_alive(device)


@pytest.mark.parametrize(
    ("line", "code"),
    [
        ("G1 A100000001 P1000", 7),
        ("G1 A10 P99", 7),
        ("G1 A10 P1000 S256", 7),
        ("G1 A99999999999 P1000", 7),
        ("G1 A200000 P10000000", 11),
        ("G1 A1000 P1000", 12),
    ],
)
def test_numbers_out_of_range(device: Device, line: str, code: int) -> None:
    assert device.session.send(line) == ErrorReply(code)
    assert_no_motion_and_alive(device)


def test_bad_checksum_asks_for_resend(device: Device) -> None:
    good = protocol.encode_line("G1 A10 P10000", line_number=1)
    corrupted = good.replace(b"A10", b"A90")
    assert device.session.send_raw(corrupted) == ErrorReply(8, resend=1)
    assert_no_motion_and_alive(device)


def test_line_number_gap_asks_for_resend(device: Device) -> None:
    assert device.session.send("G90", line_number=1) == Ok()
    assert device.session.send("G1 A10 P10000", line_number=3) == ErrorReply(9, resend=2)
    assert device.session.send("G1 A10 P10000", line_number=1) == ErrorReply(9, resend=2)
    assert_no_motion_and_alive(device)


def test_homing_finds_the_switches(start_device: Callable[..., Device]) -> None:
    dev = start_device(endstop_a=-300, endstop_b=-120)
    for line in ("$7=1", "$8=4000", "$9=50", "$10=1000", "$11=-7"):
        assert dev.session.send(line) == Ok()
    assert dev.session.send("$H") == Ok()
    report = dev.session.status()
    assert (report.state, report.a, report.b) == ("Idle", 1000, -7)
    trace = dev.finish()
    for axis, switch in (("A", -300), ("B", -120)):
        positions = [p for _, p in trace.positions(axis)]
        assert min(positions) == switch, f"{axis} stopped at {min(positions)}"
        assert positions[-1] == switch + 50


def test_endstop_outside_homing_raises_alarm(start_device: Callable[..., Device]) -> None:
    dev = start_device(endstop_a=-100)
    session = dev.session
    for line in ("$7=1", "M3 S255"):
        assert session.send(line) == Ok()
    assert session.send(wire.g1(-500, 0, 100_000)) == Ok()
    report = session.wait_state({"Alarm"})
    assert (report.detail, report.laser, report.queued) == (30, 0, 0)
    assert AlarmPush(30) in session.messages
    assert session.send(wire.g1(0, 0, 1000)) == ErrorReply(14)
    assert session.send("$X") == Ok()
    assert (session.status().state, session.status().laser) == ("Idle", 0)
    # moving away from the pressed switch is allowed ...
    assert session.send("M5") == Ok()
    assert session.send(wire.g1(0, 0, 100_000)) == Ok()
    assert (session.wait_idle().a, session.status().state) == (0, "Idle")
    # ... moving into it again is not
    assert session.send(wire.g1(-300, 0, 100_000)) == Ok()
    assert session.wait_state({"Alarm"}).a == -100
    trace = dev.finish()
    assert [p for _, p in trace.positions("A")].count(-100) == 2
    assert min(p for _, p in trace.positions("A")) == -100
    assert trace.laser_intervals()[-1][1] <= trace.steps("A")[99].cycle + 5000


def test_host_silence_turns_the_laser_off(device: Device) -> None:
    session = device.session
    for line in ("$6=100", "M3 S255", wire.g1(0, 0, 10_000_000)):
        assert session.send(line) == Ok()
    deadline = time.monotonic() + 10
    report = session.status()
    while report.state != "Hold" and time.monotonic() < deadline:
        time.sleep(0.2)  # ~1 s of emulated time between polls
        report = session.status()
    assert (report.state, report.detail, report.laser) == ("Hold", 1, 0)
    session.realtime(protocol.RT_RESET)
    session.wait_banner()
    trace = device.finish()
    ((on, off),) = trace.laser_intervals()
    # silence counts from the last byte received (the G1 line); the laser came
    # on when the queue started, CFG_START_DELAY_MS = 20 ms later
    assert 75 * 16_000 <= off - on <= 110 * 16_000, f"laser on for {(off - on) / 16e3:.1f} ms"


def test_harness_stops_cleanly_on_sigterm(device: Device) -> None:
    assert device.session.send("G1 A10 P1000") == Ok()
    device.session.wait_idle()
    device.finish()
    assert device.emulator.returncode == 0
    assert "MHz emulated" in device.emulator.stats


def test_refused_line_during_a_laser_job_holds_it(device: Device) -> None:
    session = device.session
    assert session.send("M3 S255") == Ok()
    assert session.send(wire.g1(1000, 0, 500_000)) == Ok()
    while session.status().a < 100:
        time.sleep(0.005)
    assert session.send("G5") == ErrorReply(4)
    report = session.status()
    assert (report.state, report.detail, report.laser) == ("Hold", 2, 0)
    session.realtime(protocol.RT_RESUME)
    assert session.wait_idle().a == 1000
    trace = device.finish()
    assert len(trace.steps("A")) == 1000
    assert len(trace.laser_intervals()) == 2, "laser off during the hold, back on after"


def test_g92_and_motor_enable_are_queued_in_order(device: Device) -> None:
    session = device.session
    lines = [
        wire.g1(100, 50, 10_000),
        "G92 A1000 B-5",
        wire.g1(1010, -5, 10_000),
        "M18",
    ]
    assert session.stream(lines) == [Ok()] * 4
    report = session.wait_idle()
    assert (report.a, report.b, report.done_line) == (1010, -5, 4)
    assert session.send(wire.g1(0, 0, 10_000)) == ErrorReply(15)
    assert session.send("M17") == Ok()
    assert session.send(wire.g1(1000, -5, 10_000)) == Ok()
    assert session.wait_idle().a == 1000
    trace = device.finish()
    assert len(trace.steps("A")) == 100 + 10 + 10
    assert len(trace.steps("B")) == 50
    enable = [level for _, level in trace.pin("enable")]
    assert enable[-3:] == [0, 1, 0], "enabled (low), disabled by M18, enabled by M17"
    last_disable = [c for c, level in trace.pin("enable") if level == 1][-1]
    a_steps = [s.cycle for s in trace.steps("A")]
    assert a_steps[109] < last_disable < a_steps[110], "M18 took effect after the queued moves"


def test_slow_segments_keep_their_timing(device: Device) -> None:
    """Step intervals far beyond the 16-bit timer: waits are chained exactly."""
    segs = [
        Seg(3, 1, 300_000, 0),
        Seg(-2, 5, 170_000, 0),
        Seg(0, 0, 40_000, 0),
        Seg(1, 1, 5_000, 0),
    ]
    lines = ["G91"] + [wire.g1(s.a, s.b, s.p_us, s.s) for s in segs]
    assert device.session.stream(lines) == [Ok()] * len(lines)
    device.session.wait_idle()
    worst, _ = check_job(device.finish(), segs)
    assert worst <= 400, f"a step {worst} cycles off its time"
