"""Step-timing figures shared by the firmware benchmarks: ideal schedules and jitter.

Every time here is in emulated CPU cycles (the trace's unit); edges are the
cycles of the rising step edges of ONE motor, in time order.  Two jitter
definitions, so that fivebar and other firmware (GRBL) are measured alike:

strict jitter (``strict_deviations`` + ``summarize``)
    Each rising edge against its ideal time, less the median of those
    differences (the phase is fitted, a constant latency is not jitter);
    reported as the largest absolute deviation and the RMS.  fivebar's ideal
    time of step k (1..n) of a segment of C cycles with n steps is
    ``start + floor((2k-1)C / 2n)`` (``segment_schedule``: the DDA's
    mid-interval schedule); for firmware that steps at a constant rate the
    ideal is an evenly spaced schedule at the motor's cruise rate
    (``even_schedule``, its interval from ``fit_interval``).

interval jitter (``interval_deviations`` + ``summarize``)
    Each step interval (edge k+1 - edge k) against the ideal interval (the
    same difference of the ideal schedule); nothing is subtracted, so a rate
    error shows up as a bias.  Reported as max absolute and RMS.  Unlike the
    strict figure it does not accumulate: a steady drift of the phase costs
    the strict figure a lot and this one little.

One edge displaced by d cycles in an otherwise perfect schedule of n edges
(n >= 3) gives strict max d and RMS d/sqrt(n), interval max d and RMS
d*sqrt(2/(n-1)) (two intervals change, by +d and -d).

Pure Python, no I/O.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Jitter:
    """Summary of a list of deviations, cycles."""

    max_abs: float  # largest absolute deviation
    rms: float  # root mean square of the deviations
    count: int  # number of deviations summarized


def segment_schedule(start_cycle: int, cycles: int, steps: int) -> list[int]:
    """Ideal rising-edge cycles of ``steps`` steps spread over a segment of ``cycles``.

    Step k (1..n) is due at ``start_cycle + floor((2k-1) * cycles / (2n))``: the
    middle of the k-th of n equal intervals (fivebar's DDA schedule, the one
    benchmarks/firmware.py checks against).  An empty list for ``steps == 0``.
    """
    if steps < 0 or cycles <= 0:
        raise ValueError(f"segment_schedule: steps {steps} must be >= 0, cycles {cycles} > 0")
    return [start_cycle + ((2 * k - 1) * cycles) // (2 * steps) for k in range(1, steps + 1)]


def fit_interval(edges: Sequence[float]) -> float:
    """The least-squares step interval of ``edges`` (slope of edge cycle over step index).

    The cruise rate of a motor stepping at a constant rate is ``freq / fit_interval``;
    least squares, unlike (last - first) / (n - 1), does not hang on the two end edges.
    """
    n = len(edges)
    if n < 2:
        raise ValueError(f"fit_interval needs at least 2 edges, got {n}")
    mean_k = (n - 1) / 2
    mean_e = math.fsum(edges) / n
    num = math.fsum((k - mean_k) * (e - mean_e) for k, e in enumerate(edges))
    den = math.fsum((k - mean_k) ** 2 for k in range(n))
    return num / den


def even_schedule(first_cycle: float, interval: float, count: int) -> list[float]:
    """``count`` ideal edge times ``first_cycle + k * interval`` (k = 0..count-1)."""
    return [first_cycle + k * interval for k in range(count)]


def strict_deviations(edges: Sequence[float], ideal: Sequence[float],
                      whole_cycles: bool = False) -> list[float]:
    """Each edge minus its ideal time, less the median of those differences.

    ``edges`` and ``ideal`` pair up one to one (same length).  Both motors of a
    job that share one schedule origin may be passed concatenated, so one
    median serves both (as benchmarks/firmware.py does).  ``whole_cycles``
    truncates the median to an integer first (int(), as firmware.py does), so
    integer inputs give integer deviations.
    """
    if len(edges) != len(ideal):
        raise ValueError(f"strict_deviations: {len(edges)} edges for {len(ideal)} ideal times")
    if not edges:
        return []
    raw = [e - i for e, i in zip(edges, ideal, strict=True)]
    origin: float = statistics.median(raw)
    if whole_cycles:
        origin = int(origin)
    return [d - origin for d in raw]


def interval_deviations(edges: Sequence[float], ideal: Sequence[float]) -> list[float]:
    """Each step interval minus its ideal interval: (e[k+1]-e[k]) - (i[k+1]-i[k]).

    ``edges`` and ``ideal`` are one motor's edges and ideal times, paired one
    to one; n edges give n-1 deviations.
    """
    if len(edges) != len(ideal):
        raise ValueError(f"interval_deviations: {len(edges)} edges for {len(ideal)} ideal times")
    return [(edges[k + 1] - edges[k]) - (ideal[k + 1] - ideal[k]) for k in range(len(edges) - 1)]


def summarize(deviations: Sequence[float]) -> Jitter:
    """Max absolute value and RMS of ``deviations`` (zeros for an empty list)."""
    n = len(deviations)
    if n == 0:
        return Jitter(0.0, 0.0, 0)
    worst = max(abs(d) for d in deviations)
    rms = math.sqrt(math.fsum(d * d for d in deviations) / n)
    return Jitter(float(worst), rms, n)


def even_jitter(edges: Sequence[float]) -> tuple[Jitter, Jitter, float]:
    """(strict, interval, fitted interval) of edges meant to be evenly spaced.

    The ideal schedule is evenly spaced at the least-squares interval of the
    edges themselves (the motor's measured cruise rate), its phase the median.
    """
    interval = fit_interval(edges)
    ideal = even_schedule(float(edges[0]), interval, len(edges))
    return (summarize(strict_deviations(edges, ideal)),
            summarize(interval_deviations(edges, ideal)), interval)
