"""`fivebar bridge`: present a GRBL 1.1 controller to senders and drive the five-bar behind it
(docs/grbl.md)."""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import config_option, fail, handle_errors, load, main
from fivebar_host.errors import shorten


@main.command()
@config_option
@click.option("--port", required=True, metavar="PORT",
              help="The machine: /dev/ttyUSB0, fivebar-sim://, fivebar-mock://.")
@click.option("--link", "link_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Serve on a pseudo-terminal; PATH becomes a symlink to it.")
@click.option("--listen", default=None, metavar="HOST:PORT",
              help="Serve on TCP (host defaults to 127.0.0.1). Any other address needs "
              "--allow or --insecure-listen.")
@click.option("--allow", "allow", multiple=True, metavar="ADDR[/BITS]",
              help="A sender's address or network that may connect over TCP (repeatable; "
              "loopback always may). GRBL senders cannot send a token: this list is what "
              "keeps others from driving the machine.")
@click.option("--insecure-listen", is_flag=True,
              help="Let every address that reaches --listen drive the machine, laser "
              "included (no --allow list).")
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
           allow: tuple[str, ...], insecure_listen: bool, laser: bool, origin: str,
           tolerance: float | None, mode: str | None, ok_window: int,
           hold_on_disconnect: bool, verbose: bool) -> None:
    """Serve a GRBL 1.1 interface (pty and/or TCP) in front of the five-bar at --port.

    SIGINT (Ctrl-C) or SIGTERM stops it: the machine is held and reset (queue cleared, laser
    off, position kept) and the port given up."""
    from fivebar_host.bridge.controller import Bridge
    from fivebar_host.bridge.serve import Server, parse_listen
    from fivebar_host.controllers.fivebar import Controller as Fivebar

    if link_path is None and listen is None:
        fail("give --link PATH and/or --listen HOST:PORT")
    try:
        ox, oy = (float(v) for v in origin.split(","))
    except ValueError:
        fail(f"--origin must look like X,Y in mm; got {shorten(origin)!r}")
    address = parse_listen(listen) if listen else None
    access, notice = network_access(address, allow, insecure_listen)  # before the port
    prof = load(config_path)
    machine = Fivebar.open(port, prof)  # the bridge speaks fivebar's own protocol
    if machine.notice:
        click.echo(f"warning: {machine.notice}", err=True)
    link = machine.link
    tol = tolerance if tolerance is not None else prof.motion.tolerance_mm
    log: Any = (lambda m: click.echo(m, err=True)) if verbose else None
    done = threading.Event()
    previous = {s: signal.signal(s, lambda *_: done.set())
                for s in (signal.SIGINT, signal.SIGTERM)}
    core = Bridge(link, prof, laser=laser, tolerance_mm=tol, origin_mm=(ox, oy), mode=mode,
                  log=log, ok_window=ok_window, hold_on_disconnect=hold_on_disconnect)
    server: Server | None = None
    try:
        server = Server(core, link_path, address, access,
                        log=lambda m: click.echo(f"fivebar bridge: {m}", err=True))
        core.start()
        server.start()
        where = [f"pty {server.pty.name} (link {link_path})"] if server.pty else []
        if server.address:
            where.append(f"tcp {server.address[0]}:{server.address[1]}")
        click.echo("fivebar bridge: GRBL 1.1h on " + ", ".join(where), err=True)
        if notice:
            click.echo(notice, err=True)
        while not done.wait(0.2):
            pass
        click.echo("fivebar bridge: stopping", err=True)
    finally:
        if server is not None:
            server.stop()
        core.close()
        stopped = stop_machine(link)
        link.close()
        for s, h in previous.items():
            signal.signal(s, h)
    click.echo(f"fivebar bridge: stopped; {stopped}", err=True)


def network_access(address: tuple[str, int] | None, allow: tuple[str, ...],
                   insecure: bool) -> tuple[Any, str | None]:
    """Who may connect over TCP (`bridge.serve.Access`) and what to say loudly at start;
    a non-loopback `--listen` without `--allow` or `--insecure-listen` is refused."""
    from fivebar_host.bridge.serve import LOOPBACK_ONLY, Access, is_loopback, parse_allow

    nets = [parse_allow(a) for a in allow]
    if insecure and nets:
        fail("--insecure-listen and --allow contradict each other: give one")
    if address is None:
        if nets or insecure:
            fail("--allow and --insecure-listen are for --listen (TCP)")
        return LOOPBACK_ONLY, None
    host, number = address
    if is_loopback(host):
        return Access(nets), None
    if insecure:
        return Access(None), (
            f"WARNING: fivebar bridge listens on {host} for EVERY address "
            "(--insecure-listen): anyone who reaches this computer drives the machine, laser "
            "included. GRBL senders send no token.")
    if not nets:
        fail(f"--listen {host}:{number} is not a loopback address: anyone who reaches this "
             "computer could drive the machine, laser included, and GRBL senders cannot "
             "send a token. Give --allow ADDR[/BITS] for each sender's address or network "
             "(loopback always may connect), or --insecure-listen to let every address in")
    listed = ", ".join(str(n) for n in nets)
    return Access(nets), (
        f"NOTE: fivebar bridge listens on {host}; only loopback and {listed} may "
        "connect (--allow): GRBL senders send no token, so every process at those addresses "
        "drives the machine, laser included.")


def stop_machine(link: Any) -> str:
    """Hold the machine (laser off at once), then reset it (queue cleared, laser off,
    position kept): what a stopped bridge leaves. The words for the last log line."""
    from fivebar_host import protocol
    from fivebar_host.run.errors import LinkError

    try:
        link.realtime(protocol.RT_HOLD)
        link.reset()
        st = link.status()
    except LinkError as e:
        return f"the machine did not answer the hold and reset ({e}); check it"
    return (f"machine held and reset at A = {st.a}, B = {st.b} steps (queue cleared, "
            f"laser {'ON' if st.laser else 'off'})")
