"""Benchmark GRBL 1.1h in fivebar's emulator harness with fivebar's step-timing definitions.

Issue 20 compares fivebar's firmware with GRBL 1.1h "in the same AVR emulator
harness".  This script measures GRBL in OUR harness (firmware/build/fbsim,
simavr, ATmega328P at 16 MHz, times in emulated CPU cycles) with the jitter
definitions of benchmarks/steptiming.py, so both firmwares are measured alike:

- GRBL is built from a checkout given by --grbl-src (a bare git dir is
  exported with ``git archive``; a plain source tree is copied) in a temporary
  directory with its own Makefile (avr-gcc -Os, atmega328p, F_CPU 16 MHz).
  No GRBL code enters this repository (GPL).
- The harness runs with -T (two simavr 1.6 timer corrections GRBL needs, see
  fbsim.c's header) and WITHOUT -R: steps are timed in emulated cycles, exact
  at any emulation speed; the host only sends the settings and three moves.
  Each run is capped at 5 s + 10x the moves' time emulated (fbsim -c).
- GRBL's Uno pin map puts X step/dir on D2/D5 and Y on D3/D6, the pins fbsim
  traces as stepA/dirA and stepB/dirB; GRBL's direction pin is high for a
  negative step ($3=0).
- Settings: $100=$101=STEPS_PER_MM, max rates twice the move's, accelerations
  such that the ramp to the feed takes RAMP_S, $0 step pulse (10 us default),
  $1=255 (motors kept enabled), no homing, no limits.
- Per rate ratio (slower / faster motor) the faster motor's rate is raised
  through RATES until GRBL fails, then in REFINE_HZ steps from the last pass
  up to that failure.  One measured G1 per run (G91, X positive, Y negative,
  CRUISE_S of constant feed), then REVERSAL_STEPS back and forth on both
  motors (so each direction pin changes between steps), then ``G4 P0``, whose
  ``ok`` comes when the motion is over.  Exact = every commanded step on each
  motor, each in the right direction, and each motor's cruise rate in the
  measured move (least-squares fit of its edges) within 1 % of the commanded
  rate.  Failures seen: GRBL slows (its step interrupt skips ticks), hangs
  (no end of motion) or the emulated CPU crashes (the step interrupt, which
  re-enables interrupts, re-enters itself until the stack overflows).
- Jitter over the cruise part only (the fast motor's step index past the
  ramp, RAMP_S * rate / 2 steps, and MARGIN_S of steps more at each end, so
  the GRBL segments that mix ramp and cruise are left out; the slower motor
  over the same time window): strict (each edge against an evenly spaced
  schedule at the motor's fitted cruise rate, less the median) and interval
  (each interval against the fitted interval), max and RMS in cycles.
- Also the shortest step high time, low time and direction set-up (every
  step and real direction change of the run; GRBL only reverses from a stop),
  and GRBL's flash and RAM from avr-size.
- --fivebar: fivebar's firmware beside GRBL, per ratio at GRBL's highest rate
  or lower (5 kHz steps) until fivebar's job passes (benchmarks/
  fivebar_steptiming.py, through firmware.py's own functions, with -R).

Run: python benchmarks/grbl_firmware.py [--grbl-src DIR] [--ratios 1,0.73,0.5,0.1]
     [--rates 20000,25000,...] [--pulse-us 10] [--fivebar]
"""

from __future__ import annotations

import argparse
import bisect
import math
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
# Run as a script, this folder comes first on sys.path and benchmarks/kinematics.py would
# shadow the package of that name.
sys.path[:] = [str(ROOT)] + [p for p in sys.path
                             if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

from benchmarks import steptiming  # noqa: E402
from fivebar_host.devices import sim  # noqa: E402
from fivebar_host.devices.simtrace import Step, Trace, read_trace  # noqa: E402

F_CPU = 16_000_000
NS_PER_CYCLE = 1e9 / F_CPU
GRBL_MIRROR = Path("/work/.mirror/gnea+grbl/repo")
RATIOS = (1.0, 0.73, 0.5, 0.1)
#: Per-motor rates of the faster motor tried, steps/s, in order; the search stops at the
#: first that fails.
RATES = (20_000, 25_000, 30_000, 35_000, 40_000, 44_000, 45_000, 50_000, 55_000, 60_000)
STEPS_PER_MM = 100
CRUISE_S = 0.5  # constant-feed part of each move
RAMP_S = 0.05  # acceleration (and deceleration) time of each move
MARGIN_S = 0.02  # left out of the cruise at each end: two GRBL segments (10 ms each)
RATE_TOLERANCE = 0.01
#: After the measured move: back and forth REVERSAL_STEPS on both motors, so each direction
#: pin changes between steps (GRBL writes it in the step interrupt that steps next).
REVERSAL_STEPS = 100
REFINE_HZ = 1_000  # the search refines between the last pass and the first failure


class GrblBenchError(sim.EmulatorError):
    """GRBL could not be built or did not answer as expected."""


@dataclass(frozen=True)
class GrblBuild:
    """A GRBL ELF built in a temporary directory."""

    elf: Path
    version: str
    flash_bytes: int  # .text + .data
    ram_bytes: int  # .data + .bss (static)


@dataclass(frozen=True)
class MotorFigures:
    """One motor's figures over the cruise part of a move."""

    steps: int  # steps of the whole move
    cruise_steps: int
    rate_cmd: float  # commanded rate, steps/s
    rate_hz: float  # measured cruise rate (least-squares), steps/s
    strict: steptiming.Jitter
    interval: steptiming.Jitter


@dataclass(frozen=True)
class MoveResult:
    """Outcome of one G1 move at a given pair of motor rates."""

    ok: bool
    reason: str
    motors: tuple[MotorFigures, ...] = ()
    min_high: int = 0  # shortest step high time, cycles
    min_low: int = 0  # shortest step low time, cycles
    min_dir_setup: int = 0  # shortest direction change to step edge, cycles


def export_source(src: Path, dest: Path) -> Path:
    """A buildable copy of the GRBL tree at ``src`` (bare git dir or plain tree) in ``dest``."""
    out = dest / "grbl-src"
    if (src / "grbl" / "grbl.h").exists():
        shutil.copytree(src, out, ignore=shutil.ignore_patterns(".git", "*.o", "*.elf"))
        return out
    if (src / "HEAD").exists() and (src / "objects").is_dir():
        out.mkdir()
        archive = subprocess.run(["git", "-C", str(src), "archive", "HEAD"],
                                 capture_output=True, check=False)
        if archive.returncode != 0:
            raise GrblBenchError(f"{src}: git archive failed: {archive.stderr.decode()}")
        subprocess.run(["tar", "-x", "-C", str(out)], input=archive.stdout, check=True)
        return out
    raise GrblBenchError(f"{src}: neither a GRBL source tree (grbl/grbl.h) nor a bare git dir")


def build_grbl(src: Path, dest: Path) -> GrblBuild:
    """Export and build GRBL with its own Makefile (avr-gcc -Os, atmega328p, 16 MHz)."""
    tree = export_source(src, dest)
    header = (tree / "grbl" / "grbl.h").read_text(errors="replace")
    m = re.search(r'#define\s+GRBL_VERSION\s+"([^"]+)"', header)
    version = m.group(1) if m else "?"
    makefile = (tree / "Makefile").read_text(errors="replace")
    if not re.search(r"CLOCK\s*=\s*16000000", makefile) or "atmega328p" not in makefile:
        raise GrblBenchError(f"{tree / 'Makefile'}: not an atmega328p 16 MHz build")
    (tree / "build").mkdir(exist_ok=True)
    proc = subprocess.run(["make", "-C", str(tree), "grbl.hex"], capture_output=True,
                          text=True, check=False)
    elf = tree / "build" / "main.elf"
    if proc.returncode != 0 or not elf.exists():
        raise GrblBenchError(f"GRBL build failed (needs make, avr-gcc, avr-libc):\n"
                             f"{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    size = subprocess.run(["avr-size", "--format=berkeley", str(elf)], capture_output=True,
                          text=True, check=True).stdout.splitlines()[-1].split()
    text, data, bss = (int(x) for x in size[:3])
    return GrblBuild(elf, version, text + data, data + bss)


class GrblEmulator(sim.Emulator):
    """fbsim with -T (the timer corrections GRBL needs) and a cycle limit, never -R."""

    def __init__(self, elf: Path, harness: Path, trace: Path, limit_s: float) -> None:
        super().__init__(elf, harness, trace)
        self.limit_s = limit_s

    def command(self) -> list[str]:
        """The harness command line with -T and -c (stop after limit_s emulated)."""
        cmd = super().command()
        return [cmd[0], "-T", "-c", str(round(self.limit_s * F_CPU)), *cmd[1:]]


class GrblLink:
    """Send-response streaming to GRBL on the harness's pty (pyserial at 115200)."""

    def __init__(self, port: Any) -> None:
        self.port = port
        self.log: list[str] = []

    def read_line(self, deadline: float) -> str:
        """The next line GRBL sends ('' when the deadline passed)."""
        buf = b""
        while time.monotonic() < deadline:
            buf += self.port.readline()
            if buf.endswith(b"\n"):
                line = buf.decode("ascii", errors="replace").strip()
                self.log.append(line)
                return line
        return ""

    def wait_banner(self, timeout_s: float = 20.0) -> str:
        """Read until GRBL's welcome line ("Grbl 1.1h ['$' for help]")."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            line = self.read_line(deadline)
            if line.startswith("Grbl "):
                return line
        raise GrblBenchError(f"no GRBL banner in {timeout_s:g} s (got {self.log[-5:]})")

    def send(self, line: str, timeout_s: float = 20.0) -> None:
        """Send one line and wait for its ``ok``; an ``error:`` or ``ALARM:`` raises."""
        self.port.write(line.encode("ascii") + b"\n")
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            reply = self.read_line(deadline)
            if reply == "ok":
                return
            if reply.startswith(("error:", "ALARM:")):
                raise GrblBenchError(f"GRBL answered {reply!r} to {line!r}")
        raise GrblBenchError(f"no ok for {line!r} in {timeout_s:g} s (got {self.log[-5:]})")


@dataclass(frozen=True)
class Move:
    """One G1 move: step counts, feed and settings for a faster-motor rate and a ratio."""

    n_fast: int
    n_slow: int
    feed_mm_min: float
    accel_mm_s2: float

    @classmethod
    def for_rate(cls, rate_hz: int, ratio: float) -> Move:
        """A move whose faster motor (X) steps at ``rate_hz`` for CRUISE_S plus the ramps."""
        n_fast = math.ceil(rate_hz * (CRUISE_S + 2 * (RAMP_S + MARGIN_S)) / 100) * 100
        n_slow = round(n_fast * ratio)
        feed = rate_hz * 60 / STEPS_PER_MM * math.hypot(n_fast, n_slow) / n_fast
        return cls(n_fast, n_slow, round(feed, 3), rate_hz / STEPS_PER_MM / RAMP_S)

    def rates_cmd(self) -> tuple[float, float]:
        """Commanded (X, Y) rates, steps/s, of the feed as sent (3 decimals)."""
        x = self.feed_mm_min / 60 * STEPS_PER_MM * self.n_fast / math.hypot(self.n_fast,
                                                                           self.n_slow)
        return x, x * self.n_slow / self.n_fast

    def lines(self, pulse_us: int) -> list[str]:
        """Settings, the measured move, then the two reversals (X back, Y forth, and again)."""
        max_rate = 2 * self.feed_mm_min
        back = REVERSAL_STEPS / STEPS_PER_MM
        return [f"$0={pulse_us}", "$1=255", f"$100={STEPS_PER_MM}", f"$101={STEPS_PER_MM}",
                f"$110={max_rate:.3f}", f"$111={max_rate:.3f}",
                f"$120={self.accel_mm_s2:.3f}", f"$121={self.accel_mm_s2:.3f}", "G21 G91",
                f"G1 X{self.n_fast / STEPS_PER_MM:.2f} Y{-self.n_slow / STEPS_PER_MM:.2f} "
                f"F{self.feed_mm_min:.3f}", f"G1 X{-back:.2f} Y{back:.2f}",
                f"G1 X{back:.2f} Y{-back:.2f}"]

    def duration_s(self) -> float:
        """Emulated duration of the move, s (ramps included)."""
        return self.n_fast / self.rates_cmd()[0] + 4 * RAMP_S


def run_grbl(build: GrblBuild, harness: Path, move: Move, trace_path: Path,
             pulse_us: int) -> Trace:
    """Boot GRBL in the harness, configure it, run the move and return the trace.

    Raises GrblBenchError when GRBL refuses a line or stops answering; a
    crash of the emulated CPU (a stack overflow: GRBL's step interrupt
    re-enables interrupts and re-enters itself when it runs longer than a
    tick) is reported with simavr's words.
    """
    limit_s = 5.0 + 10 * move.duration_s()
    emu = GrblEmulator(build.elf, harness, trace_path, limit_s)
    try:
        port = sim.open_port(emu.start(), timeout=0.05)
        try:
            link = GrblLink(port)
            link.wait_banner()
            for line in move.lines(pulse_us):
                link.send(line)
            # the dwell waits for the planner and steppers: its ok ends the motion
            link.send("G4 P0", timeout_s=120.0 + 20 * move.duration_s())
        finally:
            port.close()
    except (GrblBenchError, OSError) as e:  # pyserial's SerialException is an OSError
        stats = emu.stop()
        if "CPU crashed" in stats:
            nested = stats.count("run out of nested stack")
            raise GrblBenchError(
                f"emulated CPU crashed ({nested}x 'avr_service_interrupts run out of nested "
                f"stack', then a write out of RAM: the stack overflowed)") from e
        if emu.returncode == 0:
            steps = read_trace(trace_path).steps("A")
            last = f", the last at {steps[-1].cycle / F_CPU:.3f} s" if steps else ""
            raise GrblBenchError(
                f"no end of motion within {limit_s:.1f} s emulated (fbsim -c): motor A made "
                f"{len(steps)} of {move.n_fast} steps{last}") from e
        raise GrblBenchError(f"{e}; harness: {stats.strip()[-300:]}") from e
    finally:
        emu.stop()
    # GRBL's direction pin is high for a negative step ($3=0)
    return read_trace(trace_path, dir_invert=(True, True))


def cruise_window(fast: list[Step], rate_hz: float) -> tuple[int, int]:
    """[first, last] cycle of the fast motor's cruise: past the ramps and MARGIN_S."""
    skip = math.ceil(rate_hz * (RAMP_S / 2 + MARGIN_S))
    return fast[skip].cycle, fast[len(fast) - 1 - skip].cycle


def motor_figures(steps: list[Step], window: tuple[int, int],
                  rate_cmd: float) -> MotorFigures:
    """Cruise rate and jitter of one motor's edges inside ``window``."""
    edges = [s.cycle for s in steps if window[0] <= s.cycle <= window[1]]
    if len(edges) < 3:
        none = steptiming.Jitter(0.0, 0.0, 0)
        return MotorFigures(len(steps), len(edges), rate_cmd, 0.0, none, none)
    strict, interval, period = steptiming.even_jitter(edges)
    return MotorFigures(len(steps), len(edges), rate_cmd, F_CPU / period, strict, interval)


def dir_setups(trace: Trace, axis: str) -> list[int]:
    """Cycles from each real change of ``axis``'s direction pin to its next step.

    The trace's first record of the pin is its level at boot, not a change.
    """
    rises = [st.cycle for st in trace.steps(axis)]
    out = []
    for cycle, _ in trace.pin("dir" + axis)[1:]:
        k = bisect.bisect_left(rises, cycle)
        if k < len(rises):
            out.append(rises[k] - cycle)
    return out


def check_counts(steps: list[Step], runs: list[tuple[int, int]], name: str) -> str:
    """'' when ``steps`` are the (count, sign) runs in order, else what differs."""
    total = sum(n for n, _ in runs)
    if len(steps) != total:
        return f"motor {name}: {len(steps)} steps for {total} commanded"
    signs = [sign for n, sign in runs for _ in range(n)]
    if any(st.direction != sign for st, sign in zip(steps, signs, strict=True)):
        return f"motor {name}: a step in the wrong direction"
    return ""


def check_move(trace: Trace, move: Move) -> MoveResult:
    """Exactness (counts, directions, cruise rates) and the figures of one move."""
    steps_a, steps_b = trace.steps("A"), trace.steps("B")
    for steps, n, sign, name in ((steps_a, move.n_fast, 1, "A"), (steps_b, move.n_slow, -1, "B")):
        runs = [(n, sign), (REVERSAL_STEPS, -sign), (REVERSAL_STEPS, sign)]
        why = check_counts(steps, runs, name)
        if why:
            return MoveResult(False, why)
    rates = move.rates_cmd()
    window = cruise_window(steps_a[:move.n_fast], rates[0])
    pairs = ((steps_a[:move.n_fast], rates[0]), (steps_b[:move.n_slow], rates[1]))
    motors = tuple(motor_figures(steps, window, rate) for steps, rate in pairs if steps)
    for motor, name in zip(motors, "AB", strict=False):
        off = motor.rate_hz / motor.rate_cmd - 1 if motor.cruise_steps >= 3 else -1.0
        if abs(off) > RATE_TOLERANCE:
            return MoveResult(False, f"motor {name}: cruise {motor.rate_hz / 1000:.2f} kHz for "
                              f"{motor.rate_cmd / 1000:.2f} commanded ({off:+.1%})", motors)
    return MoveResult(
        True, "exact", motors,
        min(trace.pulse_widths("A") + trace.pulse_widths("B")),
        min(trace.low_widths("A") + trace.low_widths("B")),
        min(dir_setups(trace, "A") + dir_setups(trace, "B"), default=0),
    )


def try_rate(build: GrblBuild, harness: Path, rate: int, ratio: float, tmp: Path,
             pulse_us: int) -> MoveResult:
    """Run and check one move; a GRBL or harness failure is a failed result."""
    move = Move.for_rate(rate, ratio)
    try:
        return check_move(run_grbl(build, harness, move, tmp / "grbl.trace", pulse_us), move)
    except GrblBenchError as e:
        return MoveResult(False, str(e))


def rate_search(build: GrblBuild, harness: Path, ratio: float, rates: tuple[int, ...],
                tmp: Path, pulse_us: int) -> tuple[int, MoveResult | None, str]:
    """(highest passing rate of the faster motor, its result, why the next failed).

    The rates are tried in order up to the first failure, then the gap to it
    in REFINE_HZ steps (so a failure at 40 kHz after a pass at 35 tries 36..39).
    """
    best, best_res, failed = 0, None, "the last rate tried passed"
    queue = list(rates)
    refined = False
    while queue:
        rate = queue.pop(0)
        res = try_rate(build, harness, rate, ratio, tmp, pulse_us)
        print(f"    1:{ratio:g} at {rate / 1000:4.1f} kHz -> {res.reason}", flush=True)
        if res.ok:
            best, best_res = rate, res
            continue
        failed = f"{rate / 1000:.1f} kHz: {res.reason}"
        if refined or best == 0:
            break
        refined = True
        queue = list(range(best + REFINE_HZ, rate, REFINE_HZ))
    return best, best_res, failed


def print_result(ratio: float, best: int, res: MoveResult, failed: str) -> None:
    """The figures of the highest passing rate of one ratio."""
    print(f"  1:{ratio:g}: {best / 1000:.1f} kHz per motor (faster motor) exact; next: {failed}")
    for motor, name in zip(res.motors, ("A (X)", "B (Y)"), strict=False):
        print(f"    motor {name}: {motor.steps} steps, cruise {motor.cruise_steps} steps at "
              f"{motor.rate_hz:.0f} Hz (commanded {motor.rate_cmd:.0f}); "
              f"strict max {motor.strict.max_abs:.1f} RMS {motor.strict.rms:.1f} cycles, "
              f"interval max {motor.interval.max_abs:.1f} RMS {motor.interval.rms:.1f} cycles")
    print(f"    step high >= {res.min_high * NS_PER_CYCLE:.0f} ns, step low >= "
          f"{res.min_low * NS_PER_CYCLE:.0f} ns, dir set-up >= "
          f"{res.min_dir_setup * NS_PER_CYCLE:.0f} ns")


def print_summary(rows: list[tuple[float, int, MoveResult | None, str]]) -> None:
    """One line per ratio and motor: rate, strict and interval jitter."""
    print("  summary: ratio, highest exact kHz (faster motor), motor, "
          "strict max/RMS, interval max/RMS (cycles)")
    for ratio, best, res, failed in rows:
        if res is None:
            print(f"    1:{ratio:<5g} none passed   (next {failed})")
            continue
        for motor, name in zip(res.motors, "AB", strict=False):
            print(f"    1:{ratio:<5g} {best / 1000:5.1f} kHz  {name}  "
                  f"{motor.strict.max_abs:6.1f} / {motor.strict.rms:5.1f}   "
                  f"{motor.interval.max_abs:6.1f} / {motor.interval.rms:5.1f}   (next {failed})")


def parse_args(argv: list[str]) -> argparse.Namespace:
    """Command-line options."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--grbl-src", type=Path, default=GRBL_MIRROR,
                    help="GRBL 1.1h checkout: a bare git dir or a source tree")
    ap.add_argument("--ratios", default=",".join(f"{r:g}" for r in RATIOS),
                    help="comma-separated rate ratios (slower / faster motor)")
    ap.add_argument("--rates", default=",".join(str(r) for r in RATES),
                    help="comma-separated faster-motor rates to try, steps/s, ascending")
    ap.add_argument("--pulse-us", type=int, default=10, help="GRBL $0, step pulse in us")
    ap.add_argument("--fivebar", action="store_true",
                    help="also fivebar's firmware at GRBL's highest rates (firmware.py's job, "
                         "harness in real time: -R)")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Build GRBL, run the rate search for every ratio and print the figures."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    reason = sim.toolchain_missing()
    if reason:
        print(f"cannot benchmark: {reason}")
        return 1
    harness = sim.ensure_built().harness
    ratios = tuple(float(r) for r in args.ratios.split(","))
    rates = tuple(int(r) for r in args.rates.split(","))
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        try:
            build = build_grbl(args.grbl_src, tmp)
        except (GrblBenchError, OSError, subprocess.CalledProcessError) as e:
            print(f"cannot benchmark GRBL: {e}")
            return 1
        print(f"GRBL {build.version} in fivebar's harness (fbsim -T, simavr, ATmega328P @ "
              f"16 MHz, emulated cycles), built from {args.grbl_src}")
        print(f"  flash: {build.flash_bytes} bytes   RAM (static): {build.ram_bytes} bytes")
        print(f"  moves: {STEPS_PER_MM} steps/mm, ramps {RAMP_S * 1000:g} ms, cruise "
              f"{CRUISE_S * 1000:g} ms measured less {MARGIN_S * 1000:g} ms at each end, "
              f"$0={args.pulse_us}")
        rows = []
        for ratio in ratios:
            best, res, failed = rate_search(build, harness, ratio, rates, tmp, args.pulse_us)
            rows.append((ratio, best, res, failed))
            if res is None:
                print(f"  1:{ratio:g}: no rate passed ({failed})")
            else:
                print_result(ratio, best, res, failed)
        print_summary(rows)
        if args.fivebar:
            print_fivebar(rows, build, harness, tmp, args.pulse_us)
    return 0


def print_fivebar(rows: list[tuple[float, int, MoveResult | None, str]], build: GrblBuild,
                  harness: Path, tmp: Path, pulse_us: int) -> None:
    """fivebar's firmware and GRBL at one rate per ratio: GRBL's highest, or lower (5 kHz
    steps) until fivebar's job (benchmarks/firmware.py's) passes too."""
    from benchmarks.fivebar_steptiming import fivebar_figures

    print("  fivebar firmware beside GRBL at one rate (fivebar: firmware.py's job of 10 ms "
          "segments, directions alternating, -R; its strict figure is firmware.py's, both "
          "motors; max / RMS cycles):")
    for ratio, best, _, _ in rows:
        rate = best
        while rate >= 20_000:
            fig = fivebar_figures(rate, round(rate * ratio), tmp)
            if fig.ok:
                break
            print(f"    1:{ratio:<5g} {rate / 1000:5.1f} kHz  fivebar: {fig.reason}")
            rate -= 5_000
        if rate < 20_000:
            continue
        inter = "   ".join(f"{name} {j.max_abs:.1f} / {j.rms:.2f}"
                           for name, j in zip("AB", fig.intervals, strict=False))
        print(f"    1:{ratio:<5g} {rate / 1000:5.1f} kHz  fivebar: strict {fig.strict.max_abs:.1f} "
              f"/ {fig.strict.rms:.2f}   interval {inter}")
        res = try_rate(build, harness, rate, ratio, tmp, pulse_us)
        if not res.ok:
            print(f"    1:{ratio:<5g} {rate / 1000:5.1f} kHz  GRBL: {res.reason}")
            continue
        figs = "   ".join(f"{name} strict {m.strict.max_abs:.1f} / {m.strict.rms:.2f}, interval "
                           f"{m.interval.max_abs:.1f} / {m.interval.rms:.2f}"
                           for name, m in zip("AB", res.motors, strict=False))
        print(f"    1:{ratio:<5g} {rate / 1000:5.1f} kHz  GRBL:    {figs}")


if __name__ == "__main__":
    sys.exit(main())
