"""The trace reader on hand-written traces (no toolchain needed)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fivebar_host.devices.simtrace import Step, TraceError, parse_trace, read_trace

TRACE = """\
# fbsim trace v1 freq=16000000
10 stepA 0
10 dirA 0
20 dirA 1
100 stepA 1
150 stepA 0
300 stepA 1
340 stepA 0
400 dirA 0
700 stepA 1
760 stepA 0
1000 laser 1
1500 laser 0
2000 laser 1
2100 laser 0
9000 laser 1
9500 laser 0
"""


def test_steps_positions_and_timing() -> None:
    trace = parse_trace(TRACE)
    assert trace.freq == 16_000_000
    assert trace.steps("A") == [Step(100, 1), Step(300, 1), Step(700, -1)]
    assert trace.positions("A") == [(100, 1), (300, 2), (700, 1)]
    assert trace.position_at("A", 299) == 1
    assert trace.position_at("A", 300, start=10) == 12
    assert trace.pulse_widths("A") == [50, 40, 60]
    assert trace.low_widths("A") == [150, 360]
    assert trace.dir_setup("A") == [90, 80, 300]
    assert trace.steps("B") == []


def test_inverted_direction() -> None:
    trace = parse_trace(TRACE, dir_invert=(True, False))
    assert [s.direction for s in trace.steps("A")] == [-1, -1, 1]


def test_laser_pulses_merge_into_intervals() -> None:
    trace = parse_trace(TRACE)
    assert trace.laser_intervals() == [(1000, 2100), (9000, 9500)]
    assert trace.laser_intervals(max_gap=100) == [(1000, 1500), (2000, 2100), (9000, 9500)]
    assert trace.laser_on_at(1800) and not trace.laser_on_at(5000)


@pytest.mark.parametrize("bad", ["10 stepA 2", "x stepA 1", "10 stepA", "20 stepA 1\n10 stepA 0"])
def test_malformed_trace_is_refused(bad: str) -> None:
    with pytest.raises(TraceError):
        parse_trace(bad)


def test_a_live_trace_ends_at_its_last_complete_line(tmp_path: Path) -> None:
    """A running harness's buffer can go out mid-line: a live read drops the cut line, a
    finished trace with one is refused."""
    path = tmp_path / "pins.trace"
    path.write_text(TRACE + "9600 ste", encoding="ascii")
    assert read_trace(path, live=True).changes == parse_trace(TRACE).changes
    with pytest.raises(TraceError, match="9600 ste"):
        read_trace(path)
