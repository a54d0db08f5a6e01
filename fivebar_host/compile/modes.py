"""`--mode auto`'s working-mode planning (thesis Sec. 7.2): when no single working mode clears
every check, each job path gets its own mode and every change becomes a pen-up joint-space
move through a type-1 singularity.

`plan_path_modes` asks `kinematics.modes.plan_working_modes` path by path, breaking paths that
change mode inside (`break_paths`); `transition_targets` turns a planned joint path into
firmware targets; `type1_crossings`, `densify_joint` and `mode_at` measure modes and
crossings; `merge_intervals` puts the chords refined per mode back into job order.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable
from dataclasses import replace
from functools import partial

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile.chords import Chords
from fivebar_host.errors import JobError, Where
from fivebar_host.toolpath.segment import CheckFailedError, Intervals, PoseChecker
from kinematics.arrays import FloatArray, IntArray
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.modes import plan_working_modes
from kinematics.workspace import NoSafeRegionError, point_safety

#: Largest spacing (mm) of the pen points at which `--mode auto` tests the working modes when
#: it plans working-mode changes (every chord is sampled at least this finely).
MODE_SAMPLE_MM = 0.5


def mode_at(fb: FiveBar, angles: FloatArray, point: FloatArray, fallback: str) -> str:
    """Working mode of one pose; `fallback` if an arm sits exactly on a type-1 singularity."""
    s = fb.mode_of(point.reshape(1, 2), angles.reshape(1, 2))[0]
    if (s == 0).any():
        return fallback
    return ("+" if s[0] > 0 else "-") + ("+" if s[1] > 0 else "-")


def merge_intervals(parts: list[Intervals]) -> Intervals:
    """Intervals refined per working mode, merged back into job order (chord, then σ)."""
    if len(parts) == 1:
        return parts[0]
    cat = [np.concatenate([getattr(p, f) for p in parts])
           for f in ("chord", "sa", "sb", "tha", "thb", "min_margin", "dev_mm")]
    o = np.lexsort((cat[1], cat[0]))
    return Intervals(*(c[o] for c in cat))


def transition_targets(path: FloatArray, start: FloatArray, end: FloatArray,
                        max_step_rad: float) -> FloatArray:
    """Targets (K, 2) that execute a planned pen-up joint path (samples of straight legs, as
    `plan_joint_move` returns it) exactly under the firmware's linear interpolation: the
    corners of the path, each leg split into pieces of at most `max_step_rad`. The first and
    last samples are replaced by the job's own poses `start`, `end` (they agree to rounding)."""
    p = np.asarray(path, dtype=np.float64).copy()
    if (np.abs(p[0] - start).max() > 1e-6 or np.abs(p[-1] - end).max() > 1e-6):
        raise JobError("internal: the planned working-mode change does not start and end at "
                       "the job's poses", None, "internal")
    p[0], p[-1] = start, end
    d = np.diff(p, axis=0)
    scale = max(float(np.abs(d).max(initial=0.0)), 1e-12)
    turn = np.flatnonzero(np.abs(np.diff(d, axis=0)).max(axis=1) > 1e-9 * scale) + 1
    way = p[np.concatenate(([0], turn, [p.shape[0] - 1]))]
    out = []
    for q0, q1 in itertools.pairwise(way):
        n = max(1, math.ceil(float(np.abs(q1 - q0).max()) / max_step_rad))
        out.append(q0 + (np.arange(1, n + 1) / n)[:, None] * (q1 - q0))
    return np.concatenate(out)


def type1_crossings(fb: FiveBar, th: FloatArray,
                     pts: FloatArray) -> tuple[tuple[int, str, float, float], ...]:
    """Where an arm's type-1 margin changes sign along sampled poses: (arm, "stretched" or
    "folded", x, y), the pen position interpolated linearly between the samples."""
    mar = fb.singularity_margins(th, pts)
    out: list[tuple[int, str, float, float]] = []
    for arm in (0, 1):
        m = mar[:, arm]
        for k in np.flatnonzero(np.sign(m[:-1]) * np.sign(m[1:]) < 0).tolist():
            t = m[k] / (m[k] - m[k + 1])
            q = pts[k] + t * (pts[k + 1] - pts[k])
            lo, hi = fb.reach[arm]  # the arm's annulus (exact but for arm 2 off the joint)
            d = math.hypot(float(q[0]) - (0.0 if arm == 0 else fb.w), float(q[1]))
            kind = "stretched" if abs(d - hi) < abs(d - lo) else "folded"
            out.append((arm + 1, kind, float(q[0]), float(q[1])))
    return tuple(out)


def break_paths(ch: Chords, brk_chord: IntArray, brk_frac: FloatArray) -> Chords:
    """Start a new job path at each break: chord `brk_chord[k]` at chord parameter
    `brk_frac[k]` ∈ (0, 1] (1: at the chord's end vertex). The break point ends one path and
    starts the next (it appears twice, once in each), an interior break also splits its
    chord in two collinear chords. Geometry is unchanged; every new chord keeps its source
    chord's primitive, budget and direction, with the parameter range cut to its part."""
    o = np.lexsort((brk_frac, brk_chord))
    bc, bf = np.asarray(brk_chord, np.int64)[o], np.asarray(brk_frac, np.float64)[o]
    nb = bc.shape[0]
    a = ch.chord_from
    m_old = ch.pts.shape[0]
    interior = bf < 1.0
    at = np.where(interior[:, None],
                  ch.pts[a[bc]] + bf[:, None] * (ch.pts[a[bc] + 1] - ch.pts[a[bc]]),
                  ch.pts[a[bc] + 1])
    count = np.where(interior, 2, 1)
    rep = np.repeat(np.arange(nb), count)
    copy_k = np.arange(rep.shape[0]) - np.repeat(np.cumsum(count) - count, count)
    start_copy = ~interior[rep] | (copy_k == 1)
    ins_pos = np.where(interior, a[bc] + 1, a[bc] + 2)[rep]
    prim_at = np.where(interior, np.where(ch.prim[bc] >= 0, ch.prim[bc], ch.vert_prim[a[bc]]),
                       ch.vert_prim[a[bc] + 1])
    pts = np.insert(ch.pts, ins_pos, at[rep], axis=0)
    vert_prim = np.insert(ch.vert_prim, ins_pos, prim_at[rep])
    m_new = pts.shape[0]
    old_new = np.arange(m_old) + np.searchsorted(ins_pos, np.arange(m_old), side="right")
    ins_new = ins_pos + np.arange(ins_pos.shape[0])
    is_start = np.zeros(m_new, bool)
    is_start[old_new[ch.offsets[:-1]]] = True
    is_start[ins_new[start_copy]] = True
    is_end = np.zeros(m_new, bool)
    is_end[old_new[ch.offsets[1:] - 1]] = True
    is_end[ins_new[~start_copy]] = True
    is_end[old_new[a[bc[~interior]] + 1]] = True
    offsets = np.concatenate((np.flatnonzero(is_start), [m_new])).astype(np.int64)
    # Per new vertex: the source chord of the chord that starts there and its σ there; per
    # interior end copy: the chord and σ it ends.
    src = np.full(m_new, -1, np.int64)
    f0 = np.zeros(m_new)
    src[old_new[a]] = np.arange(a.shape[0])
    isc = start_copy & interior[rep]
    src[ins_new[isc]] = bc[rep[isc]]
    f0[ins_new[isc]] = bf[rep[isc]]
    vsc = ~interior[rep]
    nxt = np.searchsorted(a, a[bc[rep[vsc]]] + 1)
    src[ins_new[vsc]] = nxt
    end_c = np.full(m_new, -1, np.int64)
    end_f = np.ones(m_new)
    iec = ~start_copy
    end_c[ins_new[iec]] = bc[rep[iec]]
    end_f[ins_new[iec]] = bf[rep[iec]]
    cf = np.flatnonzero(~is_end)
    c = src[cf]
    lo = f0[cf]
    hi = np.where(end_c[cf + 1] == c, end_f[cf + 1], 1.0)
    span = ch.thi[c] - ch.tlo[c]
    rev = ch.rev[c]
    tlo = np.where(rev, ch.thi[c] - hi * span, ch.tlo[c] + lo * span)
    thi = np.where(rev, ch.thi[c] - lo * span, ch.tlo[c] + hi * span)
    old_path_v = np.insert(np.repeat(np.arange(offsets.shape[0] - 1 - nb),
                                     np.diff(ch.offsets)),
                           ins_pos, ch.path_of_chord[bc][rep])
    po = old_path_v[offsets[:-1]]
    return replace(ch, pts=pts, offsets=offsets, vert_prim=vert_prim, chord_from=cf,
                   prim=ch.prim[c], prim_first=ch.prim_first[c], tlo=tlo, thi=thi, rev=rev,
                   tol_i=ch.tol_i[c],
                   path_of_chord=np.searchsorted(offsets, cf, side="right") - 1,
                   path_source=ch.path_source[po], path_reversed=ch.path_reversed[po],
                   power=ch.power[po], feed=ch.feed[po], path_section=ch.path_section[po],
                   dwells=tuple(replace(d, stroke=int(np.flatnonzero(po == d.stroke)[
                       -1 if d.after else 0])) for d in ch.dwells))


def _point_text(points: FloatArray, match: re.Match[str]) -> str:
    """'point (x, y) mm' for a 'point <index>' in a planner message."""
    x, y = points[int(match[1])]
    return f"point ({x:.3f}, {y:.3f}) mm"


def _refuse_unsafe(fb: FiveBar, stroke: FloatArray, asm: str, min1: float, min2: float,
                   limits: tuple[tuple[float, float], tuple[float, float]],
                   where: Callable[[FloatArray], Where]) -> None:
    """Raise if a point of `stroke` is safe in no working mode (then no working-mode change
    can help), with each mode's reason at the first such point."""
    modes = WORKING_MODES
    safe = np.zeros(stroke.shape[0], bool)
    for m in modes:
        safe |= point_safety(fb, m, stroke, min1, min2, limits, assembly=asm)
    if not safe.all():
        k = int(np.flatnonzero(~safe)[0])
        why = []
        for m in modes:
            try:
                PoseChecker(fb, m, 1 if asm == "+" else -1, min1, min2,
                            limits).inverse(stroke[k:k + 1])
            except CheckFailedError as cf:
                why.append(f"{m}: {cf.message}")
        raise JobError("no working mode is safe at this point in assembly "
                       f"{asm}, so no working-mode change can help (" + "; ".join(why)
                       + ")", where(stroke[k]), "no_mode")


def plan_path_modes(ch: Chords, fb: FiveBar, home_th: FloatArray, home_mode: str, asm: str,
                min1: float, min2: float,
                limits: tuple[tuple[float, float], tuple[float, float]],
                where_of: Callable[[int, FloatArray], Where]
                ) -> tuple[Chords, NDArray[np.str_], dict[int, FloatArray]]:
    """Working modes per job path with pen-up changes (`--mode auto` when no single mode
    clears every check): every path, sampled at most `MODE_SAMPLE_MM` apart, goes through
    `kinematics.modes.plan_working_modes` in job order, from the homed pose, in the
    machine's assembly. Paths that change mode inside are broken there (`break_paths`).
    Returns the new chords, the mode of each job path and the planned joint path of each
    mode change by the travel that runs it (travel j goes into path j)."""
    offs = ch.offsets
    npath = offs.shape[0] - 1
    a = ch.chord_from
    d = ch.pts[a + 1] - ch.pts[a]
    n = np.maximum(1, np.ceil(np.hypot(*d.T) / MODE_SAMPLE_MM)).astype(np.int64)
    rep = np.repeat(np.arange(a.shape[0]), n)
    frac = (np.arange(rep.shape[0]) - np.repeat(np.cumsum(n) - n, n) + 1) / n[rep]
    dense = ch.pts[a[rep]] + frac[:, None] * d[rep]
    c_off = np.searchsorted(a, offs)
    s_off = np.concatenate(([0], np.cumsum(n)))[c_off]
    modes = WORKING_MODES
    cur, pose = home_mode, home_th
    brk_c: list[int] = []
    brk_f: list[float] = []
    path_mode: list[str] = []
    changes: dict[int, FloatArray] = {}
    for p in range(npath):
        g0, g1 = int(s_off[p]), int(s_off[p + 1])
        stroke = np.concatenate((ch.pts[offs[p]][None], dense[g0:g1]))
        _refuse_unsafe(fb, stroke, asm, min1, min2, limits, partial(where_of, p))
        try:
            mp = plan_working_modes(fb, [stroke], cur, min1, min2, limits, assembly=asm,
                                    start_angles=pose, modes=modes)
        except NoSafeRegionError as e:
            msg = re.sub(r"stroke 0:? ", "", str(e))
            msg = re.sub(r"point (\d+)", partial(_point_text, stroke), msg)
            raise JobError(f"working-mode change impossible: {msg}", where_of(p, stroke[0]),
                           "no_mode") from None
        for i, pc in enumerate(mp.pieces):
            if pc.stop - pc.start < 2 or (i > 0 and pc.start == 0):
                raise JobError("internal: the working-mode plan has a piece without a "
                               "chord", where_of(p, stroke[pc.start]), "internal")
            if i > 0:
                g = g0 + pc.start - 1
                brk_c.append(int(rep[g]))
                brk_f.append(float(frac[g]))
            if pc.transition is not None:
                changes[len(path_mode)] = pc.transition.joint_path
            path_mode.append(pc.mode)
        last = mp.pieces[-1]
        cur = last.mode
        pose = np.asarray(fb.inverse(stroke[last.stop - 1], cur), dtype=np.float64)
    if brk_c:
        ch = break_paths(ch, np.array(brk_c, np.int64), np.array(brk_f))
    return ch, np.array(path_mode), changes


def densify_joint(q: FloatArray, step_rad: float) -> FloatArray:
    """The firmware's joint-space polyline through targets q (N, 2), sampled at most
    `step_rad` apart (every target included)."""
    d = np.diff(q, axis=0)
    n = np.maximum(1, np.ceil(np.abs(d).max(axis=1) / step_rad)).astype(np.int64)
    rep = np.repeat(np.arange(d.shape[0]), n)
    s = (np.arange(rep.shape[0]) - np.repeat(np.cumsum(n) - n, n)) / n[rep]
    return np.concatenate((q[rep] + s[:, None] * d[rep], q[-1:]))
