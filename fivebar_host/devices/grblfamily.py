"""GRBL's relatives as pyserial ports, for tests without the boards: ``fivebar-grblhal://NAME``
(grblHAL) and ``fivebar-fluidnc://NAME`` (FluidNC). Both are `grblmock.GrblMock` — the same
GRBL 1.1 wire (lines, ``ok``, ``?`` reports, real-time bytes, G-code, laser mode, the
recorded blocks) — with what each says and keeps differently, from their documentation:

- **grblHAL** (grblHAL/core): the banner ``GrblHAL 1.1f ['$' or '$HELP' for help]``, ``$I``
  with ``[FIRMWARE:grblHAL]``, GRBL's ``$`` numbers plus its own (``$14``–``$19``, ``$28``,
  ``$29``, ``$33``–``$35``, ``$39``, ``$40``, ``$43``–``$46``, ``$62``–``$65``, ``$341``–``$345``
  …); ``$22`` is a bit mask (bit 0: homing on).
- **FluidNC** (bdring/FluidNC): the banner ``Grbl 3.7 [FluidNC v3.7.17 (noradio) '$' for
  help]``; its settings are a YAML configuration read and written one item at a time as
  ``$/axes/x/steps_per_mm`` (answered ``$/axes/x/steps_per_mm=80.000``) and
  ``$/axes/x/steps_per_mm=35.555556``; GRBL's ``$100``-style numbers are not its settings
  (``error:3`` here). The model keeps the axis items fivebar checks (`FLUIDNC_ITEMS`) and
  moves by them (steps per unit, rates); its laser is a Laser spindle (laser mode) with
  S0–1000 as full range.

Boards are named per scheme (`board(scheme, name)`), so the same NAME on two families is two
boards.
"""

from __future__ import annotations

import re
from typing import ClassVar

from fivebar_host.devices import grblmock
from fivebar_host.devices.grblmock import DEFAULTS, Board, GrblMock

GRBLHAL_SCHEME = "fivebar-grblhal"
FLUIDNC_SCHEME = "fivebar-fluidnc"

#: grblHAL's settings: GRBL's and some of its own, at grblHAL's documented defaults.
GRBLHAL_DEFAULTS: dict[int, float] = {
    **DEFAULTS, 14: 0, 15: 0, 16: 0, 17: 0, 18: 0, 19: 0, 28: 0.1, 29: 0, 33: 5000,
    34: 0, 35: 0, 39: 1, 40: 0, 43: 1, 44: 4, 45: 3, 46: 0, 62: 0, 63: 3, 64: 0, 65: 0,
    341: 0, 342: 30, 343: 25, 344: 200, 345: 200,
}

#: FluidNC configuration items the model keeps, and the GRBL setting each stands for (the
#: model's motion reads the GRBL numbers).
FLUIDNC_ITEMS: dict[str, int] = {
    "/axes/x/steps_per_mm": 100, "/axes/y/steps_per_mm": 101,
    "/axes/x/max_rate_mm_per_min": 110, "/axes/y/max_rate_mm_per_min": 111,
    "/axes/x/acceleration_mm_per_sec2": 120, "/axes/y/acceleration_mm_per_sec2": 121,
    "/axes/x/max_travel_mm": 130, "/axes/y/max_travel_mm": 131,
    "/axes/x/soft_limits": 20, "/axes/y/soft_limits": 20,
    "/axes/x/homing/cycle": 22, "/axes/y/homing/cycle": 22,
    "/axes/x/homing/pulloff_mm": 27, "/axes/y/homing/pulloff_mm": 27,
}
#: FluidNC's defaults where GRBL's differ (no homing cycle is -1 … here 0: none).
FLUIDNC_DEFAULTS: dict[int, float] = {**DEFAULTS, 32: 1, 100: 80.0, 101: 80.0}
_ITEM = re.compile(r"\$(/[A-Z0-9_/]+)(?:=(.*))?")


def board(scheme: str, name: str) -> Board:
    """The named board of a family (created at its defaults on first use)."""
    return grblmock.board(f"{scheme}:{name}",
                          GRBLHAL_DEFAULTS if scheme == GRBLHAL_SCHEME else FLUIDNC_DEFAULTS)


class GrblHALMock(GrblMock):
    """grblHAL: GRBL's wire and numbers, more settings, its own banner and `$I`."""

    scheme: ClassVar[str] = GRBLHAL_SCHEME
    banner: ClassVar[str] = "GrblHAL 1.1f ['$' or '$HELP' for help]"
    defaults: ClassVar[dict[int, float]] = GRBLHAL_DEFAULTS
    build_info: ClassVar[str] = ("[VER:1.1f.20240817:]\r\n[OPT:VNMSL,35,1024,3,0]\r\n"
                                 "[NEWOPT:ENUMS,RT+,HOME,SED]\r\n[FIRMWARE:grblHAL]")


class FluidNCMock(GrblMock):
    """FluidNC: GRBL's wire, a YAML configuration read and set item by item (`$/…`)."""

    scheme: ClassVar[str] = FLUIDNC_SCHEME
    banner: ClassVar[str] = "Grbl 3.7 [FluidNC v3.7.17 (noradio) '$' for help]"
    defaults: ClassVar[dict[int, float]] = FLUIDNC_DEFAULTS
    build_info: ClassVar[str] = "[VER:3.7 FluidNC v3.7.17:]\r\n[OPT:PHS]"

    def _system(self, line: str) -> str:
        """`$/item` and `$/item=value`; GRBL's numbered settings are not FluidNC's."""
        m = _ITEM.fullmatch(line)
        if m is not None:
            return self._item(m.group(1).lower(), m.group(2))
        if re.fullmatch(r"\$\d+(=.*)?", line):
            return "error:3"
        return super()._system(line)

    def _item(self, path: str, value: str | None) -> str:
        number = FLUIDNC_ITEMS.get(path)
        if number is None:
            return "error:3"
        settings = self.board.settings
        if value is None:
            v = settings[number]
            text = ("true" if v else "false") if number == 20 else f"{v:.3f}"
            self._send(f"${path}={text}")
            return "ok"
        try:
            v = 1.0 if value.lower() == "true" else 0.0 if value.lower() == "false" \
                else float(value)
        except ValueError:
            return "error:3"
        settings[number] = v
        return "ok"


#: The port class of each scheme (`urls.register` installs them).
PORTS: dict[str, type[GrblMock]] = {GRBLHAL_SCHEME: GrblHALMock, FLUIDNC_SCHEME: FluidNCMock}
