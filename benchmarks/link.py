"""How well the host uses the 115200-baud line to the firmware (emulated in real time).

Two jobs on `fivebar-sim://?realtime=1` (simavr throttled to wall-clock speed, so the UART's
baud rate binds as on hardware):
1. link-bound: segments shorter than the line can carry — bytes/s sent over the line's
   capacity (target ≥ 90 %);
2. just below capacity (~85 % of the line): does the firmware queue ever run empty mid-path
   (status `U:` counter; target: never).
Capacity is quoted two ways: nominal 8N1 (11 520 B/s) and simavr's UART model, which counts
11 bits per byte (1496 cycles at 16 MHz = 10 695 B/s), the real bound in the emulator.

3. the issue-20 job: 1000 segments of 1–2 steps per motor (a 0.1 mm chord on the default
   profile) at P = 1000 µs, so the plan asks for 1000 segments/s, laser off (S0) as a
   drawing: segments/s, mid-path underruns and bytes per segment with the protocol-2
   encoding (one `N… G1 A… B… P… S…*crc/len` line per segment) and with G6 packing, and the
   host's CPU time per segment (packing alone, and the whole stream loop, process time).

Run: python benchmarks/link.py [--segments 600] [--repeat 3] [--issue-only]
"""

from __future__ import annotations

import argparse
import statistics
import time

from fivebar_host import protocol
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.run import pack
from fivebar_host.run.link import Link

NOMINAL_BPS = 115200 / 10
SIMAVR_BPS = 16_000_000 / 1496


def job(n: int, p_us: int) -> list[str]:
    """A zig-zag of n segments of 3 steps each, P µs long, laser off (S0)."""
    out = ["G90"]
    a = 0
    for k in range(n):
        a += 3 if (k // 50) % 2 == 0 else -3
        out.append(protocol.g1(a, -a, p_us, 0))
    return out


def run(bodies: list[str]) -> tuple[float, int, int, float]:
    """Stream on a fresh emulator; (bytes/s, bytes, mid-path underruns, seconds)."""
    link = Link.open("fivebar-sim://?realtime=1")
    try:
        link.command("G92 A0 B0")
        u0 = link.wait_idle(10.0).underruns
        t0 = time.monotonic()
        res = link.stream(bodies)
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
        out.append(protocol.g1(a, b, p_us, 0))
    return out


def run_issue(bodies: list[str], packed: bool) -> tuple[float, int, float, float]:
    """(segments/s, mid-path underruns, bytes/segment, host CPU µs/segment) on a fresh
    emulator in real time."""
    link = Link.open("fivebar-sim://?realtime=1")
    try:
        link.command("G92 A0 B0")
        u0 = link.wait_idle(10.0).underruns
        c0, t0 = time.process_time(), time.monotonic()
        res = link.stream(bodies, pack_lines=packed)
        final = link.wait_idle(60.0)
        t1, c1 = time.monotonic(), time.process_time()
    finally:
        link.close()
    n = len(bodies) - 1
    return n / (t1 - t0), final.underruns - u0 - 1, res.bytes_sent / n, (c1 - c0) / n * 1e6


def pack_cost_us(bodies: list[str], repeat: int = 5) -> float:
    """Host CPU µs per segment to pack the job's bodies into wire lines (run.pack)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        j = 0
        while j < len(bodies):
            j += pack.pack_line(bodies.__getitem__, j, len(bodies), 1 + j, True, 64)[1]
        best = min(best, time.perf_counter() - t0)
    return best / len(bodies) * 1e6


def issue(repeat: int) -> None:
    """The issue-20 table at 115200 baud (simavr's UART model)."""
    bodies = issue_job()
    print("issue 20 job: 1000 segments, P = 1000 µs (the plan asks 1000 segments/s), "
          f"115200 baud, median of {repeat} runs")
    print(f"{'encoding':28s} {'seg/s':>7s} {'underruns':>10s} {'B/seg':>6s} {'CPU µs/seg':>11s}")
    for name, packed in (("protocol 2 (G1 per line)", False), ("protocol 3 (G6 packing)", True)):
        runs = [run_issue(bodies, packed) for _ in range(repeat)]
        print(f"{name:28s} {statistics.median(r[0] for r in runs):7.0f} "
              f"{max(r[1] for r in runs):10d} {statistics.median(r[2] for r in runs):6.1f} "
              f"{statistics.median(r[3] for r in runs):11.0f}")
    print(f"packing alone: {pack_cost_us(bodies):.1f} µs per segment (run.pack.pack_line)")
    print("targets: ≥ 750 segments/s, 0 mid-path underruns")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--segments", type=int, default=600)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--issue-only", action="store_true")
    args = ap.parse_args()
    why = toolchain_missing()
    if why:
        raise SystemExit(f"emulator unavailable: {why}")
    issue(args.repeat)
    if args.issue_only:
        return
    n = args.segments
    line_len = len(protocol.encode_line(job(2, 1000)[1], 12345))
    # Segment duration that needs 85 % of the emulated line: bytes per second needed =
    # line_len / P.
    p_85 = round(line_len / (0.85 * SIMAVR_BPS) * 1e6)
    print(f"link benchmark: {n} segments per job, ~{line_len} bytes per line, "
          f"median of {args.repeat} runs, emulator in real time")
    rows = []
    for name, p_us in (("link-bound (P = 500 µs)", 500), (f"85 % of line (P = {p_85} µs)",
                                                         p_85)):
        runs = [run(job(n, p_us)) for _ in range(args.repeat)]
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
