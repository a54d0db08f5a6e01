"""The terminal side of a run's planned stops (`fivebar_host.run.stops`): the pen-change
question, the countdown between copies, and the check made before anything moves.

A pen change waits for a person: it is asked on the terminal ("Layer 2/3 'red': change the
pen, then press Enter (q to stop)"), and `--yes` never answers it (`--yes` answers where
the arms are, nothing else). Without a terminal (stdin not a tty: a script, a service) a
job with pen-change stops is refused before the port is opened: plot it on a terminal,
through the daemon (`--server`: its pause state waits for the resume button), or with
`--no-pause` to draw through the stops.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable

import click

from fivebar_host.compile import Job
from fivebar_host.compile.model import LayerPause
from fivebar_host.errors import UsageError
from fivebar_host.run.stops import Copies


def terminal() -> bool:
    """Whether a person can answer on stdin (a tty)."""
    return sys.stdin.isatty()


def check_stops(job: Job, copies: Copies, controller: str) -> None:
    """Refuse, before anything moves, a run whose stops nobody could answer (no terminal)
    or that the controller cannot run (`--controller grbl` streams the job in one go)."""
    if controller == "grbl" and (job.pauses or copies.count > 1):
        raise UsageError("--controller grbl runs the job in one stream: pen-change stops "
                         "(--layer-pause, '!' layers) and --copies need the fivebar "
                         "firmware; pass --no-pause and --copies 1")
    if job.pauses and not terminal():
        names = ", ".join(p.describe() for p in job.pauses)
        raise UsageError(f"{job.file}: the job stops for {len(job.pauses)} pen change(s) "
                         f"a copy (before {names}) and there is no terminal to confirm "
                         "them (stdin is not a tty; --yes does not answer a pen change). "
                         "Run it on a terminal, send it to the daemon with --server, or "
                         "pass --no-pause to draw through the stops")


def ask_pen_change(pause: LayerPause) -> bool:
    """Ask for the pen change at `pause` (the machine idle, pen up): True to go on, False
    to stop (q, or Ctrl-C while asking). Ctrl-C interrupts the question itself, whatever
    handler the stream had installed for its hold."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        click.echo(f"\npen change: the pen is up and the machine idle before "
                   f"{pause.describe()}.", err=True)
        answer = click.prompt(f"Layer {pause.number}/{pause.of} {pause.name!r}: change the "
                              "pen, then press Enter (q to stop)", default="",
                              show_default=False, err=True)
    except (KeyboardInterrupt, click.Abort, EOFError):
        return False
    finally:
        signal.signal(signal.SIGINT, previous)
    return str(answer).strip().lower() not in ("q", "quit", "stop")


def countdown(copies: Copies) -> Callable[[float], None]:
    """The page delay's display: a line a second on a terminal ("next copy in 12 s"),
    otherwise one line when the wait starts."""
    shown = {"s": -1}

    def show(left_s: float) -> None:
        whole = int(left_s + 0.999)
        if whole == shown["s"]:
            return
        first = shown["s"] < 0 or whole > shown["s"]
        shown["s"] = whole
        if not sys.stdout.isatty():
            if first:
                click.echo(f"page delay: the next copy starts in {left_s:.1f} s "
                           "(Ctrl-C holds)")
            return
        end = "\n" if whole == 0 else ""
        click.echo(f"\rnext copy in {whole:4d} s (Ctrl-C holds)" + end, nl=False)
    return show
