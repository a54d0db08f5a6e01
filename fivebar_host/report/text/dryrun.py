"""The dry-run text report of a compiled job: what `fivebar plot --dry-run` prints.

Paths, segments, lengths, time, deviation, margins, working mode(s) and tool, one line each,
plus every pen-up working-mode change. Text only; the preview picture drawn next to it is
`fivebar_host.report.preview`, which shares `mode_sequence` and `format_duration` for its title.
"""

from __future__ import annotations

import math

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import Job, NbarOpinion, linkrate
from fivebar_host.config import Profile
from fivebar_host.errors import FivebarError
from fivebar_host.run.stops import Copies, plan_text


def mode_sequence(job: Job) -> str:
    """"+-" for a one-mode job; "++ (#0–#1) → +- (#2–#3)" for the paths' working modes."""
    modes = job.path_modes or (job.mode,)
    if len(set(modes)) == 1:
        return modes[0]
    runs: list[tuple[str, int, int]] = []
    for i, m in enumerate(modes):
        if runs and runs[-1][0] == m:
            runs[-1] = (m, runs[-1][1], i)
        else:
            runs.append((m, i, i))
    return " → ".join(f"{m} (#{a})" if a == b else f"{m} (#{a}–#{b})" for m, a, b in runs)


def format_duration(t: float) -> str:
    """A duration for people: "12.3 s", "4 min 5 s", "1 h 2 min"."""
    if t < 60:
        return f"{t:.1f} s"
    m, s = divmod(t, 60.0)
    if m < 60:
        return f"{int(m)} min {s:.0f} s"
    h, m = divmod(m, 60.0)
    return f"{int(h)} h {int(m)} min"


def tool_line(job: Job, laser: bool, profile: Profile | None = None) -> str:
    """Which tool the profile has and what the job does with it: the laser's power with
    `laser`, a servo pen's positions, moves, delays and lifts, or a pen at S0."""
    if laser:
        return ("tool          laser: S up to "
                f"{int(job.power.max(initial=0))} while drawing, S0 on travel (--laser)")
    pen = profile.pen if profile is not None else None
    if pen is None:  # a laser profile (the bundled default): without --laser it stays off
        return ("tool          laser off: S0 on every line (power only with --laser); "
                "M3/M5 mark each drawing stroke (a pen lift on M3 draws it)")
    return (f"tool          pen servo (profile [tool] pen): down {pen.down_position:g} % "
            f"({pen.pulse_us(pen.down_position)} µs) in {pen.move_ms(True)} ms + "
            f"{pen.down_delay_ms} ms settle, up {pen.up_position:g} % "
            f"({pen.pulse_us(pen.up_position)} µs) in {pen.move_ms(False)} ms + "
            f"{pen.up_delay_ms} ms; {job.pen_downs} lifts, {job.tool_time_s:.1f} s of pen "
            "moves and delays (in the time below)")


def pause_lines(job: Job) -> list[str]:
    """One line per pen-change stop of a copy (`Job.pauses`)."""
    return [f"pen change    before {p.describe()}"
            + (" (before anything moves)" if p.segment == 0 else f" at segment {p.segment}")
            + ": pen up, machine idle, waits for you" for p in job.pauses]


def link_lines(job: Job, profile: Profile) -> list[str]:
    """A line when the serial link or the firmware sets the pace of some segments
    (`compile.linkrate`): the plan is slowed there so the queue never runs empty."""
    n, wire = linkrate.bound_segments(job.steps, job.power, job.duration_us, profile)
    if not n:
        return []
    baud = profile.serial.link_baud
    fw = f"the firmware (≤ {1e6 / linkrate.FIRMWARE_SEGMENT_US:.0f} segments/s)"
    faster = ("; a faster link ([serial] link_baud = 250000 or more) would carry more"
              if baud == protocol.BASE_BAUD and wire else "")
    what = (f"{baud} baud" if wire == n else fw if not wire
            else f"{baud} baud ({wire}) and {fw} ({n - wire})")
    return [f"link          {n} of {job.n_segments} segments slowed to what {what} "
            f"{'carries' if wire in (0, n) else 'carry'}, so the queue never runs dry{faster}"]


#: Text elements listed one by one in the report; the rest are counted.
TEXTS_LISTED = 8


def text_lines(job: Job) -> list[str]:
    """One line per drawn SVG `<text>` (the first `TEXTS_LISTED`): the element, its line,
    its text, the faces that drew it and its size on the machine (font-size, after the
    placement's scale)."""
    texts = job.drawing.texts
    out = []
    for t in texts[:TEXTS_LISTED]:
        size = t.size_mm * job.placement.scale
        src = f" (source #{t.source})" if t.source >= 0 else ""
        out.append(f"text          {t.element} line {t.line}{src}: {t.text!r} in "
                   f"{', '.join(t.fonts) or 'no font (nothing drawn)'}, {size:.1f} mm, "
                   f"{t.glyphs} glyphs, {t.strokes} strokes")
    if len(texts) > TEXTS_LISTED:
        rest = texts[TEXTS_LISTED:]
        out.append(f"text          … and {len(rest)} more text elements "
                   f"({sum(t.glyphs for t in rest)} glyphs)")
    return out


def joint_lines(job: Job, profile: Profile) -> list[str]:
    """The backlash take-ups (compile.backlash) and, on servo joints, the pulse targets."""
    lines = []
    lash = profile.motors.backlash_steps
    if any(lash) and job.slack.shape[0]:
        still = (np.diff(job.joint_steps, axis=0) == 0).all(axis=1)
        piece = still & (np.diff(job.steps.astype(np.int64), axis=0) != 0).any(axis=1)
        runs = int(piece[:1].sum()) + int((piece[1:] & ~piece[:-1]).sum())
        t = float(job.duration_us[piece].sum()) * 1e-6
        lines.append(f"backlash      {runs} take-up(s) of A {lash[0]}, B {lash[1]} steps at "
                     f"reversals, {t:.2f} s (the pen stays put while a motor takes up)")
    if profile.joints is not None:
        try:
            pul = profile.joints.pulses(job.angles_rad)
            lines.append(f"servo joints  pulses A {pul[:, 0].min():g}–{pul[:, 0].max():g} µs, "
                         f"B {pul[:, 1].min():g}–{pul[:, 1].max():g} µs (0.5 µs steps, dead "
                         "band compensated); runs on the servo firmware, docs/protocol.md 6.5")
        except FivebarError as e:
            lines.append(f"servo joints  {e}")
    return lines


def fill_lines(job: Job) -> list[str]:
    """What hatching and hidden-line removal did (`--hatch`, `--hiding`): how much of the
    drawing is hatch, how much was hidden, and the pen lifts."""
    f = job.drawing.fill
    if f is None:
        return []
    hatch_src = np.array([s.role == "hatch" for s in job.drawing.sources] + [False])
    seg = job.draw & (job.source >= 0)
    hatch_mm = float(job.length_mm[seg & hatch_src[job.source]].sum())
    total = job.draw_length_mm
    out = []
    if f.hatch:
        out.append(f"hatch         {hatch_mm:.1f} mm of the {total:.1f} mm drawn "
                   f"({100 * hatch_mm / total if total else 0:.0f} %): {f.hatch}; "
                   f"{f.regions} regions ({f.simple_regions} simple, in "
                   f"{f.hatch_runs_simple} pen-down runs), {f.link_mm:.1f} mm of links "
                   "inside them")
    if f.hiding:
        out.append(f"hidden        {f.hidden_mm:.1f} mm of lines under later fills, "
                   f"{f.unstroked_mm:.1f} mm of fill-only outlines not drawn (--hiding)")
    incl = ", hatch included" if f.hatch else ""
    out.append(f"pen lifts     {job.pen_downs} (pen-down runs{incl})")
    out.extend(f"note          {n}" for n in f.notes)
    return out


def report_lines(job: Job, nbar: NbarOpinion | None = None, laser: bool = False,
                 profile: Profile | None = None, copies: Copies | None = None) -> list[str]:
    """The dry-run report: paths, segments, lengths, time, deviation, margins, mode, tool (pen,
    or laser with `laser`: the power the job would send; a servo pen's moves with
    `profile`) and the n-bar solver's second opinion on the deviation when given. The time
    covers `copies` (`--copies`, `--page-delay`) and counts the pen-change stops."""
    deg = math.degrees
    mm = job.min_margin_rad
    pl = job.placement
    w, h = pl.size_mm
    bx = pl.machine_bbox
    worst = int(np.nanargmax(job.paths.max_dev_mm)) if np.isfinite(
        job.paths.max_dev_mm).any() else -1
    lines = [
        f"file          {job.file}",
        f"working mode  {mode_sequence(job)} (assembly {'+' if job.assembly > 0 else '-'}"
        + (f"; {len(job.mode_changes)} pen-up working-mode change(s), listed below; the "
           f"homed pose is in {job.home_mode})" if job.mode_changes else ")"),
        f"placement     {pl.how}: scale {pl.scale:.4g}, rotation {pl.rotate_deg:g}°, "
        f"{w:.1f} × {h:.1f} mm at ({bx[0]:.1f}, {bx[1]:.1f})–({bx[2]:.1f}, {bx[3]:.1f}) mm",
        tool_line(job, laser, profile),
        f"paths         {job.n_paths} ({job.joined} joined across gaps < tolerance)",
        f"segments      {job.n_segments} ({int(job.draw.sum())} drawing, "
        f"{int((~job.draw).sum())} travel)",
        f"drawing       {job.draw_length_mm:.1f} mm",
        *fill_lines(job),
        f"travel        {job.travel_length_mm:.1f} mm (pen-up straight-line estimate "
        f"{job.travel_before_mm:.1f} mm in file order → {job.travel_after_mm:.1f} mm "
        "reordered)",
        f"time          {plan_text(job, copies or Copies(), format_duration)}; planned "
        "durations" + (f", pen {job.tool_time_s:.1f} s a copy" if job.tool_time_s else ""),
        f"tolerance     {job.tolerance_mm:g} mm (curves flattened to "
        f"{job.flatten_tol_mm:g} mm, the rest for joint-space interpolation)",
        f"deviation     max {job.max_dev_mm:.4f} mm, mean {job.mean_dev_mm:.4f} mm "
        f"(from the quantised steps; bound {job.tolerance_mm:g} + step quantum "
        f"{job.step_quantum_mm:.4f} = {job.tolerance_mm + job.step_quantum_mm:.4f} mm)",
    ]
    if nbar is not None:
        lines.append(f"2nd opinion   {nbar.describe()}")
    if worst >= 0 and job.n_paths > 1:
        lines.append(f"worst path    #{worst} (source element "
                     f"#{int(job.paths.source[worst])}): max "
                     f"{job.paths.max_dev_mm[worst]:.4f} mm")
    lines.append(f"margins       smallest type 1: {deg(min(mm[0], mm[1])):.1f}° "
                 f"(arm 1 {deg(mm[0]):.1f}°, arm 2 {deg(mm[1]):.1f}°), type 2: "
                 f"{deg(mm[2]):.1f}°")
    if profile is not None:
        lines.extend(link_lines(job, profile))
        lines.extend(joint_lines(job, profile))
    lines.extend(text_lines(job))
    lines.extend(pause_lines(job))
    lines.extend(f"mode change {k:<2d}{mc.describe(job.n_paths)}"
                 for k, mc in enumerate(job.mode_changes, start=1))
    lines.extend(f"note          {n}" for n in job.notes)
    return lines
