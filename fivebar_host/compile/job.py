"""Compiling a drawing file into a checked, timed, quantised `Job`.

`compile_job(path, profile, options)` runs the whole pipeline:

    read (SVG / G-code) → place (layout) → flatten curves (tol_f = tol/2) → order and join
    paths → [--mode auto when no single mode clears every check: working mode per path,
    `_plan_modes`] → inverse kinematics + checks on every vertex → refine chords in joint
    space (interpolation budget tol_i, `toolpath.segment`) → pen-up travel (checked
    joint-space moves, Cartesian fallback; planned pen-up moves for working-mode changes) →
    absolute steps (quantised once) → plan durations (`planner`: speed-up and slow-down cut
    into pieces on the same joint-space lines, the firmware's rate staircase within the joint
    acceleration and junction-jump limits at every boundary) → validate: forward kinematics
    of the *quantised* steps, including the joint-space interpolation between them, against
    the requested curves.

Tolerance budget (one `tol`, default from the profile): a curve is flattened so every chord is
within tol_f = tol/2 of it; each chord is refined so the joint-interpolated pen path stays
within tol_i of the chord: tol_i = tol − tol_f for chords of curves, tol for straight input
lines (nothing was flattened), tol − gap/2 for the short pen-down bridge that joins two paths
whose ends are closer than tol. By the triangle inequality every pen point is within tol of
the requested path; rounding to whole steps adds at most one step quantum (reported).

The data model is in `fivebar_host.compile.model`; validation in `.validate`, the firmware
lines in `.encode`, `--mode auto`'s working-mode planning in `.modes`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from fivebar_host import planner, protocol, steps
from fivebar_host.compile.chords import _prepare_chords
from fivebar_host.compile.model import (
    AUTO_ORDER,
    MAX_STEP_RAD,
    CompileOptions,
    FloatArray,
    Job,
    ModeChange,
    PathStats,
)
from fivebar_host.compile.modes import (
    _densify_joint,
    _merge_intervals,
    _mode_at,
    _plan_modes,
    _transition_targets,
    _type1_crossings,
)
from fivebar_host.compile.validate import validate
from fivebar_host.config import Profile
from fivebar_host.errors import InputError, JobError, Where
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.geometry import Drawing, flatten
from fivebar_host.toolpath.segment import (
    REASON_KEY,
    CheckFailedError,
    Intervals,
    PoseChecker,
    joint_moves,
    refine,
    wrap_to_limits,
)
from fivebar_host.toolpath.svg import read_svg
from kinematics.analysis import plan_joint_move
from kinematics.fivebar import WORKING_MODES

#: Timing (see `fivebar_host.planner`): the continuous profile plans with this share of the
#: joint acceleration limit and of the junction jump for direction changes; the rest (and a
#: corner cap from the remaining acceleration) absorbs the staircase the firmware runs.
PLAN_ACCEL_SHARE = 0.75
PLAN_JUMP_SHARE = 0.5
#: Speed-up and slow-down parts are cut into pieces whose planned speed changes by at most
#: this share of the junction jump from one piece to the next, and of at least this many
#: steps (rounding a shorter piece to whole steps would shake its rate too much).
PLAN_PIECE_JUMP_SHARE = 0.6
PLAN_MIN_PIECE_STEPS = 3
#: Interpolation tolerance for the Cartesian fallback of pen-up travel, mm.
TRAVEL_TOL_MM = 1.0
GCODE_SUFFIXES = {".gcode", ".nc", ".ngc", ".gc", ".g", ".tap", ".cnc"}


def read_drawing(path: str | Path, layers: tuple[str, ...] = ()) -> Drawing:
    """Read an SVG or G-code file, chosen by suffix (or by content when unknown)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".svg":
        return read_svg(p, layers or None)
    if suffix in GCODE_SUFFIXES:
        if layers:
            raise InputError("--layer applies to SVG files only", str(p))
        return read_gcode(p)
    try:
        head = p.read_bytes()[:512].lstrip()
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror or e}", str(p)) from e
    if head.startswith((b"<?xml", b"<svg", b"<!--", b"<!DOCTYPE")):
        return read_svg(p, layers or None)
    return read_gcode(p)


def _where(job_file: str, drawing: Drawing, pl: layout.Placement, point: tuple[float, float],
           prim: int, what: str = "path") -> Where:
    """Where for a failing point on primitive `prim` (−1: unknown)."""
    pm = np.array(point, dtype=np.float64)
    dxy: tuple[float, float] | None = None
    mxy: tuple[float, float] | None = None
    if np.all(np.isfinite(pm)):
        d = drawing.to_file_frame(pl.to_drawing(pm.reshape(1, 2)))[0]
        dxy = (float(d[0]), float(d[1]))
        mxy = (float(pm[0]), float(pm[1]))
    if prim < 0:
        return Where(file=job_file, drawing_xy=dxy, machine_xy=mxy, what=what)
    src = drawing.sources[int(drawing.stroke_source[drawing.stroke[prim]])]
    return Where(file=job_file, path_index=src.index, path_id=src.ident,
                 source_line=int(drawing.line[prim]) or src.line, drawing_xy=dxy,
                 machine_xy=mxy, what=what)


def _compile_mode(drawing: Drawing, profile: Profile, opts: CompileOptions,
                  mode: str, plan_modes: bool = False) -> Job:
    """Compile `drawing`, placed for working mode `mode`. Without `plan_modes` every path is
    drawn in `mode`. With it (`--mode auto` when no single mode clears every check), the
    modes come from `_plan_modes` and every change of mode becomes a checked pen-up
    joint-space move (`ModeChange`)."""
    fb = profile.geometry
    kin = profile.kinematics
    mot = profile.motors
    motion = profile.motion
    tol = float(opts.tolerance_mm if opts.tolerance_mm is not None else motion.tolerance_mm)
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tolerance must be a positive number of mm; got {tol!r}")
    tol_f = tol / 2.0
    min1, min2, limits = kin.min_type1_margin_rad, kin.min_type2_margin_rad, mot.limits_rad
    file = drawing.file
    asm = kin.assembly
    pl = layout.place(drawing, fb, mode, min1, min2, limits, origin_mm=opts.origin_mm,
                      scale=opts.scale, rotate_deg=opts.rotate_deg, fit=opts.fit,
                      assembly=asm)
    mdraw = drawing.transformed(pl.matrix, pl.offset)
    poly = flatten(mdraw, tol_f)

    def fail(cf: CheckFailedError, prim: int, what: str = "path",
             in_mode: str | None = None) -> JobError:
        m = in_mode or mode
        w = _where(file, drawing, pl, cf.point, prim, what)
        msg = f"{cf.message} (working mode {m})"
        if cf.reason in ("reach", "joint_limit", "type1_margin", "type2_margin", "assembly"):
            msg += "; " + layout.does_not_fit_hint(pl, fb, m, min1, min2, limits, asm)
        return JobError(msg, w, cf.reason)

    # Assembly: the machine's, from the profile (every pose must have it; the checker
    # refuses a point that is only reachable in the other one).
    assembly = 1 if asm == "+" else -1
    home = np.array(mot.home_rad, dtype=np.float64).reshape(1, 2)
    home_fk = fb.forward_batch(home, asm)
    if not home_fk.valid[0]:  # pragma: no cover - the profile parser checks the homed pose
        raise JobError(f"the homed pose {np.degrees(home[0]).round(3).tolist()}° has no pen "
                       f"position in assembly {asm}", Where(file=file, what="move from home"),
                       "assembly")
    home_pt = home_fk.points[0]
    home_mode = _mode_at(fb, home[0], home_pt,
                         kin.working_mode if kin.working_mode != "auto" else AUTO_ORDER[0])

    ch = _prepare_chords(drawing, poly, tol, tol_f, home_pt, opts.keep_order)
    changes: dict[int, FloatArray] = {}
    if plan_modes:
        def where_of(p: int, point: FloatArray) -> Where:
            return _where(file, drawing, pl, (float(point[0]), float(point[1])),
                          int(ch.vert_prim[ch.offsets[p]]))

        ch, path_mode, changes = _plan_modes(ch, fb, home[0], home_mode, asm, min1, min2,
                                             limits, where_of)
    else:
        path_mode = np.full(ch.offsets.shape[0] - 1, mode)
    npath = ch.offsets.shape[0] - 1
    checkers = {m: PoseChecker(fb, m, assembly, min1, min2, limits)
                for m in dict.fromkeys(path_mode.tolist())}
    checker = next(iter(checkers.values()))  # forward kinematics (the same in every mode)
    # Checked inverse kinematics of every vertex, in its path's working mode.
    vert_mode = np.repeat(path_mode, np.diff(ch.offsets))
    th_v = np.empty_like(ch.pts)
    for m, chk in checkers.items():
        idx = np.flatnonzero(vert_mode == m)
        try:
            th_v[idx] = chk.inverse(ch.pts[idx], idx)
        except CheckFailedError as cf:
            raise fail(cf, int(ch.vert_prim[cf.index]), in_mode=m) from None
    a = ch.chord_from
    chord_mode = path_mode[ch.path_of_chord]
    parts: list[Intervals] = []
    for m, chk in checkers.items():
        cs = np.flatnonzero(chord_mode == m)
        try:
            r = refine(chk, ch.pts[a[cs]], ch.pts[a[cs] + 1], th_v[a[cs]], th_v[a[cs] + 1],
                       ch.tol_i[cs], MAX_STEP_RAD)
        except CheckFailedError as cf:
            c = int(cs[cf.index])
            raise fail(cf, int(ch.prim[c]) if ch.prim[c] >= 0
                       else int(ch.vert_prim[a[c]]), in_mode=m) from None
        parts.append(r if len(checkers) == 1 else replace(r, chord=cs[r.chord]))
    iv = _merge_intervals(parts)

    # ------------------------------------------------------------ travel
    p_start = ch.offsets[:-1]
    p_end = ch.offsets[1:] - 1
    t_from = np.concatenate((home, th_v[p_end]))  # travel j goes into path j (j = P: park)
    t_to = np.concatenate((th_v[p_start], home))
    is_home_move = np.zeros(npath + 1, dtype=bool)
    is_home_move[0] = is_home_move[-1] = True
    t_mode = path_mode[np.minimum(np.arange(npath + 1), npath - 1)]
    is_change = np.zeros(npath + 1, dtype=bool)
    is_change[list(changes)] = True
    pieces = np.ones(npath + 1, dtype=np.int64)
    ok = np.ones(npath + 1, dtype=bool)
    code = np.zeros(npath + 1, dtype=np.int64)
    tmarg = np.full((npath + 1, 3), np.inf)
    for m, chk in checkers.items():
        js = np.flatnonzero((t_mode == m) & ~is_change)
        if js.size:
            pieces[js], ok[js], code[js], tmarg[js] = joint_moves(
                chk, t_from[js], t_to[js], MAX_STEP_RAD, check_type1=~is_home_move[js])
    if plan_modes:
        # A move from or to the homed pose that fails in a straight line: plan it like a
        # working-mode change (through a type-1 singularity if need be).
        for j in np.flatnonzero(~ok & is_home_move).tolist():
            planned = plan_joint_move(fb, t_from[j], t_to[j], asm, min2, limits)
            if planned is not None:
                changes[j] = planned[0]
                is_change[j] = ok[j] = True
    notes: list[str] = []
    travel_targets: dict[int, FloatArray] = {}  # travel j → its targets (K, 2), last = t_to[j]
    bad = np.flatnonzero(~ok)
    for j in bad.tolist():
        what = ("move from home" if j == 0 else "move to home" if j == npath
                else "travel")
        if is_home_move[j]:
            pt = (math.nan, math.nan)
            home_fail = CheckFailedError(
                0, pt, REASON_KEY.get(int(code[j]), "reach"),
                "the joint-space move between the homed pose and the drawing fails the "
                "checks: " + checkers[str(t_mode[j])].explain(int(code[j]), home[0], home_pt,
                                                              tmarg[j]))
            raise fail(home_fail, -1, what, str(t_mode[j]))
    for m, chk in checkers.items():
        bm = bad[t_mode[bad] == m]
        if not bm.size:
            continue
        # Cartesian fallback for the inter-path travels that fail in joint space.
        try:
            civ = refine(chk, ch.pts[p_end[bm - 1]], ch.pts[p_start[bm]], t_from[bm],
                         t_to[bm], np.full(bm.size, max(TRAVEL_TOL_MM, tol)), MAX_STEP_RAD)
        except CheckFailedError as cf:
            j = int(bm[cf.index])
            raise fail(cf, -1, f"travel to path #{int(ch.path_source[j])}", m) from None
        for n_, j in enumerate(bm.tolist()):
            travel_targets[j] = civ.thb[civ.chord == n_]
    if bad.size:
        notes.append(f"{bad.size} pen-up travel(s) run as straight lines (a joint-space move "
                     "would have passed too close to a singularity)")
    # Working-mode changes: the planned joint paths, checked again here sample by sample
    # (joint limits, type-2 margin, assembly; type-1 singularities may be crossed).
    for j, jpath in sorted(changes.items()):
        tg = _transition_targets(jpath, t_from[j], t_to[j], MAX_STEP_RAD)
        legs_a = np.concatenate((t_from[j][None], tg[:-1]))
        _, okc, cc, mc = joint_moves(checker, legs_a, tg, MAX_STEP_RAD, check_type1=False)
        if not okc.all():
            k = int(np.flatnonzero(~okc)[0])
            pt = checker.forward(tg[k:k + 1])[0][0]
            change_fail = CheckFailedError(
                0, (float(pt[0]), float(pt[1])), REASON_KEY.get(int(cc[k]), "reach"),
                "the pen-up working-mode change fails the checks: "
                + checker.explain(int(cc[k]), tg[k], pt, mc[k]))
            raise fail(change_fail, -1, "working-mode change", str(t_mode[j])) from None
        tmarg[j] = mc.min(axis=0)
        travel_targets[j] = tg

    # ------------------------------------------------------------ assemble segments
    # Draw segments, in order (intervals are sorted by chord, chords by job order).
    dc = iv.chord
    d_path = ch.path_of_chord[dc]
    d_end_pts = ch.pts[a[dc]] + iv.sb[:, None] * (ch.pts[a[dc] + 1] - ch.pts[a[dc]])
    # Travel pieces: uniform in joint space, or the given targets (Cartesian, mode change).
    t_pieces = pieces.copy()
    for j, tg in travel_targets.items():
        t_pieces[j] = tg.shape[0]
    t_move = np.repeat(np.arange(npath + 1), t_pieces)
    t_k = np.arange(t_move.shape[0]) - np.repeat(np.cumsum(t_pieces) - t_pieces, t_pieces)
    frac = (t_k + 1) / t_pieces[t_move]
    t_th = t_from[t_move] + frac[:, None] * (t_to[t_move] - t_from[t_move])
    for j, tg in travel_targets.items():
        t_th[t_move == j] = tg
    t_pts = checker.forward(t_th)[0]
    # Merge: key (path, part, sequence); travel into path j precedes its draw segments.
    n_d, n_t = dc.shape[0], t_move.shape[0]
    key_path = np.concatenate((d_path, t_move))
    key_part = np.concatenate((np.ones(n_d, np.int64), np.zeros(n_t, np.int64)))
    key_seq = np.concatenate((np.arange(n_d), t_k))
    perm = np.lexsort((key_seq, key_part, key_path))
    seg_draw = np.concatenate((np.ones(n_d, bool), np.zeros(n_t, bool)))[perm]
    end_th = np.concatenate((iv.thb, t_th))[perm]
    end_pts = np.concatenate((d_end_pts, t_pts))[perm]
    seg_path = key_path[perm]
    th_all = np.concatenate((home, end_th))
    pts_all = np.concatenate((home_pt[None], end_pts))
    # Per-segment provenance (draw only; −1 / 0 on travel).
    d_prim = ch.prim[dc]
    d_vprim = np.where(d_prim >= 0, d_prim, ch.vert_prim[a[dc]])
    d_src = drawing.stroke_source[drawing.stroke[d_vprim]]
    d_line = drawing.line[d_vprim]
    seg_source = np.concatenate((d_src, np.full(n_t, -1)))[perm]
    seg_line = np.concatenate((d_line, np.zeros(n_t, np.int64)))[perm]
    length = np.concatenate((
        (iv.sb - iv.sa) * np.hypot(*(ch.pts[a[dc] + 1] - ch.pts[a[dc]]).T),
        np.zeros(n_t)))[perm]
    # Travel length: distance between consecutive target points.
    tl = np.hypot(*np.diff(pts_all, axis=0).T)
    length = np.where(seg_draw, length, tl)

    # ------------------------------------------------------------ steps
    st = steps.absolute_steps(th_all, mot.home_rad, mot.steps_per_rev)
    rel = np.diff(st, axis=0)
    moving = (rel != 0).any(axis=1)
    keep_t = np.concatenate(([True], moving))
    st = st[keep_t]
    th_all = th_all[keep_t]
    pts_all = pts_all[keep_t]
    seg_draw, seg_path = seg_draw[moving], seg_path[moving]
    seg_source, seg_line, length = seg_source[moving], seg_line[moving], length[moving]
    perm_kept = perm[moving]

    # ------------------------------------------------------------ plan
    power_frac = np.where(seg_draw, ch.power[np.minimum(seg_path, npath - 1)], 0.0)
    power = np.where(seg_draw, np.clip(np.rint(power_frac * profile.laser.power), 0, 255),
                     0).astype(np.uint8)
    pfeed = ch.feed[np.minimum(seg_path, npath - 1)]
    feed = np.where(seg_draw, np.where(np.isnan(pfeed), motion.draw_feed_mm_s, pfeed),
                    motion.travel_feed_mm_s)
    stop = np.zeros(seg_draw.shape[0], dtype=bool)
    stop[:-1] = (seg_draw[1:] != seg_draw[:-1]) | (power[1:] != power[:-1])
    # 1. A continuous speed profile (junction passes) with part of the limits; 2. its
    # speed-up and slow-down parts cut into short pieces (new targets on the same joint-space
    # lines, so the path does not change); 3. the profile again on the pieces; 4. every
    # boundary of the staircase the firmware runs (constant rate per G1) made exact.
    a_c = PLAN_ACCEL_SHARE * motion.max_joint_rad_s2
    j_lim = planner.JUNCTION_JUMP_RAD_S
    prof_kw = {"junction_jump_rad_s": PLAN_JUMP_SHARE * j_lim,
               "min_duration_s": protocol.P_MIN_US * 1e-6,
               "corner_accel_rad_s2": (1.0 - PLAN_ACCEL_SHARE) * motion.max_joint_rad_s2}
    dq = np.diff(steps.step_angles(st, mot.home_rad, mot.steps_per_rev), axis=0)
    pln = planner.plan(dq, length, feed, motion.max_joint_rad_s, a_c, stop_after=stop,
                       **prof_kw)
    counts, f1 = planner.ramp_fractions(pln, np.abs(dq).max(axis=1), a_c,
                                        PLAN_PIECE_JUMP_SHARE * j_lim / a_c,
                                        PLAN_MIN_PIECE_STEPS * mot.rad_per_step)
    seg_of = np.repeat(np.arange(counts.shape[0]), counts)
    inner = np.concatenate((seg_of[1:] == seg_of[:-1], [False]))  # not a segment's last piece
    # new targets on the ideal joint-space line of their segment, rounded once
    k_in = seg_of[inner]
    th_in = th_all[k_in] + f1[inner, None] * (th_all[k_in + 1] - th_all[k_in])
    order_t = np.argsort(np.concatenate((np.arange(th_all.shape[0]) * 1.0,
                                         k_in + f1[inner])), kind="stable")
    th_all = np.concatenate((th_all, th_in))[order_t]
    pts_all = np.concatenate((pts_all, checker.forward(th_in)[0]))[order_t]
    st = steps.absolute_steps(th_all, mot.home_rad, mot.steps_per_rev)
    keep = np.concatenate(([True], (np.diff(st, axis=0) != 0).any(axis=1)))
    st, th_all, pts_all = st[keep], th_all[keep], pts_all[keep]
    seg_of, f1 = seg_of[keep[1:]], f1[keep[1:]]
    f1[np.concatenate((seg_of[1:] != seg_of[:-1], [True]))] = 1.0
    f0 = np.where(np.concatenate(([True], seg_of[1:] != seg_of[:-1])), 0.0,
                  np.concatenate(([0.0], f1[:-1])))
    seg_draw, seg_path, seg_source = seg_draw[seg_of], seg_path[seg_of], seg_source[seg_of]
    seg_line, power, feed = seg_line[seg_of], power[seg_of], feed[seg_of]
    stop = stop[seg_of] & np.concatenate((seg_of[1:] != seg_of[:-1], [True]))
    perm_kept = perm_kept[seg_of]
    length = np.where(seg_draw, length[seg_of] * (f1 - f0),
                      np.hypot(*np.diff(pts_all, axis=0).T))
    dq = np.diff(steps.step_angles(st, mot.home_rad, mot.steps_per_rev), axis=0)
    pln = planner.plan(dq, length, feed, motion.max_joint_rad_s, a_c, stop_after=stop,
                       **prof_kw)
    duration_us = planner.enforce_staircase(dq, pln.duration_us, stop,
                                            motion.max_joint_rad_s2, j_lim)

    # ------------------------------------------------------------ per-path bookkeeping
    draw_idx = np.flatnonzero(seg_draw)
    dp = seg_path[draw_idx]
    first_seg = np.full(npath, -1, dtype=np.int64)
    end_seg = np.full(npath, -1, dtype=np.int64)
    if draw_idx.size:
        u, fi = np.unique(dp, return_index=True)
        first_seg[u] = draw_idx[fi]
        li = np.unique(dp[::-1], return_index=True)[1]
        end_seg[u] = draw_idx[::-1][li] + 1
    # Requested geometry per draw segment (for validation and previews).
    src_rows = perm_kept[seg_draw]  # rows into the draw-interval arrays
    chord_rows = dc[src_rows]
    sa_d, sb_d = iv.sa[src_rows], iv.sb[src_rows]  # a piece's part of its interval
    sa_d, sb_d = sa_d + f0[seg_draw] * (sb_d - sa_d), sa_d + f1[seg_draw] * (sb_d - sa_d)
    # Smallest margins over targets and samples; the moves from/to home and the working-mode
    # changes may pass a type-1 singularity on purpose (pen up, changing working mode), so
    # their type-1 columns and targets are left out.
    free1 = is_home_move | is_change
    tmarg_rep = tmarg.copy()
    tmarg_rep[free1, :2] = np.inf
    jmargin = np.minimum(iv.min_margin.min(axis=0) if iv.min_margin.size else np.inf,
                         tmarg_rep.min(axis=0))
    seg_mode = np.where(seg_draw, path_mode[np.minimum(seg_path, npath - 1)],
                        t_mode[seg_path])
    sgn = np.stack([np.where(np.char.startswith(seg_mode, "+"), 1.0, -1.0),
                    np.where(np.char.endswith(seg_mode, "+"), 1.0, -1.0),
                    np.full(seg_mode.shape[0], float(assembly))], axis=1)
    tm = fb.singularity_margins(th_all, pts_all) * np.concatenate(
        ([[1.0, 1.0, float(assembly)]], sgn))
    home_leg = np.concatenate(([True], ~seg_draw & free1[seg_path]))
    tm[home_leg, :2] = np.inf
    jmargin = np.minimum(jmargin, tm.min(axis=0))
    jac = fb.jacobian(th_all, pts_all)
    quantum = float(steps.step_quantum_mm(jac, mot.rad_per_step).max())
    # The working-mode changes as executed (quantised steps, sampled ≤ 0.5° apart).
    mode_changes: list[ModeChange] = []
    th_q = steps.step_angles(st, mot.home_rad, mot.steps_per_rev)
    for j in sorted(changes):
        segs = np.flatnonzero(~seg_draw & (seg_path == j))
        if not segs.size:
            continue
        s0, s1 = int(segs[0]), int(segs[-1]) + 1
        q = th_q[s0:s1 + 1]
        dense = _densify_joint(q, math.radians(0.5))
        fk = fb.forward_batch(dense, asm)
        marg = (fb.singularity_margins(dense, fk.points)[:, 2] * assembly if fk.valid.all()
                else np.array([-np.inf]))
        lim_ok = wrap_to_limits(dense, limits)[1:]
        if not (fk.valid.all() and (marg > 0).all() and lim_ok[0].all() and lim_ok[1].all()):
            raise JobError("the working-mode change before path "
                           f"#{j} leaves the assembly mode or the joint limits once its "
                           "targets are rounded to whole steps", Where(file=file),
                           "assembly")
        mode_changes.append(ModeChange(
            from_mode=str(path_mode[j - 1]) if j > 0 else home_mode,
            to_mode=str(path_mode[j]) if j < npath else home_mode,
            path=j, first_seg=s0, end_seg=s1,
            lift_mm=(float(pts_all[s0, 0]), float(pts_all[s0, 1])),
            land_mm=(float(pts_all[s1, 0]), float(pts_all[s1, 1])),
            crossings=_type1_crossings(fb, dense, fk.points),
            min_type2_rad=float(marg.min()),
            duration_s=float(duration_us[s0:s1].sum()) * 1e-6))
    if mode_changes:
        seq = [str(path_mode[0])]
        for m in path_mode[1:].tolist():
            if m != seq[-1]:
                seq.append(m)
        mode_note = (f"working modes {' → '.join(seq)} with {len(mode_changes)} pen-up "
                     f"working-mode change(s), assembly {asm}")
    else:
        mode_note = f"working mode {path_mode[0]}, assembly {asm}"
    notes.insert(0, f"{mode_note}; at the homed pose the pen is at ({home_pt[0]:.1f}, "
                    f"{home_pt[1]:.1f}) mm (working mode {home_mode})")
    notes.extend(drawing.warnings)
    job = Job(
        file=file, mode=str(path_mode[0]), assembly=assembly, tolerance_mm=tol,
        flatten_tol_mm=tol_f,
        placement=pl, drawing=mdraw, steps_per_rev=mot.steps_per_rev, home_rad=mot.home_rad,
        points_mm=pts_all, angles_rad=th_all, steps=st, draw=seg_draw, power=power,
        path=seg_path, source=seg_source, source_line=seg_line, duration_us=duration_us,
        length_mm=length,
        paths=PathStats(ch.path_source, ch.path_reversed, first_seg, end_seg,
                        np.full(npath, np.nan), np.full(npath, np.nan)),
        min_margin_rad=jmargin, step_quantum_mm=quantum,
        travel_before_mm=ch.travel_before, travel_after_mm=ch.travel_after, joined=ch.joined,
        notes=notes,
        seg_prim=ch.prim[chord_rows], seg_tlo=ch.tlo[chord_rows], seg_thi=ch.thi[chord_rows],
        seg_rev=ch.rev[chord_rows], seg_sa=sa_d, seg_sb=sb_d,
        seg_ca=ch.pts[a[chord_rows]], seg_cb=ch.pts[a[chord_rows] + 1],
        ideal_max_dev_mm=float(iv.dev_mm.max()) if iv.dev_mm.size else 0.0,
        path_modes=tuple(path_mode.tolist()), home_mode=home_mode,
        mode_changes=tuple(mode_changes),
    )
    if opts.validate:
        job = validate(job, profile, opts.validation_samples)
    return job


def compile_drawing(drawing: Drawing, profile: Profile, opts: CompileOptions) -> Job:
    """Compile an already-read drawing; `opts.mode` "auto" tries every working mode."""
    mode = opts.mode or profile.kinematics.working_mode
    if mode != "auto":
        if mode not in WORKING_MODES:
            raise ValueError(f"working mode must be one of {', '.join(WORKING_MODES)} or "
                             f"auto; got {mode!r}")
        return _compile_mode(drawing, profile, opts, mode)
    results: list[Job] = []
    failures: list[tuple[str, JobError]] = []
    for m in AUTO_ORDER:
        try:
            results.append(_compile_mode(drawing, profile, opts, m))
        except JobError as e:
            failures.append((m, e))
    if not results:
        lines = "\n".join(f"  mode {m}: {e}" for m, e in failures)
        try:
            job = _compile_with_mode_changes(drawing, profile, opts)
        except JobError as e:
            raise JobError("no working mode clears every check (--mode auto):\n" + lines
                           + f"\n  with pen-up working-mode changes: {e}",
                           Where(file=drawing.file), "no_mode") from None
        used = ", ".join(dict.fromkeys(job.path_modes))
        notes = [f"--mode auto: no single working mode clears every check, so the paths are "
                 f"drawn in modes {used} with {len(job.mode_changes)} pen-up working-mode "
                 "change(s) (thesis Sec. 7.2)"]
        notes += [f"  single mode {m}: {e.detail.split(';')[0]}" for m, e in failures]
        return replace(job, notes=notes + job.notes)
    best = max(results, key=lambda j: float(np.min(j.min_margin_rad)))
    why = (f"--mode auto chose {best.mode}: it clears every check with the largest smallest "
           f"singularity margin ({math.degrees(float(np.min(best.min_margin_rad))):.1f}°)")
    others = [f"{j.mode}: passes, smallest margin "
              f"{math.degrees(float(np.min(j.min_margin_rad))):.1f}°"
              for j in results if j is not best]
    others += [f"{m}: {e.detail.split(';')[0]}" for m, e in failures]
    notes = [why] + ([f"  other modes — {o}" for o in others]) + best.notes
    return replace(best, notes=notes)


def _compile_with_mode_changes(drawing: Drawing, profile: Profile,
                               opts: CompileOptions) -> Job:
    """`--mode auto`'s second try: working modes per path with pen-up changes. With
    `--origin` the placement does not depend on the mode; otherwise the placements of the
    modes are tried in `AUTO_ORDER` (centred in, or fitted to, that mode's safe rectangle)
    and the first that can be planned wins. Raises the first mode's `JobError` if none can."""
    placements = AUTO_ORDER[:1] if opts.origin_mm is not None else AUTO_ORDER
    errors: list[JobError] = []
    for m in placements:
        try:
            return _compile_mode(drawing, profile, opts, m, plan_modes=True)
        except JobError as e:
            errors.append(e)
    raise errors[0]


def compile_job(path: str | Path, profile: Profile, opts: CompileOptions | None = None) -> Job:
    """Read and compile a drawing file (see module doc). Raises `InputError` or `JobError`."""
    o = opts or CompileOptions()
    drawing = read_drawing(path, o.layers)
    return compile_drawing(drawing, profile, o)
