"""Section 4, the physical limit: microstepping and gear ratio against the step quantum on
the page, the step rate they need against the firmware's cap, and the chart
(docs/img/perf_steps.png)."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from benchmarks.speed_accuracy.config import FIRMWARE_CONFIG, Config
from benchmarks.speed_accuracy.plot import overlay, save
from benchmarks.speed_accuracy.scene import Scene
from kinematics.workspace import step_quantum


@dataclass(frozen=True)
class StepRow:
    microsteps: int
    gear: float
    steps_per_rev: float
    quantum_max_mm: float
    quantum_median_mm: float
    rate_needed: float  # steps/s at the profile's max joint speed
    joint_speed_cap: float  # rad/s the firmware's default step-rate cap allows


def firmware_rate_cap() -> float:
    """The firmware's default step-rate limit per motor (`DEF_MAX_RATE`, $0), steps/s."""
    m = re.search(r"#define\s+DEF_MAX_RATE\s+(\d+)", FIRMWARE_CONFIG.read_text())
    if m is None:
        raise RuntimeError(f"DEF_MAX_RATE not found in {FIRMWARE_CONFIG}")
    return float(m.group(1))


def step_rows(sc: Scene, cfg: Config, rng: np.random.Generator) -> list[StepRow]:
    """Item 4: the step quantum (largest pen move of one step of either motor, exact forward
    kinematics, kinematics.workspace.step_quantum) over the page region, per drive setting."""
    pts = sc.region_pts
    if pts.shape[0] > 6000:
        pts = pts[rng.choice(pts.shape[0], 6000, replace=False)]
    full = sc.profile.motors.full_steps
    vmax = sc.profile.motion.max_joint_rad_s
    cap = firmware_rate_cap()
    gears = sorted(set(cfg.gears) | {sc.profile.motors.gear_ratio})
    rows = []
    for g in gears:
        for ms in cfg.microsteps:
            spr = full * ms * g
            rad = 2.0 * math.pi / spr
            q = step_quantum(sc.fb, sc.mode, pts, rad)
            rows.append(StepRow(ms, g, spr, float(np.nanmax(q)), float(np.nanmedian(q)),
                                vmax / rad, cap * rad))
    return rows


def chart_steps(sc: Scene, rows: Sequence[StepRow], path: Path, pitch: float) -> None:
    """Item 4 chart: quantum against microstepping per gear ratio, and the profile's map."""
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    ax = axes[0]
    gears = sorted({r.gear for r in rows})
    cmap = plt.get_cmap("plasma")
    for k, g in enumerate(gears):
        rs = sorted((r for r in rows if r.gear == g), key=lambda r: r.microsteps)
        col = cmap(k / max(len(gears), 1))
        ax.plot([r.microsteps for r in rs], [r.quantum_max_mm for r in rs], "o-", color=col,
                label=f"gear {g:g}: max over the page region")
        ax.plot([r.microsteps for r in rs], [r.quantum_median_mm for r in rs], "s--",
                color=col, label=f"gear {g:g}: median")
    ax.axhline(sc.tol_mm, color="k", ls=":", lw=1)
    ax.text(0.99, sc.tol_mm, f"tolerance {sc.tol_mm:g} mm", fontsize=8, va="bottom",
            ha="right", transform=ax.get_yaxis_transform())
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("microsteps per full step (log₂)")
    ax.set_ylabel("step quantum: pen move of one step, mm (log)")
    ax.set_title(f"{sc.profile.motors.full_steps} full steps/rev; one step of either motor",
                 fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    # map for the profile's own setting
    ax = axes[1]
    x0, x1, y0, y1 = sc.ws_box
    xs = np.arange(x0, x1 + 1e-9, pitch)
    ys = np.arange(max(y0, 0.0), y1 + 1e-9, pitch)
    xx, yy = np.meshgrid(xs, ys)
    pts = np.stack((xx.ravel(), yy.ravel()), axis=1)
    q = step_quantum(sc.fb, sc.mode, pts, sc.profile.motors.rad_per_step).reshape(xx.shape)
    asm = np.full(pts.shape[0], 0)
    inv = sc.fb.inverse_batch(pts, sc.mode)
    asm[inv.valid] = sc.fb.assembly_of(inv.angles[inv.valid], pts[inv.valid])
    q = np.where(asm.reshape(xx.shape) == int(sc.sign), q, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        lq = np.log10(q)
    finite = lq[np.isfinite(lq)]
    lo, hi = (np.percentile(finite, [1, 99]) if finite.size else (-3.0, 0.0))
    im = ax.pcolormesh(xs, ys, lq, cmap="viridis", shading="nearest", vmin=lo, vmax=hi)
    cb = fig.colorbar(im, ax=ax)
    cb.set_label("log₁₀ step quantum, mm")
    overlay(ax, sc)
    m = sc.profile.motors
    ax.set_title(f"profile: {m.microsteps} microsteps, gear {m.gear_ratio:g} "
                 f"(assembly {sc.assembly} of mode {sc.mode})", fontsize=10)
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_aspect("equal")
    ax.set_xlim(x0, x1)
    ax.set_ylim(ys[0], y1)
    fig.suptitle("Physical limit of accuracy: step resolution against the pen's step quantum",
                 fontsize=11)
    fig.tight_layout()
    save(fig, path)
