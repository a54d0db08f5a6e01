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
(`fivebar_host.compile`) gets there in four steps: (1) the continuous profile above (with a
share of α, a corner cap for direction changes between short segments, and the firmware's
shortest P as a speed cap) — it only decides where to cut; (2) `ramps.ramp_fractions` cuts the
speed-up and slow-down parts of every segment into pieces short enough in time that the
planned speed changes by a fraction of J from one piece to the next — new targets on the
same joint-space line, so the path does not change; at a sharp junction (a direction change
the joints could not jump at the segment's own speed, `sharp_junctions`) the piece next to
it is cut off even from a one-piece ramp, so that only it runs at the junction's speed;
(3) every piece's own shortest duration (`cap_durations_us`: bound (1) below); (4)
`enforce_staircase` raises those to the least integer durations that meet every staircase
limit on the rounded steps. `staircase_ratios` measures the result.

The repair (issue 20). With D = max_j |Δθ_j| (whole steps, rad) and L the pen path (mm):

    caps     P_k ≥ P_min,  P_k ≥ D_k / ω_max,  P_k ≥ L_k / F_k                     (1)
    rest     P_k ≥ D_k / J,  P_k ≥ √(2·D_k/α)  (first and last segment of every run)   (2)

and at the boundary between p = P_{k−1} and q = P_k, per joint j with b = |Δθ_{k−1,j}|,
a = |Δθ_kj|: where the joint keeps its direction (or stands in one of the two segments),
speeding up needs

    a/q − b/p ≤ J                      ⇔  q ≥ a / (J + b/p)                            (3)
    a/q − αq/2 ≤ c(p̂),  c(p) = b/p + αp/2,  p̂ = min(p, √(2b/α))
                                       ⇔  q ≥ 2a / (c + √(c² + 2αa))                    (4)

and slowing down the same with (a, q) and (b, p) swapped. (4) is the accel limit with p̂
for p — c is smallest at p̂ = √(2b/α), so (4) is a little stricter than the limit, only where
the segment before is slower than a start from rest through it would be — and in exchange
every bound is a *nondecreasing* function of the neighbour's duration. Where the joint
reverses, a/q + b/p ≤ J and ≤ α(p + q)/2 are met by the separate bounds

    q ≥ √a(√a + √b)/J,  p ≥ √b(√a + √b)/J   and   q ≥ √(2a/α),  p ≥ √(2b/α)            (5)

— J shared between the two sides as √a : √b, the split with the least p + q when both are
held by it.  (It was (a + b)/J on both sides, J shared as a : b: a 3-step segment after a
joint's 37-step run in the other direction lasted 39 ms for 13; issue 39: against TOPP-RA,
benchmarks/plotter.svg 1.108 → 1.081, voronoi.svg 1.068 → 1.040, benchmarks/topp.py.)

So every limit is a lower bound on one duration, a constant or a nondecreasing function of a
neighbour's: the integer durations meeting them all are closed under the element-wise
minimum and have a least element, the shortest plan of every segment at once, which
`enforce_staircase` reaches by Kleene's iteration from (1). Raising ω_max, a feed, α or J
lowers every bound (for (4), c(p̂) grows with α), so on given pieces no segment's duration
ever grows when a limit is raised — exactly, to the µs.

Why the plan used to grow with the limits (issue 20: 5 × 1000 chords of 0.1 mm planned 7.8 s
at 100 mm/s, 15 rad/s, 600 rad/s² and 11.1 s at 200 / 30 / 1200; 6.2 s and 29.6 s with the
chords simplified). Two causes. (a) The old repair slowed *both* segments of a broken
boundary by one factor; that breaks the boundaries next to them (a slowed segment next to a
fast one is a new jump), the next round slows those, and factors multiplied along the chain —
up to 20× on single segments, and after 60 rounds one factor for the whole job. Higher
limits gave a taller sawtooth to repair (more pieces of a few steps, whose step rounding
makes their rates uneven) and so a longer plan. The least durations above replace it.
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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Default largest instantaneous joint-speed change at a junction, rad/s.
JUNCTION_JUMP_RAD_S = 0.5
#: Durations are raised to ⌈bound − this⌉ µs, so that a bound computed a few ulp above an
#: integer does not add a µs (keeps the least durations exactly monotone in the limits).
_CEIL_SLACK_US = 1e-9


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


def _bound_after(a: FloatArray, b: FloatArray, p: FloatArray, jump: float,
                 acc: float) -> FloatArray:
    """Shortest duration q (µs) of the segment on one side of a boundary whose other side
    lasts p (µs): the largest over the joints (columns) of bounds (3) and (4) of the module
    doc ("The repair"), with a = |Δθ| on q's side and b on p's side (a joint that reverses
    there has a = b = 0 here: bound (5) covers it). Nondecreasing in p, nonincreasing in
    `jump` and `acc` (per µs and per µs²)."""
    pc = p[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = b / pc
        q_jump = a / (jump + c)  # (3)
        c += 0.5 * acc * pc  # c(p̂) = b/p̂ + αp̂/2 with p̂ = p, where p < p* = √(2b/α)...
        np.copyto(c, np.sqrt(2.0 * acc * b), where=pc >= np.sqrt(2.0 * b / acc))  # ...else c(p*)
        q_acc = 2.0 * a / (c + np.sqrt(c * c + 2.0 * acc * a))  # (4)
    q = np.nan_to_num(np.maximum(q_jump, q_acc, out=q_jump), nan=0.0, copy=False)
    # the joints' largest (numpy's max(axis=1) over 2 columns is slow)
    out: FloatArray = np.maximum(q[:, 0], q[:, 1])
    return out


def _static_bounds(dth: FloatArray, lo: FloatArray, rest: BoolArray, act: IntArray,
                   jump: float, acc: float) -> NDArray[np.bool_]:
    """Raise `lo` (µs, in place) to the rest bounds (2) on the segments next to a stop and to
    the reversal bounds (5). Returns per boundary in `act` (between segments act and act + 1)
    and joint whether the joint reverses there (`_moves_at` zeroes its |Δθ|). The reversal
    bounds are worked out on the reversing boundaries only (memory on large jobs)."""
    dist = _chebyshev(dth[rest])
    lo[rest] = np.maximum(np.maximum(lo[rest], dist / jump), np.sqrt(2 * dist / acc))
    del dist
    rev = np.empty((act.shape[0], 2), dtype=bool)
    for i in range(0, act.shape[0], STAIRCASE_BLOCK):  # (no whole-job temporaries)
        c = act[i:i + STAIRCASE_BLOCK]
        rev[i:i + STAIRCASE_BLOCK] = _reverses(dth, c)
    r = np.flatnonzero(rev[:, 0] | rev[:, 1])
    if r.size:
        rv, (ar, br) = rev[r], _moves_at(dth, act[r])
        ra, rb = np.sqrt(ar), np.sqrt(br)
        split = np.where(rv, ra + rb, 0.0) / jump  # (5): J shared as √a : √b
        np.maximum.at(lo, act[r] + 1,
                      np.maximum((ra * split).max(axis=1),
                                 np.sqrt(2 * np.where(rv, ar, 0.0).max(axis=1) / acc)))
        np.maximum.at(lo, act[r],
                      np.maximum((rb * split).max(axis=1),
                                 np.sqrt(2 * np.where(rv, br, 0.0).max(axis=1) / acc)))
    return rev


def _chebyshev(dth: FloatArray) -> FloatArray:
    """The Chebyshev joint distance D = max_j |Δθ_j| of each move (N, 2), column by column
    (numpy's max over a 2-column axis is some 30× slower than one maximum of the columns)."""
    return np.maximum(np.abs(dth[:, 0]), np.abs(dth[:, 1]))


def _reverses(dth: FloatArray, left: IntArray) -> NDArray[np.bool_]:
    """Per boundary after the segments `left`, and joint: whether the joint reverses there
    (Δθ of opposite signs on its two sides)."""
    return np.less(dth[left + 1] * dth[left], 0)


def _moves_at(dth: FloatArray, left: IntArray,
              rev: NDArray[np.bool_] | None = None) -> tuple[FloatArray, FloatArray]:
    """The joints' |Δθ| after (a) and before (b) the boundaries whose left segments are
    `left`, zeroed where `rev` (the joint reverses there: bound (5) covers it)."""
    a, b = np.abs(dth[left + 1]), np.abs(dth[left])
    if rev is not None:
        a[rev] = 0.0
        b[rev] = 0.0
    return a, b


def enforce_staircase(dtheta_rad: FloatArray, duration_us: IntArray,
                      stop_after: BoolArray | None, max_joint_rad_s2: float,
                      junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S) -> IntArray:
    """The least integer durations (µs) at least `duration_us` that meet bounds (2)–(5) of
    the module doc ("The repair") — so `staircase_ratios` are all ≤ 1 — found by raising
    durations from below until no bound moves one (Kleene's iteration: every bound is a
    nondecreasing function of a neighbour's duration, so the least fixed point exists and is
    what the iteration reaches; each round revisits only the boundaries next to a segment
    that changed). Never shortens a segment, so the feed and joint-speed limits stay
    honoured; nonincreasing in `duration_us`, `max_joint_rad_s2` and `junction_jump_rad_s`
    (raising a limit never lengthens a segment). Segments without motion keep their
    duration and count as stops on both sides."""
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    p = np.asarray(duration_us, dtype=np.float64).copy()
    del duration_us  # (the caller may hold none: then it is freed here)
    k = dth.shape[0]
    if k == 0:
        return p.astype(np.int64)
    acc, jump = float(max_joint_rad_s2) * 1e-12, float(junction_jump_rad_s) * 1e-6  # per µs
    moving = _chebyshev(dth) > 0
    st = np.zeros(k, bool) if stop_after is None else np.asarray(stop_after, bool).copy()
    st[-1] = True
    st |= ~moving
    st[:-1] |= ~moving[1:]
    rest = (st | np.concatenate(([True], st[:-1]))) & moving
    # boundary n sits between segments act[n] and act[n] + 1 — across a stop too, as
    # `staircase_ratios` measures the step from ω_{k−1} straight to ω_k there as well
    act = np.flatnonzero(moving[:-1] & moving[1:])
    if k < 1 << 31:  # int32 indices where they fit (memory on large jobs)
        act = act.astype(np.int32)
    lo = p.copy()
    rev = _static_bounds(dth, lo, rest, act, jump, acc)
    p = np.where(moving, np.maximum(p, np.ceil(lo - _CEIL_SLACK_US)), p)
    del lo, moving, st, rest
    _raise_to_least(p, act, dth, rev, jump, acc)
    return p.astype(np.int64)


def _raise_to_least(p: FloatArray, act: IntArray, dth: FloatArray, rev: NDArray[np.bool_],
                    jump: float, acc: float) -> None:
    """Kleene's iteration (`enforce_staircase`): raise durations `p` (µs, in place) by the
    bounds (3), (4) across the boundaries `act` until none changes: a first round over
    every boundary, then `_raise_near` the segments it changed. A round measures its
    boundaries in blocks (`_round_raises`) from the durations at its start and then applies
    the raises."""
    if act.size:
        _raise_near(p, _apply_raises(p, _round_raises(p, act, dth, rev, jump, acc)),
                    dth, jump, acc)


def _raise_near(p: FloatArray, changed: IntArray, dth: FloatArray, jump: float,
                acc: float) -> None:
    """Kleene's rounds (`_raise_to_least`) on durations `p` (µs, in place) whose boundaries
    all meet bounds (3), (4) except perhaps those next to the segments `changed`: each round
    revisits only the boundaries (between two moving segments) next to a segment that
    changed, until none does. The boundaries are named by their left segment, their
    reversals measured on the spot (no whole-job index arrays)."""
    last = p.shape[0] - 1
    while changed.size:
        left = np.unique(np.concatenate((changed, changed - 1)))
        left = left[(left >= 0) & (left < last)]
        left = left[(_chebyshev(dth[left]) > 0) & (_chebyshev(dth[left + 1]) > 0)]
        if not left.size:
            return
        changed = _apply_raises(p, _round_raises(p, left, dth, _reverses(dth, left), jump,
                                                 acc))


def _apply_raises(p: FloatArray, raises: tuple[_Raises, _Raises]) -> IntArray:
    """Apply one round's raises (`_round_raises`) to `p` (in place); returns the segments
    raised (with repeats)."""
    (right, q_new), (left, p_new) = raises
    p[right] = q_new  # each boundary has its own right segment...
    p[left] = np.maximum(p[left], p_new)  # ...and its own left one
    return np.concatenate((right, left))


def raise_staircase(dtheta_rad: FloatArray, duration_us: IntArray, raised: IntArray,
                    max_joint_rad_s2: float,
                    junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S) -> None:
    """`enforce_staircase` again, in place, on durations it returned (for these moves, stops
    and limits) that were then raised at the segments `raised` only: the same least
    durations, found by revisiting only the boundaries near the raises. Why the same: the
    rest and reversal bounds (2), (5) depend on the moves alone and were met already; every
    boundary away from the raises still meets (3), (4); and Kleene's iteration from any
    durations at least the input and at most the least fixed point reaches that fixed point
    whatever the order of the boundaries it revisits (each raise stays below it, since every
    bound is nondecreasing). `compile.timing`'s later link-floor passes raise a few hundred
    of a job's segments; a whole `enforce_staircase` would measure every boundary again."""
    if not raised.size:
        return
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    acc, jump = float(max_joint_rad_s2) * 1e-12, float(junction_jump_rad_s) * 1e-6  # per µs
    p = duration_us.astype(np.float64)
    _raise_near(p, np.asarray(raised, dtype=np.int64), dth, jump, acc)
    duration_us[...] = p


#: Boundaries measured at a time by `_round_raises` (bounded temporaries on large jobs;
#: every boundary is measured on its own, so the bounds are those of one pass).
STAIRCASE_BLOCK = 1 << 16

_Raises = tuple[IntArray, FloatArray]


def _round_raises(p: FloatArray, act: IntArray, dth: FloatArray, rev: NDArray[np.bool_],
                  jump: float, acc: float) -> tuple[_Raises, _Raises]:
    """One round of `_raise_to_least` over the boundaries after the segments `act`, whose
    joints reverse where `rev`, from the durations `p` (not changed here): the right
    segments whose least duration (µs, whole) is above theirs, with that duration, and the
    same for the left segments; in blocks of `STAIRCASE_BLOCK` (the joints' moves taken per
    block, `_moves_at`), keeping only the raises."""
    parts: list[list[NDArray[Any]]] = [[], [], [], []]
    for i in range(0, act.shape[0], STAIRCASE_BLOCK):
        t = slice(i, i + STAIRCASE_BLOCK)
        lf = act[t]
        a, b = _moves_at(dth, lf, rev[t])
        q_new = np.ceil(_bound_after(a, b, p[lf], jump, acc) - _CEIL_SLACK_US)
        p_new = np.ceil(_bound_after(b, a, p[lf + 1], jump, acc) - _CEIL_SLACK_US)
        up_q, up_p = q_new > p[lf + 1], p_new > p[lf]
        for part, x in zip(parts, (lf[up_q] + 1, q_new[up_q], lf[up_p], p_new[up_p]), strict=True):
            part.append(x)
    right, q, left, pl = (np.concatenate(x) if len(x) != 1 else x[0] for x in parts)
    return (right, q), (left, pl)
