"""Timing a stepped job: per-segment laser power, feed and stops, then durations from
`fivebar_host.compile.planner`, in four steps (the reasons are in the planner's module doc):

1. a continuous speed profile (junction passes), which only decides where to cut;
2. its speed-up and slow-down parts cut into short pieces (new targets on the line between
   the segment's stepped ends, so the path does not change), rounded to whole steps once;
3. every piece's own shortest duration (feed, joint speed, the firmware's shortest P);
4. raised to the least durations that meet every limit on the staircase the firmware runs
   (constant rate per G1) — exact, and never longer when a limit is raised.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fivebar_host import protocol
from fivebar_host.compile import linkrate, planner, ramps, staircase, steps
from fivebar_host.compile.dwell import dwell_stops, insert_dwells
from fivebar_host.compile.layers import section_stops
from fivebar_host.compile.model import compact_ints, release_free_memory
from fivebar_host.compile.place import Setup
from fivebar_host.compile.segments import Stepped
from fivebar_host.compile.solve import Routed, Solved
from fivebar_host.config import Motors, Profile
from fivebar_host.toolpath.segment import PoseChecker
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Timing (see `fivebar_host.compile.planner`): the continuous profile that decides the cut plans
#: with this share of the joint acceleration limit (`cut_accel`), with the whole junction
#: jump and without a corner cap — the durations come from the staircase itself (step 4),
#: so the cut needs no reserve: at half the jump (and a corner cap) the profile saw a
#: sawtooth on polygons the staircase runs at full speed (junction caps at J/2δ, a speed-up
#: in between) and cut every chord into pieces (issue 20: 1135 pieces for the 480 segments
#: of the circle job at 200 mm/s).
PLAN_ACCEL_SHARE = 0.75
#: Speed-up and slow-down parts are cut into pieces whose planned speed changes by at most
#: this share of the junction jump from one piece to the next, and of at least this many
#: steps (rounding a shorter piece to whole steps would shake its rate too much). Measured
#: against TOPP-RA (`python benchmarks/topp.py`, planned / optimal on the uncut segments;
#: the three drawings of issue 39, then docs_command_line, voronoi and plotter.svg of
#: benchmarks/drawings): 0.6 and 3 steps gave 0.9999, 1.0008, 1.0188, 1.0462, 1.0134,
#: 1.0284; 0.45 and 2 steps (with `ramps.SHARP_SHARE` 0.6, `SHARP_WAIT_S` 1.65 ms) give
#: 0.9999, 1.0011, 1.0101, 1.0319, 1.0093, 1.0189 — shorter ramp pieces follow the
#: continuous profile more closely, and the sharp junction's piece shrinks to one or two
#: steps. More pieces: 2417 → 2871 segments on bc_template.svg. 1 step, or 3 steps at
#: 0.45: longer on every drawing but the circle; 0.5 instead of 0.45: 1.0095 on
#: bc_template but longer on 6 of 8 other drawings of benchmarks/drawings (the same on 2),
#: 0.4: 1.0114.
PLAN_PIECE_JUMP_SHARE = 0.45
PLAN_MIN_PIECE_STEPS = 2


@dataclass(frozen=True)
class Planned(Stepped):
    """The stepped job after cutting the ramps into pieces, with per segment the laser
    `power` (0–255, 0 on travel), the piece's part [f0, f1] of the segment it was cut from,
    the planned `duration_us`, and whether it is a `dwell` (`compile.dwell`: no motion)."""

    power: NDArray[np.uint8]
    f0: FloatArray
    f1: FloatArray
    duration_us: IntArray
    dwell: BoolArray


def cut_accel(profile: Profile) -> float:
    """Acceleration (rad/s²) of the continuous profile that decides the cut: the share
    `PLAN_ACCEL_SHARE` of the limit, but at most J²/(4·D_min) (J the junction jump, D_min
    the smallest piece, `PLAN_MIN_PIECE_STEPS` steps; 63.7 rad/s² at 12800 steps/rev, above
    the share of the default profile's 60 rad/s²).

    Why a cap (issue 20): `ramp_fractions` cuts a ramp at equal speed steps of
    `PLAN_PIECE_JUMP_SHARE`·J and joins pieces shorter than D_min. Planned steeper, a ramp's
    first pieces are shorter than D_min and are joined, so the segment next to a stop or a
    sharp corner keeps a long first piece that the staircase must run at about J: a larger α
    planned a longer job (a zigzag ×1.65 at 3.4× the acceleration). The staircase durations
    (step 4) use the profile's whole α; only where to cut stops depending on α above the
    cap. The factor 1/4 is measured: it keeps all 440 seeded random jobs and limit pairs of
    tests/test_plan_monotone.py monotone, where 0.35 left one ×1.002 and 1 left ×1.65."""
    d_min_rad = PLAN_MIN_PIECE_STEPS * profile.motors.rad_per_step
    j_lim = profile.motion.junction_jump_rad_s
    return min(PLAN_ACCEL_SHARE * profile.motion.max_joint_rad_s2,
               0.25 * j_lim * j_lim / d_min_rad)


def _settings(profile: Profile, routed: Routed,
              sp: Stepped) -> tuple[NDArray[np.uint8], FloatArray, BoolArray]:
    """Per segment: laser power (the path's fraction × the profile's power, 0 on travel and
    backlash take-ups),
    feed (the path's F, else the profile's draw feed; travel feed on travel), and whether the
    tool stops after it (pen switch or new power)."""
    ch, npath, motion = routed.ch, routed.npath, profile.motion
    seg_draw, seg_path = sp.draw, sp.path
    power_frac = np.where(seg_draw, ch.power[np.minimum(seg_path, npath - 1)], 0.0)
    power = np.where(seg_draw, np.clip(np.rint(power_frac * profile.laser.power), 0, 255),
                     0).astype(np.uint8)
    if sp.slack.shape[0]:  # a backlash take-up stands still: no power, or it burns a dot
        power[(sp.slack[1:] != sp.slack[:-1]).any(axis=1)] = 0
    pfeed = ch.feed[np.minimum(seg_path, npath - 1)]
    feed = np.where(seg_draw, np.where(np.isnan(pfeed), motion.draw_feed_mm_s, pfeed),
                    motion.travel_feed_mm_s)
    stop = np.zeros(seg_draw.shape[0], dtype=bool)
    stop[:-1] = (seg_draw[1:] != seg_draw[:-1]) | (power[1:] != power[:-1])
    return power, feed, stop


def _cut_ramps(mot: Motors, checker: PoseChecker, sp: Stepped, counts: IntArray,
               f1: FloatArray
               ) -> tuple[FloatArray, FloatArray, IntArray, IntArray, FloatArray, FloatArray,
                          IntArray]:
    """Step 2: segment k cut into `counts[k]` pieces ending at fractions `f1` of it. Returns
    the new targets (angles, points, absolute steps; pieces that round to no move dropped),
    per piece its segment and its part [f0, f1] of it, and the slack at every target. The
    targets are written in job order straight away (target k, then the inner piece ends of
    segment k: their fractions ascend), each array once."""
    th_all, pts_all = sp.th, sp.pts
    seg_of = np.repeat(np.arange(counts.shape[0]), counts)
    inner = np.ones(seg_of.shape[0], dtype=bool)  # not a segment's last piece
    inner[np.cumsum(counts) - 1] = False
    # new targets on the line between their segment's stepped ends, rounded once (`_on_steps`)
    ends = _joint_steps(sp.steps, sp.slack)
    th = np.empty((seg_of.shape[0] + 1, 2))
    th[0] = th_all[0]
    th[1:][~inner] = th_all[1:]
    st = np.empty(th.shape, dtype=ends.dtype)
    st[0] = ends[0]
    st[1:][~inner] = ends[1:]
    th[1:][inner], st[1:][inner] = _on_steps(ends, seg_of[inner], f1[inner], mot)
    del ends
    slack = sp.slack
    if slack.shape[0]:  # motor counts = joint steps + slack (compile.backlash)
        slack = _piece_slack(slack, seg_of, np.where(inner, f1, 1.0))
        st = compact_ints(st + slack)
    keep = np.concatenate(([True], (np.diff(st, axis=0) != 0).any(axis=1)))
    every = bool(keep.all())
    if not every:
        st, th = st[keep], th[keep]
        slack = slack[keep] if slack.shape[0] else slack
    kept_inner = inner[keep[1:]]
    pts = np.empty_like(th)
    pts[0] = pts_all[0]
    pts[1:][~kept_inner] = pts_all[1:] if every else pts_all[1:][keep[1:][~inner]]
    rows = np.flatnonzero(kept_inner) + 1  # new targets: pen points by forward kinematics
    for i in range(0, rows.shape[0], DELTA_BLOCK):
        r = rows[i:i + DELTA_BLOCK]
        pts[r] = checker.forward(th[r])[0]
    del rows
    seg_of, f1 = seg_of[keep[1:]], f1[keep[1:]]
    f1[np.concatenate((seg_of[1:] != seg_of[:-1], [True]))] = 1.0
    f0 = np.where(np.concatenate(([True], seg_of[1:] != seg_of[:-1])), 0.0,
                  np.concatenate(([0.0], f1[:-1])))
    return th, pts, st, seg_of, f0, f1, slack


def _joint_steps(st: IntArray, slack: IntArray) -> IntArray:
    """The joints' absolute steps of targets whose motor counts are `st`: the counts less
    the backlash slack (`compile.backlash`; none when `slack` is empty)."""
    return st if not slack.shape[0] else compact_ints(st - slack)


def _on_steps(ends: IntArray, seg: IntArray, frac: FloatArray,
              mot: Motors) -> tuple[FloatArray, IntArray]:
    """Inner piece ends at fractions `frac` of their segments `seg`, on the straight line
    between the segment's ends in steps (`ends`, the absolute steps of every segment's
    targets) — the line the firmware's DDA runs for the whole segment — as joint angles
    (rad, on that line) and as steps (rounded once). Cut on the ideal joint line instead, a
    piece's steps were rounded from a line up to half a step beside the stepped one: a
    one-step piece came out as (−2, 1) or (0, −2) on segments of (−70, 22) or (3, −4) steps,
    a direction its neighbours do not have, so the junction jump held the pieces around it
    back (`python benchmarks/topp.py`, planned / TOPP-RA on the uncut segments, with
    `_reached_lengths`: benchmarks/drawings/bc_template.svg 1.0101 → 0.9993,
    examples/fivebar_text.svg 1.0011 → 0.9981, shorter on all 18 drawings it measures)."""
    s0 = ends[seg]
    at = s0 + frac[:, None] * (ends[seg + 1] - s0)  # fractional steps on the stepped line
    return steps.step_angles(at, mot.home_rad, mot.steps_per_rev), np.rint(at).astype(ends.dtype)


def _reached_lengths(st: IntArray, rows: IntArray, checker: PoseChecker,
                     mot: Motors) -> FloatArray:
    """The pen's straight distance (mm) over the pieces `rows` between the positions their
    joint steps `st` (the motors' less any backlash slack) really reach — a travel piece's
    length, which its feed limits. (From the targets' unrounded points instead, a piece of
    one or two steps came out up to half a step per end too long or too short: its feed
    bound it too early, or let it run fast.)"""
    at = np.unique(np.concatenate((rows, rows + 1)))
    pts = np.empty((at.shape[0], 2))
    for i in range(0, at.shape[0], DELTA_BLOCK):
        r = at[i:i + DELTA_BLOCK]
        pts[i:i + DELTA_BLOCK] = checker.forward(
            steps.step_angles(st[r], mot.home_rad, mot.steps_per_rev))[0]
    d = pts[np.searchsorted(at, rows + 1)] - pts[np.searchsorted(at, rows)]
    return np.hypot(d[:, 0], d[:, 1])


def _piece_slack(slack: IntArray, seg_of: IntArray, frac: FloatArray) -> IntArray:
    """The slack (compile.backlash) at every piece's end: constant along a segment but a
    take-up, whose slack changes in whole steps along its pieces (its joint stands still)."""
    s0, s1 = slack[seg_of], slack[seg_of + 1]
    out = np.empty((seg_of.shape[0] + 1, 2), dtype=np.int64)
    out[0] = slack[0]
    out[1:] = s0 + np.rint(frac[:, None] * (s1 - s0)).astype(np.int64)
    return out


#: Targets converted at a time by `_step_deltas`.
DELTA_BLOCK = 1 << 16


def _step_deltas(st: IntArray, mot: Motors) -> FloatArray:
    """The joint moves (T, 2) rad between consecutive absolute steps (T+1, 2), as the
    differences of `steps.step_angles`, in blocks (no whole-job float copy of the steps)."""
    dq = np.empty((max(st.shape[0] - 1, 0), 2))
    for i in range(0, dq.shape[0], DELTA_BLOCK):
        th = steps.step_angles(st[i:i + DELTA_BLOCK + 1], mot.home_rad, mot.steps_per_rev)
        dq[i:i + DELTA_BLOCK] = np.diff(th, axis=0)
    return dq


def plan_timing(su: Setup, routed: Routed, solved: Solved, handed: list[Stepped]) -> Planned:
    """Durations for every segment (module doc: steps 1–4), then the dwells inserted as
    segments without motion, each after a stop (`compile.dwell`). `handed` holds the
    stepped job and is emptied: once the ramps are cut, nothing else keeps its arrays, so
    they are freed while the pieces are timed (memory on large drawings)."""
    sp = handed.pop()
    power, feed, stop = _settings(su.profile, routed, sp)
    dwells = routed.ch.dwells
    if dwells:
        stop = stop | dwell_stops(dwells, sp)
    if routed.sections is not None:  # at rest where a pen-change stop may come
        stop = stop | section_stops(routed.ch.path_section, sp.path)
    box = [sp]
    del sp
    per_seg = [power, feed, stop]  # `_time` drops them once the pieces have theirs
    del power, feed, stop
    pd = _time(su.profile, solved.checker, box, per_seg, trim=True)
    return insert_dwells(dwells, su.profile, pd)


def time_stepped(profile: Profile, checker: PoseChecker, sp: Stepped,
                 power: NDArray[np.uint8], feed: FloatArray, stop: BoolArray) -> Planned:
    """Steps 1–4 of the module doc on stepped segments with their laser power, pen feed
    (mm/s) and stops given per segment (also used by the GRBL bridge's online compiler,
    `fivebar_host.compile.incremental`, on small batches of moves)."""
    return _time(profile, checker, [sp], [power, feed, stop])


def _time(profile: Profile, checker: PoseChecker, handed: list[Stepped],
          per_seg: list[Any], trim: bool = False) -> Planned:
    """`time_stepped` on the stepped segments in `handed` with the power, feed and stops
    in `per_seg` (both emptied, see `plan_timing`); every array is freed as soon as it was
    last read. `trim`: the heap's free pages are given back on the way (a whole job; not for the
    GRBL bridge's small batches, where the calls would only cost time)."""
    sp = handed.pop()
    power, feed, stop = per_seg
    per_seg.clear()
    mot, motion = profile.motors, profile.motion
    a_c = cut_accel(profile)
    j_lim = profile.motion.junction_jump_rad_s
    prof_kw = {"junction_jump_rad_s": j_lim, "min_duration_s": protocol.P_MIN_US * 1e-6}
    dq = _step_deltas(sp.steps, mot)
    pln = planner.plan(dq, sp.length, feed, motion.max_joint_rad_s, a_c, stop_after=stop,
                       **prof_kw)
    dist = np.maximum(np.abs(dq[:, 0]), np.abs(dq[:, 1]))  # Chebyshev joint distance
    sharp = ramps.sharp_junctions(dq, pln, j_lim, stop)
    del dq
    counts, f1 = ramps.ramp_fractions(pln, dist, a_c, PLAN_PIECE_JUMP_SHARE * j_lim / a_c,
                                        PLAN_MIN_PIECE_STEPS * mot.rad_per_step, sharp,
                                        ramps.SHARP_WAIT_S)
    del sharp
    del pln, dist
    th_all, pts_all, st, seg_of, f0, f1, slack = _cut_ramps(mot, checker, sp, counts, f1)
    del counts
    seg_of = compact_ints(seg_of)
    seg_draw = sp.draw[seg_of]
    length = sp.length[seg_of] * (f1 - f0)  # drawing: the piece's part of its segment
    kept = {"path": compact_ints(sp.path[seg_of]), "source": compact_ints(sp.source[seg_of]),
            "line": compact_ints(sp.line[seg_of]), "perm": sp.perm[seg_of]}
    del sp  # the pieces have all they need of the stepped segments
    power, feed = power[seg_of], feed[seg_of]
    stop = stop[seg_of] & np.concatenate((seg_of[1:] != seg_of[:-1], [True]))
    del seg_of
    trav = np.flatnonzero(~seg_draw)  # travel: between its targets
    length[trav] = _reached_lengths(_joint_steps(st, slack), trav, checker, mot)
    del trav
    if trim:
        release_free_memory()  # the stepped segments' arrays
    dq = _step_deltas(st, mot)
    # the pieces' feeds and the floor durations are held by no name, so each is freed as
    # soon as it was read (the feeds once the floors exist, the floors once the staircase
    # copied them)
    feeds = [feed]
    del feed
    floor_us = [planner.cap_durations_us(dq, length, feeds.pop(), motion.max_joint_rad_s,
                                         protocol.P_MIN_US)]
    if trim:
        release_free_memory()  # the per-segment settings' and the floors' inputs' holes
    duration_us = compact_ints(_link_bound_staircase(profile, (dq, length), floor_us, stop, st,
                                                      power))
    del dq, stop
    return Planned(th=th_all, pts=pts_all, draw=seg_draw, length=length, steps=st,
                   power=power, f0=f0, f1=f1, duration_us=duration_us,
                   dwell=np.zeros(seg_draw.shape[0], dtype=bool), slack=slack, **kept)


def _link_bound_staircase(profile: Profile, path: tuple[FloatArray, FloatArray],
                          handed: list[IntArray], stop: BoolArray, st: IntArray,
                          power: NDArray[np.uint8]) -> IntArray:
    """Step 4 with the link's floor (`compile.linkrate`) on the floors in `handed` (emptied:
    the staircase frees them): the staircase on the floors raised to what the wire carries,
    again while a segment of its result is shorter than the floor its own durations give
    (an item that needs a `P` costs more bytes). A later pass starts from the durations
    before it, raised where short: the least durations above those floors are the least
    above the raised floors (every pass's result is at least the one before), and the
    staircase is only measured again near the raised segments (`staircase.raise_staircase`:
    a few hundred of a large job's, where a whole staircase took some 70 ms a pass on
    100k segments). `path`: the pieces' joint moves (rad) and pen path lengths (mm)."""
    dq, length = path
    j_lim = profile.motion.junction_jump_rad_s
    acc = profile.motion.max_joint_rad_s2
    floor = handed.pop()
    linkrate.raise_to_link(floor, st, power, profile)
    duration_us = staircase.enforce_staircase(dq, floor, stop, acc, j_lim, length_mm=length)
    for _ in range(linkrate.LINK_PASSES - 1):
        need = linkrate.link_floor_us(st, power, duration_us, profile)
        short = np.flatnonzero(duration_us < need)
        if not short.size:
            break
        duration_us[short] = floor[short] = need[short]
        del need
        staircase.raise_staircase(dq, duration_us, short, stop, acc, j_lim, length_mm=length,
                                  floor_us=floor)
    return duration_us


def tool_time_s(draw: BoolArray, profile: Profile, extra_switches: int = 0) -> float:
    """Time the arms wait for the pen, s: every run of segments with the tool on (`draw`:
    drawing segments and dwells with the pen down, `Job.tool_on`) is bracketed by a pen
    down and a pen up (compile.emit), each a servo move plus its settle delay, during which
    the firmware issues no step (docs/protocol.md 6.2). 0 without a pen."""
    pen = profile.pen
    if pen is None or not draw.size:
        return 0.0
    runs = int(draw[0]) + int((draw[1:] & ~draw[:-1]).sum()) + extra_switches
    return runs * (pen.time_s(True) + pen.time_s(False))
