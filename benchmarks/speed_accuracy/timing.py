"""What a timing is worth: the machine it ran on, and side-by-side medians.

`machine_info` records the CPU, cores, library versions and load for the report's header;
`interleaved_medians` times several calls round by round, so load changes on a shared
machine fall on all of them alike.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import platform
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np


def machine_info() -> dict[str, str]:
    """Date, CPU model (from /proc/cpuinfo), cores and library versions of this run."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import scipy

    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        usable = os.cpu_count() or 1
    load = os.getloadavg() if hasattr(os, "getloadavg") else (math.nan,) * 3
    return {
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": cpu,
        "cores": f"{os.cpu_count()} logical, {usable} usable by this process",
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "matplotlib": matplotlib.__version__,
        "load": f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}",
    }


def interleaved_medians(fns: Sequence[Callable[[], object]], repeats: int
                        ) -> list[float | str]:
    """Median wall time of each call over `repeats` rounds, after one warm-up call each.
    The calls are interleaved — every round times each of them once — so a change of load
    on a shared machine falls on all of them alike, and they are compared side by side.
    A call that raises gets its exception text instead of a time."""
    out: list[float | str] = []
    live: list[int] = []
    for i, fn in enumerate(fns):
        try:
            fn()
        except Exception as e:  # reported, not hidden
            out.append(f"{type(e).__name__}: {e}")
            continue
        out.append(math.nan)
        live.append(i)
    times: dict[int, list[float]] = {i: [] for i in live}
    for _ in range(repeats):
        for i in live:
            t0 = time.perf_counter()
            fns[i]()
            times[i].append(time.perf_counter() - t0)
    for i in live:
        out[i] = statistics.median(times[i])
    return out


def timed_build(fn: Callable[[], Any]) -> tuple[Any, float]:
    """Call `fn` once: (its result, wall time in s)."""
    t0 = time.perf_counter()
    obj = fn()
    return obj, time.perf_counter() - t0
