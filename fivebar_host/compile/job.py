"""Compiling a drawing file into a checked, timed, quantised `Job`.

`compile_job(path, profile, options)` runs the whole pipeline:

    read (SVG / G-code) → place (layout) → flatten curves (tol_f = tol/2) → order and join
    paths → [--mode auto when no single mode clears every check: working mode per path,
    `plan_path_modes`] → inverse kinematics + checks on every vertex → refine chords in joint
    space (interpolation budget tol_i, `toolpath.segment`) → pen-up travel (checked
    joint-space moves, Cartesian fallback; planned pen-up moves for working-mode changes) →
    absolute steps (quantised once) → plan durations (`planner`: speed-up and slow-down cut
    into pieces on the segments' stepped lines, the firmware's rate staircase within the joint
    acceleration and junction-jump limits at every boundary) → validate: forward kinematics
    of the *quantised* steps, including the joint-space interpolation between them, against
    the requested curves.

Tolerance budget (one `tol`, default from the profile): a curve is flattened so every chord is
within tol_f = tol/2 of it; runs of straight input lines (dense polylines) are simplified so
every chord is within ε = tol_f of the lines it replaces and they of it
(`toolpath.simplify`, off with `--no-simplify`); each chord is refined so the
joint-interpolated pen path stays within tol_i of the chord: tol_i = tol − tol_f for chords
of curves and for chords that replace several lines, tol for a single straight input line
(exact), tol − gap/2 for the short pen-down bridge that joins two paths whose ends are
closer than tol. By the triangle inequality every pen point is within tol of
the requested path; rounding to whole steps adds at most one step quantum (reported).

`_compile_mode` runs the stages in order; each hands its result on as a frozen dataclass:

    place.setup / place / find_home  → Setup, Placed (placement, placed drawing, polylines),
                                       Home (homed pose)
    solve.route                      → Routed (ordered, joined `Chords`; mode per path;
                                       planned working-mode changes, `modes.plan_path_modes`)
    solve.solve                      → Solved (checked angles per vertex, refined intervals)
    travel.plan_travel               → Travel (targets, margins, mode changes, notes)
    segments.assemble                → Segments (merged targets with provenance)
    segments.drop_zero_moves         → Stepped (absolute steps, zero moves dropped)
    backlash.take_up                 → Stepped (motor counts; a take-up segment at every
                                       reversal of a motor with backlash)
    timing.plan_timing               → Planned (ramp pieces, power, durations)
    finish.finish                    → Job (per-path bookkeeping, margins, validation)

The data model is in `fivebar_host.compile.model`; validation in `.validate`, the firmware
lines in `.encode`, `--mode auto`'s working-mode planning in `.modes`.
"""

from __future__ import annotations

import gc
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host.compile import budget
from fivebar_host.compile.backlash import take_up
from fivebar_host.compile.finish import draw_geometry, finish, requested_rows
from fivebar_host.compile.layers import sections
from fivebar_host.compile.model import AUTO_ORDER, CompileOptions, Job, release_free_memory
from fivebar_host.compile.place import find_home, place, setup
from fivebar_host.compile.segments import assemble, drop_zero_moves
from fivebar_host.compile.solve import route, solve
from fivebar_host.compile.timing import plan_timing
from fivebar_host.compile.travel import plan_travel
from fivebar_host.config import Profile
from fivebar_host.errors import InputError, JobError, OptionError, Where
from fivebar_host.progress import report
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.geometry import Drawing
from fivebar_host.toolpath.svg import read_svg
from fivebar_host.toolpath.svg.reader import DEFAULT_MAX_SEGMENTS
from kinematics.fivebar import WORKING_MODES

GCODE_SUFFIXES = {".gcode", ".nc", ".ngc", ".gc", ".g", ".tap", ".cnc"}


def gcode_tool(profile: Profile | None) -> dict[str, Any]:
    """The G-code reader's tool arguments from a profile (what Z words mean: the `[tool]
    kind` and `[pen] z_threshold_mm`); none without a profile (Z words refused)."""
    if profile is None:
        return {}
    z = profile.pen.z_threshold_mm if profile.pen is not None else 0.0
    return {"tool": profile.tool, "z_threshold_mm": z}


def read_drawing(path: str | Path, layers: tuple[str, ...] = (),
                 max_segments: float | None = None, profile: Profile | None = None,
                 strict: bool = False) -> Drawing:
    """Read an SVG or G-code file, chosen by suffix (or by content when unknown); an SVG
    with more than `max_segments` path segments (None: the reader's default) is refused.
    `profile` gives G-code Z words their meaning (`gcode_tool`); `strict`: the G-code
    reader's `--strict`. The reader's own state is freed before the drawing is returned
    (`_read_and_collect`)."""
    return _read_and_collect(Path(path), layers, max_segments, profile, strict)


def _read_and_collect(p: Path, layers: tuple[str, ...], max_segments: float | None,
                      profile: Profile | None, strict: bool = False) -> Drawing:
    """`read_drawing`, then one full garbage collection: the SVG reader's walker, element
    tree and drawing builder refer to each other, so their buffers (the builder's
    per-primitive arrays, the parser's nodes: about 25 bytes per primitive and more) would
    otherwise stay resident through the whole compile until Python's next full collection,
    which a numpy-heavy compile may never trigger. Only for drawings of at least
    `COLLECT_MIN_PRIMITIVES` primitives: a collection costs some 20–30 ms, more than a small
    drawing's reader state is worth."""
    drawing = _read(p, layers, max_segments, profile, strict)
    if drawing.kind.shape[0] >= COLLECT_MIN_PRIMITIVES:
        gc.collect()
    return drawing


#: Drawings from this many primitives on get `_read_and_collect`'s full collection.
COLLECT_MIN_PRIMITIVES = 1 << 16


def _read(p: Path, layers: tuple[str, ...], max_segments: float | None,
          profile: Profile | None, strict: bool = False) -> Drawing:
    """`read_drawing` itself."""
    suffix = p.suffix.lower()
    limit = DEFAULT_MAX_SEGMENTS if max_segments is None else int(max_segments)
    text = profile.text if profile is not None else None  # the fonts of SVG <text>
    if suffix == ".svg":
        return read_svg(p, layers or None, max_segments=limit, text=text)
    if suffix in GCODE_SUFFIXES:
        if layers:
            raise InputError("--layer applies to SVG files only", str(p))
        return read_gcode(p, strict=strict, **gcode_tool(profile))
    try:
        head = p.read_bytes()[:512].lstrip()
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror or e}", str(p)) from e
    if head.startswith((b"<?xml", b"<svg", b"<!--", b"<!DOCTYPE")):
        return read_svg(p, layers or None, max_segments=limit, text=text)
    return read_gcode(p, strict=strict, **gcode_tool(profile))


def _compile_mode(drawing: Drawing, profile: Profile, opts: CompileOptions,
                  mode: str, plan_modes: bool = False, consume: bool = False) -> Job:
    """Compile `drawing`, placed for working mode `mode`. Without `plan_modes` every path is
    drawn in `mode`. With it (`--mode auto` when no single mode clears every check), the
    modes come from `plan_modes` and every change of mode becomes a checked pen-up
    joint-space move (`ModeChange`). The stages hand their results on as frozen dataclasses
    (module doc: the pipeline); each is slimmed to what the later stages read as soon as the
    next stage has its part, so a large drawing's intermediate arrays do not pile up
    (`consume`: the drawing is placed in place, `place.place`)."""
    report("placing")
    su = setup(profile, opts, mode)
    placed = place(su, drawing, opts, consume)
    del drawing
    home = find_home(su, placed.drawing.file)
    secs = sections(placed.drawing, placed.poly.stroke, opts.layer_pause, opts.no_pause)
    report("ordering paths", 0.0)
    routed = route(su, placed, home, opts.keep_order, plan_modes, not opts.no_simplify, secs)
    placed = placed.without_strokes()
    release_free_memory()
    report("solving")
    solved = solve(su, placed, routed)
    report("travel")
    tr = plan_travel(su, placed, home, routed, solved, plan_modes)
    solved = solved.summarised()
    release_free_memory()
    report("segments")
    segments = assemble(placed, home, routed, solved, tr)
    rows = requested_rows(routed, solved)
    routed, solved = routed.per_path(), solved.per_path()
    # motor counts, with a take-up segment at every reversal of a motor with backlash
    handed = [take_up(drop_zero_moves(profile.motors, segments),
                      profile.motors.backlash_steps)]  # timing empties it
    del segments  # the stepped copy replaces it
    release_free_memory()
    report("timing")
    planned = plan_timing(su, routed, solved, handed)
    geometry = draw_geometry(rows, planned)  # consumes `rows`
    planned = replace(planned, perm=_NO_INTS, f0=_NO_FLOATS, f1=_NO_FLOATS)
    release_free_memory()
    report("validating")
    return finish(su, placed, home, routed, solved, tr, planned, geometry, opts)


_NO_INTS = np.zeros(0, dtype=np.int64)
_NO_FLOATS = np.zeros(0)


def with_job_motion(profile: Profile, opts: CompileOptions) -> Profile:
    """The profile with the job's speed options in place of its [motion] values (the feeds,
    and the acceleration limit scaled by `accel_fraction` ≤ 1: never above the profile's);
    on servo joints the joint speed at most the slower servo's rated speed."""
    mo = profile.motion
    servo = profile.joints.max_joint_rad_s if profile.joints is not None else math.inf
    new = replace(mo, draw_feed_mm_s=opts.draw_feed_mm_s or mo.draw_feed_mm_s,
                  travel_feed_mm_s=opts.travel_feed_mm_s or mo.travel_feed_mm_s,
                  max_joint_rad_s=min(mo.max_joint_rad_s, servo),
                  max_joint_rad_s2=mo.max_joint_rad_s2 * (opts.accel_fraction or 1.0))
    return profile if new == mo else replace(profile, motion=new)


def compile_drawing(drawing: Drawing, profile: Profile, opts: CompileOptions,
                    consume: bool = False) -> Job:
    """Compile an already-read drawing; `opts.mode` "auto" tries every working mode.
    `consume`: the caller no longer needs `drawing`, which may then be placed in place (its
    primitives become the job's, in machine mm) to save memory on large drawings."""
    if drawing.images:
        raise InputError(f"the file's drawn content is {len(drawing.images)} <image> "
                         "element(s): a raster, burned by `fivebar plot FILE.svg` "
                         "(docs/raster.md), not drawn as paths", drawing.file)
    budget.before_compiling(drawing)
    profile = with_job_motion(profile, opts)
    mode = opts.mode or profile.kinematics.working_mode
    if mode != "auto":
        if mode not in WORKING_MODES:
            raise OptionError("mode", f"must be one of {', '.join(WORKING_MODES)} or auto; "
                              f"got {mode!r}")
        return _compile_mode(drawing, profile, opts, mode, consume=consume)
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
    `--origin` (or a G-code file at its own coordinates) the placement does not depend on
    the mode; otherwise the placements of the
    modes are tried in `AUTO_ORDER` (centred in, or fitted to, that mode's safe rectangle)
    and the first that can be planned wins. Raises the first mode's `JobError` if none can."""
    fixed = layout.keeps_own_coordinates(drawing, opts.origin_mm, opts.fit)
    placements = AUTO_ORDER[:1] if opts.origin_mm is not None or fixed else AUTO_ORDER
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
    budget.before_reading(Path(path))
    report("reading", 0.0)
    drawing = read_drawing(path, o.layers, o.max_segments, profile, o.gcode_strict)
    return compile_drawing(drawing, profile, o, consume=True)
