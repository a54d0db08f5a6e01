"""Benchmark the firmware in simavr: step rate, jitter, pulse timing, memory, segment rate.

Prints, all measured in emulated CPU cycles of the 16 MHz ATmega328P:
- flash and RAM use of the build;
- for the motor rate ratios 1:1, 1:0.73, 1:0.5 and 1:0.1, the highest per-motor
  step rate of the faster motor the firmware executes exactly (every
  commanded step, each within 1 % of its segment's duration of the ideal DDA
  time floor((2k-1)C/2n), no queue underrun), streamed over the emulated link
  as 10 ms segments whose direction alternates (so every segment start
  changes both direction pins), with the reason the next rate failed;
- step timing jitter at that rate (deviation of each rising step edge from
  the ideal schedule, less the median), max and RMS, both motors pooled: the
  strict figure; and the interval jitter (RMS of each step interval's
  deviation from its ideal interval, per motor, pooled), the figure GRBL-like
  jitter measurements give;
- from the same trace the shortest step pulse high time, low time and
  direction-change-to-step-edge set-up time in ns, against the datasheet
  minima of the common step/dir drivers (DRIVERS below);
- the most segments per second streamed over 115200 baud (line numbers and
  checksums on) without the queue ever running empty.

The harness runs throttled to real time (-R) so the Python host streams at
the link's real pace.  A busy host machine can starve the stream ("queue ran
empty") although the firmware keeps up, so a failing rate is tried up to
ATTEMPTS times; a pass cannot come from luck (every step is checked).

Run: python benchmarks/firmware.py [--pen | --both] [--ratios 1,0.73] [--at 55]
(--at: the figures at that one rate of the faster motor instead of the search)

With --pen every run first sets up the pen servo ($14=1800, then M280 S1000:
pen down) so its pulses (Timer0 compare B on D12) run all through the
measurement; --both runs every ratio without and with it.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks import steptiming
from fivebar_host import protocol, wire
from fivebar_host.devices import sim
from fivebar_host.devices.simtrace import Trace

F_CPU = 16_000_000
NS_PER_CYCLE = 1e9 / F_CPU
#: Lines that start the pen servo's pulses before a measurement (--pen).
PEN_LINES = ("$14=1800", "M280 S1000")
#: Motor rate ratios of the rate search (slower motor / faster motor).
RATIOS = (1.0, 0.73, 0.5, 0.1)
#: Per-motor rates of the faster motor tried, steps/s, in order, up to the
#: firmware's cap ($0's limit, CFG_MAX_RATE_LIMIT in config.h); the search
#: stops at the first that fails.
RATES = (20_000, 25_000, 30_000, 35_000, 40_000, 45_000, 50_000, 55_000, 60_000)
CONFIG_H = Path(__file__).resolve().parents[1] / "firmware" / "fivebar" / "config.h"
ATTEMPTS = 3
SEGMENTS = 30
SEGMENT_US = 10_000

#: Datasheet minima, ns: (step high, step low, direction set-up before the
#: step edge).  A4988: Allegro A4988 datasheet, "Timing Requirements" (Figure 1:
#: STEP high/low 1 us, setup 200 ns); DRV8825: TI SLVSA73, "Timing
#: Requirements" (tWH(STEP), tWL(STEP) 1.9 us, tSU(STEP) 650 ns); TMC2208:
#: Trinamic TMC220x datasheet, STEP/DIR timing (tSH, tSL about 100 ns, tDSU
#: 20 ns).
DRIVERS = {
    "A4988": (1000.0, 1000.0, 200.0),
    "DRV8825": (1900.0, 1900.0, 650.0),
    "TMC2208": (100.0, 100.0, 20.0),
}


@dataclass(frozen=True)
class RateResult:
    """Outcome of one streamed job at a given pair of motor rates."""

    ok: bool
    reason: str
    max_dev: int = 0  # cycles
    rms_dev: float = 0.0  # cycles
    interval_rms: float = 0.0  # cycles, RMS of interval deviations
    min_high: int = 0  # shortest step pulse high time, cycles
    min_low: int = 0  # shortest step low time between pulses, cycles
    min_dir_setup: int = 0  # shortest direction change to step edge, cycles
    attempts: int = 1


def start_pen(s: sim.FirmwareSession, pen: bool) -> int:
    """Send PEN_LINES when ``pen`` and wait for them; the queue stops they caused."""
    if not pen:
        return 0
    for line in PEN_LINES:
        if s.send(line) != protocol.Ok():
            raise sim.EmulatorError(f"{line} refused")
    return s.wait_idle().underruns


def rate_cap() -> int:
    """CFG_MAX_RATE_LIMIT from config.h: the highest $0, steps/s per motor."""
    m = re.search(r"#define\s+CFG_MAX_RATE_LIMIT\s+(\d+)", CONFIG_H.read_text())
    if not m:
        raise sim.EmulatorError(f"{CONFIG_H}: no CFG_MAX_RATE_LIMIT")
    return int(m.group(1))


def job(rate_a: int, rate_b: int) -> list[tuple[int, int, int]]:
    """SEGMENTS segments (a, b, p_us) at the given rates, directions alternating."""
    n_a = rate_a * SEGMENT_US // 1_000_000
    n_b = rate_b * SEGMENT_US // 1_000_000
    return [(n_a if k % 2 == 0 else -n_a, -n_b if k % 2 == 0 else n_b, SEGMENT_US)
            for k in range(SEGMENTS)]


def deviations(trace: Trace, segs: list[tuple[int, int, int]]) -> tuple[list[int], str]:
    """Step-edge deviations from the ideal schedule (`steptiming.strict_deviations`, both
    motors, one median); '' or why the job was not exact."""
    edges, ideal, why = edges_and_ideal(trace, segs)
    if why:
        return [], why
    both_e = edges[0] + edges[1]
    both_i = ideal[0] + ideal[1]
    return [int(d) for d in steptiming.strict_deviations(both_e, both_i, whole_cycles=True)], ""


def interval_jitter(trace: Trace, segs: list[tuple[int, int, int]]) -> float:
    """RMS, cycles, of each step interval's deviation from its ideal interval
    (`steptiming.interval_deviations`), per motor, both motors pooled; 0.0 when the job
    was not exact."""
    edges, ideal, why = edges_and_ideal(trace, segs)
    if why:
        return 0.0
    devs = [d for e, i in zip(edges, ideal, strict=True)
            for d in steptiming.interval_deviations(e, i)]
    return steptiming.summarize(devs).rms


def edges_and_ideal(trace: Trace, segs: list[tuple[int, int, int]]
                    ) -> tuple[list[list[int]], list[list[int]], str]:
    """Per motor, the rising-edge cycles and their ideal times (`steptiming.segment_schedule`
    of every segment, the segments back to back from cycle 0), and '' or why the job was
    not exact (a step missing or extra, or in the wrong direction)."""
    starts = [0]
    for _, _, p in segs:
        starts.append(starts[-1] + p * F_CPU // 1_000_000)
    edges: list[list[int]] = []
    ideal: list[list[int]] = []
    for axis, name in enumerate(("A", "B")):
        steps = trace.steps(name)
        times: list[int] = []
        signs: list[int] = []
        for j, seg in enumerate(segs):
            n = abs(seg[axis])
            times += steptiming.segment_schedule(starts[j], seg[2] * F_CPU // 1_000_000, n)
            signs += [1 if seg[axis] > 0 else -1] * n
        if len(steps) != len(times):
            return [], [], f"motor {name}: {len(steps)} steps for {len(times)} commanded"
        if any(s.direction != d for s, d in zip(steps, signs, strict=True)):
            return [], [], f"motor {name}: a step in the wrong direction"
        edges.append([s.cycle for s in steps])
        ideal.append(times)
    return edges, ideal, ""


def stream_job(build: sim.BuildPaths, segs: list[tuple[int, int, int]], trace_path: Path,
               pen: bool) -> tuple[Trace | None, str]:
    """Stream `segs` on a fresh emulator in real time ($0 at the cap, G91; the pen servo
    first with `pen`); (trace, '') or (None, why: a refusal, or the queue ran empty)."""
    dev = sim.start_device(build, trace_path, realtime=True)
    try:
        s = dev.session
        base = start_pen(s, pen)
        for line in (f"$0={rate_cap()}", "G91"):
            if s.send(line) != protocol.Ok():
                return None, f"{line} refused"
        first = 3 + (len(PEN_LINES) if pen else 0)
        replies = s.stream([wire.g1(a, b, p) for a, b, p in segs], numbered_from=first)
        if any(r != protocol.Ok() for r in replies):
            bad = next(r for r in replies if r != protocol.Ok())
            return None, f"refused: {bad}"
        report = s.wait_idle()
        trace = dev.finish()
    finally:
        dev.close()
    if report.underruns - base != 1:
        return None, f"queue ran empty {report.underruns - base - 1}x"
    return trace, ""


def run_rate(build: sim.BuildPaths, rate_a: int, rate_b: int, tmp: Path, pen: bool) -> RateResult:
    """Stream one job at the given per-motor rates and check it."""
    segs = job(rate_a, rate_b)
    trace, why = stream_job(build, segs, tmp / "rate.trace", pen)
    if trace is None:
        return RateResult(False, why)
    devs, why = deviations(trace, segs)
    if why:
        return RateResult(False, why)
    worst = max(abs(d) for d in devs)
    rms = steptiming.summarize(devs).rms
    if worst > SEGMENT_US * 16 // 100:
        return RateResult(False, f"step {worst} cycles off schedule", worst, rms)
    return RateResult(
        True, "exact", worst, rms, interval_jitter(trace, segs),
        min(trace.pulse_widths("A") + trace.pulse_widths("B")),
        min(trace.low_widths("A") + trace.low_widths("B")),
        min(trace.dir_setup("A") + trace.dir_setup("B"), default=0),
    )


def run_rate_tries(build: sim.BuildPaths, rate_a: int, rate_b: int, tmp: Path,
                   pen: bool) -> RateResult:
    """run_rate up to ATTEMPTS times; the first pass, else the last failure."""
    res = RateResult(False, "not run")
    for attempt in range(1, ATTEMPTS + 1):
        res = dataclasses.replace(run_rate(build, rate_a, rate_b, tmp, pen), attempts=attempt)
        if res.ok:
            break
    return res


def rate_search(build: sim.BuildPaths, ratio: float, tmp: Path,
                pen: bool) -> tuple[int, RateResult | None, str]:
    """(highest passing rate of the faster motor, its result, why the next failed)."""
    best, best_res, failed = 0, None, f"the cap, {rate_cap() / 1000:g} kHz ($0), reached"
    # 10 ms segments: the cap's interval ceil(F_CPU / cap) bounds the steps
    cap = rate_cap()
    top = F_CPU // -(-F_CPU // cap) // 100 * 100
    for rate in [r for r in RATES if r < top] + [top]:
        res = run_rate_tries(build, rate, round(rate * ratio), tmp, pen)
        tries = f" (attempt {res.attempts})" if res.attempts > 1 else ""
        print(f"    1:{ratio:g} at {rate / 1000:4.1f} kHz -> {res.reason}{tries}", flush=True)
        if not res.ok:
            failed = f"{rate / 1000:.1f} kHz: {res.reason}"
            break
        best, best_res = rate, res
    return best, best_res, failed


def ns(cycles: int) -> float:
    """Cycles to ns at F_CPU."""
    return cycles * NS_PER_CYCLE


def print_timing(res: RateResult) -> None:
    """The shortest high, low and set-up times against each driver's minima."""
    high, low, setup = ns(res.min_high), ns(res.min_low), ns(res.min_dir_setup)
    print(f"      step high >= {high:.0f} ns, step low >= {low:.0f} ns, "
          f"dir set-up >= {setup:.0f} ns")
    for name, (h_min, l_min, s_min) in DRIVERS.items():
        ok = high >= h_min and low >= l_min and setup >= s_min
        print(f"      {name:8s} needs high {h_min:.0f} / low {l_min:.0f} / set-up {s_min:.0f} ns:"
              f" {'met' if ok else 'NOT met'}")


def rate_table(build: sim.BuildPaths, ratios: tuple[float, ...], tmp: Path, pen: bool) -> None:
    """Print the rate search, jitter and pulse timing for every ratio."""
    label = "with the pen servo running" if pen else "without the pen servo"
    print(f"  step rate, {label} ({', '.join(PEN_LINES) if pen else 'no M280'}):")
    rows = []
    for ratio in ratios:
        best, res, failed = rate_search(build, ratio, tmp, pen)
        rows.append((ratio, best, res, failed))
        if res is None:
            print(f"  1:{ratio:g}: no rate passed ({failed})")
            continue
        print(f"  1:{ratio:g}: {best / 1000:.1f} kHz per motor (faster motor) exact; "
              f"jitter max {res.max_dev} cycles ({res.max_dev / 16:.1f} us), "
              f"RMS {res.rms_dev:.1f} cycles; interval jitter RMS {res.interval_rms:.1f} "
              f"cycles; next: {failed}")
        print_timing(res)
    print(f"  summary {label}: ratio, highest exact kHz per motor, jitter max/RMS cycles,"
          " interval jitter RMS cycles")
    for ratio, best, res, failed in rows:
        jit = f"{res.max_dev} / {res.rms_dev:.1f}" if res else "-"
        ivl = f"{res.interval_rms:.1f}" if res else "-"
        print(f"    1:{ratio:<5g} {best / 1000:5.1f} kHz   {jit:>14s}   {ivl:>6s}"
              f"   (next {failed})")


def fixed_rate_table(build: sim.BuildPaths, ratios: tuple[float, ...], rate: int, tmp: Path,
                     pen: bool) -> None:
    """Print exactness and jitter at one rate of the faster motor for every ratio."""
    print(f"  at {rate / 1000:g} kHz per motor (faster motor): ratio, result, jitter max/RMS "
          "cycles, interval jitter RMS cycles")
    for ratio in ratios:
        res = run_rate_tries(build, rate, round(rate * ratio), tmp, pen)
        jit = f"{res.max_dev} / {res.rms_dev:.1f}   {res.interval_rms:6.1f}" if res.ok else ""
        tries = f"   (attempt {res.attempts} of {ATTEMPTS})" if res.attempts > 1 else ""
        print(f"    1:{ratio:<5g} {res.reason:>8s}   {jit}{tries}")
        if res.ok:
            print_timing(res)


def run_segments(build: sim.BuildPaths, p_us: int, tmp: Path, pen: bool, count: int = 1000) -> int:
    """Stream short numbered segments; return how often the queue ran dry mid-job."""
    dev = sim.start_device(build, tmp / "seg.trace", realtime=True)
    try:
        s = dev.session
        base = start_pen(s, pen)
        s.send("G91")
        lines = [wire.g1(3 if i % 2 else -3, 2, p_us) for i in range(count)]
        replies = s.stream(lines, numbered_from=2 + (len(PEN_LINES) if pen else 0))
        if any(r != protocol.Ok() for r in replies):
            raise sim.EmulatorError(f"segments refused: {replies[:3]}")
        report = s.wait_idle()
    finally:
        dev.close()
    return report.underruns - base - 1


def segment_rate(build: sim.BuildPaths, tmp: Path, pen: bool) -> None:
    """Print the highest sustained segment rate over the link."""
    passed = None
    for p_us in (5_000, *range(3_000, 1_999, -100)):
        dry = run_segments(build, p_us, tmp, pen)
        print(f"    segments of {p_us} us ({1e6 / p_us:.0f}/s): queue ran dry {dry}x")
        if dry:
            break
        passed = p_us
    if passed:
        print(f"  sustained segment rate over 115200 baud (N + checksum lines): "
              f"{1e6 / passed:.0f} segments/s without underrun")


def memory(build: sim.BuildPaths) -> tuple[str, str]:
    """Flash and RAM lines from avr-size."""
    flash = re.search(r"Program:\s+(\d+ bytes \([\d.]+% Full\))", build.size_report)
    ram = re.search(r"Data:\s+(\d+ bytes \([\d.]+% Full\))", build.size_report)
    return (flash.group(1) if flash else "?", ram.group(1) if ram else "?")


def parse_args(argv: list[str]) -> argparse.Namespace:
    """Command-line options."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--pen", action="store_true", help="with the pen servo running")
    mode.add_argument("--both", action="store_true", help="without, then with the pen servo")
    ap.add_argument("--ratios", default=",".join(f"{r:g}" for r in RATIOS),
                    help="comma-separated rate ratios (slower / faster motor)")
    ap.add_argument("--no-segments", action="store_true", help="skip the segment-rate search")
    ap.add_argument("--at", type=float, metavar="KHZ",
                    help="instead of the rate search: exactness and jitter at this rate")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Run every measurement and print the figures."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    reason = sim.toolchain_missing()
    if reason:
        print(f"cannot benchmark: {reason}")
        return 1
    build = sim.ensure_built()
    flash, ram = memory(build)
    print("fivebar firmware benchmark (simavr, ATmega328P @ 16 MHz, emulated cycles)")
    print(f"  flash: {flash}   RAM (static): {ram}")
    ratios = tuple(float(r) for r in args.ratios.split(","))
    modes = (False, True) if args.both else ((True,) if args.pen else (False,))
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        for pen in modes:
            if args.at:
                fixed_rate_table(build, ratios, round(args.at * 1000), tmp, pen)
            else:
                rate_table(build, ratios, tmp, pen)
        if not args.no_segments:
            segment_rate(build, tmp, modes[-1])
    return 0


if __name__ == "__main__":
    sys.exit(main())
