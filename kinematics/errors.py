"""The root of every error fivebar shows a user.

It lives on the lowest floor (`kinematics`, pure math) so that the math's own errors
(unreachable points, inconsistent mechanisms, no safe region) and the host's (a bad drawing,
profile, option, link fault, …) share one root: the command line catches `FivebarError` (and
the OS errors it names) and nothing else, so a bug shows up as a bug, not as a tidy message.
"""

from __future__ import annotations

import re

#: Longest value a message quotes whole; longer ones are shortened (`shorten`).
SHOWN_CHARS = 60
#: Longest run without white space a message keeps whole (`bounded`).
WORD_CHARS = 120
_LONG_WORD = re.compile(r"[^\s:;,]{" + str(WORD_CHARS + 1) + ",}")


def shorten(value: object, limit: int = SHOWN_CHARS) -> str:
    """`value` as text for a message, at most about `limit` characters: a longer one keeps
    its first and last characters and says its length ("1234567890…7890 (1000000
    characters)"), so that echoing what a user sent never makes an unbounded line."""
    text = str(value)
    if len(text) <= limit:
        return text
    head = max(1, limit * 2 // 3)
    tail = max(1, limit - head - 1)
    return f"{text[:head]}…{text[-tail:]} ({len(text)} characters)"


def bounded(message: str) -> str:
    """`message` with every run of more than `WORD_CHARS` characters without white space
    (or `:;,`) shortened (`shorten`): the last guard on what reaches a terminal, a log or an HTTP
    answer, whatever an error quoted."""
    if len(message) <= WORD_CHARS:
        return message
    return _LONG_WORD.sub(lambda m: shorten(m.group(0)), message)


class FivebarError(Exception):
    """Something the user can fix or must know: the message says where and why.

    `exit_code` is the command line's exit status for it: 2 for bad input (drawing, profile,
    option), 3 for a machine-side failure (link, firmware, fault). Its text is `bounded`: a
    value it quotes, however long, is shown shortened."""

    exit_code: int = 2

    def __str__(self) -> str:
        return bounded(super().__str__())
