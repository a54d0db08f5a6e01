"""`fivebar bridge`: present a GRBL 1.1 controller to senders and drive the five-bar behind it
(docs/grbl.md)."""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import config_option, fail, handle_errors, load, main


@main.command()
@config_option
@click.option("--port", required=True, metavar="PORT",
              help="The machine: /dev/ttyUSB0, fivebar-sim://, fivebar-mock://.")
@click.option("--link", "link_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Serve on a pseudo-terminal; PATH becomes a symlink to it.")
@click.option("--listen", default=None, metavar="HOST:PORT",
              help="Serve on TCP (host defaults to 127.0.0.1).")
@click.option("--laser", is_flag=True,
              help="A laser machine: S powers the laser (nothing above S0 without it).")
@click.option("--origin", default="0,0", metavar="X,Y",
              help="G54 work origin in machine mm (fivebar frame: motor M1 at 0,0).")
@click.option("--tolerance", type=float, default=None,
              help="Path tolerance, mm (default: the profile's).")
@click.option("--mode", default=None, help="Working mode (default: the profile's).")
@click.option("--ok-window", type=click.IntRange(0, 200), default=15, show_default=True,
              help="Answer a line's ok only while at most this many accepted moves are "
              "ahead of the motion (GRBL's 15 planner blocks, so a sender's progress is "
              "true); 0: answer as soon as a line is in the look-ahead (up to 200 moves "
              "ahead).")
@click.option("--hold-on-disconnect", is_flag=True,
              help="Hold the machine (laser off) whenever the sender closes the port; by "
              "default a close after complete lines finishes them, as GRBL does.")
@click.option("--verbose", "-v", is_flag=True, help="Log refused lines and faults.")
@handle_errors
def bridge(config_path: Path | None, port: str, link_path: Path | None, listen: str | None,
           laser: bool, origin: str, tolerance: float | None, mode: str | None,
           ok_window: int, hold_on_disconnect: bool, verbose: bool) -> None:
    """Serve a GRBL 1.1 interface (pty and/or TCP) in front of the five-bar at --port."""
    from fivebar_host.bridge.controller import Bridge
    from fivebar_host.bridge.serve import Server, parse_listen
    from fivebar_host.controllers.fivebar import Controller as Fivebar

    if link_path is None and listen is None:
        fail("give --link PATH and/or --listen HOST:PORT")
    try:
        ox, oy = (float(v) for v in origin.split(","))
    except ValueError:
        fail(f"--origin must look like X,Y in mm; got {origin!r}")
    prof = load(config_path)
    machine = Fivebar.open(port, prof)  # the bridge speaks fivebar's own protocol
    if machine.notice:
        click.echo(f"warning: {machine.notice}", err=True)
    link = machine.link
    tol = tolerance if tolerance is not None else prof.motion.tolerance_mm
    log: Any = (lambda m: click.echo(m, err=True)) if verbose else None
    core = Bridge(link, prof, laser=laser, tolerance_mm=tol, origin_mm=(ox, oy), mode=mode,
                  log=log, ok_window=ok_window, hold_on_disconnect=hold_on_disconnect)
    server = Server(core, link_path, parse_listen(listen) if listen else None)
    core.start()
    server.start()
    where = [f"pty {server.pty.name} (link {link_path})"] if server.pty else []
    if server.address:
        where.append(f"tcp {server.address[0]}:{server.address[1]}")
    click.echo("fivebar bridge: GRBL 1.1h on " + ", ".join(where), err=True)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    try:
        done.wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
        core.close()
        link.close()
