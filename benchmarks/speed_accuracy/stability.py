"""Section 5, the stability map: the outcome of every method at every node of a grid over
the workspace (exact, within tolerance, over it, refused, a motion limit, a branch flip or a
false answer), and its chart (docs/img/perf_stability.png).

`map_methods` are the methods drawn here and along the approaches.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.patches import Patch
from numpy.typing import NDArray

from benchmarks import approx
from benchmarks.speed_accuracy.config import EXACT_MM, Config
from benchmarks.speed_accuracy.methods import guard_of, wrap
from benchmarks.speed_accuracy.nbar_forward import nbar_step_check
from benchmarks.speed_accuracy.plot import overlay, save
from benchmarks.speed_accuracy.scene import Scene, closed_form, dist, ref_forward
from fivebar_host.compile import MAX_STEP_RAD
from kinematics.arrays import BoolArray, FloatArray
from kinematics.nbar import fivebar_mechanism


class Cat(IntEnum):
    """Outcome of a method at one place of the stability map."""

    NO_ANSWER = 0  # no answer exists (closed form refuses) and the method refused too
    OTHER_ASSEMBLY = 1  # forward maps: the point belongs to the other assembly, not asked
    EXACT = 2  # error ≤ EXACT_MM
    WITHIN_TOL = 3  # error ≤ the job tolerance
    OVER_TOL = 4  # error > the job tolerance
    REFUSED = 5  # refused a point that has an answer (documented refusal)
    LIMIT = 6  # n-bar: motion limit / no convergence
    FLIP = 7  # n-bar: converged on the other assembly's branch
    FALSE_ANSWER = 8  # answered where no answer exists


CAT_STYLE: dict[Cat, tuple[str, str]] = {
    Cat.NO_ANSWER: ("#ffffff", "unreachable, refused"),
    Cat.OTHER_ASSEMBLY: ("#d9d9d9", "other assembly (not asked)"),
    Cat.EXACT: ("#1a9850", "error ≤ 1e-6 mm"),
    Cat.WITHIN_TOL: ("#a6d96a", "error ≤ tolerance"),
    Cat.OVER_TOL: ("#fdae61", "error > tolerance"),
    Cat.REFUSED: ("#74add1", "refused (documented)"),
    Cat.LIMIT: ("#313695", "n-bar: motion limit"),
    Cat.FLIP: ("#d73027", "branch flip"),
    Cat.FALSE_ANSWER: ("#000000", "answered, no answer exists"),
}


def _categorise(err: FloatArray, tol: float) -> NDArray[np.int8]:
    c = np.where(err <= EXACT_MM, Cat.EXACT, np.where(err <= tol, Cat.WITHIN_TOL, Cat.OVER_TOL))
    return np.asarray(c, dtype=np.int8)


@dataclass(frozen=True, eq=False)
class StabilityMap:
    xs: FloatArray
    ys: FloatArray
    codes: dict[str, NDArray[np.int8]]  # method → (ny, nx) Cat codes
    nbar_xs: FloatArray
    nbar_ys: FloatArray
    nbar_codes: NDArray[np.int8]
    nbar_tol: float

    def counts(self) -> dict[str, dict[Cat, int]]:
        out = {m: {c: int((v == c).sum()) for c in Cat} for m, v in self.codes.items()}
        out["n-bar forward (coarser grid)"] = {c: int((self.nbar_codes == c).sum())
                                               for c in Cat}
        return out


def map_methods(sc: Scene, cfg: Config
                ) -> dict[str, tuple[str, Callable[[FloatArray], tuple[FloatArray, BoolArray]]]]:
    """The methods drawn on the stability map and along the approaches (name → (direction,
    fn)): the closed form, Eq. 25/26 fitted on the page region, and bilinear tables over the
    workspace / joint-limit box, unguarded and guarded (`max_error` = the job tolerance)."""
    fb, mode, asm = sc.fb, sc.mode, sc.assembly
    n = cfg.map_lut
    centre = sc.page.rect.center
    lin = approx.fit_linear(fb, mode, sc.region_pts, "similarity")
    lut_i = approx.inverse_table(fb, mode, sc.ws_box, n, "linear", centre=centre)
    cap, margins = guard_of(sc)
    lut_ig = approx.inverse_table(fb, mode, sc.ws_box, n, "linear", max_error=cap,
                                  centre=centre, min_margins=margins)
    lut_fg = approx.forward_table(fb, asm, sc.joint_box, n, "linear", max_error=cap,
                                  min_margins=margins)

    closed_inv, closed_fwd = closed_form(sc)

    guard = "guarded"
    return {
        "closed form inverse": ("inverse", closed_inv),
        "closed form forward": ("forward", closed_fwd),
        "Eq. 25 inverse (page fit)": ("inverse", wrap(lin.inverse)),
        "Eq. 26 forward (page fit)": ("forward", wrap(lin.forward)),
        f"LUT bilinear {n}² inverse": ("inverse", wrap(lut_i)),
        f"LUT bilinear {n}² inverse, {guard}": ("inverse", wrap(lut_ig)),
        f"LUT bilinear {n}² forward, {guard}": ("forward", wrap(lut_fg)),
    }


def stability_map(sc: Scene, cfg: Config) -> StabilityMap:
    """Item 5: every method at every node of a grid over the workspace box (working mode of
    the profile). Inverse maps are asked everywhere; forward maps at the closed-form angles of
    reachable points of the page's assembly. The n-bar solver (a continuation step of
    MAX_STEP_RAD, as validation uses it, at its default tolerance) on every
    cfg.nbar_map_stride-th node."""
    fb, mode = sc.fb, sc.mode
    x0, x1, y0, y1 = sc.ws_box
    xs = np.arange(x0, x1 + 1e-9, cfg.map_pitch_mm)
    ys = np.arange(y0, y1 + 1e-9, cfg.map_pitch_mm)
    xx, yy = np.meshgrid(xs, ys)
    p = np.stack((xx.ravel(), yy.ravel()), axis=1)
    inv = fb.inverse_batch(p, mode)
    reach = inv.valid
    th = inv.angles
    sign = np.where(reach, fb.assembly_of(th, p), 0).astype(np.float64)
    same = reach & (sign == sc.sign)
    ref_p = ref_forward(sc, th, np.where(sign == 0, 1.0, sign))
    codes: dict[str, NDArray[np.int8]] = {}
    for name, (direction, fn) in map_methods(sc, cfg).items():
        c = np.full(p.shape[0], Cat.NO_ANSWER, dtype=np.int8)
        if direction == "inverse":
            v, ok = fn(p)
            err = dist(ref_forward(sc, v, np.where(sign == 0, 1.0, sign)), p)
            c[reach] = _categorise(err[reach], sc.tol_mm)
            c[reach & ~ok] = Cat.REFUSED
            c[~reach & ok] = Cat.FALSE_ANSWER
        else:
            c[reach & ~same] = Cat.OTHER_ASSEMBLY
            v, ok = fn(th)
            err = dist(v, ref_p)
            c[same] = _categorise(err[same], sc.tol_mm)
            c[same & ~ok] = Cat.REFUSED
        codes[name] = c.reshape(xx.shape)
    # n-bar on a coarser sub-grid
    st = cfg.nbar_map_stride
    sub = np.zeros(xx.shape, dtype=bool)
    sub[::st, ::st] = True
    idx = np.flatnonzero(sub.ravel())
    nb = np.full(idx.size, Cat.NO_ANSWER, dtype=np.int8)
    tol = fivebar_mechanism(fb, sc.profile.motors.home_rad, sc.assembly).settings.tolerance
    for k, i in enumerate(idx):
        if not reach[i]:
            continue
        if not same[i]:
            nb[k] = Cat.OTHER_ASSEMBLY
            continue
        outcome, q = nbar_step_check(sc, th[i], sign[i], tol)
        if outcome == "limit":
            nb[k] = Cat.LIMIT
        elif outcome == "start":
            nb[k] = Cat.REFUSED
        else:
            e = dist(q[None], ref_p[i:i + 1])[0]
            other = dist(q[None], ref_forward(sc, th[i:i + 1], -sign[i]))[0]
            nb[k] = Cat.FLIP if other < e and e > sc.tol_mm else int(_categorise(
                np.array([e]), sc.tol_mm)[0])
    ny2, nx2 = xx[::st, ::st].shape
    return StabilityMap(xs, ys, codes, xs[::st], ys[::st], nb.reshape(ny2, nx2), tol)


def chart_stability(sc: Scene, smap: StabilityMap, path: Path) -> None:
    """Item 5 map: categorical outcome per method over the workspace."""
    panels = list(smap.codes.items())
    panels.insert(2, (f"n-bar forward (step {MAX_STEP_RAD:g} rad, tol {smap.nbar_tol:g})",
                      smap.nbar_codes))
    ncol = 4
    nrow = -(-len(panels) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 4.3 * nrow + 0.8), squeeze=False)
    colors = [CAT_STYLE[c][0] for c in Cat]
    cmap = ListedColormap(colors)
    norm = BoundaryNorm(np.arange(len(Cat) + 1) - 0.5, len(Cat))
    x0, x1, y0, y1 = sc.ws_box
    for k, (name, codes) in enumerate(panels):
        ax = axes[k // ncol, k % ncol]
        is_nbar = name.startswith("n-bar")
        xs, ys = (smap.nbar_xs, smap.nbar_ys) if is_nbar else (smap.xs, smap.ys)
        ax.pcolormesh(xs, ys, codes, cmap=cmap, norm=norm, shading="nearest")
        overlay(ax, sc)
        ax.set_title(name, fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_xlabel("x, mm", fontsize=8)
        ax.set_ylabel("y, mm", fontsize=8)
        ax.tick_params(labelsize=7)
    for k in range(len(panels), nrow * ncol):
        axes[k // ncol, k % ncol].axis("off")
    used = set()
    for _, codes in panels:
        used |= {int(c) for c in np.unique(codes)}
    handles: list[Any] = [Patch(facecolor=CAT_STYLE[c][0], edgecolor="k",
                                label=CAT_STYLE[c][1]) for c in Cat if int(c) in used]
    handles += [plt.Line2D([], [], color="#d73027", label="type-2 curve (this mode)"),
                plt.Line2D([], [], color="#4d4d4d", ls="--", label="reach circles (type 1)"),
                Patch(facecolor="none", edgecolor="k", label="page rectangle")]
    fig.legend(handles=handles, loc="lower center", ncol=5, fontsize=8)
    fig.suptitle(f"Stability map, working mode {sc.mode}: where each method fails "
                 f"(pen error vs long-double closed form; tolerance {sc.tol_mm:g} mm)",
                 fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    save(fig, path)
