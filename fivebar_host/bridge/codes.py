"""GRBL 1.1's reply codes, as its documentation lists them (doc/csv/error_codes_en_US.csv and
alarm_codes_en_US.csv of the GRBL repository), and the error the bridge raises with one.

The bridge answers a sender in GRBL's numbers, never in the fivebar firmware's (which differ:
fivebar's error:11 is a soft limit, GRBL's error:11 a line overflow).
"""

from __future__ import annotations

from fivebar_host.errors import FivebarError
from fivebar_host.gcode import GcodeError

# error:N ----------------------------------------------------------------------------------
# The numbers of refused G-code lines are the interpreter's (`fivebar_host.gcode.errors`);
# these are the bridge's own (system commands, its states).
INVALID_STATEMENT = 3
SETTING_DISABLED = 5  # homing not enabled
NOT_IDLE = 8
GCODE_LOCK = 9  # alarm or jog state
TRAVEL_EXCEEDED = 15  # jog target beyond the machine's travel
INVALID_JOG_COMMAND = 16

ERROR_TEXT = {
    1: "Expected command letter", 2: "Bad number format", 3: "Invalid statement",
    4: "Value < 0", 5: "Setting disabled", 8: "Not idle", 9: "G-code lock",
    11: "Line overflow", 15: "Travel exceeded", 16: "Invalid jog command",
    20: "Unsupported command", 21: "Modal group violation", 22: "Undefined feed rate",
    23: "Command requires integer value", 24: "Two axis commands", 25: "Repeated word",
    26: "No axis words", 27: "Invalid line number", 28: "Value word missing",
    29: "G59.x not supported", 30: "G53 only with G0/G1", 31: "Axis words not used",
    32: "Arc needs in-plane axis word", 33: "Invalid motion target", 34: "Arc radius error",
    35: "Arc needs in-plane offset", 36: "Unused value words",
}

# ALARM:N ----------------------------------------------------------------------------------
ALARM_HARD_LIMIT = 1
ALARM_SOFT_LIMIT = 2
ALARM_ABORT_CYCLE = 3
ALARM_HOMING_FAIL_RESET = 6
ALARM_HOMING_FAIL_PULLOFF = 8
ALARM_HOMING_FAIL_APPROACH = 9

#: The fivebar firmware's alarm codes (docs/protocol.md 11) → GRBL's nearest alarm.
FIRMWARE_ALARM = {30: ALARM_HARD_LIMIT, 31: ALARM_HOMING_FAIL_APPROACH,
                  32: ALARM_HOMING_FAIL_RESET}


class GrblError(GcodeError):
    """A line the bridge itself refuses with GRBL's `error:<code>` (a `$` command, a lock);
    the message says why (for logs and tests, never sent: GRBL answers a refused line with
    the number only). Refused G-code is the interpreter's `GcodeError`, its base."""

    def __init__(self, code: int, why: str = "") -> None:
        super().__init__(code, why or ERROR_TEXT.get(code, ""))


class GrblAlarmError(FivebarError, ValueError):
    """A line that raises a GRBL alarm before anything moves (ALARM:2, soft limit: a target
    out of reach or a path through a singularity); `message` names the point and why."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(f"ALARM:{code} {message}")
        self.code = code
        self.message = message


def ascii_text(text: str) -> str:
    """GRBL's messages are ASCII and hold no `|`, `[` or `]`: symbols spelt out or replaced."""
    text = (text.replace("°", " deg").replace("→", "->").replace("−", "-")
            .replace("|", "").replace("[", "(").replace("]", ")"))
    return text.encode("ascii", "replace").decode()
