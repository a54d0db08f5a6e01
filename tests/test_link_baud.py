"""The host's side of `$B` (docs/protocol.md 1.1): `Link.open(link_baud=…)` switches after
the handshake and streams at the new rate, falls back to 115200 with a warning when the port
cannot follow, returns to 115200 on Ctrl-X and DTR resets; the profile key
`[serial] link_baud` takes only the rates the Uno makes."""

from __future__ import annotations

from typing import Any

import pytest

from fivebar_host import protocol, wire
from fivebar_host.config import ConfigError, load_profile, parse_profile
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices import simport, urls
from fivebar_host.devices.mock import MockSerial
from fivebar_host.run.errors import LinkError

URLS = ["fivebar-mock://?speed=1", pytest.param("fivebar-sim://?realtime=1",
                                                 marks=pytest.mark.sim)]


def _job(n: int) -> list[str]:
    return ["G90", "G92 A0 B0", *(wire.g1(k, -k, 1000, 0) for k in range(1, n + 1))]


@pytest.mark.parametrize("url", URLS)
@pytest.mark.parametrize("baud", [250000, 1000000])
def test_the_link_switches_streams_and_resets_back(url: str, baud: int,
                                                   request: pytest.FixtureRequest) -> None:
    if "sim" in url:
        request.getfixturevalue("sim_build")
    urls.register()
    with Link.open(url, link_baud=baud) as link:
        assert link.port.baudrate == baud and link.baud_warning is None
        res = link.stream(_job(200))
        st = link.wait_idle(10.0)
        assert (st.a, st.b, st.accepted_line) == (200, -200, res.last_line)
        link.reset()  # Ctrl-X: the firmware is back at 115200, so is the port
        assert link.port.baudrate == protocol.BASE_BAUD
        assert link.set_baud(baud) and link.port.baudrate == baud
        assert link.hardware_reset()  # DTR: likewise
        assert link.port.baudrate == protocol.BASE_BAUD
        link.command("G90")


@pytest.mark.parametrize("url", URLS)
def test_a_port_that_cannot_follow_falls_back_with_a_warning(
        url: str, monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest) -> None:
    """The adapter keeps its rate: the probe at the new rate finds nothing, the firmware's
    trial second ends, the link stays at 115200 and says so."""
    if "sim" in url:
        request.getfixturevalue("sim_build")
    urls.register()

    def stuck(self: Any, force_update: bool = False) -> None:
        """The port's rate never changes (the banner's rate stays in force)."""

    monkeypatch.setattr(MockSerial, "_reconfigure_port", stuck)
    monkeypatch.setattr(simport.Serial, "_reconfigure_port", stuck)
    with Link.open(url, link_baud=500000) as link:
        assert link.baud_warning is not None and "stays at 115200" in link.baud_warning
        link.stream(_job(20))
        assert link.wait_idle(10.0).a == 20


def test_a_firmware_without_b_leaves_the_link_at_115200(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """An older firmware answers `$B` with `error:4`: the link opens, warns, stays at
    115200, and its line counter follows the refused line (the next command runs)."""
    from fivebar_host.devices.mock.baud import UartRate
    from fivebar_host.devices.mock.codes import E_UNKNOWN_COMMAND

    urls.register()
    monkeypatch.setattr(UartRate, "request", lambda self, value: E_UNKNOWN_COMMAND)
    with Link.open("fivebar-mock://?speed=0", link_baud=250000) as link:
        assert link.port.baudrate == protocol.BASE_BAUD
        assert link.baud_warning is not None and "refused $B (error:4" in link.baud_warning
        link.command("G91")
        assert link.port.firmware.absolute is False


def test_a_rate_the_firmware_cannot_make_is_refused() -> None:
    urls.register()
    with Link.open("fivebar-mock://?speed=0") as link:
        with pytest.raises(LinkError, match="9600 baud is not one of"):
            link.set_baud(9600)
        assert link.port.baudrate == protocol.BASE_BAUD
        link.command("G90")


@pytest.mark.parametrize("value", [9600, 230400, "500000", True])
def test_the_profile_key_takes_only_link_rates(value: Any) -> None:
    import tomllib

    from fivebar_host.config import DEFAULT_PROFILE

    doc = tomllib.loads(DEFAULT_PROFILE.read_text())
    assert load_profile().serial.link_baud == protocol.BASE_BAUD  # absent: 115200
    doc["serial"]["link_baud"] = 1000000
    assert parse_profile(doc, "p.toml").serial.link_baud == 1000000
    doc["serial"]["link_baud"] = value
    with pytest.raises(ConfigError, match=r"p.toml: \[serial\] link_baud: must be one of "
                                          r"115200, 250000, 500000, 1000000"):
        parse_profile(doc, "p.toml")


def test_plot_switches_to_the_profile_rate(tmp_path: Any, clean_mock: None) -> None:
    """`fivebar plot` with `[serial] link_baud`: the job runs at that rate, all of it."""
    import shutil
    from pathlib import Path

    from click.testing import CliRunner

    from fivebar_host.cli import main
    from fivebar_host.config import DEFAULT_PROFILE
    from fivebar_host.devices import mock

    root = Path(__file__).resolve().parent.parent
    drawing = tmp_path / "simple.svg"
    shutil.copy(root / "examples" / "simple.svg", drawing)
    prof = tmp_path / "fast.toml"
    prof.write_text(DEFAULT_PROFILE.read_text().replace(
        "[serial]\n", "[serial]\nlink_baud = 1000000\n"))
    res = CliRunner().invoke(main, ["plot", str(drawing), "--port",
                                    "fivebar-mock://?machine=fast&speed=0", "--laser",
                                    "--yes", "--config", str(prof)], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "warning" not in res.output
    m = mock.machine("fast")
    assert m.firmware is not None and m.firmware.uart.baud == 1000000
    assert m.phys == [0, 0] and sum(e.kind == "G1" for e in m.ledger) > 200
