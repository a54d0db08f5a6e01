"""Calibration pictures (matplotlib, Agg backend): the `fivebar calibrate check` error map
and the benchmark's charts (docs/calibration.md).

The numbers come from `fivebar_host.calibrate.check` and `benchmarks/calibration.py`; this
module only draws them.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from fivebar_host.calibrate.check import ErrorMap


def draw_error_map(emap: ErrorMap, out: str | Path, title: str,
                   marks: np.ndarray | None = None) -> None:
    """The shape-error map over the safe region, with motors M1 and M2 and optional marks."""
    fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
    x, y = emap.xs, emap.ys
    im = ax.imshow(emap.error_mm, origin="lower", cmap="viridis",
                   extent=(x[0] - 0.5 * (x[1] - x[0]), x[-1] + 0.5 * (x[1] - x[0]),
                           y[0] - 0.5 * (y[1] - y[0]), y[-1] + 0.5 * (y[1] - y[0])))
    ok = np.isfinite(emap.error_mm)
    rows, cols = np.nonzero(ok)
    ax.set_xlim(x[cols.min()] - 5, x[cols.max()] + 5)
    ax.set_ylim(y[rows.min()] - 5, y[rows.max()] + 5)
    if marks is not None and len(marks):
        ax.plot(marks[:, 0], marks[:, 1], "r+", ms=7, label="pattern marks")
        ax.legend(loc="lower right", fontsize=8)
    fig.colorbar(im, ax=ax, label="drawing-shape error, mm")
    ax.set_title(f"{title}\nmax {emap.max_mm:.3f} mm, median {emap.median_mm:.3f} mm "
                 f"(working mode {emap.mode})", fontsize=10)
    ax.set_xlabel("x, mm (machine frame, motor M1 at the origin)")
    ax.set_ylabel("y, mm")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    fig.savefig(Path(out), dpi=110)
    plt.close(fig)


def draw_sweep(xs: Sequence[float], before: np.ndarray, after: np.ndarray, out: str | Path,
               xlabel: str, title: str, logx: bool = False, target: float | None = 0.1) -> None:
    """Shape error (max over the region; median and 90th percentile over random true
    machines) before and after the fit against one swept quantity."""
    fig, ax = plt.subplots(figsize=(7, 4.2), constrained_layout=True)
    xa = np.asarray(xs, dtype=float)
    for data, color, label in ((before, "#d62728", "uncalibrated profile"),
                               (after, "#1f77b4", "fitted profile")):
        med = np.median(data, axis=1)
        p90 = np.percentile(data, 90, axis=1)
        ax.plot(xa, med, "o-", color=color, label=f"{label}: median")
        ax.fill_between(xa, np.percentile(data, 10, axis=1), p90, color=color, alpha=0.2,
                        label=f"{label}: 10–90 %")
    if target is not None:
        ax.axhline(target, color="k", ls="--", lw=1, label=f"target {target:g} mm")
    if logx:
        ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("max drawing-shape error over the pattern's region, mm")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.savefig(Path(out), dpi=110)
    plt.close(fig)
