"""fivebar's firmware at a given rate, with the figures benchmarks/grbl_firmware.py prints.

Calls benchmarks/firmware.py's own functions (``job``, ``stream_job``,
``deviations``, ``edges_and_ideal``): the job is the one firmware.py
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
from fivebar_host.devices import sim


@dataclass(frozen=True)
class FivebarFigures:
    """fivebar's figures at one pair of rates."""

    ok: bool
    reason: str
    strict: steptiming.Jitter  # firmware.py's figure (both motors, one median)
    intervals: tuple[steptiming.Jitter, ...]  # per motor


def fivebar_figures(rate_a: int, rate_b: int, tmp: Path) -> FivebarFigures:
    """Run firmware.py's job at the given rates and measure it (up to fw.ATTEMPTS tries)."""
    build = sim.ensure_built()
    segs = fw.job(rate_a, rate_b)
    none = steptiming.Jitter(0.0, 0.0, 0)
    why = "not run"
    for _ in range(fw.ATTEMPTS):
        trace, why = fw.stream_job(build, segs, tmp / "fivebar.trace", False)
        if trace is None:
            continue
        devs, why = fw.deviations(trace, segs)
        if why:
            return FivebarFigures(False, why, none, ())
        edges, ideal, _ = fw.edges_and_ideal(trace, segs)
        intervals = tuple(steptiming.summarize(steptiming.interval_deviations(e, i))
                          for e, i in zip(edges, ideal, strict=True) if e)
        return FivebarFigures(True, "exact", steptiming.summarize(devs), intervals)
    return FivebarFigures(False, why, none, ())
