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
@handle_errors
def grbl_settings(config_path: Path | None) -> None:
    """Print the $ settings a stock GRBL 1.1 board needs for this profile (send each line
    to the board once; `--controller grbl` checks them against `$$` before every job)."""
    from fivebar_host.controllers.grbl.program import needed_settings

    prof = load(config_path)
    for s in needed_settings(prof):
        click.echo(f"{s.text():<16} ; {s.why}")
