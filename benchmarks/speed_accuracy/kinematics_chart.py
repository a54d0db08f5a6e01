"""Chart of section 1 (docs/img/perf_kinematics.png): time per point against the largest pen
error, per direction and point set, one line per family of methods."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt

from benchmarks.speed_accuracy.config import EXACT_MM
from benchmarks.speed_accuracy.methods import MethodRow
from benchmarks.speed_accuracy.nbar_forward import NbarKinRow
from benchmarks.speed_accuracy.plot import FLOOR_MM, save

FAMILY_STYLE: dict[str, tuple[str, str]] = {
    "closed form": ("#000000", "*"),
    "bare formulas": ("#555555", "P"),
    "n-bar": ("#7b3294", "D"),
    "linear Eq. 25/26": ("#d7191c", "s"),
    "linear affine": ("#fdae61", "s"),
    "tiles Eq. 25": ("#e66101", "^"),
    "tiles affine": ("#b2abd2", "^"),
    "LUT bilinear": ("#2c7bb6", "o"),
    "LUT bicubic": ("#1a9641", "o"),
}
GUARDED_STYLE = ("#00bcd4", "v")
FAMILY_STYLE["LUT bilinear guarded"] = GUARDED_STYLE


#: One point of a family's line: (ns per point, max pen error mm, label: size or tolerance).
Point = tuple[float, float, str]


def _family_points(rows: Sequence[MethodRow], nrows: Sequence[NbarKinRow], direction: str,
                   sname: str) -> dict[str, list[Point]]:
    """The points of one panel per family (the n-bar solver on forward panels only);
    methods without a finite error on the set are left out."""
    fams: dict[str, list[Point]] = {}
    for row in rows:
        if row.direction != direction:
            continue
        e = row.errors[sname].max_mm
        if not math.isfinite(e):
            continue
        fams.setdefault(row.family, []).append((row.ns_per_point, max(e, FLOOR_MM),
                                                row.size))
    if direction == "forward":
        for nr in nrows:
            e = nr.errors[sname].max_mm
            if math.isfinite(e):
                fams.setdefault("n-bar", []).append((1e3 * nr.us_per_pose,
                                                     max(e, FLOOR_MM),
                                                     f"{nr.tol:.0e}"))
    return fams


def _order_key(fam: str) -> Callable[[Point], float]:
    """Tables/tiles by size, n-bar by tolerance (loosest first), the rest as they come."""
    def key(t: Point) -> float:
        if fam == "n-bar":
            return -float(t[2])
        if t[2][0].isdigit():
            return float(t[2].split("×")[0].split("²")[0].split(" ")[0])
        return 0.0
    return key


def _draw_families(ax: Any, fams: dict[str, list[Point]]) -> None:
    """One line per family; sizes at the ends of table/tile lines, tolerances on n-bar's."""
    for fam, pts in fams.items():
        col, mk = FAMILY_STYLE.get(fam, GUARDED_STYLE)
        pts.sort(key=_order_key(fam))
        ax.plot([t[0] for t in pts], [t[1] for t in pts], marker=mk, color=col,
                label=fam, lw=1, ms=6)
        if fam.startswith(("LUT", "tiles", "n-bar")):
            for x, y, s in pts if fam == "n-bar" else (pts[0], pts[-1]):
                ax.annotate(s, (x, y), fontsize=7, xytext=(3, 3),
                            textcoords="offset points", color=col)


def _decorate(ax: Any, tol: float, title: str, xlabel: bool, ylabel: bool) -> None:
    """Tolerance and 1e-6 mm lines, log axes, grid, title and the outer axis labels."""
    ax.axhline(tol, color="k", ls="--", lw=0.8)
    ax.axhline(EXACT_MM, color="k", ls=":", lw=0.8)
    ax.text(0.99, tol, f"tolerance {tol:g} mm", fontsize=7, va="bottom", ha="right",
            transform=ax.get_yaxis_transform())
    ax.text(0.99, EXACT_MM, "1e-6 mm", fontsize=7, va="bottom", ha="right",
            transform=ax.get_yaxis_transform())
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(True, which="major", alpha=0.3)
    ax.set_title(title, fontsize=10)
    if xlabel:
        ax.set_xlabel("time per point, ns (log)")
    if ylabel:
        ax.set_ylabel(f"max pen error, mm (log; floor {FLOOR_MM:g})")


def chart_tradeoff(rows: Sequence[MethodRow], nrows: Sequence[NbarKinRow], tol: float,
                   path: Path) -> None:
    """Item 1 chart: ns per point against max pen error, per direction and per set."""
    sets = list(rows[0].errors)
    fig, axes = plt.subplots(2, len(sets), figsize=(5.2 * len(sets), 8.4), sharex=True,
                             sharey=True)
    for r, direction in enumerate(("inverse", "forward")):
        for c, sname in enumerate(sets):
            ax = axes[r, c]
            _draw_families(ax, _family_points(rows, nrows, direction, sname))
            _decorate(ax, tol, f"{direction}, {sname}", r == 1, c == 0)
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8)
    fig.suptitle("Five-bar kinematics: time per point against max pen error "
                 "(inverse answers are measured through the exact forward kinematics)",
                 fontsize=11)
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    save(fig, path)
