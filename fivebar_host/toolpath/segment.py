"""Segmentation in joint space with one tolerance, and the pose checks on and between targets.

The firmware moves both motors linearly in step (joint) space between consecutive targets, so
between targets θ_a and θ_b the pen follows g(s) = FK(θ_a + s·(θ_b − θ_a)), s ∈ [0, 1] — a
curve, not the straight chord P_a → P_b that was asked for. `refine` splits every chord until
that curve stays within the chord's interpolation budget `tol_i`:

    dev(a, b) = max over s ∈ S of dist(g(s), segment [P_a, P_b]),  S = {1/4, 1/2, 3/4}

and an interval is split at its chord midpoint (new target by inverse kinematics) while
dev > κ·tol_i (κ = `SAFETY` = 0.8). Why three samples and κ suffice: with the endpoints on
the chord, e(s) = g(s) − (P_a + s(P_b − P_a)) vanishes at s = 0, 1 and
e(s) = −½ s(1 − s)·D²FK[Δθ, Δθ] + O(|Δθ|³), so for short intervals the deviation is a
parabola peaking at s = ½ with max ‖e‖ ≤ ⅛·max‖D²FK[Δθ, Δθ]‖ — the "curvature of the forward
map along the joint chord" bound; each halving divides it by 4. The quarter points catch a
skewed peak (a cubic term from a fast-changing Jacobian near a singularity), and κ covers the
remaining gap between the sampled and the true maximum (measured densely in the tests: the
hypothesis test samples 64 points per segment near singularities). The joint-space step per
segment is also capped (`max_step_rad`) so the planner's acceleration ramps are smooth.

Where the map is nearly linear, one segment covers a long chord; near singularities the
segments get dense — the split count follows ‖D²FK‖, not a fixed point count.

Total bound on the drawn path (see `fivebar_host.compile.job`): flattening (chord within tol_f of
the curve) + interpolation (pen within tol_i of the chord) ≤ tol_f + tol_i = tol. Step
quantisation adds at most one step quantum, reported separately.

Pose checks (`PoseChecker`) run on every target and on the samples between targets: inverse
kinematics exist (reach), motor angles within limits, both type-1 margins (signed by the
working mode, so a sign flip is a working-mode change) and the type-2 margin (signed by the
assembly) at least the configured minima, and forward kinematics valid between targets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import BoolArray, FloatArray, IntArray
from kinematics.fivebar import FiveBar, UnreachableError

SAFETY = 0.8
SAMPLES = np.array([0.25, 0.5, 0.75])
MAX_ROUNDS = 60
#: Targets solved at a time by `PoseChecker.inverse`.
INVERSE_BLOCK = 1 << 16

# Check outcome codes (per pose).
OK, REACH, LIMIT1, LIMIT2, T1_ARM1, T1_ARM2, T2, ASSEMBLY, FK_INVALID = range(9)
REASON_KEY = {REACH: "reach", LIMIT1: "joint_limit", LIMIT2: "joint_limit",
              T1_ARM1: "type1_margin", T1_ARM2: "type1_margin", T2: "type2_margin",
              ASSEMBLY: "assembly", FK_INVALID: "reach"}


class CheckFailedError(Exception):
    """A pose that fails a check: `index` into the batch that was checked, the point (machine
    mm), a stable `reason` key and a human message. Converted to `JobError` by the caller,
    which knows which path and source line the index belongs to."""

    def __init__(self, index: int, point: tuple[float, float], reason: str,
                 message: str) -> None:
        super().__init__(message)
        self.index = index
        self.point = point
        self.reason = reason
        self.message = message


def wrap_to_limits(theta: FloatArray,
                   limits: tuple[tuple[float, float], tuple[float, float]]
                   ) -> tuple[FloatArray, BoolArray, BoolArray]:
    """Angles (N, 2) mapped to θ + 2πk ∈ [lo, lo + 2π), and per-motor in-limit masks.
    Both motors at once (the same arithmetic per element as one column at a time: the
    raster planner calls this for every scanline)."""
    lo = np.array([limits[0][0], limits[1][0]])
    hi = np.array([limits[0][1] + 1e-12, limits[1][1] + 1e-12])
    turn = 2.0 * math.pi
    x = theta - lo
    if x.size and not (float(x.min()) >= 0.0 and float(x.max()) < turn):
        x = np.mod(x, turn)  # (on [0, 2π) the remainder is x itself, exactly)
    t = lo + x
    d = t - lo
    out: FloatArray = t
    if d.size and float(d.max()) >= turn - 1e-12:
        out = np.where(d >= turn - 1e-12, lo, t)
    ok = out <= hi
    return out, ok[:, 0], ok[:, 1]


@dataclass(frozen=True)
class PoseChecker:
    """Vectorised pose checks for one machine, working mode and assembly sign."""

    fb: FiveBar
    mode: str
    assembly: int  # +1 / −1
    min_type1_rad: float
    min_type2_rad: float
    limits_rad: tuple[tuple[float, float], tuple[float, float]]

    @property
    def signs(self) -> FloatArray:
        return np.array([1.0 if self.mode[0] == "+" else -1.0,
                         1.0 if self.mode[1] == "+" else -1.0])

    def codes(self, angles: FloatArray, points: FloatArray,
              check_type1: bool = True) -> tuple[NDArray[np.int8], FloatArray]:
        """Per-pose outcome code (first failing check) and the signed margins (N, 3) rad,
        each margin multiplied by its expected sign (so ≥ minimum means safe)."""
        n = angles.shape[0]
        code = np.zeros(n, dtype=np.int8)
        m = self.fb.singularity_margins(angles, points)
        m = m * np.concatenate((self.signs, [float(self.assembly)]))
        # Precedence (later assignments win): joint limit, assembly change, type 1, type 2.
        code[m[:, 2] < self.min_type2_rad] = T2
        if check_type1:
            code[m[:, 1] < self.min_type1_rad] = T1_ARM2
            code[m[:, 0] < self.min_type1_rad] = T1_ARM1
        code[m[:, 2] < 0] = ASSEMBLY
        _, ok1, ok2 = wrap_to_limits(angles, self.limits_rad)
        code[~ok2] = LIMIT2
        code[~ok1] = LIMIT1
        return code, m

    def explain(self, code: int, angle: FloatArray, point: FloatArray,
                margin: FloatArray) -> str:
        """A sentence for one failing pose."""
        deg = math.degrees
        if code in (LIMIT1, LIMIT2):
            i = 0 if code == LIMIT1 else 1
            lo, hi = self.limits_rad[i]
            a, _, _ = wrap_to_limits(angle.reshape(1, 2), self.limits_rad)
            return (f"motor {i + 1} would be at {deg(a[0, i]):.2f}°, outside its limits "
                    f"[{deg(lo):g}°, {deg(hi):g}°]")
        if code in (T1_ARM1, T1_ARM2):
            i = 0 if code == T1_ARM1 else 1
            if margin[i] < 0:
                return (f"arm {i + 1} would flip its elbow (working mode {self.mode} changes: "
                        f"the arm passes a type-1 singularity, stretched or folded)")
            return (f"arm {i + 1} is {deg(margin[i]):.2f}° from a type-1 singularity "
                    f"(a{i + 1} and b{i + 1} stretched or folded); the minimum is "
                    f"{deg(self.min_type1_rad):g}°")
        if code == ASSEMBLY:
            other = "-" if self.assembly > 0 else "+"
            return (f"the pose is only reachable in assembly {other} (the pen on the other side "
                    f"of the line through the elbows R1, R2, beyond a type-2 singularity); the "
                    f"machine is built in assembly {'+' if self.assembly > 0 else '-'} "
                    "([kinematics] assembly), which a five-bar cannot change under control")
        if code == T2:
            return (f"the floating links are {deg(margin[2]):.2f}° from collinear (type-2 "
                    f"singularity); the minimum is {deg(self.min_type2_rad):g}°")
        return "the pose is not reachable"

    # ------------------------------------------------------------------ targets
    def inverse(self, points: FloatArray, index_base: IntArray | None = None) -> FloatArray:
        """Checked inverse kinematics of targets: angles (N, 2) wrapped into the limits, or
        `CheckFailedError` for the first failing point (its index from `index_base`): the
        first unreachable one if any, else the first that fails a check. In blocks of
        `INVERSE_BLOCK` points (every point is solved on its own: the same angles and the
        same error as one pass; bounded temporaries on large drawings)."""
        n = points.shape[0]
        angles = np.empty((n, 2))
        for i in range(0, n, INVERSE_BLOCK):  # every point's reach first, as one pass would
            inv = self.fb.inverse_batch(points[i:i + INVERSE_BLOCK], self.mode)
            if not inv.valid.all():
                self._unreachable(points, index_base, i + int(np.flatnonzero(~inv.valid)[0]))
            angles[i:i + INVERSE_BLOCK] = wrap_to_limits(inv.angles, self.limits_rad)[0]
            del inv
        for i in range(0, n, INVERSE_BLOCK):
            sl = slice(i, i + INVERSE_BLOCK)
            code, m = self.codes(angles[sl], points[sl])
            if code.any():
                j = int(np.flatnonzero(code)[0])
                idx = int(index_base[i + j]) if index_base is not None else i + j
                p = points[i + j]
                raise CheckFailedError(idx, (float(p[0]), float(p[1])),
                                       REASON_KEY[int(code[j])],
                                       self.explain(int(code[j]), angles[i + j], p, m[j]))
        return angles

    def _unreachable(self, points: FloatArray, index_base: IntArray | None, i: int) -> None:
        """Raise `CheckFailedError` for the unreachable point `i` of `inverse`."""
        p = points[i]
        try:
            self.fb.inverse(p, self.mode)
            msg = "is not reachable"
        except (UnreachableError, ValueError) as e:
            # "point (x, y) mm is beyond arm 1's reach: …" → "is beyond arm 1's reach: …"
            text = str(e)
            msg = text.split(" mm ", 1)[1] if text.startswith("point (") else text
        idx = int(index_base[i]) if index_base is not None else i
        raise CheckFailedError(idx, (float(p[0]), float(p[1])), "reach", f"the point {msg}")

    def forward(self, angles: FloatArray) -> tuple[FloatArray, BoolArray]:
        res = self.fb.forward_batch(angles, "+" if self.assembly > 0 else "-")
        return res.points, res.valid


@dataclass(frozen=True)
class Intervals:
    """Final pieces of chords: chord id, chord parameters σ_a < σ_b, joint angles at both
    ends, the smallest signed margins (N, 3) seen on the piece (ends and samples) and the
    sampled interpolation deviation (mm, ideal angles)."""

    chord: IntArray
    sa: FloatArray
    sb: FloatArray
    tha: FloatArray
    thb: FloatArray
    min_margin: FloatArray
    dev_mm: FloatArray


@dataclass(frozen=True)
class _Pieces:
    """Pieces of chords still being refined: chord id, chord parameters σ_a < σ_b and the
    joint angles at both ends."""

    chord: IntArray
    sa: FloatArray
    sb: FloatArray
    tha: FloatArray
    thb: FloatArray

    def select(self, mask: BoolArray) -> _Pieces:
        """The pieces where ``mask`` is true."""
        return _Pieces(self.chord[mask], self.sa[mask], self.sb[mask], self.tha[mask],
                       self.thb[mask])


@dataclass(frozen=True)
class _Samples:
    """One refinement round's samples (`SAMPLES` per piece) on the joint-space path: joint
    angles (N·S, 2), pen points (N·S, 2), the pose codes (N, S) with `FK_INVALID` where the
    forward kinematics fail, margins (N·S, 3), the deviation from the piece (N,) and the
    chord direction pb − pa (N, 2)."""

    th: FloatArray
    g: FloatArray
    codes: NDArray[np.int8]
    marg: FloatArray
    dev: FloatArray
    d: FloatArray


def refine(checker: PoseChecker, pa: FloatArray, pb: FloatArray, tha: FloatArray,
           thb: FloatArray, tol_mm: FloatArray, max_step_rad: float,
           check_type1: bool = True) -> Intervals:
    """Split chords pa[k] → pb[k] (targets with checked angles tha, thb) until the pen's
    joint-interpolated path stays within `SAFETY`·tol_mm[k] of each piece, the joint step is
    ≤ max_step_rad, and every sample passes the pose checks. Vectorised over all pieces; the
    only Python loop is over refinement rounds. Raises `CheckFailedError` (index = chord k)."""
    cur = _presplit(checker, pa, pb, tha, thb, max_step_rad)
    done: list[tuple[IntArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                     FloatArray]] = []
    ns = SAMPLES.shape[0]
    for _ in range(MAX_ROUNDS):
        if cur.chord.shape[0] == 0:
            break
        n = cur.chord.shape[0]
        smp = _sample(checker, pa, pb, cur, check_type1)
        bad_pose = (smp.codes != OK).any(axis=1)
        split = (smp.dev > SAFETY * tol_mm[cur.chord]) | bad_pose | \
            (np.abs(cur.thb - cur.tha).max(axis=1) > max_step_rad)
        keep = ~split
        if keep.any():
            mm = smp.marg.reshape(n, ns, 3)[keep].min(axis=1)
            done.append((cur.chord[keep], cur.sa[keep], cur.sb[keep], cur.tha[keep],
                         cur.thb[keep], mm, smp.dev[keep]))
        if not split.any():
            break
        _refuse_tiny(checker, cur, smp, split)
        cur = _bisect(checker, pa, pb, cur.select(split))
    else:
        raise CheckFailedError(int(cur.chord[0]), (math.nan, math.nan), "tolerance",
                               "the tolerance could not be met within the refinement limit")
    return _collect(done)


def _presplit(checker: PoseChecker, pa: FloatArray, pb: FloatArray, tha: FloatArray,
              thb: FloatArray, max_step_rad: float) -> _Pieces:
    """The chords pre-split by the joint-step cap using the end angles (uniform in σ), with
    checked angles at the new inner targets."""
    nch = pa.shape[0]
    chord = np.arange(nch, dtype=np.int64)
    n0 = np.maximum(1, np.ceil(np.abs(thb - tha).max(axis=1) / max_step_rad)).astype(np.int64)
    if not (n0 > 1).any():
        return _Pieces(chord, np.zeros(nch), np.ones(nch), tha.copy(), thb.copy())
    chord = np.repeat(chord, n0)
    k = np.arange(chord.shape[0]) - np.repeat(np.cumsum(n0) - n0, n0)
    nn = n0[chord]
    sa = k / nn
    sb = (k + 1) / nn
    inner = k > 0
    pts = pa[chord[inner]] + sa[inner, None] * (pb[chord[inner]] - pa[chord[inner]])
    th_inner = checker.inverse(pts, chord[inner])
    tha_all = tha[chord].copy()
    tha_all[inner] = th_inner
    thb_all = np.empty_like(tha_all)
    thb_all[:-1] = tha_all[1:]
    last = np.append(chord[1:] != chord[:-1], True)
    thb_all[last] = thb[chord[last]]
    return _Pieces(chord, sa, sb, tha_all, thb_all)


def _sample(checker: PoseChecker, pa: FloatArray, pb: FloatArray, cur: _Pieces,
            check_type1: bool) -> _Samples:
    """Sample every piece's joint-space path: the pen's distance to the piece [qa, qb]
    (inf where the forward kinematics fail) and the pose checks."""
    s = SAMPLES
    ns = s.shape[0]
    n = cur.chord.shape[0]
    d = pb[cur.chord] - pa[cur.chord]
    qa = pa[cur.chord] + cur.sa[:, None] * d
    qb = pa[cur.chord] + cur.sb[:, None] * d
    dth = cur.thb - cur.tha
    th_s = (cur.tha[:, None, :] + s[None, :, None] * dth[:, None, :]).reshape(-1, 2)
    g, valid = checker.forward(th_s)
    # distance of each sample to the piece [qa, qb]
    seg = qb - qa
    seg_len2 = np.einsum("ij,ij->i", seg, seg)
    rel = g.reshape(n, ns, 2) - qa[:, None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.clip(np.einsum("nsj,nj->ns", rel, seg) / seg_len2[:, None], 0.0, 1.0)
    u = np.nan_to_num(u)
    diff = rel - u[:, :, None] * seg[:, None, :]
    dev = np.sqrt(np.einsum("nsj,nsj->ns", diff, diff)).max(axis=1)
    codes, marg = checker.codes(th_s, g, check_type1)
    codes = codes.reshape(n, ns)
    codes[~valid.reshape(n, ns)] = FK_INVALID
    dev[~valid.reshape(n, ns).all(axis=1)] = np.inf
    return _Samples(th_s, g, codes, marg, dev, d)


def _refuse_tiny(checker: PoseChecker, cur: _Pieces, smp: _Samples, split: BoolArray) -> None:
    """`CheckFailedError` for the first piece to split that is already shorter than 1e-7 mm:
    its first failing pose check, or the tolerance that cannot be kept."""
    n, ns = smp.codes.shape
    length = (cur.sb[split] - cur.sa[split]) * np.sqrt(
        np.einsum("ij,ij->i", smp.d[split], smp.d[split]))
    tiny = length < 1e-7
    if not tiny.any():
        return
    i = int(np.flatnonzero(tiny)[0])
    row = int(np.flatnonzero(split)[i])
    code_row = smp.codes[row]
    bad = int(np.flatnonzero(code_row != OK)[0]) if (code_row != OK).any() else -1
    p = smp.g.reshape(n, ns, 2)[row, max(bad, 1)]
    if bad >= 0 and code_row[bad] != FK_INVALID:
        msg = checker.explain(int(code_row[bad]), smp.th.reshape(n, ns, 2)[row, bad], p,
                              smp.marg.reshape(n, ns, 3)[row, bad])
        key = REASON_KEY[int(code_row[bad])]
    else:
        msg = "the joint-space path between targets cannot be kept within tolerance"
        key = "tolerance"
    raise CheckFailedError(int(cur.chord[split][i]), (float(p[0]), float(p[1])), key,
                           f"between targets: {msg}")


def _bisect(checker: PoseChecker, pa: FloatArray, pb: FloatArray, sp: _Pieces) -> _Pieces:
    """Split pieces at their chord midpoint (new targets by checked inverse kinematics)."""
    c, a0, b0 = sp.chord, sp.sa, sp.sb
    mid = 0.5 * (a0 + b0)
    pm = pa[c] + mid[:, None] * (pb[c] - pa[c])
    thm = checker.inverse(pm, c)
    return _Pieces(np.concatenate((c, c)), np.concatenate((a0, mid)),
                   np.concatenate((mid, b0)), np.concatenate((sp.tha, thm)),
                   np.concatenate((thm, sp.thb)))


def _collect(done: list[tuple[IntArray, FloatArray, FloatArray, FloatArray, FloatArray,
                              FloatArray, FloatArray]]) -> Intervals:
    """The kept pieces of every round, ordered by chord and σ_a."""
    if not done:
        z = np.zeros((0, 2))
        return Intervals(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), z, z,
                         np.zeros((0, 3)), np.zeros(0))
    cat = [np.concatenate([d[i] for d in done]) for i in range(7)]
    order = np.lexsort((cat[1], cat[0]))
    return Intervals(cat[0].astype(np.int64)[order], cat[1][order], cat[2][order],
                     cat[3][order], cat[4][order], cat[5][order], cat[6][order])


def joint_moves(checker: PoseChecker, tha: FloatArray, thb: FloatArray, max_step_rad: float,
                check_type1: FloatArray | bool = True,
                sample_rad: float = math.radians(0.5)) -> tuple[IntArray, BoolArray, IntArray,
                                                                 FloatArray]:
    """Pen-up moves straight in joint space from tha[k] to thb[k].

    Every move is sampled at ≤ `sample_rad` of joint motion and each sample is checked
    (forward kinematics valid, joint limits, type-2 margin and assembly, and the type-1
    margins where `check_type1`). Returns (pieces per move (K,), ok per move (K,), for failed
    moves the first failing code, and for all moves the smallest signed margins (K, 3))."""
    k = tha.shape[0]
    dth = thb - tha
    span = np.abs(dth).max(axis=1)
    ns = np.maximum(2, np.ceil(span / sample_rad).astype(np.int64) + 1)
    move = np.repeat(np.arange(k), ns)
    j = np.arange(move.shape[0]) - np.repeat(np.cumsum(ns) - ns, ns)
    s = j / (ns[move] - 1)
    th = tha[move] + s[:, None] * dth[move]
    g, valid = checker.forward(th)
    t1 = np.broadcast_to(np.asarray(check_type1, dtype=bool), (k,))
    codes, marg = checker.codes(th, g, True)
    skip1 = ~t1[move] & np.isin(codes, (T1_ARM1, T1_ARM2))
    codes[skip1] = OK
    codes[~valid] = FK_INVALID
    bad = codes != OK
    ok = ~np.bincount(move, weights=bad, minlength=k).astype(bool)
    first_code = np.zeros(k, dtype=np.int64)
    if bad.any():
        idx = np.flatnonzero(bad)
        mv = move[idx]
        firsts = np.unique(mv, return_index=True)[1]
        first_code[mv[firsts]] = codes[idx[firsts]]
    big = np.full((k, 3), np.inf)
    np.minimum.at(big, move, np.where(valid[:, None], marg, np.inf))
    pieces = np.maximum(1, np.ceil(span / max_step_rad)).astype(np.int64)
    return pieces, ok, first_code, big
