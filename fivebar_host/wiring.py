"""Where each wire goes: the pin map of the fivebar firmware (firmware/fivebar/config.h) on
the common Arduino CNC shield (V3) and on a bare Uno or Nano, as `fivebar wiring` prints it
and docs/wiring.png shows it. One table, so the text, the picture and the firmware agree
(tests/test_wiring.py reads config.h)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Wire:
    """One connection: what it is, the Arduino pin (and its AVR port bit, as config.h names
    it), the CNC shield's label for it, and what to connect on a bare board."""

    what: str
    pin: str  # Arduino pin, "D2"
    avr: str  # the ATmega328P's port bit, "PD2"
    shield: str  # the CNC shield's label or header
    bare: str  # a bare Uno/Nano: what to connect there


WIRES: tuple[Wire, ...] = (
    Wire("motor A step (M1, left)", "D2", "PD2", "X driver (X.STEP)", "STEP of driver A"),
    Wire("motor B step (M2, right)", "D3", "PD3", "Y driver (Y.STEP)", "STEP of driver B"),
    Wire("motor A direction", "D5", "PD5", "X driver (X.DIR)", "DIR of driver A"),
    Wire("motor B direction", "D6", "PD6", "Y driver (Y.DIR)", "DIR of driver B"),
    Wire("drivers enable (low = on)", "D8", "PB0", "EN (both drivers)",
         "EN of both drivers (or tie EN to GND)"),
    Wire("endstop A (to GND when pressed)", "D9", "PB1", "X- / X+ endstop header",
         "switch between D9 and GND (internal pull-up)"),
    Wire("endstop B (to GND when pressed)", "D10", "PB2", "Y- / Y+ endstop header",
         "switch between D10 and GND (internal pull-up)"),
    Wire("laser (PWM, high = on)", "D11", "PB3",
         "Z+ / Z- endstop header (GRBL 1.1's spindle PWM pin)",
         "laser driver's TTL/PWM input (a pull-down keeps it off at reset)"),
    Wire("pen servo signal", "D12", "PB4", "SpnEn", "servo signal (5 V and GND from a "
         "supply that can give 0.5 A; common GND)"),
)
#: The bare boards share the Uno's pin numbers: a Nano (ATmega328P) has D2–D12 on the same
#: AVR pins; only its header layout differs.
BOARDS_NOTE = ("Uno and Nano (ATmega328P) use the same pin numbers; a Nano sits on a 'Nano "
               "CNC shield' (V4) with the same labels. Motor supply (12-24 V) goes to the "
               "drivers' VMOT, never to the Arduino's 5 V.")


def table(board: str = "shield") -> list[str]:
    """The pin map as aligned text lines: `board` "shield" (CNC shield) or "bare"."""
    rows = [(w.what, f"{w.pin} ({w.avr})", w.shield if board == "shield" else w.bare)
            for w in WIRES]
    head = ("what", "Arduino pin", "CNC shield" if board == "shield" else "connect to")
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(2)]
    return [f"{a:<{widths[0]}}  {b:<{widths[1]}}  {c}" for a, b, c in [head, *rows]]
