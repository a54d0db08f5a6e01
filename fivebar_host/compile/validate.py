"""Validation: how far the executed pen path (forward kinematics of the *quantised* steps,
including the joint-space interpolation between them) lies from the requested curves.

`deviations` measures every draw segment (Newton's method on the primitive, a join bridge to
its end points), `validate` fills the per-path and overall figures into the `Job`,
`nbar_opinion` asks the general n-bar solver (`kinematics.nbar`) for a second opinion, and
`distance_to_request` is shared with `fivebar_host.report.text.executed` (recorded runs).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from fivebar_host.compile import steps
from fivebar_host.compile.model import Job
from fivebar_host.config import Profile
from fivebar_host.toolpath.geometry import nearest_distance
from fivebar_host.toolpath.simplify import segment_distance
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Draw segments measured at a time (bounds the temporaries of forward kinematics and
#: Newton's method: a few hundred bytes a sample) — every sample is measured on its own, so
#: the distances are the same as in one pass.
VALIDATE_BLOCK = 1 << 15


def deviations(job: Job, profile: Profile, samples: int = 4,
               quantised: bool = True) -> tuple[FloatArray, IntArray]:
    """Deviation (mm) of the executed pen path from the requested path, measured on the
    quantised steps: for every draw segment, `samples` points of the joint-space
    interpolation between its quantised end targets (s = 0, 1/samples, …) plus each path's
    last target, through forward kinematics, each measured to the requested curve (Newton's
    method on the primitive; a join bridge is measured to its two end points). Returns the
    distances and the segment index of each. `quantised=False` measures the ideal
    (unrounded) joint targets instead: the tolerance bound itself, without the step quantum."""
    di = np.flatnonzero(job.draw)
    return _sample_distances(job, profile, samples, quantised, di), np.repeat(di, samples + 1)


def _sample_distances(job: Job, profile: Profile, samples: int, quantised: bool,
                      di: IntArray) -> FloatArray:
    """`deviations`' distances, draw segments `di`, in blocks of `VALIDATE_BLOCK`."""
    out = np.empty(di.shape[0] * (samples + 1))
    for i, d in _distance_blocks(job, profile, samples, quantised, di):
        out[i * (samples + 1):i * (samples + 1) + d.shape[0]] = d
    return out


def _distance_blocks(job: Job, profile: Profile, samples: int, quantised: bool,
                     di: IntArray) -> Iterator[tuple[int, FloatArray]]:
    """The distances of `_sample_distances` block by block: (first position in `di`, the
    distances of its `VALIDATE_BLOCK` segments × (samples + 1)). Only a block's angles are
    converted from steps, so no whole-job float copy is made."""
    joint = job.joint_steps  # the joints' steps: the counts less the backlash slack

    def angles(rows: IntArray) -> FloatArray:
        return (steps.step_angles(joint[rows], job.home_rad, job.steps_per_rev)
                if quantised else job.angles_rad[rows])

    s = np.arange(samples + 1) / samples
    asm = "+" if job.assembly > 0 else "-"
    for i in range(0, di.shape[0], VALIDATE_BLOCK):
        b = di[i:i + VALIDATE_BLOCK]
        tha, thb = angles(b), angles(b + 1)
        q = (tha[:, None, :] + s[None, :, None] * (thb - tha)[:, None, :]).reshape(-1, 2)
        fk = profile.geometry.forward_batch(q, asm)
        rank = np.repeat(np.arange(i, i + b.shape[0]), samples + 1)
        d = distance_to_request(job, fk.points, rank, np.tile(s, b.shape[0]))
        d[~fk.valid] = np.inf
        yield i, d


def _deviation_of(job: Job, e: FloatArray, valid: BoolArray, di: IntArray,
                  samples: int) -> tuple[FloatArray, IntArray]:
    """Distances of pen points e ((len(di)·(samples+1), 2), samples s = 0, 1/S, …, 1 of each
    draw segment di) to the requested curves; invalid rows count as infinitely far."""
    s = np.tile(np.arange(samples + 1) / samples, di.shape[0])
    rank = np.repeat(np.arange(di.shape[0]), samples + 1)
    dist = distance_to_request(job, e, rank, s)
    dist[~valid] = np.inf
    return dist, di[rank]


def distance_to_request(job: Job, e: FloatArray, rank: IntArray, s: FloatArray) -> FloatArray:
    """Distance of pen points `e` to the requested curve of draw segment number `rank`
    (counted among draw segments), at fraction `s` ∈ [0, 1] along it as the parameter guess
    for Newton's method on the primitive (a join bridge: distance to its nearer end)."""
    sa, tlo, thi = job.seg_sa[rank], job.seg_tlo[rank], job.seg_thi[rank]
    sig = sa + s * (job.seg_sb[rank] - sa)
    span = thi - tlo
    tg = np.where(job.seg_rev[rank], thi - sig * span, tlo + sig * span)
    prim = job.seg_prim[rank]
    dist = np.empty(e.shape[0])
    real = prim >= 0
    if real.any():
        dist[real] = nearest_distance(job.drawing.kind[prim[real]],
                                      job.drawing.params[prim[real]], e[real], tg[real])
    if job.seg_prim_first.shape == job.seg_prim.shape:
        first = job.seg_prim_first[rank]
        run = real & (first < prim)
        if run.any():
            dist[run] = _distance_to_lines(job, e[run], first[run], prim[run])
    if (~real).any():
        ca, cb = job.seg_ca[rank[~real]], job.seg_cb[rank[~real]]
        dist[~real] = np.minimum(np.hypot(*(e[~real] - ca).T), np.hypot(*(e[~real] - cb).T))
    return dist


def _distance_to_lines(job: Job, e: FloatArray, first: IntArray, last: IntArray) -> FloatArray:
    """Distance of each point e[i] to the nearest of the input lines first[i] … last[i] (a
    simplified run, `toolpath.simplify`): exact, by projection onto every line of the run."""
    span = last - first + 1
    row = np.repeat(np.arange(e.shape[0]), span)
    start = np.cumsum(span) - span
    prim = first[row] + (np.arange(row.shape[0]) - start[row])
    p = job.drawing.params[prim]
    d = segment_distance(e[row], p[:, 0:2], p[:, 2:4])
    return np.asarray(np.minimum.reduceat(d, start), dtype=np.float64)


#: Most poses the n-bar second opinion follows (continuation is ~25 µs per pose).
NBAR_MAX_POSES = 20_000


@dataclass(frozen=True)
class NbarOpinion:
    """The general n-bar solver's view of the executed path (quantised steps, `samples` per
    segment): its largest deviation from the requested path, its largest disagreement with the
    closed form, and how many poses were followed (of how many)."""

    max_dev_mm: float
    max_disagreement_mm: float
    poses: int
    total_poses: int

    def describe(self) -> str:
        part = ("" if self.poses == self.total_poses
                else f" (the first {self.poses} of {self.total_poses} poses)")
        return (f"n-bar solver: max deviation {self.max_dev_mm:.4f} mm, differs from the closed "
                f"form by at most {self.max_disagreement_mm:.2g} mm{part}")


def nbar_opinion(job: Job, profile: Profile, samples: int = 4,
                 max_poses: int = NBAR_MAX_POSES) -> NbarOpinion | None:
    """Second opinion on the validation through `kinematics.nbar` (continuation along the
    whole executed path from the homed pose); None if that solver is not installed."""
    try:
        from kinematics.nbar.validate import validate_fivebar_path
    except ImportError:  # pragma: no cover - the n-bar package ships with the project
        return None
    th = steps.step_angles(job.joint_steps, job.home_rad, job.steps_per_rev)
    s = np.arange(samples) / samples
    q = (th[:-1, None, :] + s[None, :, None] * np.diff(th, axis=0)[:, None, :]).reshape(-1, 2)
    q = np.concatenate((q, th[-1:]))
    total = q.shape[0]
    n = min(total, max_poses)
    v = validate_fivebar_path(profile.geometry, q[:n], job.assembly)
    pts, ok = v.nbar_points, v.valid
    # draw segments whose samples (incl. the end, the next segment's first) were all followed
    di = np.flatnonzero(job.draw)
    di = di[(di + 1) * samples < n]
    idx = (di[:, None] * samples + np.arange(samples + 1)[None, :]).ravel()
    dist, _ = _deviation_of(job, pts[idx], ok[idx], di, samples)
    dis = v.deviation[ok]
    return NbarOpinion(float(dist.max()) if dist.size else 0.0,
                       float(dis.max()) if dis.size else math.nan, n, total)


def validate(job: Job, profile: Profile, samples: int = 4) -> Job:
    """Fill the per-path and overall max/mean deviation from the quantised steps, block by
    block (`_distance_blocks`: the distances of a large job are never held at once). Every
    path's sum is accumulated sample by sample in order, carried from block to block, so the
    per-path means are those of one `np.bincount` pass; the overall mean sums the blocks'
    sums (equal to one pass's up to rounding in the last bits)."""
    if not job.draw.any():
        return job
    di = np.flatnonzero(job.draw)
    n, per_seg = job.n_paths, samples + 1
    mx = np.full(n, -np.inf)
    cnt = np.zeros(n, dtype=np.int64)
    total: FloatArray = np.zeros(n)
    bins = np.arange(n)
    overall_max, overall_sum = -np.inf, 0.0
    for i, d in _distance_blocks(job, profile, samples, True, di):
        path = np.repeat(job.path[di[i:i + VALIDATE_BLOCK]], per_seg)
        np.maximum.at(mx, path, d)
        cnt += np.bincount(path, minlength=n)
        total = np.bincount(np.concatenate((bins, path)), minlength=n,
                            weights=np.concatenate((total, d))).astype(np.float64, copy=False)
        overall_max = max(overall_max, float(d.max()))
        overall_sum += float(d.sum())
    mean = total / np.maximum(cnt, 1)
    mx[cnt == 0] = np.nan
    mean[cnt == 0] = np.nan
    ps = replace(job.paths, max_dev_mm=mx, mean_dev_mm=mean)
    return replace(job, paths=ps, max_dev_mm=overall_max,
                   mean_dev_mm=overall_sum / (di.shape[0] * per_seg))
