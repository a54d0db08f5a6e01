"""The last stage: per-path bookkeeping, the requested geometry of every draw segment (for
validation and previews), the smallest singularity margins, the step quantum, the
working-mode changes as executed, the notes — the `Job`, validated if asked.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile import steps
from fivebar_host.compile.fill import outline_notes
from fivebar_host.compile.layers import break_switches, layer_pauses
from fivebar_host.compile.model import (
    CompileOptions,
    Job,
    ModeChange,
    PathStats,
    compact_ints,
)
from fivebar_host.compile.modes import densify_joint, type1_crossings
from fivebar_host.compile.place import Home, Placed, Setup
from fivebar_host.compile.solve import Routed, Solved
from fivebar_host.compile.timing import Planned, tool_time_s
from fivebar_host.compile.travel import Travel
from fivebar_host.compile.validate import validate
from fivebar_host.errors import JobError, Where
from fivebar_host.toolpath.segment import wrap_to_limits
from kinematics.arrays import FloatArray, IntArray

#: Targets measured at a time for the margins and the step quantum (bounds the temporaries;
#: minima and maxima over blocks are those of one pass).
FINISH_BLOCK = 1 << 16

#: The requested geometry of each draw segment, as `Job` fields (`seg_prim`, …, `seg_cb`).
Geometry = dict[str, NDArray[Any]]


def _path_ranges(pd: Planned, npath: int) -> tuple[IntArray, IntArray]:
    """First draw segment and one past the last of every job path (−1 if none)."""
    seg_draw, seg_path = pd.draw, pd.path
    draw_idx = np.flatnonzero(seg_draw)
    dp = seg_path[draw_idx]
    first_seg = np.full(npath, -1, dtype=np.int64)
    end_seg = np.full(npath, -1, dtype=np.int64)
    if draw_idx.size:
        u, fi = np.unique(dp, return_index=True)
        first_seg[u] = draw_idx[fi]
        li = np.unique(dp[::-1], return_index=True)[1]
        end_seg[u] = draw_idx[::-1][li] + 1
    return first_seg, end_seg


def _margins(su: Setup, routed: Routed, solved: Solved, tr: Travel,
             pd: Planned) -> FloatArray:
    """Smallest margins (3,) over targets and samples; the moves from/to home and the
    working-mode changes may pass a type-1 singularity on purpose (pen up, changing working
    mode), so their type-1 columns and targets are left out. The targets are measured in
    blocks of `FINISH_BLOCK` (minima over blocks are those of one pass)."""
    iv, npath, assembly = solved.iv, routed.npath, su.assembly
    free1 = tr.is_home_move | tr.is_change
    tmarg_rep = tr.margins.copy()
    tmarg_rep[free1, :2] = np.inf
    jmargin = np.minimum(iv.min_margin.min(axis=0) if iv.min_margin.size else np.inf,
                         tmarg_rep.min(axis=0))
    tmin = np.full(3, np.inf)
    for i in range(0, pd.th.shape[0], FINISH_BLOCK):
        # target i + r ends segment i + r − 1 (target 0, the homed pose, ends none)
        k = np.arange(max(i - 1, 0), min(i + FINISH_BLOCK, pd.th.shape[0]) - 1)
        seg_draw, seg_path = pd.draw[k], pd.path[k]
        seg_mode = np.where(seg_draw, routed.path_mode[np.minimum(seg_path, npath - 1)],
                            tr.t_mode[seg_path])
        sgn = np.stack([np.where(np.char.startswith(seg_mode, "+"), 1.0, -1.0),
                        np.where(np.char.endswith(seg_mode, "+"), 1.0, -1.0),
                        np.full(seg_mode.shape[0], float(assembly))], axis=1)
        leg = ~seg_draw & free1[seg_path]
        if i == 0:
            sgn = np.concatenate(([[1.0, 1.0, float(assembly)]], sgn))
            leg = np.concatenate(([True], leg))
        sl = slice(i, i + FINISH_BLOCK)
        tm = su.fb.singularity_margins(pd.th[sl], pd.pts[sl]) * sgn
        tm[leg, :2] = np.inf
        tmin = np.minimum(tmin, [tm[:, c].min() for c in range(3)])  # (min(axis=0) is slow)
    out: FloatArray = np.minimum(jmargin, tmin)
    return out


def _step_quantum(su: Setup, pd: Planned) -> float:
    """The largest step quantum (mm) over the targets, in blocks of `FINISH_BLOCK`."""
    q = 0.0
    for i in range(0, pd.th.shape[0], FINISH_BLOCK):
        jac = su.fb.jacobian(pd.th[i:i + FINISH_BLOCK], pd.pts[i:i + FINISH_BLOCK])
        q = max(q, float(steps.step_quantum_mm(jac, su.profile.motors.rad_per_step).max()))
    return q


def _executed_mode_changes(su: Setup, file: str, home: Home, routed: Routed, tr: Travel,
                           pd: Planned) -> list[ModeChange]:
    """The working-mode changes as executed (quantised steps, sampled ≤ 0.5° apart): each
    must keep the assembly and the joint limits; where the arms cross type-1."""
    fb, asm, assembly, mot = su.fb, su.asm, su.assembly, su.profile.motors
    path_mode, npath, pts_all = routed.path_mode, routed.npath, pd.pts
    mode_changes: list[ModeChange] = []
    for j in sorted(tr.changes):
        segs = np.flatnonzero(~pd.draw & ~pd.dwell & (pd.path == j))
        if not segs.size:
            continue
        s0, s1 = int(segs[0]), int(segs[-1]) + 1
        st = pd.steps[s0:s1 + 1]
        if pd.slack.shape[0]:  # the joints' steps: the counts less the backlash slack
            st = st.astype(np.int64) - pd.slack[s0:s1 + 1]
        q = steps.step_angles(st, mot.home_rad, mot.steps_per_rev)
        dense = densify_joint(q, math.radians(0.5))
        fk = fb.forward_batch(dense, asm)
        marg = (fb.singularity_margins(dense, fk.points)[:, 2] * assembly if fk.valid.all()
                else np.array([-np.inf]))
        lim_ok = wrap_to_limits(dense, su.limits)[1:]
        if not (fk.valid.all() and (marg > 0).all() and lim_ok[0].all() and lim_ok[1].all()):
            raise JobError("the working-mode change before path "
                           f"#{j} leaves the assembly mode or the joint limits once its "
                           "targets are rounded to whole steps", Where(file=file),
                           "assembly")
        mode_changes.append(ModeChange(
            from_mode=str(path_mode[j - 1]) if j > 0 else home.mode,
            to_mode=str(path_mode[j]) if j < npath else home.mode,
            path=j, first_seg=s0, end_seg=s1,
            lift_mm=(float(pts_all[s0, 0]), float(pts_all[s0, 1])),
            land_mm=(float(pts_all[s1, 0]), float(pts_all[s1, 1])),
            crossings=type1_crossings(fb, dense, fk.points),
            min_type2_rad=float(marg.min()),
            duration_s=float(pd.duration_us[s0:s1].sum()) * 1e-6))
    return mode_changes


def _mode_note(su: Setup, home: Home, routed: Routed, n_changes: int) -> str:
    """The first note: the working mode(s), the assembly and the homed pen position."""
    path_mode = routed.path_mode
    if n_changes:
        seq = [str(path_mode[0])]
        for m in path_mode[1:].tolist():
            if m != seq[-1]:
                seq.append(m)
        mode_note = (f"working modes {' → '.join(seq)} with {n_changes} pen-up "
                     f"working-mode change(s), assembly {su.asm}")
    else:
        mode_note = f"working mode {path_mode[0]}, assembly {su.asm}"
    return (f"{mode_note}; at the homed pose the pen is at ({home.pt[0]:.1f}, "
            f"{home.pt[1]:.1f}) mm (working mode {home.mode})")


def _dwell_notes(routed: Routed) -> list[str]:
    """One note on the G4 dwells, if any: how many, how long, how many with the tool on."""
    dw = routed.ch.dwells
    if not dw:
        return []
    on = sum(d.tool_on for d in dw)
    return [f"{len(dw)} dwell(s) (G4), {sum(d.seconds for d in dw):g} s in all, {on} with "
            "the tool on (laser at the current power with --laser, pen down); paths drawn "
            "in file order"]


def requested_rows(routed: Routed, solved: Solved) -> Geometry:
    """The requested geometry of every refined draw interval (row as in `solved.iv`): the
    primitive(s) and parameter range its chord lies on, the chord's ends and the interval's
    part σ_a … σ_b of it. Taken before timing so the chords and intervals can go. The
    first primitives are left empty when every chord covers one primitive (`Job`)."""
    ch, iv = routed.ch, solved.iv
    c = iv.chord
    a = ch.chord_from[c]
    prim = compact_ints(ch.prim[c])
    first = compact_ints(ch.prim_first[c])
    if np.array_equal(first, prim):
        first = first[:0]
    return {"seg_prim": prim, "seg_prim_first": first, "seg_tlo": ch.tlo[c],
            "seg_thi": ch.thi[c], "seg_rev": ch.rev[c], "seg_ca": ch.pts[a],
            "seg_cb": ch.pts[a + 1], "seg_sa": iv.sa, "seg_sb": iv.sb}


def draw_geometry(rows: Geometry, pd: Planned) -> Geometry:
    """Per draw segment of the planned job, its requested geometry from `requested_rows`
    (a piece keeps its interval's geometry, over its part [f0, f1] of it). `rows` is
    consumed: each per-interval array is dropped once its per-segment copy exists."""
    seg_draw = pd.draw
    src = pd.perm[seg_draw]  # rows into the draw-interval arrays
    sa, sb = rows.pop("seg_sa")[src], rows.pop("seg_sb")[src]
    f0, f1 = pd.f0[seg_draw], pd.f1[seg_draw]
    out = {"seg_sa": sa + f0 * (sb - sa), "seg_sb": sa + f1 * (sb - sa)}
    del sa, sb, f0, f1
    for name in list(rows):
        arr = rows.pop(name)
        out[name] = arr[src] if arr.shape[0] else arr
    return out


def finish(su: Setup, placed: Placed, home: Home, routed: Routed, solved: Solved,
           tr: Travel, pd: Planned, geometry: Geometry, opts: CompileOptions) -> Job:
    """The `Job` from every stage's result and the draw segments' requested `geometry`
    (`draw_geometry`; validated unless `opts.validate` is off)."""
    ch, iv, npath, mot = routed.ch, solved.iv, routed.npath, su.profile.motors
    file = placed.drawing.file
    seg_draw = pd.draw
    first_seg, end_seg = _path_ranges(pd, npath)
    jmargin = _margins(su, routed, solved, tr, pd)
    mode_changes = _executed_mode_changes(su, file, home, routed, tr, pd)
    g = geometry
    notes = [_mode_note(su, home, routed, len(mode_changes)), *tr.notes,
             *placed.drawing.warnings, *outline_notes(placed.drawing, opts),
             *_dwell_notes(routed)]
    pauses = layer_pauses(routed.sections, ch.path_section, pd.path)
    tool_on = seg_draw | (pd.dwell & (pd.power > 0))
    job = Job(
        file=file, mode=str(routed.path_mode[0]), assembly=su.assembly, tolerance_mm=su.tol,
        flatten_tol_mm=su.tol_f,
        placement=placed.pl, drawing=placed.mdraw, steps_per_rev=mot.steps_per_rev,
        home_rad=mot.home_rad,
        points_mm=pd.pts, angles_rad=pd.th, steps=pd.steps, draw=seg_draw, power=pd.power,
        path=pd.path, source=pd.source, source_line=pd.line, duration_us=pd.duration_us,
        length_mm=pd.length,
        paths=PathStats(ch.path_source, ch.path_reversed, first_seg, end_seg,
                        np.full(npath, np.nan), np.full(npath, np.nan)),
        min_margin_rad=jmargin, step_quantum_mm=_step_quantum(su, pd),
        travel_before_mm=ch.travel_before, travel_after_mm=ch.travel_after, joined=ch.joined,
        notes=notes, seg_prim=g["seg_prim"], seg_prim_first=g["seg_prim_first"],
        seg_tlo=g["seg_tlo"], seg_thi=g["seg_thi"], seg_rev=g["seg_rev"], seg_sa=g["seg_sa"],
        seg_sb=g["seg_sb"], seg_ca=g["seg_ca"], seg_cb=g["seg_cb"],
        ideal_max_dev_mm=float(iv.dev_mm.max()) if iv.dev_mm.size else 0.0,
        path_modes=tuple(routed.path_mode.tolist()), home_mode=home.mode,
        mode_changes=tuple(mode_changes),
        tool_time_s=tool_time_s(tool_on, su.profile, break_switches(tool_on, pauses)),
        dwell=pd.dwell, pauses=pauses, slack=pd.slack,
    )
    g.clear()
    if opts.validate:
        job = validate(job, su.profile, opts.validation_samples)
    return job
