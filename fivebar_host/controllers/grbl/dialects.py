"""The GRBL family `--controller grbl` drives: GRBL 1.1, grblHAL and FluidNC speak the same
wire (lines, `ok`, `?` reports, real-time bytes, G-code) and differ in how a board says who
it is and how its settings are read. The dialect is found from the banner (`detect`) and
checks the board's settings against what the profile needs (`differences`,
`program.needed_settings`):

- **GRBL 1.1** (`Grbl 1.1h ['$' for help]`): `$$`, every needed setting.
- **grblHAL** (`GrblHAL 1.1f ['$' or '$HELP' for help]`): `$$` with GRBL's numbers and
  its own; `$22` is a bit mask there (bit 0: homing on), so only that bit is compared.
- **FluidNC** (`Grbl 3.7 [FluidNC v3.7.17 …]`): a YAML configuration; the axis items are read
  one by one (`$/axes/x/steps_per_mm` → `$/axes/x/steps_per_mm=35.556`) and compared
  (`FLUIDNC_PATHS`: steps per degree, rates, accelerations, travel, soft limits, homing
  cycle and pull-off); what has no single item there — the laser's S range (`speed_map`
  0=0% … 1000=100%), laser mode (a `Laser` spindle), MPos in status reports, millimetre
  reports — is a manual check the controller names in its notice (docs/grbl.md).
"""

from __future__ import annotations

import re

from fivebar_host.config import Profile
from fivebar_host.controllers.grbl.link import GrblError, GrblLink
from fivebar_host.controllers.grbl.program import settings_differences

GRBL = "GRBL 1.1"
GRBLHAL = "grblHAL"
FLUIDNC = "FluidNC"

#: FluidNC configuration items for the GRBL settings fivebar needs (X carries motor A).
FLUIDNC_PATHS: dict[int, tuple[str, ...]] = {
    100: ("/axes/x/steps_per_mm",), 101: ("/axes/y/steps_per_mm",),
    110: ("/axes/x/max_rate_mm_per_min",), 111: ("/axes/y/max_rate_mm_per_min",),
    120: ("/axes/x/acceleration_mm_per_sec2",), 121: ("/axes/y/acceleration_mm_per_sec2",),
    130: ("/axes/x/max_travel_mm",), 131: ("/axes/y/max_travel_mm",),
    20: ("/axes/x/soft_limits", "/axes/y/soft_limits"),
    22: ("/axes/x/homing/cycle", "/axes/y/homing/cycle"),
    27: ("/axes/x/homing/pulloff_mm", "/axes/y/homing/pulloff_mm"),
}
#: What a FluidNC board is not asked and must be checked by hand.
FLUIDNC_MANUAL = ("the laser's speed_map covers S0-1000 linearly (0=0% 1000=100%), the "
                  "spindle is a Laser (laser mode; a servo pen: not a laser), status reports "
                  "give MPos, reports in mm")
_ITEM = re.compile(r"^\$(/[\w/]+)=(.*)$")


def detect(banner: str) -> str | None:
    """The dialect a banner names, None for a board outside the family fivebar drives."""
    if banner.startswith("GrblHAL 1.1"):
        return GRBLHAL
    if banner.startswith("Grbl ") and "FluidNC" in banner:
        return FLUIDNC
    if banner.startswith("Grbl 1.1"):
        return GRBL
    return None


def differences(link: GrblLink, profile: Profile) -> list[str]:
    """Every setting of the board that is not what `profile` needs, in the board's own
    terms (`$N` or a FluidNC item)."""
    if link.dialect == FLUIDNC:
        return _fluidnc_differences(link, profile)
    board = link.settings()
    if link.dialect == GRBLHAL and 22 in board:
        board[22] = float(int(board[22]) & 1)
    return settings_differences(profile, board)


def _item(link: GrblLink, path: str) -> float | None:
    """One FluidNC item's value (booleans as 1/0), None when the board has no such item."""
    try:
        rows = link.command(f"${path}")
    except GrblError:
        return None
    for row in rows:
        m = _ITEM.match(row)
        if m and m.group(1).lower() == path:
            text = m.group(2).strip().lower()
            if text in ("true", "false"):
                return 1.0 if text == "true" else 0.0
            try:
                return float(text)
            except ValueError:
                return None
    return None


def _fluidnc_differences(link: GrblLink, profile: Profile) -> list[str]:
    """The FluidNC items (`FLUIDNC_PATHS`) against the GRBL settings they stand for."""
    from fivebar_host.controllers.grbl.program import needed_settings, soft_limits

    soft = soft_limits(profile)[0]
    out = []
    for s in needed_settings(profile):
        if s.number not in FLUIDNC_PATHS or (s.number in (27, 130, 131) and not soft):
            continue
        for path in FLUIDNC_PATHS[s.number]:
            have = _item(link, path)
            want = s.text().split("=", 1)[1]
            if have is None:
                out.append(f"{path}: not reported by the board, needed {want} ({s.why})")
            elif s.number == 22 and (have >= 1) != bool(s.value):
                need = "a cycle >= 1 (homes)" if s.value else "0 (no homing)"
                out.append(f"{path}: board {have:g}, needed {need} ({s.why})")
            elif s.number != 22 and not s.matches(have):
                out.append(f"{path}: board {have:g}, needed {want} ({s.why})")
    return out
