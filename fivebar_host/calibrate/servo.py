"""`fivebar calibrate` for a servo profile (`[joints] kind = "servo"`, issue 38).

The pattern: numbered ticks, each a short stroke that *ends* on its mark, drawn in the
direction that turns each joint into the mark from the side `approach_signs` asks (the
joint velocity s maps to the pen direction J·s), so every joint comes into the marks from
both sides and the dead band is told apart from the curve's offset
(kinematics.servo_calibration). The user measures each tick's end. The marks file is the
stepper one (`fivebar-calibration-pattern/1`, the job's steps included) with, per mark, the
pulses the servo firmware is sent there (`pulses_us`: each servo's curve at the job's
angle, 0.5 µs) and the sign of each joint's last move into it (`approach`), both read from
the compiled job itself.

The fit (`calibrate_servo`) is `kinematics.servo_calibration.fit_servo`: the geometry
(lengths, the pen's extension), each servo's pulse ↔ angle curve (a polynomial whose order
the marks choose) and dead band, with standard deviations; the ticks of a second round (laid
out by the first round's fit, `second_round`) are fitted together with the first's. The
fitted profile gets `[geometry]`, and in `[joints]` the curves as tables (`curve_us`/
`curve_deg`, `curve_fit = "table"`, 33 nodes over each servo's pulse range: 62.5 µs apart
over 500–2500 µs, so that the piecewise-linear table follows a higher-order curve) and
`dead_band_deg`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fivebar_host.calibrate.fit import replace_value
from fivebar_host.calibrate.measure import Measured, MeasurementError, PatternMarks
from fivebar_host.calibrate.pattern import (
    DIGIT_GAP,
    DIGIT_H,
    DIGIT_W,
    Mark,
    Pattern,
    PatternError,
    digit_strokes,
    pattern_mode,
    svg_text,
)
from fivebar_host.compile import CompileOptions, Job, compile_job, write_atomic
from fivebar_host.config import ConfigError, Profile, load_profile
from fivebar_host.joints import ServoJoints
from kinematics.arrays import FloatArray
from kinematics.calibration import CalibrationError
from kinematics.calibration_analysis import SafeGrid
from kinematics.extension import ExtendedFiveBar
from kinematics.servo import ServoError
from kinematics.servo_calibration import (
    MIN_SERVO_MARKS,
    SERVO_PARAM_NAMES,
    ServoFit,
    ServoMachine,
    ServoMarks,
    approach_signs,
    fit_servo,
    pattern_points,
)

#: Length of each tick, mm, and how far inside the joint limits the marks stay, rad.
TICK_MM = 3.0
LIMIT_INSET_RAD = math.radians(8.0)


def servo_joints(profile: Profile) -> ServoJoints:
    """The profile's servos (a `CalibrationError` for a stepper profile)."""
    if profile.joints is None:
        raise CalibrationError(f"{profile.source}: not a servo profile")
    return profile.joints


def servo_nominal(profile: Profile) -> ServoMachine:
    """The profile as a servo model: its geometry, each curve as a cubic about 1500 µs, its
    dead bands."""
    j = servo_joints(profile)
    g = profile.geometry
    geo = g if isinstance(g, ExtendedFiveBar) else ExtendedFiveBar(g.a1, g.b1, g.a2, g.b2, g.w)
    return ServoMachine.from_curves(geo, (j.joints[0].curve, j.joints[1].curve),
                                    (j.joints[0].dead_band_rad, j.joints[1].dead_band_rad),
                                    (1500.0, 1500.0))


def _tick(model: ServoMachine, centre: FloatArray, s: FloatArray, mode: str, assembly: str
          ) -> FloatArray:
    """The tick ending at `centre` whose pen direction turns the joints with signs `s`."""
    fb = model.fivebar()
    th = np.asarray(fb.inverse_batch(centre[None, :], mode).require(centre[None, :]))[0]
    back = fb.forward_batch(np.array([th - 1e-3 * s]), assembly)
    d = centre - np.asarray(back.points)[0]
    return np.array([centre - TICK_MM * d / np.linalg.norm(d), centre])


def _label_corner(start: FloatArray, middle: FloatArray, n: int) -> tuple[float, float]:
    """Bottom-left corner of tick n's number: beside the tick's start, towards the middle of
    the pattern (the marks at the edge of the reach keep their numbers inside it)."""
    w = len(str(n)) * (DIGIT_W + DIGIT_GAP)
    v = middle - start
    v = v / max(float(np.linalg.norm(v)), 1e-9)
    centre = start + v * (1.0 + 0.5 * max(w, DIGIT_H))
    return float(centre[0] - 0.5 * w), float(centre[1] - 0.5 * DIGIT_H)


def _candidates(profile: Profile, model: ServoMachine, m: str, count: int) -> FloatArray:
    """Candidate mark centres spread over the joint limits (`pattern_points`, three per
    mark, `LIMIT_INSET_RAD` inside the limits)."""
    k = profile.kinematics
    lim = tuple((lo + LIMIT_INSET_RAD, hi - LIMIT_INSET_RAD)
                for lo, hi in profile.motors.limits_rad)
    try:
        return pattern_points(model, m, k.assembly, lim,  # type: ignore[arg-type]
                              (max(k.min_type1_margin_rad, math.radians(15.0)),
                               max(k.min_type2_margin_rad, math.radians(20.0))), 3 * count)
    except CalibrationError as e:
        raise PatternError(f"working mode {m}: {e}") from e


def _layout_ticks(profile: Profile, model: ServoMachine, m: str, count: int,
                  given: FloatArray | None = None) -> tuple[FloatArray, list[FloatArray]]:
    """Mark centres (count, 2) and the strokes (ticks and numbers): candidates (`given`, or
    `_candidates`) kept in turn while the tick and its number lie where the profile reaches
    safely; the approach signs go in that order. With `given` centres (a second round) all
    that fit are kept, at least `MIN_SERVO_MARKS`."""
    k = profile.kinematics
    cand = _candidates(profile, model, m, count) if given is None else given
    count = count if given is None else given.shape[0]
    fb = model.fivebar()
    signs = approach_signs(count)
    middle = cand.mean(axis=0)
    centres: list[FloatArray] = []
    strokes: list[FloatArray] = []
    for c in np.round(cand, 3):  # the SVG's precision: the centre is a target exactly
        n = len(centres) + 1
        tick = _tick(model, c, signs[n - 1], m, k.assembly)
        label = digit_strokes(n, *_label_corner(tick[0], middle, n))
        pts = np.concatenate([tick, *label])
        inv = fb.inverse_batch(pts, m)
        if not inv.valid.all():
            continue
        sm = fb.singularity_margins(inv.angles, pts)
        if (np.abs(sm[:, :2]) < k.min_type1_margin_rad).any() or (
                np.abs(sm[:, 2]) < k.min_type2_margin_rad).any():
            continue
        centres.append(c)
        strokes.append(tick)
        strokes.extend(label)
        if len(centres) == count:
            return np.array(centres), strokes
    if given is not None and len(centres) >= MIN_SERVO_MARKS:
        return np.array(centres), strokes
    raise PatternError(f"working mode {m}: room for only {len(centres)} ticks; make fewer "
                       "(--count)")


def make_servo_pattern(profile: Profile, svg_path: Path, *, mode: str | None = None,
                       count: int = 60, centres_from: FloatArray | None = None
                       ) -> tuple[Pattern, list[dict[str, list[float]]]]:
    """Lay out the ticks, write the SVG and compile it the way `fivebar plot` will; the
    pattern and each mark's servo fields (`servo_mark_fields`). `centres_from`: a second
    round's marks (mm, machine frame): the first round's, drawn again with the pulses the
    profile (the first round's fit) sends there (docs/calibration.md)."""
    m = pattern_mode(profile, mode)
    model = servo_nominal(profile)
    centres, strokes = _layout_ticks(profile, model, m, count, centres_from)
    count = centres.shape[0]
    allpts = np.concatenate(strokes)
    x0, y0 = (float(math.floor(v)) - 2.0 for v in allpts.min(axis=0))
    x1, y1 = (float(math.ceil(v)) + 2.0 for v in allpts.max(axis=0))
    origin, page = (x0, y0), (x1 - x0, y1 - y0)
    note = (f"fivebar servo calibration pattern, {count} ticks (measure each tick's end), "
            f"working mode {m}: plot 1:1 with --origin {x0:g},{y0:g} --mode {m} --keep-order "
            f"and the profile {profile.source}")
    write_atomic(svg_path, svg_text(strokes, origin, page, note))
    job = compile_job(svg_path, profile, CompileOptions(origin_mm=origin, mode=m,
                                                        keep_order=True, validate=False))
    signs = approach_signs(count)
    marks, fields = [], []
    for n, c in enumerate(centres, start=1):
        hit = np.flatnonzero(np.max(np.abs(job.points_mm - c), axis=1) < 1e-6)
        hit = hit[hit > 0]
        if hit.size == 0:
            raise PatternError(f"tick {n} at ({c[0]:.3f}, {c[1]:.3f}) mm is not a target of "
                               "the compiled pattern")
        i = int(hit[0])
        fields.append(servo_mark_fields(profile, job, i))
        if fields[-1]["approach"] != list(signs[n - 1]):
            raise PatternError(f"tick {n}: the compiled pattern comes into it from the other "
                               "side than planned")
        marks.append(Mark(n, float(c[0]), float(c[1]),
                          (int(job.steps[i, 0]), int(job.steps[i, 1]))))
    grid = SafeGrid(np.zeros(1), np.zeros(1), np.zeros((1, 1), dtype=bool))
    return Pattern(marks, origin, page, m, strokes, grid), fields


def servo_plot_command(svg: Path, profile: Profile, pattern: Pattern) -> str:
    """The command that plots the servo pattern as the marks file assumes: in file order
    and direction (`--keep-order`: each tick is drawn towards its mark)."""
    return (f"fivebar plot {svg} --config {profile.source} --origin "
            f"{pattern.origin_mm[0]:g},{pattern.origin_mm[1]:g} --mode {pattern.mode} "
            "--keep-order --port PORT")


def servo_mark_fields(profile: Profile, job: Job, row: int) -> dict[str, list[float]]:
    """`pulses_us` and `approach` of the job's target `row`: the pulses the servo firmware
    is sent there (`ServoMap`: the motor counts, the dead band's take-up included, through
    the curves) and the sign of each joint's last move into it."""
    from fivebar_host.controllers.fivebar.servo import TICKS_PER_US, ServoMap

    smap = ServoMap.of(servo_joints(profile), profile)
    out_p, out_s = [], []
    for k in range(2):
        out_p.append(float(smap.ticks(k, job.steps[row:row + 1, k])[0]) / TICKS_PER_US)
        d = np.diff(job.angles_rad[: row + 1, k])
        moved = d[np.abs(d) > 1e-12]
        out_s.append(float(np.sign(moved[-1])) if moved.size else 0.0)
    return {"pulses_us": out_p, "approach": out_s}


@dataclass(frozen=True)
class ServoCalibration:
    """A finished servo fit and the measured marks it used."""

    result: ServoFit
    measured: Measured
    nominal: ServoMachine
    pulses: FloatArray  # (N, 2) µs the measured marks (of every round) were drawn with
    rounds: int = 1


def servo_marks(pattern: PatternMarks, measured: Measured) -> ServoMarks:
    """The fit's input from the marks file's servo fields and the measured positions."""
    rows = pattern.doc["marks"]
    try:
        p = np.array([rows[i]["pulses_us"] for i in measured.index], dtype=np.float64)
        s = np.array([rows[i]["approach"] for i in measured.index], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as e:
        raise MeasurementError(f"{pattern.source}: not a servo pattern (marks need "
                               "pulses_us and approach: make it with `fivebar calibrate "
                               "pattern` and the servo profile)") from e
    if p.shape != (measured.index.size, 2) or s.shape != p.shape:
        raise MeasurementError(f"{pattern.source}: pulses_us and approach must be pairs")
    if np.any(s == 0.0):
        raise MeasurementError(f"{pattern.source}: a mark no joint moved into (approach 0)")
    return ServoMarks(p, s, measured.xy, pattern.assembly)


def calibrate_servo(profile: Profile, pattern: PatternMarks, measured: Measured, *,
                    sigma: float | None = None, max_iterations: int = 200,
                    also: Sequence[tuple[PatternMarks, Measured]] = ()) -> ServoCalibration:
    """Fit the servo model to the measured ticks (module doc); `also`: the ticks of other
    rounds of the pattern (each its own sheet, placed on its own), fitted together."""
    rounds = [(pattern, measured), *also]
    for pat, _ in rounds:
        if pat.assembly != profile.kinematics.assembly:
            raise MeasurementError(f"{pat.source}: made for assembly {pat.assembly}, the "
                                   f"profile {profile.source} is "
                                   f"{profile.kinematics.assembly}")
    nominal = servo_nominal(profile)
    fit_ext = isinstance(profile.geometry, ExtendedFiveBar) and profile.geometry.extension > 0
    parts = [servo_marks(pat, meas) for pat, meas in rounds]
    data = ServoMarks(np.concatenate([d.pulses for d in parts]),
                      np.concatenate([d.approach for d in parts]),
                      np.concatenate([d.measured for d in parts]), pattern.assembly,
                      np.concatenate([np.full(d.n, j) for j, d in enumerate(parts)]))
    res = fit_servo(nominal, data, sigma=sigma, fit_extension=fit_ext,
                    max_iterations=max_iterations)
    return ServoCalibration(res, measured, nominal, data.pulses, len(rounds))


def servo_report_lines(cal: ServoCalibration) -> list[str]:
    """Fitted values with their 1σ, the dead bands and the curves' largest departures from
    the profile's."""
    r = cal.result
    x, sd = r.x, r.std
    rounds = f" in {cal.rounds} rounds" if cal.rounds > 1 else ""
    lines = [f"servo fit: {cal.pulses.shape[0]} marks{rounds}, rms residual "
             f"{r.rms_before_mm:.4f} mm (profile) → {r.rms_after_mm:.4f} mm (fitted), σ = "
             f"{r.sigma:.4f} mm ({r.sigma_source}), {r.iterations} iterations; curve orders "
             f"{r.orders[0]} and {r.orders[1]} (least BIC of {len(r.criteria)} tried)"]
    for i, name in enumerate(SERVO_PARAM_NAMES[:7]):
        if not r.free[i]:
            continue
        if name == "gamma":
            lines.append(f"  extension_angle = {math.degrees(x[i]):9.4f}° ± "
                         f"{math.degrees(sd[i]):.4f}°")
        else:
            lines.append(f"  {name:<15} = {x[i]:9.4f} mm ± {sd[i]:.4f} mm")
    for k in range(2):
        lines.append(f"  dead band {k + 1}     = {math.degrees(r.dead_band[k]):9.4f}° ± "
                     f"{math.degrees(r.dead_band_std[k]):.4f}°")
    for k in range(2):
        p = np.linspace(*_measured_range(cal, k), 9)
        pp = np.column_stack((p, p))
        d = np.degrees(r.machine.curve_angles(pp)[:, k] - cal.nominal.curve_angles(pp)[:, k])
        std = np.degrees(r.curve_std(k, p))
        lines.append(f"  servo {k + 1} curve over {p[0]:.0f}–{p[-1]:.0f} µs: off the "
                     f"profile's by up to {np.max(np.abs(d)):.3f}° (1σ ≤ {std.max():.3f}°)")
    return lines


def _measured_range(cal: ServoCalibration, k: int) -> tuple[float, float]:
    """The pulses servo k was measured over (the fitted curve extrapolates beyond)."""
    return float(cal.pulses[:, k].min()), float(cal.pulses[:, k].max())


def _set_value(text: str, table: str, key: str, value: str) -> str:
    """Replace `key = …` inside `[table]`, or add it right after the table's header."""
    try:
        return replace_value(text, table, key, value)
    except ConfigError:
        pass
    head = re.search(rf"^\s*\[{re.escape(table)}\][^\n]*\n", text, flags=re.MULTILINE)
    if head is None:
        raise ConfigError(f"[{table}] not found in the profile text")
    return text[:head.end()] + f"{key} = {value}\n" + text[head.end():]


def fitted_servo_text(profile: Profile, profile_text: str, res: ServoFit, note: str,
                      samples: int = 33) -> str:
    """The profile text with the fitted [geometry] and the [joints] curves (tables over
    each servo's pulse range) and dead bands (module doc)."""
    m = res.machine
    text = profile_text
    for name, v in zip(("a1", "b1", "a2", "b2", "w"), m.geometry[:5], strict=True):
        text = _set_value(text, "geometry", name, f"{v:.4f}")
    if res.free[5]:
        text = _set_value(text, "geometry", "extension", f"{m.geometry[5]:.4f}")
        text = _set_value(text, "geometry", "extension_angle_deg",
                          f"{math.degrees(m.geometry[6]):.4f}")
    j = servo_joints(profile)
    us, deg = [], []
    for k, joint in enumerate(j.joints):
        lo, hi = joint.curve.range_us
        try:
            c = m.curve(k, (lo, hi), samples)
        except ServoError as e:
            raise CalibrationError(f"servo {k + 1}: the fitted curve is not monotone over "
                                   f"{lo:g}–{hi:g} µs ({e}); nothing was written") from e
        us.append("[" + ", ".join(f"{p:.1f}" for p in c.pulse_us) + "]")
        deg.append("[" + ", ".join(f"{math.degrees(a):.3f}" for a in c.angle_rad) + "]")
    text = _set_value(text, "joints", "curve_us", "[" + ", ".join(us) + "]")
    text = _set_value(text, "joints", "curve_deg", "[" + ", ".join(deg) + "]")
    text = _set_value(text, "joints", "curve_fit", '"table"')
    dead = ", ".join(f"{math.degrees(v):.3f}" for v in m.dead_band)
    text = _set_value(text, "joints", "dead_band_deg", f"[{dead}]")
    return "".join(f"# {line}\n" for line in note.splitlines()) + text


def write_fitted_servo(path: Path, profile: Profile, cal: ServoCalibration, note: str
                       ) -> Profile:
    """Write the fitted servo profile after loading it back (it must be a valid profile,
    partial ones with the bundled default's keys, as `load_profile` reads them)."""
    import tempfile

    text = fitted_servo_text(profile, Path(profile.source).read_text(encoding="utf-8"),
                             cal.result, note)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            check = Path(tmp) / path.name
            check.write_text(text, encoding="utf-8")
            fitted = load_profile(check)
    except ConfigError as e:
        raise CalibrationError(f"the fitted values do not make a valid profile ({e}); "
                               "nothing was written") from e
    write_atomic(path, text)
    return fitted
