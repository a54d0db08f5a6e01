"""`fivebar calibrate pattern|fit|check`: find the machine's real link lengths and home angles
(for a servo profile: each servo's pulse ↔ angle curve and dead band, and the link lengths,
`fivebar_host.calibrate.servo`) from a drawn test pattern (docs/calibration.md). Thin wrappers over
`fivebar_host.calibrate` (pipeline steps) and `kinematics.calibration` (the math)."""

from __future__ import annotations

import json
from datetime import date
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fivebar_host.cli.common import config_option, handle_errors, load, main

if TYPE_CHECKING:
    from fivebar_host.calibrate.measure import Measured, PatternMarks
    from fivebar_host.config import Profile


@main.group("calibrate")
def calibrate() -> None:
    """Calibrate link lengths and home angles (servos: curves and dead bands) from a drawn
    test pattern."""


@calibrate.command("pattern")
@config_option
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="The pattern drawing (SVG) to plot.")
@click.option("--marks", "marks_path", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="Where to write the marks file (JSON).")
@click.option("--count", type=click.IntRange(25, 200), default=None,
              help="Number of marks (default: 30; 60 ticks on a servo profile, which fits "
              "twice the unknowns).")
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--"]), default=None,
              help="Working mode (default: the profile's).")
@click.option("--second-round", "first_marks", default=None,
              type=click.Path(dir_okay=False, path_type=Path), metavar="MARKS",
              help="Servo profiles: the first round's marks file; its marks drawn again with "
              "the pulses of the profile, the first round's fit (then `calibrate fit "
              "--also`).")
@handle_errors
def pattern_cmd(config_path: Path | None, output: Path, marks_path: Path, count: int | None,
                mode: str | None, first_marks: Path | None) -> None:
    """Write a test pattern of numbered marks over the safe region and its marks file."""
    from fivebar_host.calibrate.pattern import (
        make_pattern,
        marks_document,
        plot_command,
        write_marks,
    )

    prof = load(config_path)
    if first_marks is not None and prof.joints is None:
        raise click.UsageError("--second-round is for servo profiles")
    if prof.joints is not None:  # servos: ticks with planned approaches (calibrate/servo.py)
        from fivebar_host.calibrate.measure import read_pattern
        from fivebar_host.calibrate.servo import make_servo_pattern, servo_plot_command

        given = None
        if first_marks is not None:
            first = read_pattern(first_marks)
            given = first.nominal
            mode = mode or first.mode
        pat, fields = make_servo_pattern(prof, output, mode=mode, count=count or 60,
                                         centres_from=given)
        doc = marks_document(prof, pat, output)
        doc["plot_command"] = servo_plot_command(output, prof, pat)
        for mk, f in zip(doc["marks"], fields, strict=True):
            mk.update(f)
        write_marks(marks_path, doc)
        click.echo(f"wrote {output} ({len(pat.marks)} ticks, {pat.page_mm[0]:g} × "
                   f"{pat.page_mm[1]:g} mm page, working mode {pat.mode}) and {marks_path}")
        click.echo(f"plot it 1:1 with: {doc['plot_command']}")
        click.echo("then measure each numbered tick's end (where the pen stopped) and write "
                   "a CSV with the header id,x_mm,y_mm")
        if first_marks is None:
            click.echo(f"after `calibrate fit`, draw the same marks again with the fitted "
                       f"profile: calibrate pattern --config FITTED --second-round "
                       f"{marks_path} (docs/calibration.md: two rounds of 30)")
        return
    pat = make_pattern(prof, output, mode=mode, count=count or 30)
    write_marks(marks_path, marks_document(prof, pat, output))
    click.echo(f"wrote {output} ({len(pat.marks)} marks, {pat.page_mm[0]:g} × "
               f"{pat.page_mm[1]:g} mm page, working mode {pat.mode}) and {marks_path}")
    click.echo(f"plot it 1:1 with: {plot_command(output, prof, pat)}")
    click.echo("then measure each cross's centre on the paper and write a CSV with the "
               "header id,x_mm,y_mm")


@calibrate.command("fit")
@click.argument("measured", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--marks", "marks_path", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="The marks file written by `calibrate pattern`.")
@config_option
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="Where to write the fitted profile (TOML).")
@click.option("--sigma", type=click.FloatRange(min=0.0, min_open=True), default=None,
              help="Measurement standard deviation, mm, to scale the uncertainties by "
              "(default: the residual standard deviation).")
@click.option("--max-iterations", type=click.IntRange(1, 10_000), default=100,
              show_default=True, help="Give up (and write nothing) after this many.")
@click.option("--also", nargs=2, multiple=True,
              type=click.Path(dir_okay=False, path_type=Path), metavar="MEASURED MARKS",
              help="Servo profiles: the measured CSV and marks file of another round of the "
              "pattern, fitted together with this one (repeatable).")
@handle_errors
def fit_cmd(measured: Path, marks_path: Path, config_path: Path | None, output: Path,
            sigma: float | None, max_iterations: int,
            also: tuple[tuple[Path, Path], ...]) -> None:
    """Fit a1, b1, a2, b2, w and the home angles (servos: the curves and dead bands) to
    MEASURED (CSV id,x_mm,y_mm)."""
    from fivebar_host.calibrate.fit import calibrate as run_fit
    from fivebar_host.calibrate.fit import report_lines, write_fitted
    from fivebar_host.calibrate.measure import read_measured, read_pattern

    prof = load(config_path)
    pat = read_pattern(marks_path)
    meas = read_measured(measured, pat)
    if also and prof.joints is None:
        raise click.UsageError("--also is for servo profiles")
    if prof.joints is not None:
        more = []
        for m_csv, m_json in also:
            p2 = read_pattern(m_json)
            more.append((p2, read_measured(m_csv, p2)))
        _fit_servo(prof, pat, meas, measured, marks_path, output, sigma, max_iterations, more)
        return
    cal = run_fit(prof, pat, meas, sigma=sigma, max_iterations=max_iterations)
    for line in report_lines(cal, prof):
        click.echo(line)
    note = (f"[geometry] and [motors] home_deg fitted by `fivebar calibrate fit` on "
            f"{date.today().isoformat()}\nfrom {int(cal.kept.sum())} marks of {measured} "
            f"(pattern {marks_path}), starting from {prof.source}; rms residual "
            f"{cal.result.rms_after_mm:.4f} mm")
    write_fitted(output, prof, cal, note)
    click.echo(f"wrote {output}")


def _fit_servo(prof: Profile, pat: PatternMarks, meas: Measured, measured: Path, marks_path: Path,
               output: Path, sigma: float | None, max_iterations: int,
               also: list[tuple[PatternMarks, Measured]]) -> None:
    """`calibrate fit` on a servo profile: curves, dead bands and geometry."""
    from fivebar_host.calibrate.servo import (
        calibrate_servo,
        servo_report_lines,
        write_fitted_servo,
    )

    cal = calibrate_servo(prof, pat, meas, sigma=sigma, max_iterations=max_iterations,
                          also=also)
    for line in servo_report_lines(cal):
        click.echo(line)
    note = (f"[geometry] and [joints] curves and dead bands fitted by `fivebar calibrate "
            f"fit` on {date.today().isoformat()}\nfrom {cal.pulses.shape[0]} marks of "
            f"{measured} (pattern {marks_path})"
            + "".join(f" and {m.source}" for _, m in also)
            + f", starting from {prof.source}; rms residual "
            f"{cal.result.rms_after_mm:.4f} mm")
    write_fitted_servo(output, prof, cal, note)
    click.echo(f"wrote {output}")


@calibrate.command("check")
@config_option
@click.option("--old", "old_path", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="The profile before calibration.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("calibration-check.png"), show_default=True,
              help="The error map (PNG).")
@click.option("--marks", "marks_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Show the marks of this marks file on the map.")
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--"]), default=None,
              help="Working mode (default: the profile's).")
@handle_errors
def check_cmd(config_path: Path | None, old_path: Path, output: Path,
              marks_path: Path | None, mode: str | None) -> None:
    """Map the old profile's predicted drawing error, taking --config (fitted) as true."""
    import numpy as np

    from fivebar_host.calibrate.check import error_map
    from fivebar_host.report.calibration import draw_error_map

    fitted = load(config_path)
    old = load(old_path)
    emap = error_map(fitted, old, mode)
    marks = None
    if marks_path is not None:
        doc = json.loads(marks_path.read_text(encoding="utf-8"))
        marks = np.array([[m["x_mm"], m["y_mm"]] for m in doc.get("marks", [])])
    draw_error_map(emap, output, f"drawing-shape error of {old_path} on the machine "
                   f"{fitted.source}", marks)
    click.echo(f"old profile {old_path} on the machine {fitted.source} (working mode "
               f"{emap.mode}): drawing-shape error max {emap.max_mm:.3f} mm, median "
               f"{emap.median_mm:.3f} mm over the safe region")
    click.echo(f"map {output}")
