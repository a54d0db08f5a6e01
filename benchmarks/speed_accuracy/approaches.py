"""Section 5, the approaches: poses closing in on each singularity type, every map method and
the n-bar solver along them, at the singular pose and past it, and the chart
(docs/img/perf_approach.png).

`variant_scene` gives a machine with a Mode 1a singularity when the profile's has none.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from benchmarks.speed_accuracy.config import EXACT_MM, Config
from benchmarks.speed_accuracy.plot import FLOOR_MM, save
from benchmarks.speed_accuracy.scene import Scene, dist, make_scene, ref_forward, signs
from benchmarks.speed_accuracy.stability import map_methods
from kinematics.arrays import FloatArray
from kinematics.fivebar import FiveBar
from kinematics.nbar import Status, fivebar_mechanism, simulate


@dataclass(frozen=True, eq=False)
class Approach:
    """Poses closing in on one singularity: δ (mm) the distance parameter (reach circle:
    distance of P inside it; type 2: how much shorter |R1R2| is than b1 + b2, or |R1R2|
    itself for Mode 1b), the poses, and the angular margin to that singularity."""

    name: str
    deltas: FloatArray
    points: FloatArray
    angles: FloatArray
    sign: float
    margin_deg: FloatArray
    on: tuple[FloatArray, FloatArray]  # (point, angles) exactly at the singularity (δ = 0)
    beyond: tuple[FloatArray, FloatArray]  # δ = −1e-9: past it (point or angles)


def _type1_approach(sc: Scene, arm: int, folded: bool, deltas: FloatArray) -> Approach | None:
    fb = sc.fb
    a, b, mx = (fb.a1, fb.b1, 0.0) if arm == 1 else (fb.a2, fb.b2, fb.w)
    if folded and a == b:
        return None
    radius = abs(a - b) if folded else a + b
    sgn = 1.0 if folded else -1.0  # δ > 0 is inside the reachable annulus
    cx, cy = sc.page.rect.center
    phi0 = math.atan2(cy, cx - mx)
    for dphi in np.radians(np.concatenate(([0.0], np.arange(5, 180, 5),
                                           -np.arange(5, 180, 5)))):
        phi = phi0 + dphi
        u = np.array([math.cos(phi), math.sin(phi)])
        allp = np.array([mx, 0.0]) + (radius + sgn * np.concatenate((deltas, [0.0, -1e-9])))[
            :, None] * u
        inv = fb.inverse_batch(allp[:-1], sc.mode)
        if not inv.valid.all():
            continue
        th = np.asarray(inv.angles)
        m = fb.singularity_margins(th, allp[:-1])
        other = [j for j in range(3) if j != arm - 1]
        if (np.abs(m[:, other]).min() < math.radians(10.0)
                or not np.all(fb.assembly_of(th[:-1], allp[:-2]) == int(sc.sign))):
            continue
        kind = "folded" if folded else "stretched"
        return Approach(f"type 1: arm {arm} {kind}", deltas, allp[:-2], th[:-1], sc.sign,
                        np.degrees(np.abs(m[:-1, arm - 1])), (allp[-2], th[-1]),
                        (allp[-1], np.full(2, np.nan)))
    return None


def _type2_approach(sc: Scene, mode_1b: bool, deltas: FloatArray) -> Approach | None:
    """Joint-space poses closing in on a type-2 singularity, P by the closed-form forward
    kinematics in the page's assembly, in the page's working mode and ≥ 10° from type 1.

    Mode 1a (|R1R2| → b1 + b2): θ1 from a scan over its limits, θ2 solving
    |R1R2| = b1 + b2 − δ (R2 = circle |R2 − M2| = a2 ∩ circle of radius L about R1).
    Mode 1b class I (b1 = b2, R1 = R2 = X at an intersection of the two elbow circles):
    θ = θ_X + δ·(σ1/a1, σ2/a2), so the elbows part along σ2·t2 − σ1·t1 (t_i the circles'
    tangents at X), not along a tangent — along one, P would close in on a type-1
    singularity of the other arm at the same time; δ is then the elbow distance's scale."""
    fb = sc.fb
    if mode_1b and fb.b1 != fb.b2:
        return None
    asm = sc.assembly
    s1, s2 = signs(sc.mode)
    dd = np.concatenate((deltas, [0.0, -1e-9]))
    cands: list[FloatArray] = []
    if mode_1b:
        for xp in approx_elbow_meets(fb):
            tx = np.array([math.atan2(xp[1], xp[0]), math.atan2(xp[1], xp[0] - fb.w)])
            for sg1 in (1.0, -1.0):
                for sg2 in (1.0, -1.0):
                    cands.append(tx + dd[:, None] * np.array([sg1 / fb.a1, sg2 / fb.a2]))
    else:
        lim = sc.profile.motors.limits_rad
        lengths = fb.b1 + fb.b2 - dd
        for th1 in np.linspace(lim[0][0], lim[0][1], 33):
            r1 = np.array([fb.a1 * math.cos(th1), fb.a1 * math.sin(th1)])
            d = np.array([fb.w, 0.0]) - r1
            dn = float(np.hypot(*d))
            kk = ((lengths + fb.a2 + dn) * (lengths + fb.a2 - dn) * (lengths - fb.a2 + dn)
                  * (-lengths + fb.a2 + dn))
            if np.any(kk[:-1] < 0):
                continue
            along = (dn * dn + lengths ** 2 - fb.a2 ** 2) / (2 * dn * dn)
            across = np.sqrt(np.maximum(kk, 0.0)) / (2 * dn * dn)
            for branch in (1.0, -1.0):
                r2 = (r1 + along[:, None] * d
                      + branch * across[:, None] * np.array([-d[1], d[0]]))
                th2 = np.arctan2(r2[:, 1], r2[:, 0] - fb.w)
                cands.append(np.stack((np.full(th2.size, th1), th2), axis=1))
    for th in cands:
        fw = fb.forward_batch(th[:-2], asm)
        if not fw.valid.all():
            continue
        pts = np.asarray(fw.points)
        modes = fb.mode_of(pts, th[:-2])
        if not (np.all(modes[:, 0] == s1) and np.all(modes[:, 1] == s2)):
            continue
        m = fb.singularity_margins(th[:-2], pts)
        if np.abs(m[:, :2]).min() < math.radians(10.0):
            continue
        on = fb.forward_batch(th[-2:-1], asm)
        on_p = np.asarray(on.points[0]) if on.valid[0] else np.full(2, np.nan)
        name = "type 2: Mode 1b (R1 = R2)" if mode_1b else "type 2: Mode 1a"
        beyond = th[-1]  # 1a: the links cannot meet; 1b: the elbows have crossed
        return Approach(name, deltas, pts, th[:-2], sc.sign, np.degrees(np.abs(m[:, 2])),
                        (on_p, th[-2]), (np.full(2, np.nan), beyond))
    return None


def approx_elbow_meets(fb: FiveBar) -> list[FloatArray]:
    """Points X where the elbow circles |X| = a1 and |X − M2| = a2 meet (R1 = R2 = X)."""
    d = fb.w
    a = (d * d + fb.a1 ** 2 - fb.a2 ** 2) / (2 * d)
    h2 = fb.a1 ** 2 - a * a
    if h2 < 0:
        return []
    h = math.sqrt(h2)
    return [np.array([a, h]), np.array([a, -h])]


def approaches(sc: Scene, cfg: Config) -> list[Approach]:
    """One approach per singularity the machine has in its working mode."""
    deltas = 10.0 ** np.asarray(cfg.approach_exponents)
    found = [_type1_approach(sc, 1, False, deltas), _type1_approach(sc, 1, True, deltas),
             _type2_approach(sc, False, deltas), _type2_approach(sc, True, deltas)]
    return [a for a in found if a is not None]


def variant_scene(sc: Scene) -> Scene | None:
    """If the machine has no Mode 1a singularity (b1 + b2 > a1 + a2 + w: the floating links
    can never be stretched into one line), the same profile with floating links of
    (a1 + a2 + w)/2 − 10 mm each, which has one; None if it has one already."""
    fb = sc.fb
    reach = fb.a1 + fb.a2 + fb.w
    if fb.b1 + fb.b2 < reach:
        return None
    b = 0.5 * reach - 10.0
    geo = FiveBar(fb.a1, b, fb.a2, b, fb.w)
    return make_scene(dataclasses.replace(sc.profile, geometry=geo))


@dataclass(frozen=True, eq=False)
class ApproachResult:
    approach: Approach
    machine: str  # which machine ("profile" or the variant's links)
    errors: dict[str, FloatArray]  # method → (K,) pen error mm, NaN where refused
    at: dict[str, str]  # method → outcome exactly at the singularity
    past: dict[str, str]  # method → outcome just beyond it


def _outcome(call: Callable[[], Any]) -> str:
    try:
        call()
    except Exception as e:  # the exception type is the outcome reported
        return f"{type(e).__name__}"
    return "answer"


def run_approaches(sc: Scene, cfg: Config, only: tuple[str, ...] | None = None,
                   machine: str = "profile") -> list[ApproachResult]:
    """Every method along every approach (all, or those named in `only`). The n-bar solver
    follows each approach by continuation (one simulate over the δ sequence from the
    farthest pose), then one more step onto the singular pose and, separately, past it;
    there it is judged by continuity: the distance of its answer from the closed-form
    point of the nearest approach pose, and the assembly sign it ends in."""
    methods = map_methods(sc, cfg)
    fb = sc.fb
    out = []
    for ap in approaches(sc, cfg):
        if only is not None and ap.name not in only:
            continue
        errs: dict[str, FloatArray] = {}
        at: dict[str, str] = {}
        past: dict[str, str] = {}
        ref_p = ref_forward(sc, ap.angles, ap.sign)
        for name, (direction, fn) in methods.items():
            if direction == "inverse":
                v, ok = fn(ap.points)
                e = dist(ref_forward(sc, v, ap.sign), ap.points)
                on_q, past_q = ap.on[0], ap.beyond[0]
            else:
                v, ok = fn(ap.angles)
                e = dist(v, ref_p)
                on_q, past_q = ap.on[1], ap.beyond[1]
            errs[name] = np.where(ok, e, np.nan)
            for q, store in ((on_q, at), (past_q, past)):
                if np.isnan(q).any():
                    store[name] = "—"
                    continue
                _, okk = fn(q[None])
                store[name] = "answer" if okk[0] else "refused"
        # the single-pose closed form raises its documented errors
        for k, (q, store) in enumerate(((ap.on[0], at), (ap.beyond[0], past),
                                        (ap.on[1], at), (ap.beyond[1], past))):
            if np.isnan(q).any():
                continue
            if k < 2:
                store["closed form inverse"] = _outcome(partial(fb.inverse, q, sc.mode))
            else:
                store["closed form forward"] = _outcome(partial(fb.forward, q, sc.assembly))
        mech = fivebar_mechanism(fb, ap.angles[0], sc.assembly)
        sim = simulate(mech, ap.angles)
        good = np.isin(sim.status, (Status.OK, Status.SUBDIVIDED))
        errs["n-bar"] = np.where(good, dist(sim.path("P"), ref_p), np.nan)
        last = ap.points[-1]
        for q, store in ((ap.on[1], at), (ap.beyond[1], past)):
            if np.isnan(q).any():
                store["n-bar"] = "—"
                continue
            s2 = simulate(mech, np.concatenate((ap.angles, q[None])))
            st = Status(int(s2.status[-1])).name.lower()
            if st in ("ok", "subdivided"):
                p2 = s2.path("P")[-1]
                r1, r2 = fb.elbows(q)
                d, e = r2[0] - r1[0], p2 - r1[0]
                sg = float(np.sign(d[0] * e[1] - d[1] * e[0]))
                side = "same" if sg == ap.sign else "other" if sg == -ap.sign else "no"
                st = (f"{st}: {float(np.hypot(*(p2 - last))):.2g} mm from the last approach "
                      f"pose, {side} assembly")
            elif s2.limits:
                before = "motion limit before it" if st == "unreached" else st
                st = f"{before} ({s2.limits[-1].reason.split(':')[0]})"
            store["n-bar"] = st
        out.append(ApproachResult(ap, machine, errs, at, past))
    return out


def chart_approaches(results: Sequence[ApproachResult], tol: float, path: Path) -> None:
    """Item 5 approaches: pen error against distance to each singularity."""
    n = len(results)
    ncol = 2
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(13, 4.4 * nrow + 0.6), squeeze=False)
    names = list(dict.fromkeys(m for r in results for m in r.errors))
    cmap = plt.get_cmap("tab10")
    styles = {m: (cmap(k % 10), "os^vDP*Xh"[k % 9]) for k, m in enumerate(names)}
    for k, res in enumerate(results):
        ax = axes[k // ncol, k % ncol]
        d = res.approach.deltas
        for m, e in res.errors.items():
            col, mk = styles[m]
            ax.plot(d, np.maximum(e, FLOOR_MM), marker=mk, color=col, lw=1, ms=4, label=m)
            refused = np.isnan(e)
            if refused.any():
                ax.plot(d[refused], np.full(refused.sum(), FLOOR_MM), marker=mk, ls="",
                        mfc="none", color=col, ms=7)
        ax.axhline(tol, color="k", ls="--", lw=0.8)
        ax.axhline(EXACT_MM, color="k", ls=":", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.invert_xaxis()
        ax.grid(True, alpha=0.3)
        where = "" if res.machine == "profile" else f", machine with {res.machine}"
        ax.set_title(f"{res.approach.name}{where} (margin {res.approach.margin_deg[0]:.2g}° → "
                     f"{res.approach.margin_deg[-1]:.2g}°)", fontsize=10)
        ax.set_xlabel("δ: distance parameter to the singularity, mm (log, decreasing →)")
        ax.set_ylabel("pen error, mm (log; hollow at floor = refused)")
    for k in range(n, nrow * ncol):
        axes[k // ncol, k % ncol].axis("off")
    handles = [plt.Line2D([], [], color=styles[m][0], marker=styles[m][1], label=m)
               for m in names]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle("Approaching each singularity: error growth and refusals "
                 f"(dashed: tolerance {tol:g} mm, dotted: 1e-6 mm)", fontsize=11)
    fig.tight_layout(rect=(0, 0.07, 1, 0.96))
    save(fig, path)
