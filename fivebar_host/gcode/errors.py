"""The error of a refused G-code line, and GRBL 1.1's numbers for what can be wrong with one
(doc/csv/error_codes_en_US.csv of the GRBL repository).

Every refusal of the interpreter carries both: the GRBL `error:N` a sender is answered with
(`fivebar bridge`) and a message naming the word, which the file reader puts after the file
and line (`InputError`).
"""

from __future__ import annotations

from fivebar_host.errors import FivebarError, bounded

EXPECTED_COMMAND_LETTER = 1
BAD_NUMBER_FORMAT = 2
NEGATIVE_VALUE = 4
LINE_OVERFLOW = 11
UNSUPPORTED_COMMAND = 20
MODAL_GROUP_VIOLATION = 21
UNDEFINED_FEED_RATE = 22
COMMAND_VALUE_NOT_INTEGER = 23
AXIS_COMMAND_CONFLICT = 24
WORD_REPEATED = 25
NO_AXIS_WORDS = 26
INVALID_LINE_NUMBER = 27
VALUE_WORD_MISSING = 28
UNSUPPORTED_COORD_SYS = 29
G53_INVALID_MOTION_MODE = 30
AXIS_WORDS_EXIST = 31
NO_AXIS_WORDS_IN_PLANE = 32
INVALID_TARGET = 33
ARC_RADIUS_ERROR = 34
NO_OFFSETS_IN_PLANE = 35
UNUSED_WORDS = 36
TOOL_NUMBER_EXCEEDED = 38


class GcodeError(FivebarError, ValueError):
    """A G-code line refused: `code` is GRBL's error number, `message` says why and names
    the word (`word`, as written, when one word is to blame)."""

    def __init__(self, code: int, message: str, word: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.message = bounded(message)  # a sender's 10^6-digit number is not echoed whole
        self.word = word
