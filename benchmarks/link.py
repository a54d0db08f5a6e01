"""The link to the firmware, emulated in real time: segments/s per baud rate, line use, noise.

Everything runs on `fivebar-sim://?realtime=1` (simavr throttled to wall-clock speed; its
UART times every byte from UBRR/U2X, so the baud rate binds as on hardware).

1. the issue-20 job at 115200, 250000, 500000 and 1000000 baud (negotiated with `$B`,
   docs/protocol.md 1.1): 1000 segments of 1–2 steps per motor (a 0.1 mm chord on the
   default profile), laser off (S0) as a drawing, at P = 1000 µs (the plan asks 1000
   segments/s) and at P = 250 µs (4000/s: what the link carries at each rate).
   Segments/s, mid-path underruns, bytes per segment, and the host's CPU µs per segment
   (process time of the stream loop, packing included; packing alone printed too); at
   115200 the protocol-2 encoding (one numbered G1 line per segment) beside G6 packing;
2. the same kind of job built by the real planner: a 100 mm straight line given as 1000
   G-code moves of 0.1 mm, compiled with `compile_job` (no simplification, draw feed
   100 mm/s) and streamed as `fivebar plot` does (`run.moves.build_program`), on the
   default profile and at 1000 rad/s²; and the same line wobbling ±0.03 mm at 300 mm/s,
   planned for each baud rate (the link's floor under durations, `compile.linkrate`);
3. `--line-use`: bytes/s over the line's capacity, protocol-2 lines (nominal 8N1 11 520 B/s;
   simavr counts 11 bits a byte: 10 695 B/s), and whether the queue runs empty just below
   capacity;
4. `--noise`: miss rates of G6 lines under the mock's line noise (benchmarks/link_noise.py).

Run: python benchmarks/link.py [--repeat 3] [--noise [--noise-lines N]] [--line-use] [--dense]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

# Run as a script, this folder comes first on sys.path and benchmarks/kinematics.py would
# shadow the `kinematics` package: drop the folder before importing the project.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
from fivebar_host import protocol, wire  # noqa: E402
from fivebar_host.compile import CompileOptions, compile_job  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from fivebar_host.controllers.fivebar.link import Link  # noqa: E402
from fivebar_host.devices import register  # noqa: E402
from fivebar_host.devices.sim import toolchain_missing  # noqa: E402
from fivebar_host.program import Program  # noqa: E402
from fivebar_host.run.moves import build_program  # noqa: E402

NOMINAL_BPS = 115200 / 10
#: How far the wobbly planned job's points stray from its line, mm.
WOBBLE_MM = 0.03
SIMAVR_BPS = 16_000_000 / 1496


def job(n: int, p_us: int) -> list[str]:
    """A zig-zag of n segments of 3 steps each, P µs long, laser off (S0)."""
    out = ["G90"]
    a = 0
    for k in range(n):
        a += 3 if (k // 50) % 2 == 0 else -3
        out.append(wire.g1(a, -a, p_us, 0))
    return out


def run(bodies: Program | list[str]) -> tuple[float, int, int, float]:
    """Stream on a fresh emulator; (bytes/s, bytes, mid-path underruns, seconds)."""
    link = Link.open("fivebar-sim://?realtime=1")
    try:
        link.command("G92 A0 B0")
        u0 = link.wait_idle(10.0).underruns
        t0 = time.monotonic()
        res = link.stream(bodies, pack_lines=False)
        t1 = time.monotonic()
        final = link.wait_idle(60.0)
    finally:
        link.close()
    mid = final.underruns - u0 - 1  # the queue empties once at the end of the job
    return res.bytes_sent / (t1 - t0), res.bytes_sent, mid, t1 - t0


def issue_job(n: int = 1000, p_us: int = 1000) -> list[str]:
    """`n` short segments (1–2 steps per motor, the size of a 0.1 mm chord), P µs each."""
    out = ["G90"]
    a = b = 0
    for k in range(n):
        a += 1 + (k % 3 == 0)
        b -= 1 + (k % 2)
        out.append(wire.g1(a, b, p_us, 0))
    return out


@dataclasses.dataclass(frozen=True)
class Run:
    """One streamed job: segments/s (the wall clock, and the emulated time from the first
    step to the last), mid-path underruns, bytes and host CPU per segment."""

    seg_s: float
    underruns: int
    bytes_seg: float
    cpu_us_seg: float
    seg_s_steps: float = float("nan")


def step_span_s(trace: Path | None) -> float:
    """Emulated seconds from the first rising step edge to the last in a harness trace
    (`fbsim -t`; exact, whatever the wall clock did)."""
    if trace is None or not trace.exists():
        return float("nan")
    first = last = -1
    with trace.open() as f:
        for ln in f:
            if ln.endswith((" stepA 1\n", " stepB 1\n")):
                c = int(ln.split()[0])
                first = c if first < 0 else first
                last = c
    return (last - first) / 16e6 if last > first else float("nan")


def run_issue(bodies: Program | list[str], packed: bool, baud: int = protocol.BASE_BAUD,
              segments: int | None = None) -> Run:
    """Stream `bodies` on a fresh emulator in real time at `baud` ($B after the banner).
    `segments`: how many of the bodies are segments (default: all but the first)."""
    link = Link.open("fivebar-sim://?realtime=1", link_baud=baud)
    try:
        if link.port.baudrate != baud:
            raise SystemExit(f"{baud} baud: {link.baud_warning}")
        link.command("G92 A0 B0")
        u0 = link.wait_idle(10.0).underruns
        c0, t0 = time.process_time(), time.monotonic()
        res = link.stream(bodies, pack_lines=packed)
        final = link.wait_idle(60.0)
        t1, c1 = time.monotonic(), time.process_time()
    finally:
        link.close()
    n = segments if segments is not None else len(bodies) - 1
    span = step_span_s(getattr(link.port, "trace_path", None))
    return Run(n / (t1 - t0), final.underruns - u0 - 1, res.bytes_sent / n,
               (c1 - c0) / n * 1e6, n / span)


def pack_cost_us(bodies: list[str], repeat: int = 5) -> float:
    """Host CPU µs per segment to pack the job's bodies into wire lines (wire.pack_line)."""
    prog = wire.read_lines(bodies)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        j = 0
        while j < len(prog):
            j += wire.pack_line(prog, j, 1 + j, True, 64)[1]
        best = min(best, time.perf_counter() - t0)
    return best / len(bodies) * 1e6


def _row(name: str, runs: list[Run]) -> str:
    med = statistics.median
    return (f"{name:36s} {med(r.seg_s for r in runs):7.0f} "
            f"{med(r.seg_s_steps for r in runs):11.0f} "
            f"{max(r.underruns for r in runs):10d} {med(r.bytes_seg for r in runs):6.1f} "
            f"{med(r.cpu_us_seg for r in runs):11.0f}")


HEADER = (f"{'':36s} {'seg/s':>7s} {'seg/s steps':>11s} {'underruns':>10s} {'B/seg':>6s} "
          f"{'CPU µs/seg':>11s}")


def issue(repeat: int) -> None:
    """The issue-20 table: every baud rate, the planned rate and the link's own limit."""
    print(f"issue-20 job: 1000 segments of 1-2 steps, emulator in real time, median of "
          f"{repeat} runs (underruns: the worst run)")
    for p_us in (1000, 250):
        bodies = issue_job(p_us=p_us)
        print(f"P = {p_us} µs: the plan asks {1e6 / p_us:.0f} segments/s")
        print(HEADER)
        for baud in protocol.BAUD_RATES:
            if baud == protocol.BASE_BAUD:
                runs = [run_issue(bodies, False, baud) for _ in range(repeat)]
                print(_row(f"{baud} protocol 2 (G1 per line)", runs))
            runs = [run_issue(bodies, True, baud) for _ in range(repeat)]
            print(_row(f"{baud} protocol 3 (G6 packing)", runs))
    print(f"packing alone: {pack_cost_us(issue_job()):.1f} µs per segment (wire.pack_line)")
    print("(seg/s: segments over the wall clock from the first byte sent to idle, the start "
          "and the end's status polls included; seg/s steps: over the emulated time from the "
          "first step to the last, exact)")
    print("targets: ≥ 750 segments/s and 0 mid-path underruns at 115200 (P = 1000 µs)")


def planned_job(max_joint_rad_s2: float | None, feed_mm_s: float = 100.0,
                wobble_mm: float = 0.0,
                link_baud: int = protocol.BASE_BAUD) -> tuple[Program, int, float, float]:
    """A 100 mm line in 1000 G-code moves of 0.1 mm, compiled at `feed_mm_s` (the profile's
    joint acceleration, or `max_joint_rad_s2`, and then a joint speed of 50 rad/s), each
    point moved off the line by up to `wobble_mm` (chords of varied lengths: their
    durations differ, so their G6 items carry `P`), planned for a link at `link_baud`:
    (the program as `fivebar plot` sends it, laser off; segments; segments/s the plan asks on
    the line; on the whole job, travel from and back to the home pose included)."""
    prof = dataclasses.replace(load_profile(), serial=dataclasses.replace(
        load_profile().serial, link_baud=link_baud))
    if max_joint_rad_s2 is not None:
        prof = dataclasses.replace(prof, motion=dataclasses.replace(
            prof.motion, max_joint_rad_s2=max_joint_rad_s2, max_joint_rad_s=50.0))
    x0, y0 = -40.0, 101.6  # a horizontal line the default machine reaches in mode +-
    src = Path(tempfile.mkdtemp()) / "line.gcode"
    moves = [f"G1 X{x0 + 0.1 * k + wobble_mm * math.sin(k):.3f} "
             f"Y{y0 + wobble_mm * math.cos(0.7 * k):.3f}" for k in range(1, 1001)]
    src.write_text("\n".join(["G21", "G90", f"G0 X{x0} Y{y0}", "M3 S255", *moves, "M5"])
                   + "\n")
    job = compile_job(src, prof, CompileOptions(no_simplify=True, draw_feed_mm_s=feed_mm_s,
                                                validate=False))
    us = job.duration_us
    on_line = int(job.draw.sum()) / (float(us[job.draw].sum()) * 1e-6)
    prog = build_program(job, prof, False, 0, (0, 0))
    return prog, len(us), on_line, len(us) / (float(us.sum()) * 1e-6)


def planned(repeat: int) -> None:
    """The real planner's job, G6 packing: the profile at 115200, and with a joint
    acceleration that lets the plan ask ≥ 750 segments/s on the line at every rate."""
    print("the same job from the planner: a 100 mm line as 1000 G-code moves of 0.1 mm, "
          "draw feed 100 mm/s, G6 packing; seg/s over the whole job (travel included)")
    print(HEADER + f" {'plan s':>7s} {'run s':>7s}")
    for acc, rates, wobble in ((None, (protocol.BASE_BAUD,), 0.0),
                               (1000.0, protocol.BAUD_RATES, 0.0),
                               (2000.0, protocol.BAUD_RATES, WOBBLE_MM)):
        name = "profile" if acc is None else f"{acc:g} rad/s²"
        if wobble:
            name = f"wobbly, 300 mm/s, {name}"
            print(f"{name}: chords of varied lengths (±{wobble} mm), so most items carry P; "
                  "planned per baud rate (compile.linkrate)")
        for baud in rates:
            bodies, segments, on_line, whole = planned_job(
                acc, 300.0 if wobble else 100.0, wobble, baud if wobble else protocol.BASE_BAUD)
            if wobble or baud == rates[0]:
                print(f"{name}: the plan asks {on_line:.0f} segments/s on the line, "
                      f"{whole:.0f} on the whole job" + (f" at {baud}" if wobble else ""))
            runs = [run_issue(bodies, True, baud, segments) for _ in range(repeat)]
            run_s = segments / statistics.median(r.seg_s for r in runs)
            print(_row(f"  {name[:22]} at {baud}", runs)
                  + f" {segments / whole:7.3f} {run_s:7.3f}")
    print("(run s: from the first byte sent until the machine is idle again, the start-up")
    print(" delay of the firmware's queue included. The firmware runs every segment for its")
    print(" exact P; only an empty queue (an underrun) makes a job fall behind its plan, so")
    print(" with 0 underruns the line runs at the rate the plan asks. The default")
    print(" max_joint_rad_s2 = 60 limits this line: its chords of 1-3 steps zig-zag in joint")
    print(" space and each corner is taken within the corner acceleration)")


def dense(repeat: int) -> None:
    """The wall-clock figure of tests/test_linkrate.py's dense job (the wobbly line at
    300 mm/s, 2000 rad/s², planned for 115200 baud) on the emulator in real time: mid-path
    underruns per run and their median. Host and emulator share the cores, so this depends
    on the machine's load (the test checks the same job in emulated time instead)."""
    bodies, segments, on_line, _ = planned_job(2000.0, 300.0, WOBBLE_MM, protocol.BASE_BAUD)
    runs = [run_issue(bodies, True, protocol.BASE_BAUD, segments) for _ in range(repeat)]
    under = [r.underruns for r in runs]
    print(f"dense job: {segments} segments, the plan asks {on_line:.0f} segments/s on the "
          f"line at 115200 baud; real time on the emulator, {repeat} runs")
    print(f"  mid-path underruns per run: {under}; median {statistics.median(under):g}; "
          f"segments/s median {statistics.median(r.seg_s for r in runs):.0f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--segments", type=int, default=600, help="--line-use job size")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--issue-only", action="store_true", help="only the issue-20 tables")
    ap.add_argument("--line-use", action="store_true", help="also the line-use table")
    ap.add_argument("--noise", action="store_true", help="only the G6 miss rates")
    ap.add_argument("--noise-lines", type=int, default=1_000_000)
    ap.add_argument("--dense", action="store_true",
                    help="only the dense job of tests/test_linkrate.py, in real time")
    args = ap.parse_args()
    register()  # the emulator's URL scheme
    if args.noise:
        from benchmarks import link_noise

        link_noise.report(args.noise_lines)
        return
    why = toolchain_missing()
    if why:
        raise SystemExit(f"emulator unavailable: {why}")
    if args.dense:
        dense(args.repeat)
        return
    issue(args.repeat)
    if args.issue_only:
        return
    planned(args.repeat)
    if args.line_use:
        line_use(args.segments, args.repeat)


def line_use(n: int, repeat: int) -> None:
    """Bytes/s over the line's capacity with protocol-2 lines, and underruns just below."""
    line_len = len(protocol.encode_line(job(2, 1000)[1], 12345))
    # Segment duration that needs 85 % of the emulated line: bytes per second needed =
    # line_len / P.
    p_85 = round(line_len / (0.85 * SIMAVR_BPS) * 1e6)
    print(f"line use: {n} segments per job, ~{line_len} bytes per line (protocol 2), "
          f"median of {repeat} runs, emulator in real time")
    rows = []
    for name, p_us in (("link-bound (P = 500 µs)", 500), (f"85 % of line (P = {p_85} µs)",
                                                         p_85)):
        runs = [run(job(n, p_us)) for _ in range(repeat)]
        bps = statistics.median(r[0] for r in runs)
        mid = max(r[2] for r in runs)
        secs = statistics.median(r[3] for r in runs)
        rows.append((name, bps, mid, secs))
    print(f"{'job':32s} {'B/s':>8s} {'% nominal':>10s} {'% simavr':>9s} {'underruns':>10s} "
          f"{'s':>6s}")
    for name, bps, mid, secs in rows:
        print(f"{name:32s} {bps:8.0f} {100 * bps / NOMINAL_BPS:9.1f}% "
              f"{100 * bps / SIMAVR_BPS:8.1f}% {mid:10d} {secs:6.2f}")
    print("targets: link-bound ≥ 90 % of the line; no mid-path underrun below capacity")


if __name__ == "__main__":
    main()
