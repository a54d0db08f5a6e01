"""Constants of the ``fivebar-mock://`` firmware model, shared by its parts.

The values mirror the firmware (firmware/fivebar/config.h, status.h): the CPU clock the DDA
counts in, the queue's start rule, the boot values and indices of the ``$`` settings, and
the reply and alarm codes by name (from the shared table in ``fivebar_host.protocol``), so
the parser, the firmware model and the URL options all answer with the firmware's codes.
"""

from __future__ import annotations

from typing import Final

from fivebar_host import protocol

SCHEME: Final = "fivebar-mock"

F_CPU: Final = 16_000_000
CYCLES_PER_US: Final = F_CPU // 1_000_000
START_BLOCKS: Final = 4  # config.h CFG_START_BLOCKS
START_DELAY_S: Final = 0.020  # config.h CFG_START_DELAY_MS
P_MIN_US: Final = protocol.P_MIN_US
P_MAX_US: Final = protocol.P_MAX_US

#: Boot values of the $ settings, in order 0..14 (firmware/fivebar/config.h DEF_*).  Names
#: and ranges come from protocol.SETTINGS; the contract suite compares ``$$`` of both devices.
#: $14 (the pen's park pulse) is kept in the EEPROM: a boot takes the stored value.
DEFAULT_SETTINGS: Final = (20000, -100000, 100000, -100000, 100000, 1, 2000, 0, 2000, 100,
                           0, 0, 20000, 0, 0)
S_MAX_RATE, S_A_MIN, S_A_MAX, S_B_MIN, S_B_MAX, S_SOFT, S_LASER_TIMEOUT, S_HOMING = range(8)
S_HOMING_RATE, S_PULLOFF, S_HOME_A, S_HOME_B, S_TRAVEL, S_HOMING_DIR, S_PEN_PARK = range(8, 15)

# Reply codes (status.h), by name from the shared table.
_CODE = {c.name: c.code for c in protocol.CODES.values()}
OK: Final = 0
E_INVALID_CHAR: Final = _CODE["INVALID_CHAR"]
E_LINE_TOO_LONG: Final = _CODE["LINE_TOO_LONG"]
E_BAD_NUMBER: Final = _CODE["BAD_NUMBER"]
E_UNKNOWN_COMMAND: Final = _CODE["UNKNOWN_COMMAND"]
E_BAD_WORD: Final = _CODE["BAD_WORD"]
E_MISSING_WORD: Final = _CODE["MISSING_WORD"]
E_OUT_OF_RANGE: Final = _CODE["OUT_OF_RANGE"]
E_CHECKSUM: Final = _CODE["CHECKSUM"]
E_LINE_NUMBER: Final = _CODE["LINE_NUMBER"]
E_NO_CHECKSUM: Final = _CODE["NO_CHECKSUM"]
E_SOFT_LIMIT: Final = _CODE["SOFT_LIMIT"]
E_TOO_FAST: Final = _CODE["TOO_FAST"]
E_BUSY: Final = _CODE["BUSY"]
E_ALARM_LOCK: Final = _CODE["ALARM_LOCK"]
E_MOTORS_OFF: Final = _CODE["MOTORS_OFF"]
E_HOMING_DISABLED: Final = _CODE["HOMING_DISABLED"]
E_UNKNOWN_SETTING: Final = _CODE["UNKNOWN_SETTING"]
E_RX_OVERFLOW: Final = _CODE["RX_OVERFLOW"]
E_NO_PEN: Final = _CODE["NO_PEN"]
A_ENDSTOP: Final = _CODE["ENDSTOP"]
A_HOMING_FAIL: Final = _CODE["HOMING_FAIL"]
A_HOMING_ABORT: Final = _CODE["HOMING_ABORT"]

WAIT: Final = -1  # a command that needs a queue slot (or homing) and must wait
