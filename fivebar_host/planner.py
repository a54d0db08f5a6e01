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
and its duration is that trapezoid's time, rounded *up* to whole microseconds for the wire
(the firmware runs each segment at its constant average rate; with segments of at most
`max_step_rad` the staircase of rates follows the ramps closely).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

#: Default largest instantaneous joint-speed change at a junction, rad/s.
JUNCTION_JUMP_RAD_S = 0.5


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
         junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S) -> Plan:
    """Plan the chain of segments (see module doc).

    dtheta_rad (K, 2), length_mm (K,) pen path length, feed_mm_s (K,) allowed pen speed,
    stop_after (K,) True where the machine must stand still after segment k (the last one
    always stops). Zero-motion segments get a duration of 0.
    """
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    k = dth.shape[0]
    if k == 0:
        z = np.zeros(0)
        return Plan(z, z, z, z, np.zeros(0, dtype=np.int64))
    alpha = float(max_joint_rad_s2)
    dist = np.abs(dth).max(axis=1)  # D_k
    moving = dist > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(moving[:, None], dth / np.where(moving, dist, 1.0)[:, None], 0.0)
        feed_cap = np.where(length_mm > 0, feed_mm_s * dist / length_mm, np.inf)
    vmax = np.minimum(max_joint_rad_s, feed_cap)
    vmax = np.where(moving, vmax, 0.0)

    # Junction caps (K+1 junctions; junction n sits before segment n).
    cap = np.zeros(k + 1)
    jump = np.abs(u[1:] - u[:-1]).max(axis=1)
    with np.errstate(divide="ignore"):
        jcap = np.where(jump > 0, junction_jump_rad_s / jump, np.inf)
    cap[1:k] = np.minimum(np.minimum(vmax[:-1], vmax[1:]), jcap)
    if stop_after is not None:
        st = np.asarray(stop_after, dtype=bool)
        cap[1:k][st[:-1]] = 0.0
    cap[1:k][~(moving[:-1] & moving[1:])] = 0.0
    w_cap = cap * cap

    d2 = 2.0 * alpha * dist
    s = np.concatenate(([0.0], np.cumsum(d2)))  # S_n
    fwd = s + np.minimum.accumulate(w_cap - s)
    # backward: R_n = Σ_{k ≥ n} d2_k = S_K − S_n
    r = s[-1] - s
    bwd = r + np.minimum.accumulate((w_cap - r)[::-1])[::-1]
    w = np.clip(np.minimum(fwd, bwd), 0.0, None)
    w = np.minimum(w, w_cap)
    v = np.sqrt(w)
    v0, v1 = v[:-1], v[1:]
    vp = np.minimum(vmax, np.sqrt(0.5 * (v0 * v0 + v1 * v1) + alpha * dist))
    vp = np.maximum(vp, np.maximum(v0, v1))
    with np.errstate(divide="ignore", invalid="ignore"):
        t_acc = (vp - v0) / alpha
        t_dec = (vp - v1) / alpha
        d_ramp = (vp * vp - v0 * v0) / (2 * alpha) + (vp * vp - v1 * v1) / (2 * alpha)
        t_cruise = np.where(vp > 0, np.maximum(dist - d_ramp, 0.0) / vp, 0.0)
    t = np.where(moving, t_acc + t_dec + t_cruise, 0.0)
    us = np.ceil(np.round(t * 1e6, 6)).astype(np.int64)
    us[moving & (us < 1)] = 1
    return Plan(v0, v1, vp, t, us)


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
