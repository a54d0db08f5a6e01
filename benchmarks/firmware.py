"""Benchmark the firmware in simavr: step rate, jitter, memory, segment rate.

Prints, all measured in emulated CPU cycles of the 16 MHz ATmega328P:
- flash and RAM use of the build;
- the highest sustained two-motor aggregate step rate the firmware executes
  exactly (every commanded step, each within 1 % of its segment's duration of
  the ideal DDA time, no queue underrun), streamed over the emulated link as
  10 ms segments, for equal motor rates and for a 1 : 0.73 ratio;
- step timing jitter (deviation of each rising step edge from the ideal
  schedule floor((2k-1)C/2n)), max and RMS, at the highest passing rate;
- the most segments per second streamed over 115200 baud (line numbers and
  checksums on) without the queue ever running empty.

The harness runs throttled to real time (-R) so the Python host streams at
the link's real pace.  Run: python benchmarks/firmware.py [--pen]

With --pen every run first sets up the pen servo ($14=1800, then M280 S1000:
pen down) so its pulses (Timer0 compare B on D12) run all through the
measurement: the figures show what the servo costs the step generator.
"""

from __future__ import annotations

import dataclasses
import math
import re
import statistics
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fivebar_host import protocol
from fivebar_host.devices import sim
from fivebar_host.devices.simtrace import Trace

F_CPU = 16_000_000
#: --pen: lines that start the pen servo's pulses before each measurement.
PEN_LINES = ("$14=1800", "M280 S1000") if "--pen" in sys.argv[1:] else ()


def start_pen(s: sim.FirmwareSession) -> int:
    """Send PEN_LINES and wait for them; the queue stops it caused (0 without --pen)."""
    for line in PEN_LINES:
        if s.send(line) != protocol.Ok():
            raise sim.EmulatorError(f"{line} refused")
    return s.wait_idle().underruns if PEN_LINES else 0


@dataclass(frozen=True)
class RateResult:
    """Outcome of one streamed job at a given rate."""

    ok: bool
    reason: str
    max_dev: int  # cycles
    rms_dev: float  # cycles
    underruns: int
    min_pulse: int = 0  # shortest step pulse, cycles
    min_dir_setup: int = 0  # shortest direction-to-step time, cycles


def deviations(trace: Trace, segs: list[tuple[int, int, int]]) -> tuple[list[int], str]:
    """Step-edge deviations from the ideal schedule; '' or why the job was not exact."""
    starts = [0]
    for _, _, p in segs:
        starts.append(starts[-1] + p * F_CPU // 1_000_000)
    raw: list[int] = []
    for axis, name in enumerate(("A", "B")):
        steps = trace.steps(name)
        ideal: list[int] = []
        for j, seg in enumerate(segs):
            n = abs(seg[axis])
            c = seg[2] * F_CPU // 1_000_000
            ideal += [starts[j] + ((2 * k - 1) * c) // (2 * n) for k in range(1, n + 1)]
        if len(steps) != len(ideal):
            return [], f"motor {name}: {len(steps)} steps for {len(ideal)} commanded"
        raw += [s.cycle - t for s, t in zip(steps, ideal, strict=True)]
    origin = int(statistics.median(raw))
    return [d - origin for d in raw], ""


def run_rate(build: sim.BuildPaths, rate_a: int, rate_b: int, tmp: Path) -> RateResult:
    """Stream 30 segments of 10 ms at the given per-motor rates and check them."""
    p_us = 10_000
    segs = [(rate_a * p_us // 1_000_000, rate_b * p_us // 1_000_000, p_us) for _ in range(30)]
    dev = sim.start_device(build, tmp / "rate.trace", realtime=True)
    try:
        s = dev.session
        base = start_pen(s)
        for line in ("$0=40000", "G91"):
            if s.send(line) != protocol.Ok():
                return RateResult(False, f"{line} refused", 0, 0.0, 0)
        replies = s.stream([protocol.g1(a, b, p) for a, b, p in segs],
                           numbered_from=3 + len(PEN_LINES))
        if any(r != protocol.Ok() for r in replies):
            return RateResult(False, f"refused: {replies}", 0, 0.0, 0)
        report = s.wait_idle()
        trace = dev.finish()
    finally:
        dev.close()
    report = dataclasses.replace(report, underruns=report.underruns - base)
    devs, why = deviations(trace, segs)
    if why:
        return RateResult(False, why, 0, 0.0, report.underruns)
    worst = max(abs(d) for d in devs)
    rms = math.sqrt(sum(d * d for d in devs) / len(devs))
    if report.underruns != 1:
        return RateResult(False, f"queue ran empty {report.underruns - 1}x", worst, rms, 0)
    if worst > p_us * 16 // 100:
        return RateResult(False, f"step {worst} cycles off schedule", worst, rms, 1)
    pulse = min(trace.pulse_widths("A") + trace.pulse_widths("B"))
    setup = min(trace.dir_setup("A") + trace.dir_setup("B"), default=0)
    return RateResult(True, "exact", worst, rms, 1, pulse, setup)


def run_segments(build: sim.BuildPaths, p_us: int, tmp: Path, count: int = 1000) -> int:
    """Stream short numbered segments; return how often the queue ran dry mid-job."""
    dev = sim.start_device(build, tmp / "seg.trace", realtime=True)
    try:
        s = dev.session
        base = start_pen(s)
        s.send("G91")
        lines = [protocol.g1(3 if i % 2 else -3, 2, p_us) for i in range(count)]
        replies = s.stream(lines, numbered_from=2 + len(PEN_LINES))
        if any(r != protocol.Ok() for r in replies):
            raise sim.EmulatorError(f"segments refused: {replies[:3]}")
        report = s.wait_idle()
    finally:
        dev.close()
    return report.underruns - base - 1


def memory(build: sim.BuildPaths) -> tuple[str, str]:
    """Flash and RAM lines from avr-size."""
    flash = re.search(r"Program:\s+(\d+ bytes \([\d.]+% Full\))", build.size_report)
    ram = re.search(r"Data:\s+(\d+ bytes \([\d.]+% Full\))", build.size_report)
    return (flash.group(1) if flash else "?", ram.group(1) if ram else "?")


def main() -> int:
    """Run every measurement and print the figures."""
    reason = sim.toolchain_missing()
    if reason:
        print(f"cannot benchmark: {reason}")
        return 1
    build = sim.ensure_built()
    flash, ram = memory(build)
    print("fivebar firmware benchmark (simavr, ATmega328P @ 16 MHz, emulated cycles)")
    print(f"  flash: {flash}   RAM (static): {ram}")
    if PEN_LINES:
        print("  pen servo running all through (--pen): " + ", ".join(PEN_LINES))
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        for label, ratio in (("equal rates", 1.0), ("ratio 1:0.73", 0.73)):
            best: tuple[int, RateResult] | None = None
            for total in range(20_000, 80_001, 5_000):
                rate_a = round(total / (1 + ratio))
                rate_b = total - rate_a
                if max(rate_a, rate_b) > 40_000:
                    break
                res = run_rate(build, rate_a, rate_b, tmp)
                print(f"    {label}: {total / 1000:5.1f} kHz aggregate -> {res.reason}")
                if not res.ok:
                    break
                best = (total, res)
            if best is None:
                print(f"  {label}: no rate passed")
                continue
            total, res = best
            print(
                f"  {label}: highest exact sustained aggregate step rate {total / 1000:.1f} kHz; "
                f"jitter max {res.max_dev} cycles ({res.max_dev / 16:.1f} us), "
                f"RMS {res.rms_dev:.0f} cycles ({res.rms_dev / 16:.1f} us); "
                f"shortest step pulse {res.min_pulse / 16:.1f} us, "
                f"shortest dir set-up {res.min_dir_setup / 16:.1f} us"
            )
        passed = None
        for p_us in (5_000, *range(3_000, 1_999, -100)):
            dry = run_segments(build, p_us, tmp)
            print(f"    segments of {p_us} us ({1e6 / p_us:.0f}/s): queue ran dry {dry}x")
            if dry:
                break
            passed = p_us
        if passed:
            print(
                f"  sustained segment rate over 115200 baud (N + checksum lines): "
                f"{1e6 / passed:.0f} segments/s without underrun"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
