"""Section 3, job compilation: tolerance against segment count, compile time, plot time and
the deviation measured from the quantised steps; adaptive segmentation against a fixed
spacing; the cost of validation; and the chart (docs/img/perf_jobs.png)."""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import NullFormatter

from benchmarks.kinematics import median_time
from benchmarks.speed_accuracy.config import Config
from benchmarks.speed_accuracy.plot import save
from benchmarks.speed_accuracy.scene import Scene
from fivebar_host.compile import (
    CompileOptions,
    Job,
    compile_job,
    deviations,
    nbar_opinion,
    validate,
)
from fivebar_host.toolpath.geometry import evaluate, nearest_distance
from kinematics.arrays import FloatArray
from kinematics.fivebar import FiveBar


@dataclass(frozen=True)
class JobRow:
    """One compile of a scene at one tolerance, and the fixed-spacing segmentation that
    meets the same tolerance (`fixed_spacing`)."""

    scene: str
    tol: float
    segments: int
    draw_segments: int
    compile_s: float
    plot_s: float
    ideal_max_mm: float
    quant_max_mm: float
    quantum_mm: float
    uniform_segments: int
    uniform_h_mm: float
    uniform_dev_mm: float
    error: str = ""  # the exception, if compiling raised one
    off_chord_mm: float = math.nan  # largest distance of a draw segment's start from its chord


def _segment_distance(e: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance of points e from the segments a → b (row by row)."""
    ab = b - a
    den = np.maximum((ab * ab).sum(axis=1), 1e-300)
    t = np.clip(((e - a) * ab).sum(axis=1) / den, 0.0, 1.0)
    return np.asarray(np.hypot(*(e - a - t[:, None] * ab).T), dtype=np.float64)


def fixed_spacing(job: Job, fb: FiveBar, tol: float, samples: int = 16,
                  iterations: int = 10) -> tuple[int, float, float]:
    """The fixed-point-count alternative to adaptive segmentation: cut every primitive of the
    placed drawing into k = ⌈length/h⌉ equal-parameter pieces (one spacing h for the whole
    drawing), take the closed-form inverse at the piece ends and let the machine interpolate
    in joint space between them. Returns the segment count, the largest h whose deviation
    from the drawing (measured like `fivebar_host.compile.deviations`: `samples` + 1 points per
    piece through the forward kinematics, distance to the primitive) stays ≤ tol (to 0.1 %
    in h), and that deviation."""
    dr = job.drawing
    kind, params = dr.kind, dr.params
    n = kind.shape[0]
    t64 = np.linspace(0.0, 1.0, 65)
    poly = evaluate(np.repeat(kind, 65), np.repeat(params, 65, axis=0), np.tile(t64, n))
    length = np.hypot(*np.diff(poly.reshape(n, 65, 2), axis=1).transpose(2, 0, 1)).sum(axis=1)
    asm = "+" if job.assembly > 0 else "-"
    s = np.arange(samples + 1) / samples

    def trial(h: float) -> tuple[float, int]:
        k = np.maximum(np.ceil(length / h).astype(np.int64), 1)
        prim = np.repeat(np.arange(n), k)
        m = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)
        ta, tb = m / k[prim], (m + 1) / k[prim]
        inv_a = fb.inverse_batch(evaluate(kind[prim], params[prim], ta), job.mode)
        inv_b = fb.inverse_batch(evaluate(kind[prim], params[prim], tb), job.mode)
        if not (inv_a.valid.all() and inv_b.valid.all()):
            return math.inf, int(k.sum())
        tha, thb = inv_a.angles, inv_b.angles
        q = (tha[:, None, :] + s[None, :, None] * (thb - tha)[:, None, :]).reshape(-1, 2)
        fk = fb.forward_batch(q, asm)
        rep = np.repeat(prim, samples + 1)
        tg = (ta[:, None] + s[None, :] * (tb - ta)[:, None]).ravel()
        d = nearest_distance(kind[rep], params[rep], np.asarray(fk.points), tg)
        d[~fk.valid] = np.inf
        return float(d.max()), int(k.sum())

    # Halve h from the longest element until the tolerance is met, then bisect (log h)
    # between the last failing and the first passing spacing; coarse trials are cheap.
    h = max(float(length.max()), 1e-3)
    best = trial(h)
    fail = math.inf
    while best[0] > tol:
        if h < 1e-4:
            raise RuntimeError(f"no fixed spacing ≥ 1e-4 mm meets {tol} mm")
        fail, h = h, 0.5 * h
        best = trial(h)
    lo, hi = math.log(h), math.log(fail) if math.isfinite(fail) else math.log(h)
    for _ in range(iterations):
        if hi - lo < 1e-3:
            break
        mid = 0.5 * (lo + hi)
        d_mid, c_mid = trial(math.exp(mid))
        if d_mid <= tol:
            lo, best = mid, (d_mid, c_mid)
        else:
            hi = mid
    return best[1], math.exp(lo), best[0]


def job_rows(sc: Scene, cfg: Config, scenes: dict[str, Path]) -> list[JobRow]:
    """Item 3: compile each scene at every tolerance (median time of cfg.job_repeats), count
    segments, plot time, deviation from the ideal and the quantised steps (16 samples per
    segment) and the fixed spacing that would meet the same tolerance."""
    rows = []
    prof = sc.profile
    for name, path in scenes.items():
        for tol in cfg.job_tols:
            opts = CompileOptions(tolerance_mm=tol, fit=True, validate=False)
            times = []
            job: Job | None = None
            try:
                for _ in range(cfg.job_repeats):
                    t0 = time.perf_counter()
                    job = compile_job(path, prof, opts)
                    times.append(time.perf_counter() - t0)
            except Exception as e:  # an undocumented failure is a finding: report it
                nan = math.nan
                rows.append(JobRow(name, tol, 0, 0, nan, nan, nan, nan, nan, 0, nan, nan,
                                   f"{type(e).__name__}: {e}"))
                continue
            assert job is not None
            ideal, _ = deviations(job, prof, samples=16, quantised=False)
            quant, _ = deviations(job, prof, samples=16, quantised=True)
            n_u, h_u, d_u = fixed_spacing(job, sc.fb, tol)
            di = np.flatnonzero(job.draw)
            off = _segment_distance(job.points_mm[di], job.seg_ca, job.seg_cb)
            rows.append(JobRow(name, tol, job.n_segments, int(job.draw.sum()),
                               statistics.median(times), job.total_time_s,
                               float(ideal.max()), float(quant.max()), job.step_quantum_mm,
                               n_u, h_u, d_u, "", float(off.max()) if off.size else 0.0))
    return rows


@dataclass(frozen=True)
class ValidationCost:
    """Closed-form validation against the n-bar second opinion on one job."""

    scene: str
    poses: int
    closed_s: float
    nbar_s: float
    closed_max_mm: float
    nbar_max_mm: float
    disagreement_mm: float


def validation_cost(sc: Scene, path: Path, name: str, repeats: int) -> ValidationCost | None:
    """Time `validate` (closed form) and `nbar_opinion` (n-bar continuation) on one job
    (None if the job does not compile: job_rows reports why)."""
    prof = sc.profile
    try:
        job = compile_job(path, prof, CompileOptions(fit=True, validate=False))
    except Exception:
        return None
    t_c = median_time(lambda: validate(job, prof), repeats)
    vj = validate(job, prof)
    t0 = time.perf_counter()
    op = nbar_opinion(job, prof)
    t_n = time.perf_counter() - t0
    assert op is not None
    return ValidationCost(name, op.poses, t_c, t_n, vj.max_dev_mm, op.max_dev_mm,
                          op.max_disagreement_mm)


def chart_jobs(rows: Sequence[JobRow], path: Path) -> None:
    """Item 3 chart: tolerance against segments (adaptive and fixed spacing), compile time,
    plot time and measured deviation."""
    scenes = list(dict.fromkeys(r.scene for r in rows))
    fig, axes = plt.subplots(1, 4, figsize=(18, 4.8))
    cols = plt.get_cmap("tab10")
    ok_rows = [r for r in rows if not r.error]
    for k, sname in enumerate(scenes):
        rs = sorted((r for r in ok_rows if r.scene == sname), key=lambda r: r.tol)
        tol = [r.tol for r in rs]
        col = cols(k)
        axes[0].plot(tol, [r.draw_segments for r in rs], "o-", color=col,
                     label=f"{sname}: adaptive")
        axes[0].plot(tol, [r.uniform_segments for r in rs], "s--", color=col,
                     label=f"{sname}: fixed spacing")
        axes[1].plot(tol, [1e3 * r.compile_s for r in rs], "o-", color=col, label=sname)
        axes[2].plot(tol, [r.plot_s for r in rs], "^-", color=col, label=sname)
        axes[3].plot(tol, [r.quant_max_mm for r in rs], "o-", color=col,
                     label=f"{sname}: from quantised steps")
        axes[3].plot(tol, [r.ideal_max_mm for r in rs], "^:", color=col,
                     label=f"{sname}: ideal joint targets")
        axes[3].plot(tol, [r.quantum_mm for r in rs], "-", color=col, alpha=0.35, lw=3,
                     label=f"{sname}: step quantum")
    if ok_rows:
        lo = min(r.tol for r in ok_rows)
        hi = max(r.tol for r in ok_rows)
        axes[3].plot([lo, hi], [lo, hi], "k--", lw=0.8, label="deviation = tolerance")
    titles = ("draw segments: adaptive vs fixed spacing meeting the same tolerance",
              "compile time (drawing → steps)", "plot time of the job",
              "max deviation from the drawing")
    ylabels = ("segments (log)", "compile time, ms (log)", "plot time, s (log)",
               "max deviation, mm (log)")
    for ax, t, yl in zip(axes, titles, ylabels, strict=True):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("tolerance, mm (log)")
        ax.set_ylabel(yl)
        ax.set_title(t, fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=7)
    fig.suptitle("Job compilation: one tolerance against segments, time and measured deviation",
                 fontsize=11)
    fig.tight_layout()
    save(fig, path)
