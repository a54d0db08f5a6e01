"""The staircase the firmware runs, and the least durations that keep it within the limits.

The firmware runs each segment at one constant step rate for its P µs (docs/protocol.md 6.1),
so the joints really move with the piecewise-constant velocity ω_k = Δθ_k / P_k and every speed
change happens at a segment boundary, as a jump. What the limits mean on that staircase — the
same constraints a continuous time-optimal parameterisation is given (TOPP-RA in
benchmarks/topp.py): the joints' speeds ≤ ω_max, their accelerations ≤ α, and at a
junction of the joint path a jump of the joints' speeds ≤ J, where the path's own speed is
continuous. With x_k the segment's path distance (the pen's path length L_k, or the
Chebyshev joint distance D_k = max_j |Δθ_kj| where no length is given), its path speed
S_k = x_k / P_k, its slopes g_k = Δθ_k / x_k, its path-acceleration limit α_k = α / max_j
|g_kj| = α·x_k / D_k (a joint's acceleration is its slope times the path's) and its top
speed V_k = x_k / (its shortest duration: feed, ω_max, the firmware's shortest P):

    jump  (J1)  max_j |ω_{k,j} − ω_{k−1,j}| ≤ J at every boundary, and max_j |ω_kj| ≤ J next to
                a stop — the instantaneous change the firmware really makes;
    accel (A1)  S_k ≤ the mean over P_k of min(c_in + α_k t, c_out + α_k (P_k − t), V_k) —
                the highest mean of a path speed that leaves the segment's entry at most at
                c_in, reaches its exit at most at c_out, changes at most at α_k and never
                exceeds V_k (a "tent", flat-topped where V_k binds). Each end's cap is the
                least of: J / δ at a junction whose slopes change by δ = max_j |g_{k,j} −
                g_{k−1,j}| (the joints' speeds jump by δ times the path speed there), 0 at a
                stop, and what the neighbour's own mean speed reaches there, S_j + α_j P_j/2
                (a path speed changing at α_j through its mean).

Two neighbours' means so differ by at most α's worth between their midpoints, a mean above
both neighbours' is held to a tent between them, and a segment at its top speed must start
and end at it. (Before issue 39's second round the acceleration was measured joint by
joint, |Δω_kj| ≤ α (P_{k−1} + P_k)/2, which counts a joint's direction change at a junction as
acceleration — a joint that stood still in one segment had to start the next as if from
rest; against TOPP-RA that cost 1.061× on benchmarks/drawings/bc_template.svg.)

The repair. With a, b the joints' |Δθ| on the two sides of a boundary and q, p their
durations:

    rest    P_k ≥ D_k / J  (first and last segment of every run)                        (2)
    (J1) where the joint keeps its direction (or stands in one of the two segments):
         a/q − b/p ≤ J  ⇔  q ≥ a / (J + b/p), and the same with the sides swapped       (3)
    (A1) q ≥ the least duration whose tent mean covers x_k (`tent_duration`, closed
         form), each end's neighbour reach taken at p̂ = min(p, √(2x_j/α_j)), where
         x_j/p + α_j p/2 is least                                                       (4)
    (J1) where the joint reverses: a/q + b/p ≤ J, met by q ≥ √a(√a + √b)/J and
         p ≥ √b(√a + √b)/J — J shared as √a : √b, the split with the least p + q       (5)

(4) takes p̂ for p — a little stricter than (A1) only where the neighbour is slower than a
start from rest through it would be — and in exchange every bound is a constant or a
*nondecreasing* function of the neighbours' durations: the integer durations meeting them
all are closed under the element-wise minimum and have a least element, the shortest plan
of every segment at once, which `enforce_staircase` reaches by Kleene's iteration. Raising
α or J lowers every bound, so on given pieces no segment's duration ever grows when a
limit is raised — exactly, to the µs. `staircase_ratios` measures a staircase against
(J1) and (A1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Default largest instantaneous joint-speed change at a junction, rad/s.
JUNCTION_JUMP_RAD_S = 0.5
#: Durations are raised to ⌈bound − this⌉ µs, so that a bound computed a few ulp above an
#: integer does not add a µs (keeps the least durations exactly monotone in the limits).
CEIL_SLACK_US = 1e-9
#: Boundaries measured at a time by `_round_raises` (bounded temporaries on large jobs;
#: every boundary is measured on its own, so the bounds are those of one pass).
STAIRCASE_BLOCK = 1 << 16
#: Bisection steps of `tent_duration` (the interval shrinks 2^-60: well under a µs).
_TENT_STEPS = 60


@dataclass(frozen=True)
class Moves:
    """The moves as the rules see them (module doc), in µs: the joints' moves `dth` (N, 2)
    rad, the path distance `x` (N,), the path-acceleration limit `acc` (N,) per µs², the
    top path speed `top` (N,) per µs and the junction jump `jump` per µs."""

    dth: FloatArray
    x: FloatArray
    acc: FloatArray
    top: FloatArray
    jump: float

    @classmethod
    def of(cls, dtheta_rad: FloatArray, length_mm: FloatArray | None,
           limits: tuple[float, float],
           floor_us: IntArray | FloatArray | None) -> Moves:
        """The moves with their path: the pen's length where given and positive, else the
        Chebyshev joint distance (α_k = α·x_k/D_k, module doc); `limits` (α rad/s², J rad/s);
        each segment's top path speed x/floor from its shortest duration `floor_us` (none
        where not given)."""
        max_joint_rad_s2, junction_jump_rad_s = limits
        dth = np.asarray(dtheta_rad, dtype=np.float64).reshape(-1, 2)
        d = chebyshev(dth)
        x = d.copy() if length_mm is None else np.asarray(length_mm, dtype=np.float64)
        x = np.where((x > 0) & (d > 0), x, d)
        with np.errstate(divide="ignore", invalid="ignore"):
            acc = float(max_joint_rad_s2) * 1e-12 * np.where(d > 0, x / d, 1.0)
        if floor_us is None:
            top = np.full(x.shape[0], np.inf)
        else:
            f = np.asarray(floor_us, dtype=np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                top = np.where(f > 0, x / f, np.inf)
        return cls(dth, x, acc, top, float(junction_jump_rad_s) * 1e-6)


class _Side(NamedTuple):
    """One side of some boundaries: the joints' |Δθ| (N, 2; 0 for a joint that reverses
    there), the path distance and the path-acceleration limit."""

    a: FloatArray
    x: FloatArray
    acc: FloatArray


def chebyshev(dth: FloatArray) -> FloatArray:
    """The Chebyshev joint distance D = max_j |Δθ_j| of each move (N, 2), column by column
    (numpy's max over a 2-column axis is some 30× slower than one maximum of the columns)."""
    return np.maximum(np.abs(dth[:, 0]), np.abs(dth[:, 1]))


def rest_flags(moving: BoolArray, stop_after: BoolArray | None) -> tuple[BoolArray, BoolArray]:
    """Per segment, whether it moves and starts from (ends at) rest: the job's ends, a stop,
    or a neighbour without motion."""
    k = moving.shape[0]
    st = np.zeros(k, bool) if stop_after is None else np.asarray(stop_after, bool).copy()
    st[-1] = True
    st |= ~moving
    st[:-1] |= ~moving[1:]
    return np.concatenate(([True], st[:-1])) & moving, st & moving


def turn_caps(mv: Moves, left: IntArray) -> FloatArray:
    """The path speed allowed at the boundaries after the moving segments `left` (per µs):
    J / δ with δ = max_j |g_{k+1,j} − g_{k,j}| (module doc, (A1)); infinite where the slopes
    do not change."""
    gl = mv.dth[left] / mv.x[left, None]
    gr = mv.dth[left + 1] / mv.x[left + 1, None]
    delta = np.maximum(np.abs(gr[:, 0] - gl[:, 0]), np.abs(gr[:, 1] - gl[:, 1]))
    with np.errstate(divide="ignore"):
        out: FloatArray = mv.jump / delta
    return out


def segment_caps(mv: Moves, rest: tuple[BoolArray, BoolArray],
                 act: IntArray) -> tuple[FloatArray, FloatArray]:
    """Each segment's entry and exit caps c_in, c_out ((A1)) before the neighbours' reach:
    0 at rest, the turn cap at a boundary `act` between two moves, else infinite."""
    c_in = np.where(rest[0], 0.0, np.inf)
    c_out = np.where(rest[1], 0.0, np.inf)
    for i in range(0, act.shape[0], STAIRCASE_BLOCK):
        c = act[i:i + STAIRCASE_BLOCK]
        cap = turn_caps(mv, c)
        np.minimum.at(c_in, c + 1, cap)
        np.minimum.at(c_out, c, cap)
    return c_in, c_out


def tent_mean(ends: tuple[FloatArray, FloatArray], q: FloatArray, acc: FloatArray,
              top: FloatArray) -> FloatArray:
    """The highest mean over a time q of a speed that starts at most c_in, ends at most
    c_out (`ends`), never exceeds `top` and changes at most at rate acc: the mean of
    min(c_in + acc·t, c_out + acc·(q − t), top). With c ≤ C the two caps (each at most top)
    and Δ = C − c: where the rise to top and the fall from it fit in q, a trapezoid of area
    q·top − ((top − c)² + (top − C)²)/(2·acc); else where Δ ≥ acc·q the speed only rises
    (mean c + acc·q/2), else it rises and falls (a tent) with area (c + C)·q/2 + acc·q²/4 −
    Δ²/(4·acc)."""
    lo = np.minimum(np.minimum(ends[0], ends[1]), top)
    hi = np.minimum(np.maximum(ends[0], ends[1]), top)
    with np.errstate(invalid="ignore", divide="ignore"):
        qs = np.maximum(q, 1e-300)
        dd = hi - lo
        tent = 0.5 * (lo + hi) + 0.25 * acc * q - dd * dd / (4.0 * acc * qs)
        out = np.where(dd >= acc * q, lo + 0.5 * acc * q, tent)
        flat = top - ((top - lo) ** 2 + (top - hi) ** 2) / (2.0 * acc * qs)
        fits = np.isfinite(top) & ((top - lo) + (top - hi) <= acc * q)
    res: FloatArray = np.where(fits, flat, out)
    return res


def tent_duration(x: FloatArray, ends: tuple[FloatArray, FloatArray], acc: FloatArray,
                  top: FloatArray) -> FloatArray:
    """The least duration q with x ≤ q · `tent_mean`(ends, q, acc, top) (bound (4)), in
    closed form, branch by branch of `tent_mean` (q · mean grows with q): the rise alone,
    q = (√(c² + 2·acc·x) − c)/acc, where it ends before the other cap binds; else the root
    of acc·q²/4 + (c + C)·q/2 = x + Δ²/(4·acc); and where that q has room for the rise to
    top and the fall from it, q = (x + ((top − c)² + (top − C)²)/(2·acc)) / top."""
    lo = np.minimum(np.minimum(ends[0], ends[1]), top)
    hi = np.minimum(np.maximum(ends[0], ends[1]), top)
    with np.errstate(invalid="ignore", divide="ignore"):
        rise = 2.0 * x / (lo + np.sqrt(lo * lo + 2.0 * acc * x))
        dd = hi - lo
        h = 0.5 * (lo + hi)
        tent = 2.0 * (np.sqrt(h * h + acc * (x + dd * dd / (4.0 * acc))) - h) / acc
        q = np.where(~(dd < acc * rise), rise, tent)
        ramps = ((top - lo) + (top - hi)) / acc
        flat = (x + ((top - lo) ** 2 + (top - hi) ** 2) / (2.0 * acc)) / top
    out: FloatArray = np.where(np.isfinite(top) & (q > ramps), flat, q)
    return out


def reach(mv: Moves, k: IntArray, p: FloatArray) -> FloatArray:
    """The highest path speed at either end of the segments `k` lasting p (µs) that their
    mean speed allows: x/p + acc·p/2 (a speed changing at acc through the mean), taken at
    p̂ = min(p, √(2x/acc)) — never lower, and nondecreasing in p (module doc, (4))."""
    x, acc = mv.x[k], mv.acc[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        ph = np.minimum(p, np.sqrt(2.0 * x / acc))
        out: FloatArray = x / ph + 0.5 * acc * ph
    return out


def staircase_ratios(dtheta_rad: FloatArray, duration_us: IntArray,
                     stop_after: BoolArray | None, max_joint_rad_s2: float,
                     junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S, *,
                     length_mm: FloatArray | None = None,
                     floor_us: IntArray | FloatArray | None = None
                     ) -> tuple[FloatArray, FloatArray]:
    """The staircase the firmware runs against the limits (module doc). Returns (jump,
    accel) ratios, each ≤ 1 when honoured: jump = (J1) at every boundary and next to every
    stop; accel = (A1) per moving segment, its path speed against its tent's mean (its top
    speed from `floor_us`, each segment's shortest duration, where given)."""
    mv = Moves.of(dtheta_rad, length_mm, (max_joint_rad_s2, junction_jump_rad_s), floor_us)
    k = mv.dth.shape[0]
    if k == 0:
        return np.zeros(0), np.zeros(0)
    t = np.asarray(duration_us, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(t[:, None] > 0, mv.dth / t[:, None], 0.0)
    moving = chebyshev(mv.dth) > 0
    rest = rest_flags(moving, stop_after)
    jump = np.concatenate((chebyshev(np.diff(w, axis=0)),
                           chebyshev(w[rest[0] | rest[1]]))) / mv.jump
    act = np.flatnonzero(moving[:-1] & moving[1:])
    c_in, c_out = segment_caps(mv, rest, act)
    with np.errstate(divide="ignore", invalid="ignore"):
        np.minimum.at(c_in, act + 1, mv.x[act] / t[act] + 0.5 * mv.acc[act] * t[act])
        np.minimum.at(c_out, act, mv.x[act + 1] / t[act + 1] + 0.5 * mv.acc[act + 1] * t[act + 1])
        m = np.flatnonzero(moving)
        acc = mv.x[m] / t[m] / tent_mean((c_in[m], c_out[m]), t[m], mv.acc[m], mv.top[m])
    return jump, np.nan_to_num(acc, nan=0.0)


def enforce_staircase(dtheta_rad: FloatArray, duration_us: IntArray,
                      stop_after: BoolArray | None, max_joint_rad_s2: float,
                      junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S, *,
                      length_mm: FloatArray | None = None,
                      floor_us: IntArray | FloatArray | None = None) -> IntArray:
    """The least integer durations (µs) at least `duration_us` that meet bounds (2)–(5) of
    the module doc — so `staircase_ratios` are all ≤ 1 — found by raising durations from
    below until no bound moves one (Kleene's iteration: every bound is a constant or a
    nondecreasing function of the neighbours' durations, so the least fixed point exists
    and is what the iteration reaches; each round revisits only the segments next to one
    that changed). Never shortens a segment, so the feed and joint-speed limits stay
    honoured; nonincreasing in `duration_us`, `max_joint_rad_s2` and `junction_jump_rad_s`
    (raising a limit never lengthens a segment). Segments without motion keep their
    duration and count as stops on both sides. `length_mm`: the pen's path per segment
    (the path whose speed is continuous; module doc); `floor_us`: each segment's shortest
    duration (its feed, joint speed and the firmware's floor: its top speed, (A1)),
    `duration_us` where not given."""
    mv = Moves.of(dtheta_rad, length_mm, (max_joint_rad_s2, junction_jump_rad_s),
                  duration_us if floor_us is None else floor_us)
    p = np.asarray(duration_us, dtype=np.float64).copy()
    del duration_us  # (the caller may hold none: then it is freed here)
    if not p.shape[0]:
        return p.astype(np.int64)
    moving = chebyshev(mv.dth) > 0
    rest = rest_flags(moving, stop_after)
    act = np.flatnonzero(moving[:-1] & moving[1:])
    _static_bounds(mv, p, rest, act)
    caps = segment_caps(mv, rest, act)
    del rest, act
    _raise_near(p, np.flatnonzero(moving), mv, caps)
    return p.astype(np.int64)


def raise_staircase(dtheta_rad: FloatArray, duration_us: IntArray, raised: IntArray,
                    stop_after: BoolArray | None, max_joint_rad_s2: float,
                    junction_jump_rad_s: float = JUNCTION_JUMP_RAD_S, *,
                    length_mm: FloatArray | None = None,
                    floor_us: IntArray | FloatArray | None = None) -> None:
    """`enforce_staircase` again, in place, on durations it returned (for these moves, stops
    and limits) that were then raised at the segments `raised` only: the same least
    durations, found by revisiting only the segments next to the raises. Why the same: the
    constant bounds (2), (5) were met already; every segment away from the raises still
    meets the others; and Kleene's iteration from any durations at least the input and at
    most the least fixed point reaches that fixed point whatever the order of the segments
    it revisits (each raise stays below it, since every bound is nondecreasing).
    `compile.timing`'s later link-floor passes raise a few hundred of a job's segments; a
    whole `enforce_staircase` would measure every segment again. `floor_us`: the segments'
    shortest durations as `enforce_staircase` was given them, with the raises."""
    if not raised.size:
        return
    mv = Moves.of(dtheta_rad, length_mm, (max_joint_rad_s2, junction_jump_rad_s), floor_us)
    p = duration_us.astype(np.float64)
    moving = chebyshev(mv.dth) > 0
    rest = rest_flags(moving, stop_after)
    caps = segment_caps(mv, rest, np.flatnonzero(moving[:-1] & moving[1:]))
    _raise_near(p, _next_to(np.asarray(raised, dtype=np.int64), moving), mv, caps)
    duration_us[...] = p


def _static_bounds(mv: Moves, lo: FloatArray, rest: tuple[BoolArray, BoolArray],
                   act: IntArray) -> None:
    """Raise `lo` (µs, in place) to the constant bounds: (2) next to a stop and (5) on both
    sides of a reversing joint, in blocks of `STAIRCASE_BLOCK` boundaries (no whole-job
    temporaries)."""
    at_rest = rest[0] | rest[1]
    lo[at_rest] = np.maximum(lo[at_rest], np.ceil(chebyshev(mv.dth[at_rest]) / mv.jump
                                                  - CEIL_SLACK_US))
    for i in range(0, act.shape[0], STAIRCASE_BLOCK):
        c = act[i:i + STAIRCASE_BLOCK]
        rv = np.less(mv.dth[c + 1] * mv.dth[c], 0)
        r = np.flatnonzero(rv[:, 0] | rv[:, 1])
        if not r.size:
            continue
        ra, rb = np.sqrt(np.abs(mv.dth[c[r] + 1])), np.sqrt(np.abs(mv.dth[c[r]]))
        split = np.where(rv[r], ra + rb, 0.0) / mv.jump  # (5): J shared as √a : √b
        np.maximum.at(lo, c[r] + 1, np.ceil((ra * split).max(axis=1) - CEIL_SLACK_US))
        np.maximum.at(lo, c[r], np.ceil((rb * split).max(axis=1) - CEIL_SLACK_US))


def _next_to(changed: IntArray, moving: BoolArray) -> IntArray:
    """The moving segments among `changed` and their neighbours."""
    k = np.unique(np.concatenate((changed - 1, changed, changed + 1)))
    k = k[(k >= 0) & (k < moving.shape[0])]
    out: IntArray = k[moving[k]]
    return out


def _raise_near(p: FloatArray, todo: IntArray, mv: Moves,
                caps: tuple[FloatArray, FloatArray]) -> None:
    """Kleene's rounds on durations `p` (µs, in place): a round raises each segment in
    `todo` (all moving) to its bounds (3), (4) from its neighbours' durations at the
    round's start; the next round revisits the segments next to one that changed, until
    none does. `caps`: the segments' constant entry and exit caps (`segment_caps`)."""
    moving = chebyshev(mv.dth) > 0
    while todo.size:
        parts = []
        for i in range(0, todo.shape[0], STAIRCASE_BLOCK):
            k = todo[i:i + STAIRCASE_BLOCK]
            q = np.ceil(_least(p, k, mv, caps, moving) - CEIL_SLACK_US)
            parts.append((k[q > p[k]], q[q > p[k]]))
        up = np.concatenate([x[0] for x in parts])
        p[up] = np.concatenate([x[1] for x in parts])
        todo = _next_to(up, moving)


def _least(p: FloatArray, k: IntArray, mv: Moves, caps: tuple[FloatArray, FloatArray],
           moving: BoolArray) -> FloatArray:
    """The least duration (µs) of each moving segment in `k` from its neighbours' durations
    `p`: bound (3) per joint from each moving neighbour, and (4) with each end's cap lowered
    to what the neighbour there reaches (`reach`)."""
    last = p.shape[0] - 1
    c_in, c_out = caps[0][k], caps[1][k]
    q = np.zeros(k.shape[0])
    a = np.abs(mv.dth[k])
    for side, cap in ((-1, c_in), (1, c_out)):
        j = np.clip(k + side, 0, last)
        nb = moving[j] & (j != k)
        if not nb.any():
            continue
        i, j = np.flatnonzero(nb), j[nb]
        np.minimum.at(cap, i, reach(mv, j, p[j]))
        b = np.abs(mv.dth[j])
        keep = ~np.less(mv.dth[j] * mv.dth[k[i]], 0)  # a reversal: (5)
        with np.errstate(divide="ignore", invalid="ignore"):
            qj = np.where(keep, a[i] / (mv.jump + b / p[j, None]), 0.0)  # (3)
        np.maximum.at(q, i, np.nan_to_num(chebyshev(qj), nan=0.0))
    tent = tent_duration(mv.x[k], (c_in, c_out), mv.acc[k], mv.top[k])
    return np.maximum(q, np.nan_to_num(tent, nan=0.0, posinf=0.0))
