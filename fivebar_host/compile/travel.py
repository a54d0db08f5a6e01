"""Pen-up travel: the moves from the homed pose into the first path, between paths, and back
home (travel j goes into path j; j = P is the park move).

Each travel is first tried as a straight joint-space move (`toolpath.segment.joint_moves`,
checked sample by sample; the moves from and to the homed pose may cross a type-1
singularity). An inter-path travel that fails runs as a straight Cartesian line instead
(refined like a chord, within `TRAVEL_TOL_MM` or the tolerance); a failing move from or to
home is refused, unless `--mode auto` can plan it like a working-mode change
(`kinematics.modes.plan_joint_move`). Working-mode changes (thesis Sec. 7.2) run their
planned joint paths as targets (`modes.transition_targets`), checked again here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile.model import MAX_STEP_RAD
from fivebar_host.compile.modes import transition_targets
from fivebar_host.compile.place import Home, Placed, Setup, fail
from fivebar_host.compile.solve import Routed, Solved
from fivebar_host.toolpath.segment import REASON_KEY, CheckFailedError, joint_moves, refine
from kinematics.arrays import BoolArray, FloatArray, IntArray
from kinematics.modes import plan_joint_move

#: Interpolation tolerance for the Cartesian fallback of pen-up travel, mm.
TRAVEL_TOL_MM = 1.0


@dataclass(frozen=True)
class Travel:
    """Per travel j (P+1 rows): joint angles from and to, working mode, whether it is a move
    from or to the homed pose or a working-mode change, its number of uniform joint-space
    pieces (straight moves) and its smallest margins (3,). `targets`: the travels that run
    through given targets (Cartesian fallback, mode change), j → (K, 2) with the last =
    `t_to[j]`. `changes`: the planned joint path of every working-mode change (including
    planned moves from or to home)."""

    t_from: FloatArray
    t_to: FloatArray
    t_mode: NDArray[np.str_]
    is_home_move: BoolArray
    is_change: BoolArray
    pieces: IntArray
    margins: FloatArray
    targets: Mapping[int, FloatArray]
    changes: Mapping[int, FloatArray]
    notes: tuple[str, ...]


def plan_travel(su: Setup, placed: Placed, home: Home, routed: Routed, solved: Solved,
                plan_modes: bool) -> Travel:
    """Checked pen-up travel for every path (see module doc)."""
    ch, npath = routed.ch, routed.npath
    t_from = np.concatenate((home.th, solved.th_v[ch.offsets[1:] - 1]))
    t_to = np.concatenate((solved.th_v[ch.offsets[:-1]], home.th))
    is_home_move = np.zeros(npath + 1, dtype=bool)
    is_home_move[0] = is_home_move[-1] = True
    t_mode = routed.path_mode[np.minimum(np.arange(npath + 1), npath - 1)]
    changes = dict(routed.changes)
    is_change = np.zeros(npath + 1, dtype=bool)
    is_change[list(changes)] = True
    pieces = np.ones(npath + 1, dtype=np.int64)
    ok = np.ones(npath + 1, dtype=bool)
    code = np.zeros(npath + 1, dtype=np.int64)
    tmarg = np.full((npath + 1, 3), np.inf)
    for m, chk in solved.checkers.items():
        js = np.flatnonzero((t_mode == m) & ~is_change)
        if js.size:
            pieces[js], ok[js], code[js], tmarg[js] = joint_moves(
                chk, t_from[js], t_to[js], MAX_STEP_RAD, check_type1=~is_home_move[js])
    if plan_modes:
        # A move from or to the homed pose that fails in a straight line: plan it like a
        # working-mode change (through a type-1 singularity if need be).
        for j in np.flatnonzero(~ok & is_home_move).tolist():
            planned = plan_joint_move(su.fb, t_from[j], t_to[j], su.asm, su.min2, su.limits)
            if planned is not None:
                changes[j] = planned[0]
                is_change[j] = ok[j] = True
    bad = np.flatnonzero(~ok)
    _refuse_home_moves(su, placed, home, solved, bad, is_home_move, t_mode, code, tmarg)
    targets = _cartesian_fallback(su, placed, routed, solved, bad, t_from, t_to, t_mode)
    notes: tuple[str, ...] = ()
    if bad.size:
        notes = (f"{bad.size} pen-up travel(s) run as straight lines (a joint-space move "
                 "would have passed too close to a singularity)",)
    for j, (tg, marg) in _mode_change_targets(su, placed, solved, changes, t_from, t_to,
                                              t_mode).items():
        tmarg[j] = marg
        targets[j] = tg
    return Travel(t_from=t_from, t_to=t_to, t_mode=t_mode, is_home_move=is_home_move,
                  is_change=is_change, pieces=pieces, margins=tmarg, targets=targets,
                  changes=changes, notes=notes)


def _refuse_home_moves(su: Setup, placed: Placed, home: Home, solved: Solved, bad: IntArray,
                       is_home_move: BoolArray, t_mode: NDArray[np.str_], code: IntArray,
                       tmarg: FloatArray) -> None:
    """Raise for the first failing (`bad`) move from or to the homed pose: there is no
    Cartesian fallback for those."""
    npath = is_home_move.shape[0] - 1
    for j in bad.tolist():
        what = ("move from home" if j == 0 else "move to home" if j == npath
                else "travel")
        if is_home_move[j]:
            pt = (math.nan, math.nan)
            home_fail = CheckFailedError(
                0, pt, REASON_KEY.get(int(code[j]), "reach"),
                "the joint-space move between the homed pose and the drawing fails the "
                "checks: " + solved.checkers[str(t_mode[j])].explain(
                    int(code[j]), home.th[0], home.pt, tmarg[j]))
            raise fail(su, placed, home_fail, -1, what, str(t_mode[j]))


def _cartesian_fallback(su: Setup, placed: Placed, routed: Routed, solved: Solved,
                        bad: IntArray, t_from: FloatArray, t_to: FloatArray,
                        t_mode: NDArray[np.str_]) -> dict[int, FloatArray]:
    """The inter-path travels that fail in joint space as straight Cartesian lines, refined
    within `TRAVEL_TOL_MM` (or the tolerance, if larger): travel j → its targets."""
    ch = routed.ch
    p_start = ch.offsets[:-1]
    p_end = ch.offsets[1:] - 1
    targets: dict[int, FloatArray] = {}
    for m, chk in solved.checkers.items():
        bm = bad[t_mode[bad] == m]
        if not bm.size:
            continue
        try:
            civ = refine(chk, ch.pts[p_end[bm - 1]], ch.pts[p_start[bm]], t_from[bm],
                         t_to[bm], np.full(bm.size, max(TRAVEL_TOL_MM, su.tol)), MAX_STEP_RAD)
        except CheckFailedError as cf:
            j = int(bm[cf.index])
            raise fail(su, placed, cf, -1, f"travel to path #{int(ch.path_source[j])}",
                       m) from None
        for n_, j in enumerate(bm.tolist()):
            targets[j] = civ.thb[civ.chord == n_]
    return targets


def _mode_change_targets(su: Setup, placed: Placed, solved: Solved,
                         changes: Mapping[int, FloatArray], t_from: FloatArray,
                         t_to: FloatArray, t_mode: NDArray[np.str_]
                         ) -> dict[int, tuple[FloatArray, FloatArray]]:
    """Working-mode changes: the planned joint paths as targets, checked again here sample by
    sample (joint limits, type-2 margin, assembly; type-1 singularities may be crossed).
    Travel j → (its targets, its smallest margins (3,))."""
    checker = solved.checker
    out: dict[int, tuple[FloatArray, FloatArray]] = {}
    for j, jpath in sorted(changes.items()):
        tg = transition_targets(jpath, t_from[j], t_to[j], MAX_STEP_RAD)
        legs_a = np.concatenate((t_from[j][None], tg[:-1]))
        _, okc, cc, mc = joint_moves(checker, legs_a, tg, MAX_STEP_RAD, check_type1=False)
        if not okc.all():
            k = int(np.flatnonzero(~okc)[0])
            pt = checker.forward(tg[k:k + 1])[0][0]
            change_fail = CheckFailedError(
                0, (float(pt[0]), float(pt[1])), REASON_KEY.get(int(cc[k]), "reach"),
                "the pen-up working-mode change fails the checks: "
                + checker.explain(int(cc[k]), tg[k], pt, mc[k]))
            raise fail(su, placed, change_fail, -1, "working-mode change",
                       str(t_mode[j])) from None
        out[j] = (tg, mc.min(axis=0))
    return out
