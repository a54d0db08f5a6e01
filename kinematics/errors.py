"""The root of every error fivebar shows a user.

It lives on the lowest floor (`kinematics`, pure math) so that the math's own errors
(unreachable points, inconsistent mechanisms, no safe region) and the host's (a bad drawing,
profile, option, link fault, …) share one root: the command line catches `FivebarError` (and
the OS errors it names) and nothing else, so a bug shows up as a bug, not as a tidy message.
"""

from __future__ import annotations


class FivebarError(Exception):
    """Something the user can fix or must know: the message says where and why.

    `exit_code` is the command line's exit status for it: 2 for bad input (drawing, profile,
    option), 3 for a machine-side failure (link, firmware, fault)."""

    exit_code: int = 2
