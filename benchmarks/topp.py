"""The planner against a time-optimal path parameterisation (issue 39): TOPP-RA.

For each drawing the job is compiled as `fivebar plot` compiles it (default profile), and
its joint path — the segments as the firmware runs them, ramps cut into pieces — is split
into runs between the stops (the machine is at rest at each pen change, and at the end).
Three times per drawing:

* **planned**: the sum of the job's integer durations (what the firmware runs);
* **continuous**: fivebar's own planner (`compile.planner.plan`) on the same pieces with the
  same limits at the full joint acceleration — its continuous profile, before it is
  realised as one constant step rate per segment;
* **optimal**: TOPP-RA (Pham & Pham, "A new approach to time-optimal path parameterization
  based on reachability analysis", IEEE T-RO 2018; the `toppra` package, a benchmark-only
  extra: ``pip install -e '.[bench]'``), independent of fivebar's code, on each run.

The constraints given to TOPP-RA, and to fivebar's planner: the joint path is the pieces'
straight joint-space chords (the firmware's segments) through the targets' joint angles, as
a function of the pen's path length s (mm); each joint's speed ≤ `max_joint_rad_s` (6 rad/s)
and acceleration ≤ `max_joint_rad_s2` (60 rad/s²) on every chord; the pen's speed ṡ ≤ the
segment's feed (the profile's draw feed on drawing runs, its travel feed on travel); at a
chord's end, each joint's speed may jump by at most `junction_jump_rad_s` (0.5 rad/s):
|Δθ'|∞ · ṡ ≤ 0.5.  TOPP-RA takes a twice-differentiable path: the chords are given as a
path whose value is the chords' (linear interpolation), whose first derivative is the
chord's slope and whose second is 0; the junction is a velocity constraint at the
gridpoint on it (one more coordinate, its derivative |Δθ'|∞ there, 0 elsewhere), the feed
one on a coordinate equal to s, and a joint's speed is held at a junction with the slopes
of both chords (two coordinates a joint).  Grid: every target and `--sub` points inside each
chord (TOPP-RA holds s̈ constant between gridpoints).  Not given to either: the firmware's
shortest segment (`P` ≥ 250 µs) and the link's floor under durations (`compile.linkrate`;
the planned time includes them where they bind) and the corner acceleration cap (off in the
default profile).

Run: python benchmarks/topp.py [--sub 3] [--drawing FILE ...]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

_HERE = Path(__file__).resolve().parent
sys.path[:] = [str(_HERE.parent)] + [p for p in sys.path if Path(p or ".").resolve() != _HERE]
from benchmarks import plan_jobs  # noqa: E402
from fivebar_host import protocol  # noqa: E402
from fivebar_host.compile import CompileOptions, compile_job, linkrate, planner  # noqa: E402
from fivebar_host.compile import job as jobmod  # noqa: E402
from fivebar_host.compile import steps as stepsmod  # noqa: E402
from fivebar_host.config import Profile, load_profile  # noqa: E402

try:
    import toppra
    import toppra.algorithm
    import toppra.constraint
    from toppra.interpolator import AbstractGeometricPath
except ImportError:  # pragma: no cover - a benchmark-only extra
    sys.exit("benchmarks/topp.py needs TOPP-RA: pip install -e '.[bench]'")

ROOT = _HERE.parent
#: The issue's three drawings: a dense circle, the bundled text, a real line drawing.
DRAWINGS = ("circle", "examples/fivebar_text.svg", "benchmarks/drawings/bc_template.svg")
#: A large number for the coordinates whose acceleration is not limited.
FREE = 1e12


class ChordPath(AbstractGeometricPath):  # type: ignore[misc]
    """The run's joint chords as a path of s (mm) for TOPP-RA (module doc): coordinates
    θA, θB (slope of the chord after a knot), θA, θB again (slope of the chord before),
    the junction coordinate and s itself."""

    def __init__(self, s_knots: np.ndarray, theta: np.ndarray, cap: np.ndarray) -> None:
        self.s = s_knots
        self.s_gain = cap.max() / cap  # ṡ·gain ≤ max cap  ⇔  ṡ ≤ cap
        self.theta = theta
        slope = np.diff(theta, axis=0) / np.diff(s_knots)[:, None]
        self.slope = slope
        jump = np.zeros(s_knots.shape[0])
        jump[1:-1] = np.abs(slope[1:] - slope[:-1]).max(axis=1)
        self.jump = jump

    @property
    def dof(self) -> int:
        return 6

    @property
    def path_interval(self) -> np.ndarray:
        return np.array([self.s[0], self.s[-1]])

    def __call__(self, ss: Any, order: int = 0) -> np.ndarray:
        ss = np.atleast_1d(np.asarray(ss, dtype=np.float64))
        n = self.slope.shape[0]
        after = np.clip(np.searchsorted(self.s, ss, side="right") - 1, 0, n - 1)
        before = np.clip(np.searchsorted(self.s, ss, side="left") - 1, 0, n - 1)
        at_knot = np.isclose(ss, self.s[np.clip(np.searchsorted(self.s, ss), 0, n)],
                             rtol=0.0, atol=1e-12)
        out = np.zeros((ss.shape[0], 6))
        if order == 0:
            th = self.theta[after] + self.slope[after] * (ss - self.s[after])[:, None]
            out[:, 0:2] = th
            out[:, 2:4] = th
            out[:, 5] = ss
        elif order == 1:
            out[:, 0:2] = self.slope[after]
            out[:, 2:4] = self.slope[before]
            k = np.clip(np.searchsorted(self.s, ss), 0, self.s.shape[0] - 1)
            out[:, 4] = np.where(at_knot, self.jump[k], 0.0)
            # at a knot the slower of its chords' caps
            out[:, 5] = np.maximum(self.s_gain[after], self.s_gain[before])
        return out


def optimal_s(s_knots: np.ndarray, theta: np.ndarray, prof: Profile, cap: np.ndarray,
              sub: int, ds_mm: float = 0.0) -> float:
    """TOPP-RA's least time for one run from rest to rest (module doc); `cap` (K,) the pen
    speed allowed on each chord, mm/s (the s coordinate's derivative is scaled so that one
    limit, the largest cap, holds each chord's)."""
    path = ChordPath(s_knots, theta, cap)
    feed = float(cap.max())
    m = prof.motion
    v = m.max_joint_rad_s
    vlim = np.array([[-v, v]] * 4 + [[-m.junction_jump_rad_s, m.junction_jump_rad_s],
                                    [-feed, feed]])
    a = m.max_joint_rad_s2
    alim = np.array([[-a, a]] * 2 + [[-FREE, FREE]] * 4)
    cons = [toppra.constraint.JointVelocityConstraint(vlim),
            toppra.constraint.JointAccelerationConstraint(
                alim, discretization_scheme=toppra.constraint.DiscretizationType.Collocation)]
    grid = _grid(s_knots, sub, ds_mm)
    algo = toppra.algorithm.TOPPRA(cons, path, gridpoints=grid,
                                   parametrizer="ParametrizeConstAccel")
    sd = algo.compute_parameterization(0.0, 0.0)[1]  # the path speed at each gridpoint
    if sd is None or not np.isfinite(sd).all():
        raise RuntimeError("TOPP-RA found no parameterisation")
    # time over each grid interval at constant s̈: Δs / mean speed
    ds = np.diff(grid)
    vm = 0.5 * (sd[1:] + sd[:-1])
    return float(np.sum(ds / np.maximum(vm, 1e-12)))


def _grid(s_knots: np.ndarray, sub: int, ds_mm: float) -> np.ndarray:
    """Every knot, `sub` points inside each chord and more where its points would lie
    farther apart than `ds_mm` (TOPP-RA's time converges as the grid refines; on long
    chords `sub` alone left it some % above its limit)."""
    ln = np.diff(s_knots)
    n = np.maximum(sub + 1, np.ceil(ln / ds_mm).astype(np.int64) if ds_mm > 0 else 0)
    i = np.repeat(np.arange(ln.shape[0]), n)
    j = np.arange(i.shape[0]) - np.repeat(np.cumsum(n) - n, n)
    return np.concatenate((s_knots[i] + ln[i] * j / n[i], s_knots[-1:]))


def runs(draw: np.ndarray, moving: np.ndarray) -> list[tuple[int, int]]:
    """(first, end) segment ranges between the stops: the pen's changes."""
    cut = np.flatnonzero(draw[1:] != draw[:-1]) + 1
    edges = np.concatenate(([0], cut, [draw.shape[0]]))
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges) if moving[a:b].any()]


def _compiled(name: str, prof: Profile, fit: bool) -> tuple[Any, np.ndarray]:
    """The job as `fivebar plot` compiles it, and each of its segments' end as a fraction of
    the stepped segment it was cut from (`compile.timing.Planned.f1`, which the job drops:
    read on its way by wrapping the timing step)."""
    seen: list[np.ndarray] = []
    timing_step = jobmod.plan_timing

    def keep_f1(*args: Any) -> Any:
        planned = timing_step(*args)
        seen.append(planned.f1.copy())
        return planned

    jobmod.plan_timing = keep_f1
    try:
        job = (plan_jobs.compiled(plan_jobs.circle_job(), prof) if name == "circle"
               else compile_job(ROOT / name, prof, CompileOptions(validate=False, fit=fit)))
    finally:
        jobmod.plan_timing = timing_step
    return job, seen[-1]


def measure(name: str, prof: Profile, grid: tuple[int, float], fit: bool,
            floors: bool) -> dict[str, float]:
    """planned, continuous and optimal seconds over a drawing's runs (module doc); `grid`:
    TOPP-RA's points inside each chord and their largest spacing (mm)."""
    job, f1 = _compiled(name, prof, fit)
    mot = prof.motors
    th = stepsmod.step_angles(job.steps, mot.home_rad, mot.steps_per_rev)
    dq = np.diff(th, axis=0)
    moving = np.abs(dq).max(axis=1) > 0
    m = prof.motion
    floor_us = np.maximum(linkrate.link_floor_us(job.steps, job.power, job.duration_us, prof),
                          protocol.P_MIN_US).astype(np.float64)
    bound = linkrate.bound_segments(job.steps, job.power, job.duration_us, prof)
    out = dict.fromkeys(("planned", "continuous", "optimal", "uncut", "topp_cpu"), 0.0)
    t0 = time.process_time()
    for a, b in runs(job.draw, moving):
        seg = np.arange(a, b)[moving[a:b]]
        feed = m.draw_feed_mm_s if job.draw[a] else m.travel_feed_mm_s
        length = np.maximum(job.length_mm[seg], 1e-6)
        # the floors as a pen-speed cap per chord: s' ≤ L / T_floor
        floor_s = floor_us[seg] * 1e-6 if floors else np.zeros(seg.shape[0])
        out["planned"] += float(job.duration_us[seg].sum()) * 1e-6  # the pen's moves: not path
        cap = np.minimum(feed, length / np.maximum(floor_s, 1e-300))
        pl = planner.plan(dq[seg], length, cap, m.max_joint_rad_s,
                          m.max_joint_rad_s2, junction_jump_rad_s=m.junction_jump_rad_s)
        out["continuous"] += float(pl.duration_s.sum())
        t1 = time.process_time()
        s_knots = np.concatenate(([0.0], np.cumsum(length)))
        theta = np.concatenate((th[seg[:1]], th[seg + 1]))
        out["optimal"] += optimal_s(s_knots, theta, prof, cap, *grid)
        # the stepped segments before the cut: their ends, each one's pieces' floors summed
        ends = np.unique(np.concatenate((np.flatnonzero(f1[seg] >= 1.0), [seg.shape[0] - 1])))
        of = np.searchsorted(ends, np.arange(seg.shape[0]))
        whole = np.bincount(of, weights=length)
        cap_w = np.minimum(feed, whole / np.maximum(np.bincount(of, weights=floor_s), 1e-300))
        out["uncut"] += optimal_s(np.concatenate(([0.0], np.cumsum(whole))),
                                  np.concatenate((th[seg[:1]], th[seg[ends] + 1])), prof,
                                  cap_w, *grid)
        out["topp_cpu"] += time.process_time() - t1
    return {**out, "segments": float(job.duration_us.shape[0]), "bound": float(bound.total),
            "all_cpu": time.process_time() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sub", type=int, default=3, help="gridpoints inside each chord")
    ap.add_argument("--ds", type=float, default=0.05,
                    help="TOPP-RA's largest grid spacing along the path, mm")
    ap.add_argument("--drawing", nargs="*", default=list(DRAWINGS))
    ap.add_argument("--no-floors", action="store_true",
                    help="give neither side the link's and the firmware's floors")
    ap.add_argument("--fit", action="store_true",
                    help="fit the drawings into the reach (the real drawings: always)")
    args = ap.parse_args()
    prof = load_profile()
    m = prof.motion
    print(f"planner vs TOPP-RA (default profile: {m.max_joint_rad_s:g} rad/s, "
          f"{m.max_joint_rad_s2:g} rad/s², feeds {m.draw_feed_mm_s:g}/{m.travel_feed_mm_s:g} "
          f"mm/s, junction jump {m.junction_jump_rad_s:g} rad/s; grid: knots + {args.sub} a "
          f"chord, ≤ {args.ds:g} mm apart)")
    print(f"{'drawing':42} {'segments':>8} {'planned s':>10} {'continuous':>10} "
          f"{'opt (own)':>10} {'opt (uncut)':>11} {'plan/own':>9} {'plan/uncut':>10}  "
          f"goal ≤ 1.01")
    for name in args.drawing:
        r = measure(name, prof, (args.sub, args.ds), args.fit or name.startswith("benchmarks/"),
                    not args.no_floors)
        ratio = r["planned"] / r["uncut"]
        print(f"{name:42} {int(r['segments']):8d} {r['planned']:10.3f} {r['continuous']:10.3f} "
              f"{r['optimal']:10.3f} {r['uncut']:11.3f} {r['planned'] / r['optimal']:9.4f} "
              f"{ratio:10.4f}  {'ok' if ratio <= 1.01 else 'MISSED'}  "
              f"(TOPP-RA {r['topp_cpu']:.1f} s CPU)")


if __name__ == "__main__":
    main()
