"""The pin map that `fivebar wiring` prints and docs/wiring.png shows is the firmware's
(firmware/fivebar/config.h), and `fivebar doctor` says in words what it finds."""

from __future__ import annotations

import re
from pathlib import Path

from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.wiring import WIRES

ROOT = Path(__file__).resolve().parents[1]
CONFIG = (ROOT / "firmware" / "fivebar" / "config.h").read_text()
#: config.h's pin macros for each wire, in WIRES' order.
MACROS = [("STEP", "STEP_A"), ("STEP", "STEP_B"), ("DIR", "DIR_A"), ("DIR", "DIR_B"),
          ("ENABLE", "ENABLE"), ("ENDSTOP", "ENDSTOP_A"), ("ENDSTOP", "ENDSTOP_B"),
          ("LASER", "LASER"), ("SERVO", "SERVO")]
#: Arduino Uno pin numbers of the AVR port bits (PD0-7 = D0-7, PB0-5 = D8-13).
ARDUINO = {"D": 0, "B": 8}


def test_the_pin_map_is_the_firmware_s() -> None:
    assert len(WIRES) == len(MACROS)
    for wire, (port, bit) in zip(WIRES, MACROS, strict=True):
        p = re.search(rf"#define PIN_{port}_PORT\s+(\w)", CONFIG)
        b = re.search(rf"#define PIN_{bit}_BIT\s+(\d+)", CONFIG)
        assert p and b, (port, bit)
        assert wire.avr == f"P{p.group(1)}{b.group(1)}"
        assert wire.pin == f"D{ARDUINO[p.group(1)] + int(b.group(1))}"


def test_wiring_prints_both_boards_and_draws_the_picture(tmp_path: Path) -> None:
    r = CliRunner()
    shield = r.invoke(main, ["wiring"]).output
    bare = r.invoke(main, ["wiring", "--board", "bare", "--picture", str(tmp_path / "w.png")])
    assert "pen servo signal" in shield and "SpnEn" in shield and "D12 (PB4)" in shield
    assert bare.exit_code == 0 and "STEP of driver A" in bare.output
    assert (tmp_path / "w.png").stat().st_size > 10_000


def test_doctor_reads_the_board_and_says_what_is_wrong(sim_build: object) -> None:
    r = CliRunner()
    ok = r.invoke(main, ["doctor", "--port", "fivebar-sim://?usb=2341:0043"])
    assert ok.exit_code == 0, ok.output
    assert "12800 steps per motor revolution" in ok.output
    assert "home pose θ1 = 120°, θ2 = 60°" in ok.output
    assert "board: Arduino Uno R3 (USB 2341:0043)" in ok.output
    assert "firmware: fivebar 1.1.0" in ok.output and "position: unknown" in ok.output
    empty = r.invoke(main, ["doctor", "--port", "fivebar-sim://?bootloader=optiboot"])
    assert empty.exit_code == 3
    assert "problem:" in empty.output and "fivebar flash --port" in empty.output
