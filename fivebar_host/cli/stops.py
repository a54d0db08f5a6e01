"""The check made before a plot with pen-change stops opens the port.

A pen change waits for a person: it is asked on the terminal (`cli.operator`), and `--yes`
never answers it (`--yes` answers where the arms are, nothing else). Without a terminal
(stdin not a tty: a script, a service) a job with pen-change stops is refused before the port
is opened: plot it on a terminal, through the daemon (`--server`: its pause state waits for
the resume button), or with `--no-pause` to draw through the stops.
"""

from __future__ import annotations

from fivebar_host.cli.operator import terminal
from fivebar_host.compile import Job
from fivebar_host.errors import UsageError


def check_stops(job: Job) -> None:
    """Refuse, before anything moves, a run whose stops nobody could answer (no terminal)."""
    if job.pauses and not terminal():
        names = ", ".join(p.describe() for p in job.pauses)
        raise UsageError(f"{job.file}: the job stops for {len(job.pauses)} pen change(s) "
                         f"a copy (before {names}) and there is no terminal to confirm "
                         "them (stdin is not a tty; --yes does not answer a pen change). "
                         "Run it on a terminal, send it to the daemon with --server, or "
                         "pass --no-pause to draw through the stops")
