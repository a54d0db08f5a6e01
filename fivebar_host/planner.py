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

The staircase. The firmware runs each segment at one constant step rate for its P µs (docs/
protocol.md 6.1), so the joints really move with the piecewise-constant velocity ω_k = Δθ_k/P_k
and every speed change happens at a segment boundary, as a jump. The limits are honoured on
that staircase, at every boundary — between consecutive segments, and from standstill into the
first and out of the last segment of every run between stops (start, pen/laser switches, end):

    jump:    max_j |ω_{k,j} − ω_{k−1,j}| ≤ junction jump J
    accel:   max_j |ω_{k,j} − ω_{k−1,j}| ≤ α · (P_{k−1} + P_k)/2   (rest: ω_k ≤ α · P_k/2)

— the second is the average acceleration between the segments' midpoints: a velocity that
changes at most at rate α has segment averages that differ by at most that much. The job
(`fivebar_host.compile`) gets there in four steps: (1) the continuous profile above with a share of
α and of J (and a corner cap for direction changes between short segments, and the firmware's
shortest P as a speed cap); (2) `ramp_fractions` cuts the speed-up and slow-down parts of every
segment into pieces short enough in time that the planned speed changes by a fraction of J
from one piece to the next — new targets on the same joint-space line, so the path does not
change; (3) the profile again on the pieces; (4) `enforce_staircase` measures the staircase of
the rounded steps and integer durations and slows (never speeds up) the few segments that
still break a limit (step rounding makes short pieces' rates uneven) until none does.
`staircase_ratios` reports the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinematics.arrays import BoolArray, FloatArray, IntArray

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
    dist = np.abs(dth).max(axis=1)  # D_k
    moving = dist > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(moving[:, None], dth / np.where(moving, dist, 1.0)[:, None], 0.0)
        feed_cap = np.where(length_mm > 0, feed_mm_s * dist / length_mm, np.inf)
    vmax = np.minimum(max_joint_rad_s, feed_cap)
    if min_duration_s > 0.0:
        vmax = np.minimum(vmax, dist / min_duration_s)
    vmax = np.where(moving, vmax, 0.0)

    # Junction caps (K+1 junctions; junction n sits before segment n).
    cap = np.zeros(k + 1)
    jump = np.abs(u[1:] - u[:-1]).max(axis=1)
    with np.errstate(divide="ignore"):
        jcap = np.where(jump > 0, junction_jump_rad_s / jump, np.inf)
        if corner_accel_rad_s2 is not None:
            ccap = np.sqrt(corner_accel_rad_s2 * 0.5 * (dist[:-1] + dist[1:]) / jump)
            jcap = np.minimum(jcap, np.where(jump > 0, ccap, np.inf))
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


# ----------------------------------------------------------------------------- the staircase
def ramp_fractions(pl: Plan, dist: FloatArray, alpha: float, piece_s: float,
                   min_piece_rad: float = 0.0) -> tuple[IntArray, FloatArray]:
    """Where to cut each segment so that its speed-up and slow-down parts (under the planned
    trapezoid with acceleration `alpha` along the Chebyshev distance `dist`) become pieces of
    at most `piece_s` each — the planned speed changes by at most alpha·piece_s within a
    piece. A cruise part stays whole, and so does a ramp that fits in one piece (it joins
    its neighbour). No piece is made shorter than `min_piece_rad` (a shorter one joins the
    piece before it). Returns the number of pieces per segment (K,) and every piece's end as
    a fraction of its segment's distance (ascending within a segment, the last exactly 1)."""
    v0, v1, vp = pl.v_entry, pl.v_exit, pl.v_peak
    d = np.asarray(dist, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        ta = np.where(vp > v0, (vp - v0) / alpha, 0.0)
        td = np.where(vp > v1, (vp - v1) / alpha, 0.0)
        da = np.clip((vp * vp - v0 * v0) / (2 * alpha), 0.0, d)
        dd = np.clip((vp * vp - v1 * v1) / (2 * alpha), 0.0, d - da)
    dc = np.maximum(d - da - dd, 0.0)
    na = np.where(ta > 0, np.ceil(ta / piece_s), 0).astype(np.int64)
    nd = np.where(td > 0, np.ceil(td / piece_s), 0).astype(np.int64)
    nc = (dc > 0).astype(np.int64)
    n = np.maximum(na + nc + nd, 1)
    seg = np.repeat(np.arange(d.shape[0]), n)
    i = np.arange(seg.shape[0]) - np.repeat(np.cumsum(n) - n, n) + 1  # 1-based piece number
    nas, nds, ncs = na[seg], nd[seg], nc[seg]
    in_a = i <= nas
    in_d = i > nas + ncs
    t_a = np.where(in_a, i / np.maximum(nas, 1), 0.0) * ta[seg]
    x_a = v0[seg] * t_a + 0.5 * alpha * t_a * t_a
    t_d = np.where(in_d, (i - nas - ncs) / np.maximum(nds, 1), 0.0) * td[seg]
    x_d = da[seg] + dc[seg] + vp[seg] * t_d - 0.5 * alpha * t_d * t_d
    x = np.where(in_a, x_a, np.where(in_d, x_d, da[seg] + dc[seg]))
    ds = d[seg]
    last = np.concatenate((seg[1:] != seg[:-1], [True])) if seg.size else np.zeros(0, bool)
    x[last] = ds[last]
    # Boundaries not needed: after a one-piece ramp up, before a one-piece ramp down.
    keep = last | ~(((i == nas) & (nas == 1)) | ((i == nas + ncs) & (nds == 1) & (ncs == 1)))
    if min_piece_rad > 0.0:
        prev = np.concatenate(([0.0], x[:-1]))
        prev[np.concatenate(([True], seg[1:] != seg[:-1]))] = 0.0
        keep &= last | ((x - prev >= min_piece_rad) & (ds - x >= min_piece_rad))
    seg, x, ds = seg[keep], x[keep], ds[keep]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.clip(np.where(ds > 0, x / ds, 1.0), 0.0, 1.0)
    f[np.concatenate((seg[1:] != seg[:-1], [True])) if seg.size else np.zeros(0, bool)] = 1.0
    return np.bincount(seg, minlength=d.shape[0]).astype(np.int64), f


def _rest_sides(k: int, stop_after: BoolArray | None) -> tuple[IntArray, IntArray]:
    """First and last segment of every run between stops (start, stops, end)."""
    st = np.zeros(k, dtype=bool) if stop_after is None else np.asarray(stop_after, bool).copy()
    st[-1] = True
    ends = np.flatnonzero(st)
    starts = np.concatenate(([0], ends[:-1] + 1))
    return starts.astype(np.int64), ends.astype(np.int64)


def staircase_ratios(dtheta_rad: FloatArray, duration_us: IntArray,
                     stop_after: BoolArray | None, max_joint_rad_s2: float,
                     junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S
                     ) -> tuple[FloatArray, FloatArray]:
    """The joint velocities the firmware really runs — ω_k = Δθ_k / P_k, constant over each
    segment — against the limits, at every boundary: between consecutive segments, and from
    rest into the first and out of the last segment of every run between stops. Returns
    (jump, accel) ratios, each ≤ 1 when honoured: jump = max_j |Δω_j| / junction jump;
    accel = max_j |Δω_j| / (α · time between the two segments' midpoints) — the staircase's
    average acceleration (rest counts as a point, so a run's first segment needs
    |ω| ≤ α·P/2: it cannot average more than accelerating at α from standstill would)."""
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    k = dth.shape[0]
    if k == 0:
        return np.zeros(0), np.zeros(0)
    t = np.asarray(duration_us, dtype=np.float64) * 1e-6
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(t[:, None] > 0, dth / t[:, None], 0.0)
    dw = np.abs(np.diff(w, axis=0)).max(axis=1)
    tb = 0.5 * (t[1:] + t[:-1])
    starts, ends = _rest_sides(k, stop_after)
    sides = np.concatenate((starts, ends))
    wn = np.abs(w[sides]).max(axis=1)
    jump = np.concatenate((dw, wn)) / junction_jump_rad_s
    with np.errstate(divide="ignore", invalid="ignore"):
        acc = np.concatenate((dw / tb, wn / (0.5 * t[sides]))) / max_joint_rad_s2
    return jump, np.nan_to_num(acc, nan=0.0)


def enforce_staircase(dtheta_rad: FloatArray, duration_us: IntArray,
                      stop_after: BoolArray | None, max_joint_rad_s2: float,
                      junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S,
                      max_rounds: int = 60) -> IntArray:
    """Lengthen segment durations (integer µs, never shorten) until `staircase_ratios` are all
    ≤ 1. At a boundary that breaks a limit, both segments are slowed by the same factor f:
    that scales |Δω| by f and the midpoint spacing by 1/f, so f = min(J/|Δω|,
    √(α·T̄/|Δω|)) honours it exactly (from rest: T̄ = P/2). A segment takes the smallest
    factor of its boundaries; rounds repeat while a neighbour's change breaks another
    boundary. Slowing only lowers speeds, so the feed and joint-speed limits stay honoured.
    After `max_rounds` (never seen on real jobs) one factor for the whole job finishes it."""
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    us = np.asarray(duration_us, dtype=np.int64).copy()
    k = dth.shape[0]
    if k == 0:
        return us
    a, j = float(max_joint_rad_s2), float(junction_jump_rad_s)
    starts, ends = _rest_sides(k, stop_after)
    sides = np.concatenate((starts, ends))
    for rnd in range(max_rounds + 20):
        t = us * 1e-6
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(t[:, None] > 0, dth / t[:, None], 0.0)
        dw = np.abs(np.diff(w, axis=0)).max(axis=1)
        tb = 0.5 * (t[1:] + t[:-1])
        wn = np.abs(w[sides]).max(axis=1)
        ts = 0.5 * t[sides]
        # Rounding up to whole µs slows the two sides by slightly different factors, which
        # can undo a small correction; two µs more on the shorter side absorb that.
        with np.errstate(divide="ignore", invalid="ignore"):
            fi = np.where(dw > np.minimum(j, a * tb),
                          np.minimum(j / dw, np.sqrt(a * tb / dw))
                          * (1.0 - 2.0 / np.minimum(us[1:], us[:-1])), 1.0)
            fs = np.where(wn > np.minimum(j, a * ts),
                          np.minimum(j / wn, np.sqrt(a * ts / wn)) * (1.0 - 2.0 / us[sides]),
                          1.0)
        if (fi >= 1.0).all() and (fs >= 1.0).all():
            return us
        f = np.ones(k)
        if rnd >= max_rounds:  # one factor for everything: exact, since all scale alike
            f[:] = min(float(fi.min(initial=1.0)), float(fs.min(initial=1.0)))
        else:
            np.minimum.at(f, np.arange(k - 1), fi)
            np.minimum.at(f, np.arange(1, k), fi)
            np.minimum.at(f, sides, fs)
        slow = f < 1.0
        us[slow] = np.ceil(us[slow] / f[slow]).astype(np.int64)
    raise RuntimeError("staircase limits could not be met")  # pragma: no cover
