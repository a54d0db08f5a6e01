"""Timing: per-segment durations from the pen feed, joint speed and joint acceleration limits.

The job is a chain of segments, each a straight line in joint space (the firmware interpolates
linearly in steps): segment k moves the joints by Δθ_k (rad) and the pen by L_k (mm). We plan
a speed profile v along the chain in the *Chebyshev joint distance* D_k = max_j |Δθ_kj|:
within segment k the joint velocity is u_k·v with u_k = Δθ_k / D_k, max_j |u_kj| = 1, so

    joint speed ≤ ω_max       ⇔  v ≤ ω_max
    joint accel ≤ α_max       ⇔  |dv/dt| ≤ α_max   (u_k is constant within a segment)
    pen speed   ≤ feed_k      ⇔  v ≤ feed_k · D_k / L_k

At the junction between k and k+1 the joint velocity jumps by (u_{k+1} − u_k)·v; that jump is
limited to `junction_jump_rad_s` per joint (the role of Marlin's jerk or GRBL's junction
deviation), which caps v at the junction. The machine stops (v = 0) at the start, at the end
and wherever the pen/laser switches (the pen must be still while it lifts or drops).

Junction-speed planning with forward and backward passes (as GRBL's planner), in closed form:
with w = v² the forward pass is w_{n+1} = min(cap_{n+1}, w_n + 2α·D_n); writing
S_n = Σ_{k<n} 2α·D_k, w_n − S_n = min(cap_n − S_n, w_{n−1} − S_{n−1}), i.e. a running minimum —
`np.minimum.accumulate`, no Python loop. The backward pass is the same on the reversed chain;
the junction speed is the smaller of the two. Each segment then runs the time-optimal
trapezoid between its entry and exit speeds (peak v_p = min(v_max, sqrt((v0² + v1²)/2 + α·D)))
and its duration is that trapezoid's time, rounded *up* to whole microseconds for the wire.

The staircase. The firmware runs each segment at one constant step rate for its P µs, so the
joints move with a piecewise-constant velocity and every speed change is a jump at a segment
boundary; `compile.staircase` says what the limits mean on that staircase and finds the least
durations that keep them. The job (`fivebar_host.compile`) gets there in four steps: (1) the
continuous profile above (with a share of α, a corner cap for direction changes between short
segments, and the firmware's shortest P as a speed cap) — it only decides where to cut; (2)
`ramps.ramp_fractions` cuts the speed-up and slow-down parts of every segment into pieces
short enough in time that the planned speed changes by a fraction of J from one piece to the
next — new targets on the segment's stepped line (the line between its ends' steps, which
the firmware runs for the whole segment), so the path does not change; at a sharp
junction (a direction change the joints could not jump at the segment's own speed,
`sharp_junctions`) the piece next to it is cut off short, so that only it runs near the
junction's speed; (3) every piece's own shortest duration (`cap_durations_us`); (4)
`staircase.enforce_staircase` raises those to the least integer durations that meet every
staircase limit on the rounded steps.

Why the plan used to grow with the limits (issue 20: 5 × 1000 chords of 0.1 mm planned 7.8 s
at 100 mm/s, 15 rad/s, 600 rad/s² and 11.1 s at 200 / 30 / 1200; 6.2 s and 29.6 s with the
chords simplified). Two causes. (a) The old repair slowed *both* segments of a broken
boundary by one factor; that breaks the boundaries next to them (a slowed segment next to a
fast one is a new jump), the next round slows those, and factors multiplied along the chain —
up to 20× on single segments, and after 60 rounds one factor for the whole job. Higher
limits gave a taller sawtooth to repair (more pieces of a few steps, whose step rounding
makes their rates uneven) and so a longer plan. The least durations (`compile.staircase`)
replace it.
(b) The cut, which the continuous profile decides. It planned with half of J and a corner
cap, so on a polygon it saw a sawtooth (junctions capped at J/2δ, a speed-up in between)
that the staircase does not need, and cut every chord into pieces of a few steps (1135 for
the circle job's 480 segments at 200 mm/s); and at a high α a ramp became too short to cut
(`ramp_fractions` joins pieces under 3 steps), so the segment next to a stop or a sharp
corner kept a long first piece that the staircase must start at about J — a zigzag planned
×1.65 longer at 3.4× the acceleration. `compile.timing` now plans the cut with all of J, no
corner cap, and α at most J²/(4·D_min) (`compile.timing.cut_accel`), so above that the cut no
longer depends on α; a raised feed or joint speed can still move a cut (whole jobs are
tested to 0.5 %, tests/test_plan_monotone.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host.compile.staircase import CEIL_SLACK_US as _CEIL_SLACK_US
from fivebar_host.compile.staircase import JUNCTION_JUMP_RAD_S
from kinematics.arrays import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class Plan:
    """Per segment: entry/exit/peak speed (rad/s, Chebyshev), duration (s and integer µs)."""

    v_entry: FloatArray
    v_exit: FloatArray
    v_peak: FloatArray
    duration_s: FloatArray
    duration_us: IntArray

    @property
    def total_s(self) -> float:
        """Total time, s, from the integer durations the firmware will run."""
        return float(self.duration_us.sum()) * 1e-6


def plan(dtheta_rad: FloatArray, length_mm: FloatArray, feed_mm_s: FloatArray,
         max_joint_rad_s: float, max_joint_rad_s2: float,
         stop_after: BoolArray | None = None,
         junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S, min_duration_s: float = 0.0,
         corner_accel_rad_s2: float | None = None) -> Plan:
    """Plan the chain of segments (see module doc).

    dtheta_rad (K, 2), length_mm (K,) pen path length, feed_mm_s (K,) allowed pen speed,
    stop_after (K,) True where the machine must stand still after segment k (the last one
    always stops). Zero-motion segments get a duration of 0. `min_duration_s` caps each
    segment's speed so that it lasts at least that long (the firmware's shortest `P`).
    `corner_accel_rad_s2` adds a junction cap for direction changes between short segments:
    a joint-velocity change δ·v between two segments whose midpoints are about
    (D_a + D_b)/(2v) apart in time is an acceleration, so v ≤ √(a·(D_a + D_b)/(2δ)) (the
    joint-space analogue of a centripetal limit; δ = max_j |u_{k+1,j} − u_{k,j}|).
    """
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    k = dth.shape[0]
    if k == 0:
        z = np.zeros(0)
        return Plan(z, z, z, z, np.zeros(0, dtype=np.int64))
    alpha = float(max_joint_rad_s2)
    dist = np.maximum(np.abs(dth[:, 0]), np.abs(dth[:, 1]))  # D_k
    moving = dist > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        feed_cap = np.where(length_mm > 0, feed_mm_s * dist / length_mm, np.inf)
    vmax = np.minimum(max_joint_rad_s, feed_cap)
    del feed_cap
    if min_duration_s > 0.0:
        vmax = np.minimum(vmax, dist / min_duration_s)
    vmax = np.where(moving, vmax, 0.0)
    w_cap = _junction_caps(dth, dist, vmax, moving, stop_after, junction_jump_rad_s,
                           corner_accel_rad_s2)
    w = _passes(w_cap, dist, alpha)
    np.minimum(w, w_cap, out=w)
    del w_cap
    v = np.sqrt(w, out=w)
    vp, t, us = _trapezoids(v, vmax, dist, moving, alpha)
    return Plan(v[:-1], v[1:], vp, t, us)


#: Segments timed at a time by `_trapezoids`.
TRAPEZOID_BLOCK = 1 << 16


def _trapezoids(v: FloatArray, vmax: FloatArray, dist: FloatArray, moving: BoolArray,
                alpha: float) -> tuple[FloatArray, FloatArray, IntArray]:
    """Every segment's time-optimal trapezoid between its junction speeds v[k], v[k+1]
    (module doc): peak speed, duration (s) and whole µs (rounded up, ≥ 1 when it moves),
    in blocks of `TRAPEZOID_BLOCK` (each segment on its own: the values of one pass)."""
    k = dist.shape[0]
    vp_all, t_all = np.empty(k), np.empty(k)
    us_all = np.empty(k, dtype=np.int64)
    for b in range(0, k, TRAPEZOID_BLOCK):
        e = min(b + TRAPEZOID_BLOCK, k)
        sl = slice(b, e)
        v0, v1 = v[b:e], v[b + 1:e + 1]
        d = dist[sl]
        vp = np.minimum(vmax[sl], np.sqrt(0.5 * (v0 * v0 + v1 * v1) + alpha * d))
        vp = np.maximum(vp, np.maximum(v0, v1))
        with np.errstate(divide="ignore", invalid="ignore"):
            t_acc = (vp - v0) / alpha
            t_dec = (vp - v1) / alpha
            d_ramp = (vp * vp - v0 * v0) / (2 * alpha) + (vp * vp - v1 * v1) / (2 * alpha)
            t_cruise = np.where(vp > 0, np.maximum(d - d_ramp, 0.0) / vp, 0.0)
        t = np.where(moving[sl], t_acc + t_dec + t_cruise, 0.0)
        us = np.ceil(np.round(t * 1e6, 6)).astype(np.int64)
        us[moving[sl] & (us < 1)] = 1
        vp_all[sl], t_all[sl], us_all[sl] = vp, t, us
    return vp_all, t_all, us_all


def _junction_caps(dth: FloatArray, dist: FloatArray, vmax: FloatArray, moving: BoolArray,
                   stop_after: BoolArray | None, junction_jump_rad_s: float,
                   corner_accel_rad_s2: float | None) -> FloatArray:
    """`plan`'s squared speed caps w_cap (K+1,) at the junctions (junction n sits before
    segment n; 0 at the ends, at stops and next to a zero-motion segment), in blocks of
    `JUNCTION_BLOCK` junctions (each on its own: the values of one pass)."""
    k = dist.shape[0]
    cap = np.zeros(k + 1)
    for b in range(0, k - 1, JUNCTION_BLOCK):
        e = min(b + JUNCTION_BLOCK, k - 1) + 1  # segments b … e−1, junctions b+1 … e−1
        mv, d = moving[b:e], dist[b:e]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(mv[:, None], dth[b:e] / np.where(mv, d, 1.0)[:, None], 0.0)
        jump = np.abs(u[1:] - u[:-1]).max(axis=1)  # δ = max_j |u_{n+1,j} − u_{n,j}|
        with np.errstate(divide="ignore"):
            jcap = np.where(jump > 0, junction_jump_rad_s / jump, np.inf)
            if corner_accel_rad_s2 is not None:
                ccap = np.sqrt(corner_accel_rad_s2 * 0.5 * (d[:-1] + d[1:]) / jump)
                jcap = np.minimum(jcap, np.where(jump > 0, ccap, np.inf))
        cap[b + 1:e] = np.minimum(np.minimum(vmax[b:e - 1], vmax[b + 1:e]), jcap)
    if stop_after is not None:
        st = np.asarray(stop_after, dtype=bool)
        cap[1:k][st[:-1]] = 0.0
    cap[1:k][~(moving[:-1] & moving[1:])] = 0.0
    cap *= cap
    return cap


#: Junctions capped at a time by `_junction_caps`.
JUNCTION_BLOCK = 1 << 16


def _passes(w_cap: FloatArray, dist: FloatArray, alpha: float) -> FloatArray:
    """`plan`'s forward and backward passes (module doc) on the squared junction caps
    `w_cap` (K+1,) with d2_k = 2α·D_k: the squared junction speeds, clipped at 0."""
    s = np.empty(dist.shape[0] + 1)  # S_n
    s[0] = 0.0
    np.cumsum(2.0 * alpha * dist, out=s[1:])
    fwd = w_cap - s
    np.minimum.accumulate(fwd, out=fwd)
    fwd += s
    # backward: R_n = Σ_{k ≥ n} d2_k = S_K − S_n (written over S)
    r = np.subtract(s[-1], s, out=s)
    bwd = (w_cap - r)[::-1]
    np.minimum.accumulate(bwd, out=bwd)
    bwd = bwd[::-1]
    bwd += r
    del r
    np.minimum(fwd, bwd, out=fwd)
    del bwd
    return np.clip(fwd, 0.0, None, out=fwd)


def check_plan(pl: Plan, dtheta_rad: FloatArray, length_mm: FloatArray,
               feed_mm_s: FloatArray, max_joint_rad_s: float) -> tuple[float, float]:
    """Largest ratio of (average joint speed / limit) and (average pen speed / feed) over the
    segments, from the integer durations — both must be ≤ 1 (a self-check for reports)."""
    t = pl.duration_us * 1e-6
    moving = t > 0
    if not moving.any():
        return 0.0, 0.0
    js = np.abs(dtheta_rad[moving]).max(axis=1) / t[moving] / max_joint_rad_s
    ps = length_mm[moving] / t[moving] / feed_mm_s[moving]
    return float(js.max()), float(ps.max()) if ps.size else 0.0


def cap_durations_us(dtheta_rad: FloatArray, length_mm: FloatArray, feed_mm_s: FloatArray,
                     max_joint_rad_s: float, min_duration_us: int = 1) -> IntArray:
    """Shortest integer durations (µs) each segment allows on its own — bound (1) of the
    module doc: the firmware's shortest P, the joint speed limit on the Chebyshev distance,
    the pen feed on the path length. 0 for a segment without motion. Nonincreasing in
    `feed_mm_s` and `max_joint_rad_s`; `enforce_staircase` raises them to a staircase."""
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    dist = np.abs(dth).max(axis=1)
    length = np.asarray(length_mm, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.maximum.reduce([np.full(dist.shape[0], float(min_duration_us)),
                                dist / (max_joint_rad_s * 1e-6),
                                np.where(length > 0, length / (feed_mm_s * 1e-6), 0.0)])
    return np.where(dist > 0, np.ceil(lo - _CEIL_SLACK_US), 0.0).astype(np.int64)


# ----------------------------------------------------------------------------- the staircase
