"""Section 2, the n-bar solver on the paper examples: convergence tolerance and input step
against run time and constraint drift, beside the scipy baseline of benchmarks/nbar.py, and
its chart (docs/img/perf_nbar.png)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import NullFormatter

from benchmarks.kinematics import median_time
from benchmarks.speed_accuracy.config import ROOT, Config
from benchmarks.speed_accuracy.plot import FLOOR_MM, save
from benchmarks.speed_accuracy.timing import interleaved_medians
from fivebar_host.report.text.linkage import load_mechanism
from kinematics.arrays import FloatArray
from kinematics.nbar import sweep


@dataclass(frozen=True)
class ExampleRow:
    """One (example, step factor, tolerance) run of `sweep`, or the scipy baseline (tol NaN)."""

    example: str
    factor: float
    steps: int
    tol: float
    ms: float
    iterations: float
    residual: float
    tracer_dev: float
    limits: int
    solver: str  # "n-bar" or "scipy"
    error: str = ""  # the exception, if the run raised one


def example_rows(cfg: Config) -> tuple[list[ExampleRow], str]:
    """Item 2: every mechanism file, input step × factor (steps adjusted to cover the same
    input range) × tolerance: median time of `sweep`, Newton iterations per step, the largest
    exact-equation residual (the constraint drift) and the tracer's deviation from the run at
    the tightest tolerance that completed; beside scipy (benchmarks/nbar.py's baseline) on the
    same inputs. A run that raises is recorded with its exception, not hidden."""
    baseline: Callable[[Any, FloatArray, bool], tuple[FloatArray, int, int]] | None
    try:
        from benchmarks.nbar import baseline
    except ImportError as e:  # pragma: no cover - benchmarks/nbar.py missing
        baseline = None
        note = f"scipy baseline unavailable ({e})"
    else:
        note = "scipy baseline: benchmarks/nbar.py `baseline` (fsolve / least_squares)"
    rows: list[ExampleRow] = []
    files = sorted((ROOT / "configs" / "mechanisms").glob("*.toml"))
    if cfg.max_examples:
        files = files[:cfg.max_examples]
    for path in files:
        mech = load_mechanism(path)
        tracer = mech.tracers[0] if mech.tracers else mech.joints[-1].name
        for f in cfg.ex_factors:
            steps = max(2, round(mech.settings.steps / f))
            step = mech.step * f
            runs: list[tuple[float, float, Any]] = []  # (tol, median s, Simulation | error)
            tols = sorted(cfg.ex_tols, reverse=True)
            meds = interleaved_medians([partial(sweep, mech, steps, step, tolerance=tol)
                                        for tol in tols], cfg.ex_runs)
            for tol, t in zip(tols, meds, strict=True):
                if isinstance(t, str):  # an undocumented failure is a finding: report it
                    runs.append((tol, math.nan, t))
                else:
                    runs.append((tol, t, sweep(mech, steps, step, tolerance=tol)))
            done = [r for r in runs if not isinstance(r[2], str)]
            ref = done[-1][2] if done else None
            for tol, t, sim in runs:
                if isinstance(sim, str):
                    rows.append(ExampleRow(path.stem, f, steps, tol, math.nan, math.nan,
                                           math.nan, math.nan, 0, "n-bar", sim))
                    continue
                dev = math.nan
                if (ref is not None and sim.inputs.shape == ref.inputs.shape
                        and np.allclose(sim.inputs, ref.inputs)):
                    dev = float(np.nanmax(np.abs(sim.path(tracer) - ref.path(tracer))))
                rows.append(ExampleRow(path.stem, f, len(sim.status) - 1, tol, 1e3 * t,
                                       float(np.mean(sim.iterations[1:])),
                                       float(np.nanmax(sim.residual)), dev, len(sim.limits),
                                       "n-bar"))
            if baseline is not None and ref is not None:
                inputs = ref.inputs
                t = median_time(partial(baseline, mech, inputs, False), cfg.ex_base_runs)
                qb, nfev, fails = baseline(mech, inputs, False)
                cb = mech.coords_batch(qb, inputs)
                res = float(np.max(np.abs(mech.residuals(cb, inputs))))
                dev = float(np.nanmax(np.abs(mech.positions(cb, tracer) - ref.path(tracer))))
                rows.append(ExampleRow(path.stem, f, inputs.shape[0] - 1, math.nan, 1e3 * t,
                                       nfev / max(inputs.shape[0] - 1, 1), res, dev, fails,
                                       "scipy"))
    return rows, note


def chart_examples(rows: Sequence[ExampleRow], path: Path) -> None:
    """Item 2 chart: per example, ms per run against max residual; one line per step factor
    (points at the tolerances), scipy baseline as black crosses."""
    names = sorted({r.example for r in rows})
    ncol = min(4, len(names))
    nrow = -(-len(names) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.6 * nrow), squeeze=False)
    factors = sorted({r.factor for r in rows})
    cmap = plt.get_cmap("viridis")
    for k, name in enumerate(names):
        ax = axes[k // ncol, k % ncol]
        for j, f in enumerate(factors):
            rs = sorted((r for r in rows if r.example == name and r.factor == f
                         and r.solver == "n-bar"), key=lambda r: -r.tol)
            col = cmap(j / max(len(factors) - 1, 1))
            ax.plot([r.ms for r in rs], [max(r.residual, FLOOR_MM) for r in rs], "o-",
                    color=col, ms=4, label=f"step ×{f:g}")
            for r in rs[:1] + rs[-1:]:
                ax.annotate(f"{r.tol:.0e}", (r.ms, max(r.residual, FLOOR_MM)), fontsize=6,
                            xytext=(2, 2), textcoords="offset points", color=col)
            bs = [r for r in rows if r.example == name and r.factor == f
                  and r.solver == "scipy"]
            if bs:
                ax.plot([b.ms for b in bs], [max(b.residual, FLOOR_MM) for b in bs], "x",
                        color=col, ms=8, mew=2)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, alpha=0.3)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("wall time per run, ms (log)")
        ax.set_ylabel("max relative residual (log)")
    for k in range(len(names), nrow * ncol):
        axes[k // ncol, k % ncol].axis("off")
    h, lab = axes[0, 0].get_legend_handles_labels()
    h.append(plt.Line2D([], [], color="k", marker="x", ls="", mew=2))
    lab.append("scipy baseline (same step)")
    fig.legend(h, lab, loc="lower center", ncol=len(lab), fontsize=8)
    fig.suptitle("n-bar solver: tolerance (labels) and input step against time and constraint "
                 "residual", fontsize=11)
    fig.tight_layout(rect=(0, 0.05, 1, 0.96))
    save(fig, path)
