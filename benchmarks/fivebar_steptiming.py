"""fivebar's firmware at a given rate, with the figures benchmarks/grbl_firmware.py prints.

Calls benchmarks/firmware.py's own functions (``job``, ``deviations``,
``rate_cap``) without changing that file: the job is the one firmware.py
streams (SEGMENTS 10 ms segments, directions alternating), its strict
figure is firmware.py's (both motors against floor((2k-1)C/2n) of each
segment, one median), and the interval figure is steptiming's, per motor,
against the differences of the same ideal schedule.  The harness runs
throttled to real time (-R), as firmware.py runs it, so the host streams at
the link's real pace; a "queue ran empty" failure is retried like there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from benchmarks import firmware as fw
from benchmarks import steptiming
from fivebar_host import protocol
from fivebar_host.devices import sim
from fivebar_host.devices.simtrace import Trace


@dataclass(frozen=True)
class FivebarFigures:
    """fivebar's figures at one pair of rates."""

    ok: bool
    reason: str
    strict: steptiming.Jitter  # firmware.py's figure (both motors, one median)
    intervals: tuple[steptiming.Jitter, ...]  # per motor


def ideal_edges(segs: list[tuple[int, int, int]], axis: int) -> list[int]:
    """The ideal rising edges of one motor over the job (firmware.py's schedule)."""
    out: list[int] = []
    start = 0
    for seg in segs:
        cycles = seg[2] * fw.F_CPU // 1_000_000
        out += steptiming.segment_schedule(start, cycles, abs(seg[axis]))
        start += cycles
    return out


def stream_job(build: sim.BuildPaths, segs: list[tuple[int, int, int]],
               trace_path: Path) -> tuple[Trace | None, str]:
    """Stream the job as firmware.py does; (trace, '') or (None, why it failed)."""
    dev = sim.start_device(build, trace_path, realtime=True)
    try:
        s = dev.session
        for line in (f"$0={fw.rate_cap()}", "G91"):
            if s.send(line) != protocol.Ok():
                return None, f"{line} refused"
        replies = s.stream([protocol.g1(a, b, p) for a, b, p in segs], numbered_from=3)
        bad = [r for r in replies if r != protocol.Ok()]
        if bad:
            return None, f"refused: {bad[0]}"
        report = s.wait_idle()
        trace = dev.finish()
    finally:
        dev.close()
    if report.underruns != 1:
        return None, f"queue ran empty {report.underruns - 1}x"
    return trace, ""


def fivebar_figures(rate_a: int, rate_b: int, tmp: Path) -> FivebarFigures:
    """Run firmware.py's job at the given rates and measure it (up to fw.ATTEMPTS tries)."""
    build = sim.ensure_built()
    segs = fw.job(rate_a, rate_b)
    none = steptiming.Jitter(0.0, 0.0, 0)
    why = "not run"
    for _ in range(fw.ATTEMPTS):
        trace, why = stream_job(build, segs, tmp / "fivebar.trace")
        if trace is None:
            continue
        devs, why = fw.deviations(trace, segs)
        if why:
            return FivebarFigures(False, why, none, ())
        intervals = tuple(
            steptiming.summarize(steptiming.interval_deviations(
                [st.cycle for st in trace.steps(name)], ideal_edges(segs, axis)))
            for axis, name in enumerate(("A", "B")) if any(seg[axis] for seg in segs))
        return FivebarFigures(True, "exact", steptiming.summarize(devs), intervals)
    return FivebarFigures(False, why, none, ())
