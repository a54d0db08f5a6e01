"""`fivebar serve`: the plotter daemon in the foreground (docs/serve.md)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from fivebar_host.cli.common import config_option, fail, main
from fivebar_host.errors import FivebarError


@main.command("serve")
@click.option("--port", "port_url", required=True, metavar="PORT",
              help="The machine's serial port or URL (as for plot --port).")
@config_option
@click.option("--listen", default="127.0.0.1:8765", show_default=True, metavar="HOST:PORT",
              help="Address of the HTTP API. Any non-loopback address requires the token on "
              "every request.")
@click.option("--state-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Database and token (default: $STATE_DIRECTORY, else "
              "~/.local/state/fivebar).")
@click.option("--require-token", is_flag=True,
              help="Require the token on loopback too (a computer shared by several users).")
@click.option("--max-upload-mb", type=click.FloatRange(min=0.001, max=1024.0), default=8.0,
              show_default=True, help="Largest accepted drawing upload.")
@click.option("--auto-resume", is_flag=True,
              help="On start, continue held jobs that have a resume point (after a stop, a "
              "crash or a fault) without waiting for a resume request.")
@click.option("--banner-timeout", type=click.FloatRange(min=0.1, max=60.0), default=None,
              help="Seconds to wait for the firmware's banner (default: the profile's).")
@click.option("--access-log", is_flag=True, help="Log every HTTP request.")
@click.option("--ready-file", type=click.Path(dir_okay=False, path_type=Path), default=None,
              hidden=True)
def serve(port_url: str, config_path: Path | None, listen: str, state_dir: Path | None,
          require_token: bool, max_upload_mb: float, auto_resume: bool,
          banner_timeout: float | None, access_log: bool, ready_file: Path | None) -> None:
    """Run the plotter daemon in the foreground: own the machine's port, queue and run jobs,
    serve the HTTP + JSON API (docs/serve.md). Logs go to stderr; SIGTERM stops the running
    job at a segment boundary with the laser off, then exits."""
    from fivebar_host.server.daemon import ServeConfig, run_foreground

    cfg = ServeConfig(port_url=port_url, profile_path=config_path, listen=listen,
                      state_dir=state_dir, require_token=require_token,
                      max_upload_bytes=int(max_upload_mb * 1024 * 1024),
                      auto_resume=auto_resume, banner_timeout_s=banner_timeout,
                      ready_file=ready_file, access_log=access_log)
    try:
        code = run_foreground(cfg)
    except FivebarError as e:
        fail(str(e))
        return
    sys.exit(code)
