"""`fivebar grbl-settings`: the `$` settings a stock GRBL board needs for a profile.

Every machine command takes `--controller fivebar|grbl` (`cli.common.controller_option`);
this is the one command of GRBL's own.
"""

from __future__ import annotations

from pathlib import Path

import click

from fivebar_host.cli.common import config_option, handle_errors, load, main


@main.command("grbl-settings")
@config_option
@click.option("--fluidnc", is_flag=True,
              help="FluidNC's configuration items ($/axes/x/steps_per_mm=...) instead of "
              "GRBL's numbers (grblHAL takes GRBL's).")
@handle_errors
def grbl_settings(config_path: Path | None, fluidnc: bool) -> None:
    """Print the $ settings a GRBL 1.1 or grblHAL board needs for this profile (send each
    line to the board once; `--controller grbl` checks them against `$$` before every job);
    with --fluidnc the FluidNC items and what to check by hand."""
    from fivebar_host.controllers.grbl.dialects import FLUIDNC_MANUAL, FLUIDNC_PATHS
    from fivebar_host.controllers.grbl.program import needed_settings, soft_limits

    prof = load(config_path)
    for s in needed_settings(prof):
        if not fluidnc:
            click.echo(f"{s.text():<16} ; {s.why}")
            continue
        if s.number not in FLUIDNC_PATHS or (s.number in (27, 130, 131)
                                             and not soft_limits(prof)[0]):
            continue
        value = s.text().split("=", 1)[1]
        if s.number == 20:
            value = "true" if s.value else "false"
        click.echo(f"; {s.why}")  # on its own line: a board's receive buffer is small
        for path in FLUIDNC_PATHS[s.number]:
            click.echo(f"${path}={value}")
    if fluidnc:
        click.echo(f"; and by hand: {FLUIDNC_MANUAL}")
