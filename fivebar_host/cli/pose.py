"""`fivebar config check` / `config show`, `fivebar ik` and `fivebar fk`: the profile and
single poses."""

from __future__ import annotations

import math
from pathlib import Path

import click
import numpy as np

from fivebar_host.cli.common import config_option, handle_errors, load, main
from fivebar_host.config import load_profile
from fivebar_host.config_show import describe, show_lines


@main.group()
def config() -> None:
    """Machine profiles."""


@config.command("check")
@click.argument("path", type=click.Path(dir_okay=False, path_type=Path))
@handle_errors
def config_check(path: Path) -> None:
    """Parse and validate the profile PATH; print it, or the error naming the key."""
    click.echo(describe(load_profile(path)))


@config.command("show")
@config_option
@handle_errors
def config_show(config_path: Path | None) -> None:
    """Every key of the profile with its value and where it came from: the profile itself,
    or the bundled default that a partial profile inherits."""
    for line in show_lines(config_path):
        click.echo(line)


@main.command("ik")
@click.argument("x_mm", type=float)
@click.argument("y_mm", type=float)
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--"]), default=None,
              help="Working mode (default: the profile's).")
@config_option
@handle_errors
def ik(x_mm: float, y_mm: float, mode: str | None, config_path: Path | None) -> None:
    """Motor angles (and steps from home) that put the pen at X_MM, Y_MM."""
    prof = load(config_path)
    fb = prof.geometry
    m = mode or (prof.kinematics.working_mode if prof.kinematics.working_mode != "auto"
                 else "+-")
    th = np.asarray(fb.inverse((x_mm, y_mm), m))
    margins = fb.singularity_margins(th, (x_mm, y_mm))[0]
    mu = fb.transmission_angles(th, (x_mm, y_mm))[0]
    steps = [round((th[i] - prof.motors.home_rad[i]) / prof.motors.rad_per_step)
             for i in range(2)]
    click.echo(f"mode {m}: θ1 = {math.degrees(th[0]):.6f}°, θ2 = {math.degrees(th[1]):.6f}°")
    click.echo(f"steps from home: A = {steps[0]}, B = {steps[1]}")
    click.echo(f"transmission angles: μ1 = {math.degrees(mu[0]):.3f}°, "
               f"μ2 = {math.degrees(mu[1]):.3f}°")
    click.echo("singularity margins: type 1 arm 1 = {:.3f}°, arm 2 = {:.3f}°, type 2 = {:.3f}°"
               .format(*np.degrees(margins)))


@main.command("fk")
@click.argument("theta1_deg", type=float)
@click.argument("theta2_deg", type=float)
@click.option("--assembly", type=click.Choice(["+", "-"]), default=None,
              help="Assembly mode: '+' puts P left of R1→R2 (default: the profile's).")
@config_option
@handle_errors
def fk(theta1_deg: float, theta2_deg: float, assembly: str | None,
       config_path: Path | None) -> None:
    """Pen position for motor angles THETA1_DEG, THETA2_DEG (from +x, counter-clockwise)."""
    prof = load(config_path)
    fb = prof.geometry
    assembly = assembly or prof.kinematics.assembly
    th = np.radians([theta1_deg, theta2_deg])
    p = np.asarray(fb.forward(th, assembly))
    modes = fb.mode_of(p, th)[0]
    mode = "".join("+" if s > 0 else "-" if s < 0 else "0" for s in modes)
    click.echo(f"P = ({p[0]:.6f}, {p[1]:.6f}) mm  (assembly {assembly}, working mode {mode})")
