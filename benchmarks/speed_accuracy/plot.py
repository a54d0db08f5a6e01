"""Pieces shared by the charts: saving a figure, the error floor of log axes and the
singularity overlay of the workspace maps.

Matplotlib draws off-screen (Agg, set in the package's `__init__`), so the benchmark runs
without a display.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Rectangle

from benchmarks.speed_accuracy.scene import Scene
from kinematics.workspace import type1_circles, type2_traces

#: Errors are drawn at least this large on log axes (an exact 0 would vanish).
FLOOR_MM = 1e-16


def save(fig: Any, path: Path) -> None:
    """Write the figure as a PNG at 100 dpi and release it."""
    fig.savefig(path, dpi=100)
    plt.close(fig)


def overlay(ax: Any, sc: Scene) -> None:
    """Singularity curves of the working mode, reach circles, motors and the page."""
    for tr in type2_traces(sc.fb):
        for pl in tr.polylines(sc.mode):
            ax.plot(pl[:, 0], pl[:, 1], color="#d73027", lw=1.0)
    for _, _, (cx, cy), r in type1_circles(sc.fb):
        t = np.linspace(0, 2 * np.pi, 361)
        ax.plot(cx + r * np.cos(t), cy + r * np.sin(t), color="#4d4d4d", lw=0.6, ls="--")
    rc = sc.page.rect
    ax.add_patch(Rectangle((rc.x0, rc.y0), rc.width, rc.height, fill=False, ec="k", lw=1.2))
    ax.plot([0.0, sc.fb.w], [0.0, 0.0], "ks", ms=4)
