"""`fivebar plot --server URL`: hand the drawing to a running `fivebar serve` and follow it.

The plot command itself is untouched: without --server the wrapper calls it unchanged; with
it, the same job option values go to the daemon as query parameters (generated from their one
definition in `fivebar_host.options`), and this module follows the job with the same progress
bar. Ctrl-C pauses the job on the daemon (held, laser off) and asks to resume or abort (no
terminal: abort cancels it); a question of the daemon (are the arms at the home pose?) is asked
here, and --yes answers it in advance.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from fivebar_host.cli.common import fail
from fivebar_host.cli.operator import terminal
from fivebar_host.options import JOB_OPTIONS

if TYPE_CHECKING:
    from fivebar_host.server.client import ServerClient

F = TypeVar("F", bound=Callable[..., Any])


def server_option(fn: F) -> F:
    """Add `--server URL` and `--token` to `plot`."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        server = kwargs.pop("server", None)
        token = kwargs.pop("token", None)
        if server is None:
            return fn(*args, **kwargs)
        return plot_via_server(server, token, kwargs)

    wrapper = click.option(
        "--token", default=None, metavar="TOKEN", envvar="FIVEBAR_TOKEN",
        help="The daemon's token (needed when it listens on a non-loopback address). "
        "Default: $FIVEBAR_TOKEN, else the local daemon's token file.")(wrapper)
    wrapper = click.option(
        "--server", default=None, metavar="URL",
        help="Send the drawing to a running `fivebar serve` at URL (http://HOST:PORT) and "
        "follow it there, instead of opening --port.")(wrapper)
    return wrapper  # type: ignore[return-value]


def _submit(client: ServerClient, kw: dict[str, Any]) -> dict[str, Any]:
    """Send the drawing with the plot's job option values; the queued job."""
    from fivebar_host.server.client import plot_options

    given = [flag for flag, key in (("--port", "port"), ("--dry-run", "dry_run"),
                                    ("--resume", "resume"), ("--config", "config_path"))
             if kw.get(key)]
    if given:
        fail(f"--server hands the drawing to the daemon, which has its own port and profile "
             f"(fivebar serve --port/--config) and resumes its own jobs; drop "
             f"{', '.join(given)}")
    drawing = Path(kw["drawing"])
    try:
        data = drawing.read_bytes()
    except OSError as e:
        fail(f"{drawing}: {e.strerror or e}")
    values = {o.name: kw[o.name] for o in JOB_OPTIONS if o.name in kw}
    job: dict[str, Any] = client.submit(data, drawing.name, plot_options(
        **values, confirm=bool(kw.get("yes", False))))
    return job


def plot_via_server(server: str, token: str | None, kw: dict[str, Any]) -> None:
    """Submit, then follow the job's progress until it is over."""
    from fivebar_host.server.client import ServerClient, ServerError, default_token

    try:
        client = ServerClient(server, token or default_token())
        job = _submit(client, kw)
    except ServerError as e:
        fail(str(e), code=2 if e.status in (400, 413, 415, 422) else 3)
        return
    click.echo(f"job {job['id']} queued on {client.base}: {job['segments_total']} segments, "
               f"mode {job['mode']}, ≈ {job['estimated_s']:.1f} s"
               + (f", max deviation {job['max_dev_mm']:.4f} mm" if job["max_dev_mm"] else ""))
    try:
        job = _follow_with_bar(client, job)
    except ServerError as e:
        fail(str(e), code=3)
        return
    if job["state"] != "done":
        fail(f"job {job['id']} {job['state']}: {job['message']}", code=3)
    click.echo(str(job["message"]))


def _follow_with_bar(client: ServerClient, job: dict[str, Any]) -> dict[str, Any]:
    """Follow a job with a progress bar until it is over or a person must act; Ctrl-C
    pauses it on the daemon and asks."""
    from fivebar_host.server.client import follow

    jid = int(job["id"])
    interrupted = {"flag": False}

    def on_sigint(signum: int, frame: Any) -> None:
        interrupted["flag"] = True

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        copies = int(job["options"].get("copies", 1))
        with click.progressbar(length=int(job["segments_total"]) * copies, label="plotting",
                               show_eta=False, show_percent=True,
                               item_show_func=lambda s: s) as bar:
            bar_update = _bar_updater(bar)
            seen: dict[str, Any] = {}
            #: the pen change last answered, until the daemon shows the job running again
            answered = {"message": ""}

            def on_update(j: dict[str, Any]) -> None:
                seen.update(j)
                if j.get("state") != "paused":
                    answered["message"] = ""
                bar_update(j)

            def pen_change() -> bool:  # asked on a terminal; otherwise the page resumes it
                msg = str(seen.get("message", ""))
                return (terminal() and seen.get("state") == "paused"
                        and msg.startswith("pen change:") and msg != answered["message"])

            while True:
                job = follow(client, jid, on_update,
                             should_stop=lambda: interrupted["flag"] or pen_change())
                if interrupted["flag"]:
                    interrupted["flag"] = False
                    _after_ctrl_c(client, job)
                    continue
                if pen_change():
                    if _ask_pen_change(client, job):
                        answered["message"] = str(job.get("message", ""))
                        continue
                    return client.job(jid)
                if job["state"] == "held" and sys.stdin.isatty() and _ask_held(client, job):
                    continue
                return job
    finally:
        signal.signal(signal.SIGINT, previous)


def _ask_pen_change(client: ServerClient, job: dict[str, Any]) -> bool:
    """A pen-change stop on the daemon, followed on a terminal: Enter resumes the job (True),
    q (or Ctrl-C) leaves it paused there — the page's resume button goes on later."""
    click.echo(f"\n{job['message']}", err=True)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        answer = click.prompt("change the pen, then press Enter (q to stop following; the "
                              "job stays paused on the daemon)", default="",
                              show_default=False, err=True)
    except (KeyboardInterrupt, click.Abort, EOFError):
        answer = "q"
    finally:
        signal.signal(signal.SIGINT, previous)
    if str(answer).strip().lower() in ("q", "quit", "stop"):
        return False
    client.resume(int(job["id"]))
    return True


def _bar_updater(bar: Any) -> Callable[[dict[str, Any]], None]:
    """A `follow` callback that advances the progress bar (over all copies; the text names
    the copy when there are several, as the local `plot` does)."""
    state = {"done": 0}

    def on_update(j: dict[str, Any]) -> None:
        total, copy = int(j["segments_total"]), int(j.get("copy_number", 1))
        copies = int(j["options"].get("copies", 1))
        done = (copy - 1) * total + int(j["segments_done"])
        if done > state["done"] or j["state"] != "running":
            of = f"copy {copy}/{copies}, " if copies > 1 else ""
            bar.update(max(0, done - state["done"]),
                       f"{of}segment {j['segments_done']}/{total}, "
                       f"{j['elapsed_s']:.0f} s elapsed, "
                       f"≈ {j['remaining_s'] or 0:.0f} s left"
                       + ("" if j["state"] == "running" else f" ({j['state']})"))
            state["done"] = max(state["done"], done)

    return on_update


def _after_ctrl_c(client: ServerClient, job: dict[str, Any]) -> None:
    """Ctrl-C: pause the running job on the daemon, then resume or abort it."""
    jid = int(job["id"])
    if job["state"] in ("queued", "running"):
        job = client.pause(jid) if job["state"] == "running" else job
        click.echo("\npaused on the daemon: held, laser off.", err=True)
    choice = click.prompt("resume or abort?", type=click.Choice(["resume", "abort"]),
                          default="abort", err=True) if sys.stdin.isatty() else "abort"
    if choice == "abort":
        client.cancel(jid)
    elif client.job(jid)["state"] in ("paused", "held"):
        client.resume(jid)


def _ask_held(client: ServerClient, job: dict[str, Any]) -> bool:
    """A held job on a terminal: answer its question or choose; True to keep following."""
    jid = int(job["id"])
    if job.get("question"):
        if click.confirm(f"\n{job['question']}", default=False, err=True):
            client.resume(jid, confirm=True)
            return True
        return False
    click.echo(f"\nheld: {job['message']}", err=True)
    choice = click.prompt("resume, abort or leave it held?",
                          type=click.Choice(["resume", "abort", "leave"]),
                          default="leave", err=True)
    if choice == "resume":
        client.resume(jid)
        return True
    if choice == "abort":
        client.cancel(jid)
        return True
    return False
