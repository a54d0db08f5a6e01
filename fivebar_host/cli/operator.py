"""The terminal's operator: a person at `fivebar plot` (and the machine commands) answering a
run's questions (`run.operator.Operator`).

- **Questions.** "Are the arms at the home pose?" is asked on the terminal; `--yes` answers
  it. Where the arms are after a power loss only a person may answer: asked on a terminal,
  never answered by `--yes`; without a terminal the answer is no (nothing moves).
- **Ctrl-C** holds the machine at once (laser off) and asks resume or abort (abort without
  a terminal); a pen change waits for Enter (q to stop), and `--yes` never answers it.
- **Progress**: a bar on a terminal, with the live feed and power when the override keys
  (`cli.keys`) are on; otherwise a line every few seconds, so a log shows the job advance.
- **Copies**: the page delay counts down ("next copy in 12 s").

`TerminalOperator.attached(...)` installs the Ctrl-C handler, the override keys and the
progress display for one run and takes them away after it.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

import click

from fivebar_host.cli.keys import HELP, KeyReader, override_keys
from fivebar_host.compile.model import LayerPause
from fivebar_host.run.operator import Progress, QuietOperator
from fivebar_host.run.overrides import FEED_MAX_PCT, Overrides

#: Without a terminal (a log file, systemd): a progress line every this many seconds or
#: this share of the job, whichever comes first.
PROGRESS_EVERY_S = 5.0
PROGRESS_EVERY_SHARE = 0.1


def terminal() -> bool:
    """Whether a person can answer on stdin (a tty)."""
    return sys.stdin.isatty()


class TerminalOperator(QuietOperator):
    """A person at the terminal (module doc); `yes`: `--yes` was given."""

    def __init__(self, yes: bool = False) -> None:
        self.yes = yes
        # A pen change is asked on the terminal; without one, `cli.stops.check_stops` has
        # refused the job before the port opened.
        self.attended = True
        self._stop = False
        self._keys: KeyReader | None = None
        self._show: Callable[[Progress], None] | None = None
        self._shown_s = -1

    # ------------------------------------------------------------------ questions
    def _leave_bar(self) -> None:
        """A question or a note while the progress bar is drawn on the terminal starts on
        a line of its own (the bar is redrawn below it at the next update)."""
        if self._show is not None and sys.stdout.isatty():
            click.echo("")

    def confirm(self, question: str) -> bool:
        self._leave_bar()
        if self.yes:
            click.echo(f"{question} yes (--yes)")
            return True
        if not terminal():
            click.echo(f"{question} (no terminal to ask: pass --yes)", err=True)
            return False
        return click.confirm(question, default=False)

    def confirm_placed(self, question: str) -> bool:
        self._leave_bar()
        if not terminal():
            click.echo(f"{question} (no terminal to ask; --yes does not answer this)"
                       if self.yes else f"{question} (no terminal to ask)", err=True)
            return False
        if self.yes:
            click.echo("--yes does not answer this question after a power loss:", err=True)
        return click.confirm(question, default=False)

    def note(self, text: str) -> None:
        self._leave_bar()
        click.echo(text)

    # ------------------------------------------------------------------ holds and stops
    def should_stop(self) -> bool:
        if self._keys is not None:
            self._keys.poll()
        return self._stop

    def interrupted(self) -> bool:
        self._stop = False
        with self._cooked():
            return ask_resume()

    def pen_change(self, pause: LayerPause) -> bool:
        self._stop = False
        with self._cooked():
            return ask_pen_change(pause)

    @contextmanager
    def _cooked(self) -> Iterator[None]:
        """The terminal as a person types at it while a question is asked."""
        if self._keys is None:
            yield
            return
        with self._keys.paused():
            yield

    # ------------------------------------------------------------------ what it shows
    def progress(self, p: Progress) -> None:
        if self._show is not None:
            self._show(p)

    def waiting(self, left_s: float) -> None:
        """The page delay: a line a second on a terminal ("next copy in 12 s"), otherwise
        one line when the wait starts."""
        whole = int(left_s + 0.999)
        if whole == self._shown_s:
            return
        first = self._shown_s < 0 or whole > self._shown_s
        self._shown_s = whole
        if not sys.stdout.isatty():
            if first:
                click.echo(f"page delay: the next copy starts in {left_s:.1f} s "
                           "(Ctrl-C holds)")
            return
        end = "\n" if whole == 0 else ""
        click.echo(f"\rnext copy in {whole:4d} s (Ctrl-C holds)" + end, nl=False)

    @contextmanager
    def attached(self, total: int, copies: int, laser: bool,
                 overrides: Overrides | None) -> Iterator[None]:
        """For one run: Ctrl-C holds, the override keys read (on a terminal), the progress
        shown; all taken away after it."""

        def on_sigint(signum: int, frame: Any) -> None:
            self._stop = True

        previous = signal.signal(signal.SIGINT, on_sigint)
        try:
            with ExitStack() as stack:
                if overrides is not None:
                    self._keys = stack.enter_context(override_keys(overrides))
                if self._keys is not None:
                    click.echo(HELP)
                shown = overrides if self._keys is not None else None
                self._show = stack.enter_context(progress_display(total, shown, laser,
                                                                  copies))
                yield
        finally:
            self._show = None
            self._keys = None
            signal.signal(signal.SIGINT, previous)


def ask_resume() -> bool:
    """After Ctrl-C: resume or abort (abort without a terminal)."""
    click.echo("\nheld: motion stopped, laser off.", err=True)
    choice = click.prompt("resume or abort?", type=click.Choice(["resume", "abort"]),
                          default="abort", err=True) if terminal() else "abort"
    return bool(choice == "resume")


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


@contextmanager
def progress_display(total: int, overrides: Overrides | None = None, laser: bool = False,
                     copies: int = 1) -> Iterator[Callable[[Progress], None]]:
    """The progress hook: a progress bar on a terminal; otherwise one line at a steady pace
    ("plotting: 40% (segment 110/275), 4 s elapsed, ≈ 6 s left"), so a log shows that the
    job advances and when it will end. With `overrides` (keys on a terminal) the bar shows
    the requested feed (and, with `laser`, power) and the time left at that feed. With
    `copies` > 1 the share is of all copies and the text names the copy."""
    def text(p: Progress) -> str:
        of = f"copy {p.copy}/{p.copies}, " if p.copies > 1 else ""
        if overrides is None:
            return (f"{of}segment {p.segments_done}/{p.segments_total}, {p.elapsed_s:.0f} s "
                    f"elapsed, ≈ {p.remaining_s:.0f} s left")
        feed, power = overrides.values()
        left = p.remaining_s * FEED_MAX_PCT / feed
        return (f"{of}segment {p.segments_done}/{p.segments_total}, ≈ {left:.0f} s left, "
                f"feed {feed}%" + (f" power {power}%" if laser else ""))

    def overall(p: Progress) -> int:
        return (p.copy - 1) * p.segments_total + p.segments_done

    if not sys.stdout.isatty():
        last = {"t": time.monotonic(), "share": 0.0}

        def log_line(p: Progress) -> None:
            share = overall(p) / max(1, p.segments_total * p.copies)
            now = time.monotonic()
            if (share >= last["share"] + PROGRESS_EVERY_SHARE and share < 1.0) or (
                    now - last["t"] >= PROGRESS_EVERY_S and share > last["share"]):
                click.echo(f"plotting: {100 * share:.0f}% ({text(p)})")
                last.update(t=now, share=share)

        click.echo("plotting")
        yield log_line
        return
    with click.progressbar(length=total * copies, label="plotting", show_eta=False,
                           show_percent=True, item_show_func=lambda s: s) as bar:
        state = {"done": 0}

        def on_progress(p: Progress) -> None:
            if overall(p) > state["done"]:
                bar.update(overall(p) - state["done"], text(p))
                state["done"] = overall(p)

        yield on_progress
