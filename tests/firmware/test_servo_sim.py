"""The servo build of the firmware (`make -C firmware SERVO=1`) in the emulator: a joint's
position is its pulse in 0.5 µs ticks; each 20 ms frame sends each arm servo (svA, svB in
the trace) one pulse as wide as the joint's position, so a G1 segment's pulse widths are
interpolated frame by frame, and the frames at rest send the commanded width."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from fivebar_host import protocol, wire
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.devices.simservo import ensure_servo_built, frame_pulses, start_servo_device

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")


def test_servo_pulses_follow_the_segments(tmp_path: Path) -> None:
    dev = start_servo_device(ensure_servo_built(), tmp_path / "servo.trace")
    try:
        s = dev.session
        assert s.send("G92 A3000 B2000") == protocol.Ok()
        assert s.send("G91") == protocol.Ok()
        replies = s.stream([wire.g1(1000, -400, 400_000), wire.g1(0, 0, 200_000)],
                           numbered_from=3)
        assert all(r == protocol.Ok() for r in replies)
        st = s.wait_idle()
        assert (st.a, st.b) == (4000, 1600)
        trace = dev.finish()
    finally:
        dev.close()
    a = [w for c, w in frame_pulses(trace, 0) if c > 0]
    b = [w for c, w in frame_pulses(trace, 1) if c > 0]
    # from the G92 position to the target, each frame one step of the line (20 ms of a
    # 400 ms segment: 1/20 of 500 µs = 25 µs for A, 10 µs for B), ending on the target
    # (the first pulse at most one frame's step into the line: the job may start first)
    assert 1498.5 <= a[0] <= 1526.5 and 988.5 <= b[0] <= 1001.5
    assert abs(a[-1] - 2000.0) <= 1.5 and abs(b[-1] - 800.0) <= 1.5
    steps_a = [y - x for x, y in itertools.pairwise(a) if abs(y - x) > 3.0]
    # (the first and last frames of the move take part of a frame's step)
    assert len(steps_a) >= 15 and all(22.0 <= d <= 28.0 for d in steps_a[1:-1])
    assert all(x <= y + 1.5 for x, y in itertools.pairwise(a))
    assert all(x >= y - 1.5 for x, y in itertools.pairwise(b))


def test_no_pulses_before_the_position_is_set(tmp_path: Path) -> None:
    dev = start_servo_device(ensure_servo_built(), tmp_path / "servo.trace")
    try:
        s = dev.session
        s.status()
        assert s.send("M18") == protocol.Ok()  # queued: the servos go limp
        s.wait_idle()
        trace = dev.finish()
    finally:
        dev.close()
    # a power-on's position 0 is outside 500..2500 µs: no arm pulse at all
    assert [p for p in frame_pulses(trace, 0) if p[0] > 0] == []
    assert [p for p in frame_pulses(trace, 1) if p[0] > 0] == []


def test_the_servo_build_says_so_in_its_banner(tmp_path: Path) -> None:
    dev = start_servo_device(ensure_servo_built(), tmp_path / "servo.trace")
    try:
        dev.session.realtime(b"\x18")  # Ctrl-X: the banner again
        assert dev.session.wait_banner().joints == "servo"
    finally:
        dev.close()
    line = "fivebar 1.0.0 proto:3 rx:128 queue:16 line:80 joints:servo"
    assert protocol.parse_message(line) == protocol.Banner("1.0.0", 3, 128, 16, 80, "servo")
    assert protocol.parse_message(line[:-13]).joints == "stepper"  # type: ignore[union-attr]
