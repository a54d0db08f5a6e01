"""A `fivebar-mock://` machine served on a pseudo-terminal: a controller that outlives the host.

    python -m fivebar_host.server.ptydevice --link /tmp/fivebar-tty --url 'fivebar-mock://?speed=2'

makes a pty, points the symlink `--link` at its device (`/dev/pts/N`) and runs the Python
mock of the firmware behind it until SIGTERM/SIGINT. Point `fivebar serve --port` (or
`fivebar plot --port`) at the link: it behaves like a controller on a USB-serial adapter whose
board is not reset when the port is opened. Because it lives in its own process, the daemon
can be killed and restarted while the "machine" keeps running its queue and its counters —
which is what the daemon's crash tests need, and a way to try the daemon without hardware.

`--ledger FILE` writes, on SIGUSR1 and at exit, a JSON summary of what the machine executed
(per-motor steps issued, final position, laser switch-ons, boots, blocks), from the mock's
ledger, and the bytes it received; `--record FILE` keeps those bytes themselves (what every
host that opened the pty wrote, in order: the port-ownership tests read it).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import select
import signal
import sys
import termios
import tty
from pathlib import Path
from typing import Any

import serial

from fivebar_host.devices import urls
from fivebar_host.devices.mock import MockSerial


def ledger_summary(port: MockSerial, bytes_in: int = 0) -> dict[str, Any]:
    """What the mock machine executed, in numbers a test can compare with a plan."""
    entries = port.ledger
    g1 = [e for e in entries if e.kind == "G1"]
    laser_log = list(port.machine.laser_log)
    snap = port.snapshot()
    return {
        "steps_abs": [sum(abs(e.steps[0]) for e in g1), sum(abs(e.steps[1]) for e in g1)],
        "steps_net": [sum(e.steps[0] for e in g1), sum(e.steps[1] for e in g1)],
        "blocks": len(g1),
        "partial_blocks": sum(1 for e in g1 if not e.complete),
        "position": [snap.a, snap.b],
        "laser_now": port.machine.laser,
        "laser_on_events": sum(1 for _, p in laser_log if p > 0),
        "boots": port.machine.boots,
        "lines": [e.line for e in g1],
        "bytes_in": bytes_in,
    }


def serve(url: str, link: Path, ledger: Path | None, poll_s: float = 0.001,
          record: Path | None = None) -> int:
    """Run the mock behind a pty until SIGTERM/SIGINT (see the module docstring)."""
    urls.register()
    port = serial.serial_for_url(url, timeout=0)
    assert isinstance(port, MockSerial)
    master, slave = os.openpty()
    os.set_blocking(master, False)
    tty.setraw(slave, termios.TCSANOW)  # no echo, no line discipline before a client opens
    name = os.ttyname(slave)
    tmp = link.with_name(link.name + ".tmp")
    with contextlib.suppress(FileNotFoundError):
        tmp.unlink()
    tmp.symlink_to(name)
    tmp.replace(link)
    stop = {"flag": False}
    received = {"bytes": 0}
    recording = record.open("ab", buffering=0) if record is not None else None

    def write_ledger() -> None:
        if ledger is not None:
            t = ledger.with_name(ledger.name + ".tmp")
            t.write_text(json.dumps(ledger_summary(port, received["bytes"])) + "\n",
                         encoding="utf-8")
            t.replace(ledger)

    def on_term(signum: int, frame: Any) -> None:
        stop["flag"] = True

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)
    signal.signal(signal.SIGUSR1, lambda s, f: write_ledger())
    print(f"PTY {name}", flush=True)
    try:
        while not stop["flag"]:
            try:
                ready, _, _ = select.select([master], [], [], poll_s)
            except InterruptedError:
                continue
            if ready:
                try:
                    data = os.read(master, 4096)
                except OSError:  # EAGAIN, or EIO while no client has the pty open
                    data = b""
                if data:
                    received["bytes"] += len(data)
                    if recording is not None:
                        recording.write(data)
                    port.write(data)
            out = port.read(port.in_waiting or 1)
            if out:
                # Nobody reading (the host is gone) and the pty buffer full: the bytes are
                # lost, as on a serial line with no one listening.
                with contextlib.suppress(BlockingIOError):
                    os.write(master, out)
    finally:
        write_ledger()
        with contextlib.suppress(FileNotFoundError):
            link.unlink()
        os.close(master)
        os.close(slave)
        port.close()
        if recording is not None:
            recording.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m fivebar_host.server.ptydevice",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--url", default="fivebar-mock://?speed=1",
                    help="the mock's URL and options (default: real-time motion)")
    ap.add_argument("--link", type=Path, required=True,
                    help="symlink to create, pointing at the pty device")
    ap.add_argument("--ledger", type=Path, default=None,
                    help="JSON summary of what was executed (on SIGUSR1 and at exit)")
    ap.add_argument("--record", type=Path, default=None,
                    help="append every byte received from the host to FILE")
    args = ap.parse_args(argv)
    return serve(args.url, args.link, args.ledger, record=args.record)


if __name__ == "__main__":
    sys.exit(main())
