"""Servo build of the firmware (`make -C firmware SERVO=1`): flash, RAM and its arm servo
pulses measured in the simavr trace.

    python benchmarks/servo.py

A joint's position is its pulse in 0.5 µs ticks. The job: G92 to 1500 µs on both arms, then
a sweep of each arm out and back (A +500 µs / B −300 µs over 0.5 s, and back), then rest.
Printed, per arm, from the trace's svA / svB pulses (fbsim -V):
  - static width error: pulses of the frames at rest against the commanded 1500.0 µs;
  - frame-to-frame jitter: rise-to-rise period against 20 ms, and the width's spread at rest;
  - moving width error: each moving frame's width against the ideal pulse line of the
    segments at the sample time (the previous frame's fall), the job's start fitted once.
The stepper build's step rates are `benchmarks/firmware.py` (its hex is unchanged).
"""

from __future__ import annotations

import itertools
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fivebar_host import protocol, wire
from fivebar_host.devices import sim, simservo

CENTRE = 3000  # ticks: 1500 µs
#: (ticks A, ticks B, duration µs) of each G91 segment
SEGMENTS = [(1000, -600, 500_000), (-1000, 600, 500_000)]
FRAME_CYCLES = 320_000


def ideal_ticks(t_cycles: float, joint: int) -> float:
    """The commanded pulse line of the job, ticks, `t_cycles` after the first segment's
    start (before it: the centre; after the last: its end)."""
    pos = float(CENTRE)
    t = t_cycles
    for seg in SEGMENTS:
        dur = seg[2] * 16.0
        if t <= 0:
            return pos
        frac = min(t / dur, 1.0)
        pos_end = pos + seg[joint]
        if frac < 1.0:
            return pos + frac * seg[joint]
        pos, t = pos_end, t - dur
    return pos


def run(tmp: Path) -> list[list[tuple[int, float]]]:
    """Run the job on the servo build; each arm's (rise cycle, width µs) pulses."""
    build = simservo.ensure_servo_built()
    dev = simservo.start_servo_device(build, tmp / "servo.trace")
    try:
        s = dev.session
        for line in (f"G92 A{CENTRE} B{CENTRE}", "G91"):
            if s.send(line) != protocol.Ok():
                raise sim.EmulatorError(f"{line} refused")
        # the job, then 0.3 s of dwell: the last 8 frames are at rest whatever the pace
        rest = [wire.g1(None, None, 60_000) for _ in range(5)]
        replies = s.stream([wire.g1(a, b, p) for a, b, p in SEGMENTS] + rest, numbered_from=3)
        if any(r != protocol.Ok() for r in replies):
            raise sim.EmulatorError(f"refused: {replies}")
        s.wait_idle()
        trace = dev.finish()
    finally:
        dev.close()
    print("  " + build.size_report.strip().replace("\n\n", "\n").replace("\n", "\n  "))
    return [[p for p in simservo.frame_pulses(trace, j) if p[0] > 0] for j in (0, 1)]


def fit_start(pulses: list[tuple[int, float]], joint: int) -> tuple[int, list[float]]:
    """The job's start cycle that fits the moving frames best, and their width errors, µs.
    A frame's width is the position at the previous frame's fall (board_servo.c)."""
    moving = [(c, w) for c, w in pulses if abs(w - CENTRE / 2) > 1.0]
    if not moving:
        return 0, []
    first = moving[0][0]
    best: tuple[float, int, list[float]] | None = None
    for start in range(first - 2 * FRAME_CYCLES, first, 1600):
        errs = [w - ideal_ticks(c - FRAME_CYCLES + w * 16 - start, joint) / 2 for c, w in pulses
                if start < c - FRAME_CYCLES]
        score = max(abs(e) for e in errs) if errs else float("inf")
        if best is None or score < best[0]:
            best = (score, start, errs)
    assert best is not None
    return best[1], best[2]


def report(pulses: list[tuple[int, float]], joint: int) -> None:
    """Print one arm's figures."""
    name = "AB"[joint]
    rest = [w for _, w in pulses[-8:]]
    periods = [(b[0] - a[0]) / 16.0 - 20_000.0 for a, b in itertools.pairwise(pulses)]
    _, errs = fit_start(pulses, joint)
    print(f"  arm {name}: {len(pulses)} frames")
    worst = max(abs(w - 1500) for w in rest)
    print(f"    static width error (at rest, commanded 1500.0 us): mean "
          f"{statistics.mean(rest) - 1500:+.3f} us, max |e| {worst:.3f} us")
    print(f"    width spread at rest: {max(rest) - min(rest):.3f} us (max - min of "
          f"{len(rest)} frames)")
    print(f"    frame period jitter: max |T - 20 ms| {max(abs(p) for p in periods):.3f} us, "
          f"RMS {statistics.pstdev(periods):.3f} us")
    if errs:
        print(f"    moving width error vs the pulse line: max |e| {max(abs(e) for e in errs):.3f}"
              f" us, RMS {(sum(e * e for e in errs) / len(errs)) ** 0.5:.3f} us "
              f"({len(errs)} frames)")


def main() -> int:
    """Build, run and print."""
    reason = sim.toolchain_missing()
    if reason:
        print(f"cannot benchmark: {reason}")
        return 1
    print("fivebar servo build (make -C firmware SERVO=1), simavr, ATmega328P @ 16 MHz")
    with tempfile.TemporaryDirectory() as tmpdir:
        arms = run(Path(tmpdir))
    for j, pulses in enumerate(arms):
        report(pulses, j)
    return 0


if __name__ == "__main__":
    sys.exit(main())
