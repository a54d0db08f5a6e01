"""The GRBL bridge under test: a `fivebar bridge` core in front of the mock or the emulated
firmware, served on TCP (and a pty when asked)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from grbl_client import GrblClient

from fivebar_host.bridge.controller import Bridge
from fivebar_host.bridge.serve import Server
from fivebar_host.config import load_profile
from fivebar_host.controllers.fivebar.link import Link

#: Work origin of the tests' drawings: G54 X0 Y0 at machine (5, 95) mm, inside the default
#: profile's safe region (x 0…40, y 80…140).
ORIGIN = (5.0, 95.0)


@dataclass
class Running:
    """A bridge under test: its core, its server, the machine URL and kind."""

    kind: str
    core: Bridge
    server: Server
    link: Link
    trace: Path | None

    def client(self) -> GrblClient:
        c = GrblClient(tcp=self.server.address)
        c.wait_for(lambda s: s.startswith("Grbl 1.1h"))
        return c


def start_bridge(kind: str, tmp_path: Path, *, laser: bool = True, pty: bool = False,
                 realtime: bool = False, profile: Path | None = None) -> Running:
    """Open the machine, start the bridge core and its server (TCP on a free port)."""
    trace = None
    if kind == "sim":
        trace = tmp_path / "pins.trace"
        url = f"fivebar-sim://?trace={trace}" + ("&realtime=1" if realtime else "")
    else:
        url = "fivebar-mock://?speed=10"
    link = Link.open(url)
    core = Bridge(link, load_profile(profile), laser=laser, tolerance_mm=0.05,
                  origin_mm=ORIGIN)
    server = Server(core, tmp_path / "grbl-tty" if pty else None, ("127.0.0.1", 0))
    core.start()
    server.start()
    return Running(kind, core, server, link, trace)


def stop_bridge(r: Running) -> None:
    r.server.stop()
    r.core.close()
    r.link.close()
