"""`fivebar workspace`, `fivebar design` and `fivebar linkage`: analysis of a machine
profile, link-length search, and general linkages through the n-bar solver."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import click

from fivebar_host.cli.common import (
    config_option,
    fail,
    handle_errors,
    landscape_option,
    load,
    main,
    page_size,
)


@main.command("workspace")
@config_option
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("workspace.png"), show_default=True, help="Picture (PNG).")
@click.option("--no-plot", is_flag=True, help="Print the figures only, draw nothing.")
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--", "auto"]), default=None,
              help="Working mode to analyse in detail (default: the profile's).")
@click.option("--page", "page_text", default=None, metavar="SIZE",
              help="Also check that a page fits (exit status 1 if not): WxH in mm or with "
              "units (200x150, 8.5inx11in), or a name (A4, A5, letter …).")
@landscape_option
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Per-grid-point numbers (CSV).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="The printed figures as JSON.")
@click.option("--resolution", type=click.FloatRange(min=0.01), default=None,
              help="Grid pitch in mm (default: ~400 cells across the workspace).")
@click.option("--delta-deg", type=click.FloatRange(min=0.0, min_open=True, max=45.0),
              default=5.0, show_default=True,
              help="Motor error for the ±δ sensitivity traces (thesis Sec. 4.1).")
@handle_errors
def workspace(config_path: Path | None, output: Path, no_plot: bool, mode: str | None,
              page_text: str | None, landscape: bool, csv_path: Path | None, json_path: Path | None,
              resolution: float | None, delta_deg: float) -> None:
    """Workspace per working mode, singularity curves, safe region, largest page rectangle,
    transmission-angle and error-sensitivity maps for the machine profile."""
    from fivebar_host.report.text import workspace as ws
    from fivebar_host.report.workspace import plot_workspace
    from kinematics.workspace import workspace_report

    prof = load(config_path)
    page = page_size(page_text, landscape) if page_text is not None else None
    kin = prof.kinematics
    rep = workspace_report(
        prof.geometry, mode or kin.working_mode, kin.min_type1_margin_rad,
        kin.min_type2_margin_rad, prof.motors.limits_rad, prof.motors.rad_per_step,
        delta_rad=math.radians(delta_deg), resolution_mm=resolution, page=page,
        assembly=kin.assembly)
    for line in ws.summary_lines(rep, prof.geometry):
        click.echo(line)
    if csv_path is not None:
        n = ws.write_csv(csv_path, rep)
        click.echo(f"wrote {csv_path} ({n} grid points)")
    if json_path is not None:
        ws.write_json(json_path, ws.summary_dict(rep, prof.geometry))
        click.echo(f"wrote {json_path}")
    if not no_plot:
        plot_workspace(rep, prof.geometry, output, title=str(prof.source))
        click.echo(f"wrote {output}")
    if page is not None and rep.page is None:
        sys.exit(1)


@main.command("design")
@click.option("--page", "page_text", required=True, metavar="SIZE",
              help="Page that must fit inside the safe workspace: WxH in mm or with units "
              "(200x150, 8.5inx11in), or a name (A4, A5, letter …).")
@landscape_option
@click.option("--margin-deg", type=click.FloatRange(min=0.0, max=89.0), default=None,
              help="Minimum margin to both singularity types (default: the profile's).")
@click.option("--motor-spacing", default=None, metavar="W|LO:HI",
              help="Fix the motor spacing w (mm) or search it in LO:HI (default: searched).")
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--"]), default=None,
              help="Working mode (default: the profile's; '+-' if it says auto).")
@click.option("--candidates", type=click.IntRange(min=1, max=1_000_000), default=10_000,
              show_default=True, help="Random candidate designs to evaluate.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option("--top", type=click.IntRange(min=1, max=50), default=5, show_default=True,
              help="How many verified candidates to list.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("design.toml"), show_default=True,
              help="Profile (TOML) written for the best candidate.")
@config_option
@handle_errors
def design(page_text: str, landscape: bool, margin_deg: float | None, motor_spacing: str | None,
           mode: str | None, candidates: int, seed: int, top: int, output: Path,
           config_path: Path | None) -> None:
    """Search link lengths (a1, b1, a2, b2, w) whose safe workspace holds the page, ranked by
    worst transmission angle and worst error sensitivity over it; write the best as a profile
    (motors, motion, laser and serial settings are copied from --config)."""
    import time

    from fivebar_host.report.text import workspace as ws
    from kinematics.design import design_search

    prof = load(config_path)
    pw, ph = page_size(page_text, landscape)
    spacing: float | tuple[float, float] | None = None
    if motor_spacing is not None:
        try:
            vals = [float(v) for v in motor_spacing.split(":")]
        except ValueError:
            raise click.BadParameter(f"--motor-spacing must be W or LO:HI in mm; got "
                                     f"{motor_spacing!r}") from None
        if len(vals) not in (1, 2) or not all(math.isfinite(v) and v > 0 for v in vals) or (
                len(vals) == 2 and vals[0] >= vals[1]):
            raise click.BadParameter(f"--motor-spacing must be W or LO:HI (LO < HI, positive); "
                                     f"got {motor_spacing!r}")
        spacing = vals[0] if len(vals) == 1 else (vals[0], vals[1])
    kin = prof.kinematics
    m = mode or (kin.working_mode if kin.working_mode != "auto" else "+-")
    min1 = math.radians(margin_deg) if margin_deg is not None else kin.min_type1_margin_rad
    min2 = math.radians(margin_deg) if margin_deg is not None else kin.min_type2_margin_rad
    t0 = time.perf_counter()
    res = design_search(pw, ph, m, min1, min2, prof.motors.limits_rad, prof.motors.rad_per_step,
                        n_candidates=candidates, motor_spacing=spacing, seed=seed, top=top)
    seconds = time.perf_counter() - t0
    for line in ws.design_lines(res, seconds):
        click.echo(line)
    if not res.candidates:
        fail(f"no design among {candidates} candidates fits a {pw:g} x {ph:g} mm page in mode "
              f"{m} with these margins and joint limits; try more --candidates, a smaller "
              "page, smaller --margin-deg or another --motor-spacing", code=1)
        return
    best = res.candidates[0]
    text = ws.design_profile_text(Path(prof.source).read_text(encoding="utf-8"), prof.source,
                                  best, min1, min2)
    output.write_text(text, encoding="utf-8")
    click.echo(f"wrote {output} (rank 1); check it with: fivebar workspace --config {output} "
               f"--page {pw:g}x{ph:g}")


@main.group()
def linkage() -> None:
    """General linkages through the n-bar solver (mechanism files: docs/mechanisms.md)."""


@linkage.command("simulate")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--steps", type=click.IntRange(min=1), default=None,
              help="Input steps to take (default: the file's [simulation] steps).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write every step (inputs, joints, residual, status) to a .csv or .json.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Draw the mechanism and the tracer curve (.png, .svg, .pdf).")
@handle_errors
def linkage_simulate(file: Path, steps: int | None, output: Path | None,
                     plot_path: Path | None) -> None:
    """Simulate the mechanism FILE from its initial pose in equal input steps.

    Prints a summary; a motion limit is reported with its input value (exit 0), inconsistent
    constraints (nothing could move) exit with 1, an unusable file with 2.
    """
    from fivebar_host.report.linkage import plot_simulation
    from fivebar_host.report.text.linkage import load_mechanism, summary, write_result
    from kinematics.nbar import sweep

    if output is not None and output.suffix.lower() not in (".csv", ".json"):
        fail(f"{output}: -o must end in .csv or .json")
        return
    mech = load_mechanism(file)
    sim = sweep(mech, steps)
    click.echo(summary(sim))
    if output is not None:
        click.echo(f"wrote {write_result(sim, output)}")
    if plot_path is not None:
        click.echo(f"wrote {plot_simulation(sim, plot_path)}")
    if any(lim.kind == "inconsistent" for lim in sim.limits):
        sys.exit(1)
