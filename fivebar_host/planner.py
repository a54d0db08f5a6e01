"""Timing: per-segment durations from the pen feed, joint speed and joint acceleration limits,
planned directly on the staircase the firmware runs — the shortest durations that honour every
limit exactly, and that never grow when a limit is raised.

The staircase. The firmware runs each segment at one constant step rate for its P µs (docs/
protocol.md 6.1), so the joints move with the piecewise-constant velocity ω_k = Δθ_k / P_k
(Δθ_k: the segment's whole steps, in rad) and every speed change is a jump at a segment
boundary. The limits, with D_k = max_j |Δθ_kj| and L_k the pen path (mm):

    caps     P_k ≥ P_min,  P_k ≥ D_k / ω_max,  P_k ≥ L_k / F_k                     (1)
    jump     max_j |ω_kj − ω_{k−1,j}| ≤ J                      (junction jump, J = 0.5 rad/s)
    accel    max_j |ω_kj − ω_{k−1,j}| ≤ α · (P_{k−1} + P_k)/2  (average acceleration between
                                                                the two segments' midpoints)
    rest     D_k / P_k ≤ J  and  D_k / P_k ≤ α · P_k / 2  ⇔  P_k ≥ D_k/J, P_k ≥ √(2D_k/α)  (2)

where "rest" applies to the first and the last segment of every run between stops (start,
pen/laser switches, end): the machine stands still there, which counts as a point. Jump and
accel hold between every two consecutive segments, across a stop too.
`staircase_ratios` measures these on any durations.

The shortest durations, monotone in the limits. Write p = P_{k−1}, q = P_k and, per joint j,
b = |Δθ_{k−1,j}|, a = |Δθ_kj|. Where the joint keeps its direction (or stands in one of the
two segments), jump and accel for speeding up read

    a/q − b/p ≤ J                      ⇔  q ≥ a / (J + b/p)                            (3)
    a/q − αq/2 ≤ c(p̂),  c(p) = b/p + αp/2,  p̂ = min(p, √(2b/α))
                                       ⇔  q ≥ 2a / (c + √(c² + 2αa))                    (4)

and for slowing down the same with (a, q) and (b, p) swapped. (4) is the accel limit with
p̂ for p: c is smallest at p* = √(2b/α), so c(p̂) ≤ c(p) and (4) is a little stricter than
the limit (only when the segment before is slower than a start from rest through it would
be); in exchange every bound is a *nondecreasing* function of the neighbour's duration.
Where the joint reverses, a/q + b/p ≤ J and ≤ α(p + q)/2 are met by the separate bounds

    q, p ≥ (a + b)/J   and   q ≥ √(2a/α),  p ≥ √(2b/α)                                  (5)

(exact for the jump when p = q; the accel as if both sides met at rest). So every
constraint is a lower bound on one duration — a constant, or a nondecreasing function of a
neighbour's duration. The set of integer duration vectors meeting them all is closed under
the element-wise minimum, so it has a least element P*, the shortest plan of every segment
at once. `staircase_durations` finds it by raising durations from the caps (1), (2), (5):
P_k ← max(P_k, ⌈bound(P_neighbour)⌉) on every boundary whose neighbour changed, until none
changes (Kleene's iteration of a monotone map from below converges to its least fixed
point; each round is one vectorised pass over the boundaries still changing). Raising any of
ω_max, F, α, J lowers every bound of (1)–(5) — for (4), c(p̂) grows with α — so every
segment's P*, and the plan's total, never grows: exactly, to the µs.

The cut. A long segment run at one rate cannot speed up (its own jump and rest limits (2)
bind it), so `cut_fractions` splits segments into pieces on their joint-space lines (new
targets, rounded to whole steps once; the path does not change): from each end pieces of
s_i = max(s_first, ⌈g·i⌉) steps, i = 1, 2, … (a J-sized speed change per piece is then a
constant time per piece, g·q/J with q one step, on a ramp), as many as fit while a middle
piece of at least s_first steps remains, at most `n_max` per end. The cut depends only on
the geometry — never on the limits — so the plan of a given job compares like with like
when a limit is raised. Pieces much shorter than this would lose to step rounding: one
step more or less on a joint from one piece to the next is a jump of q/P, which is J at
P = q/J ≈ 1 ms.
"""

from __future__ import annotations

import numpy as np

from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Default largest instantaneous joint-speed change at a junction, rad/s.
JUNCTION_JUMP_RAD_S = 0.5
#: Durations are raised to ⌈bound − this⌉ µs, so that a bound computed a few ulp above an
#: integer does not add a µs (keeps the least element exactly monotone in the limits).
_CEIL_SLACK_US = 1e-9


# ----------------------------------------------------------------------------- the cut
def piece_sizes(first_steps: float, growth_steps: float, n_max: int) -> FloatArray:
    """Piece sizes in steps from a segment's end inward: s_i = max(first, ⌈g·i⌉), i = 1…n_max
    (module doc, "the cut")."""
    i = np.arange(1, n_max + 1, dtype=np.float64)
    return np.maximum(float(first_steps), np.ceil(growth_steps * i))


def cut_fractions(n_steps: FloatArray, sizes: FloatArray) -> tuple[IntArray, FloatArray]:
    """Cut every segment of `n_steps` (Chebyshev) steps into pieces of `sizes` from both ends
    and one middle piece of at least sizes[0] steps. Returns the number of pieces per segment
    (K,) and every piece's end as a fraction of its segment (ascending within a segment, the
    last exactly 1). Depends on the geometry only."""
    n = np.asarray(n_steps, dtype=np.float64)
    cum = np.cumsum(sizes)  # C_i: where the i-th piece from an end stops
    m = np.searchsorted(cum, 0.5 * (n - sizes[0]), side="right")  # pieces per end
    counts = (2 * m + 1).astype(np.int64)
    seg = np.repeat(np.arange(n.shape[0]), counts)
    i = np.arange(seg.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
    ms, ns = m[seg], n[seg]
    left = cum[np.minimum(i, cum.shape[0] - 1)]
    right = ns - cum[np.clip(2 * ms - 1 - i, 0, cum.shape[0] - 1)]
    x = np.where(i < ms, left, np.where(i < 2 * ms, right, ns))
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(ns > 0, x / ns, 1.0)
    f[i == 2 * ms] = 1.0
    return counts, f


# ----------------------------------------------------------------------------- the plan
def _rest_sides(k: int, stop_after: BoolArray | None) -> tuple[IntArray, IntArray]:
    """First and last segment of every run between stops (start, stops, end)."""
    st = np.zeros(k, dtype=bool) if stop_after is None else np.asarray(stop_after, bool).copy()
    st[-1] = True
    ends = np.flatnonzero(st)
    starts = np.concatenate(([0], ends[:-1] + 1))
    return starts.astype(np.int64), ends.astype(np.int64)


def _bound_after(a: FloatArray, b: FloatArray, p: FloatArray, jump: float,
                 acc: float) -> FloatArray:
    """Shortest q (µs) of the segment on one side of a boundary whose other side lasts p:
    max over joints (columns) of (3) and (4) in the module doc, a = |Δθ| on q's side, b on
    p's side (0 for a joint that reverses there: (5) covers it). Nondecreasing in p."""
    pc = p[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        q_jump = a / (jump + b / pc)  # (3)
        p_star = np.sqrt(2.0 * b / acc)
        c = np.where(pc >= p_star, np.sqrt(2.0 * acc * b), b / pc + 0.5 * acc * pc)  # c(p̂)
        q_acc = 2.0 * a / (c + np.sqrt(c * c + 2.0 * acc * a))  # (4)
    return np.nan_to_num(np.maximum(q_jump, q_acc), nan=0.0).max(axis=1)


def _static_bounds(dth: FloatArray, lo: FloatArray, rest: BoolArray, act: IntArray,
                   jump: float, acc: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Add the rest bounds (2) and the reversal bounds (5) to `lo` (µs) in place. Returns per
    active boundary the joints' |Δθ| after (a) and before (b) it, zeroed where the joint
    reverses (those joints are done by (5))."""
    dist = np.abs(dth).max(axis=1)
    lo[rest] = np.maximum.reduce([lo[rest], dist[rest] / jump, np.sqrt(2 * dist[rest] / acc)])
    a, b = np.abs(dth[act + 1]), np.abs(dth[act])
    rev = dth[act + 1] * dth[act] < 0
    r = rev.any(axis=1)
    if r.any():
        both = np.where(rev, a + b, 0.0).max(axis=1)[r] / jump
        np.maximum.at(lo, act[r] + 1,
                      np.maximum(both, np.sqrt(2 * np.where(rev, a, 0.0).max(axis=1)[r] / acc)))
        np.maximum.at(lo, act[r],
                      np.maximum(both, np.sqrt(2 * np.where(rev, b, 0.0).max(axis=1)[r] / acc)))
    return np.where(rev, 0.0, a), np.where(rev, 0.0, b), lo


def staircase_durations(dtheta_rad: FloatArray, length_mm: FloatArray, feed_mm_s: FloatArray,
                        max_joint_rad_s: float, max_joint_rad_s2: float,
                        stop_after: BoolArray | None = None,
                        junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S,
                        min_duration_us: int = 1) -> IntArray:
    """The least integer durations (µs) under (1)–(5) of the module doc: dtheta_rad (K, 2)
    per segment (whole steps), length_mm (K,) pen path, feed_mm_s (K,) allowed pen speed,
    stop_after (K,) True where the tool stops after segment k (the last always does).
    A segment that does not move gets 0 µs and stops the machine on both sides."""
    dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
    k = dth.shape[0]
    if k == 0:
        return np.zeros(0, dtype=np.int64)
    acc, jump = float(max_joint_rad_s2) * 1e-12, float(junction_jump_rad_s) * 1e-6  # per µs
    dist = np.abs(dth).max(axis=1)
    moving = dist > 0
    length = np.asarray(length_mm, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.maximum.reduce([np.full(k, float(min_duration_us)),
                                dist / (max_joint_rad_s * 1e-6),
                                np.where(length > 0, length / (feed_mm_s * 1e-6), 0.0)])  # (1)
    st = np.zeros(k, bool) if stop_after is None else np.asarray(stop_after, bool).copy()
    st[-1] = True
    st |= ~moving
    st[:-1] |= ~moving[1:]
    rest = st | np.concatenate(([True], st[:-1]))
    # boundary n sits between segments act[n] and act[n] + 1; across a stop too, since the
    # jump is also checked there (the staircase from ω_{k−1} straight to ω_k)
    act = np.flatnonzero(moving[:-1] & moving[1:])
    a, b, lo = _static_bounds(dth, lo, rest, act, jump, acc)
    p = np.where(moving, np.ceil(lo - _CEIL_SLACK_US), 0.0)
    _raise_to_least(p, act, a, b, jump, acc)
    return p.astype(np.int64)


def _raise_to_least(p: FloatArray, act: IntArray, a: FloatArray, b: FloatArray, jump: float,
                    acc: float) -> None:
    """Kleene's iteration (module doc): raise durations `p` (µs, in place) by the bounds (3),
    (4) across the boundaries `act` until none changes; each round only revisits the
    boundaries next to a segment that changed."""
    by_left = np.full(p.shape[0] + 1, -1, dtype=np.int64)  # boundary index by its left segment
    by_left[act] = np.arange(act.shape[0])
    todo = np.arange(act.shape[0])
    while todo.size:
        left = act[todo]
        q_new = np.ceil(_bound_after(a[todo], b[todo], p[left], jump, acc) - _CEIL_SLACK_US)
        p_new = np.ceil(_bound_after(b[todo], a[todo], p[left + 1], jump, acc)
                        - _CEIL_SLACK_US)
        up_q, up_p = q_new > p[left + 1], p_new > p[left]
        p[left[up_q] + 1] = q_new[up_q]  # each boundary has its own right segment...
        p[left[up_p]] = np.maximum(p[left[up_p]], p_new[up_p])  # ...and its own left one
        changed = np.concatenate((left[up_q] + 1, left[up_p]))
        near = np.concatenate((by_left[changed], by_left[changed - 1]))
        todo = np.unique(near[near >= 0])


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
