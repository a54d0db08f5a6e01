"""What the bridge reads of G-code: GRBL 1.1's reading of fivebar's interpreter
(`fivebar_host.gcode`) and the bridge's own refusals, with GRBL's error codes.

- `parse`: a pre-parsed line → `Block` with GRBL's word rules (`strict`), refusing the
  commands GRBL knows that the bridge does not honour (`REFUSED_G`).
- `run`: `execute` with GRBL's rules (`RULES`), then, as GRBL's parser checks a line before
  anything of it runs, each move's arc (`error:33`–`35`) and target (`error:33`: a
  coordinate of 1e6 mm or more). The path of G28/G30 is left to the solver's checks.
"""

from __future__ import annotations

import math

from fivebar_host.gcode import (
    Action,
    ArcRules,
    Block,
    GcodeError,
    ModalState,
    Move,
    Policy,
    Rules,
    Word,
    check_target,
    execute,
    words,
)
from fivebar_host.gcode import errors as gcode_errors

#: G commands the interpreter knows that the bridge refuses, with GRBL's answer: the XZ and
#: YZ planes (a pen or laser five-bar has no such arcs) and inverse-time feed, `error:20`;
#: G90.1 (absolute arc centres) is not GRBL 1.1's, which answers it `error:23` (G90 takes no
#: decimal). Probing (G38.x) and dynamic tool length (G43.1) are unknown words: `error:20`.
REFUSED_G = {180: gcode_errors.UNSUPPORTED_COMMAND, 190: gcode_errors.UNSUPPORTED_COMMAND,
             930: gcode_errors.UNSUPPORTED_COMMAND,
             901: gcode_errors.COMMAND_VALUE_NOT_INTEGER}
#: GRBL's reading (gcode.c): strict words, a feed before G1–G3; an I/J arc's end within
#: 0.005 mm of the circle or 0.1 % of the radius up to 0.5 mm, an R no shorter than half the
#: chord, R used when I/J come with it; an R arc's end within 1e-9 mm of its start and a
#: sweep within 1e-9 rad of zero are the start (a full turn for I/J).
RULES = Rules(strict=True,
              arcs=ArcRules(end_tol_mm=0.005, end_tol_rel=0.001, end_tol_cap_mm=0.5,
                            r_short_mm2=0.0, same_point_mm=1e-9, full_circle_rad=1e-9,
                            full_circle_chord_mm=0.0, zero_radius_ok=True,
                            r_with_offsets_ok=True))
#: Targets must be below 1e6 mm in every axis.
MAX_COORD_MM = math.nextafter(1e6, 0.0)


def _refuse_g(w: Word) -> None:
    """Refuse the G commands in `REFUSED_G`."""
    if w.letter == "G":
        tenths = words.g_tenths(w.value)
        if tenths in REFUSED_G:
            raise GcodeError(REFUSED_G[tenths], f"{w.text} is not supported by the bridge",
                             w.text)


#: Every word the interpreter knows is honoured but the G commands of `REFUSED_G`.
POLICY = Policy(frozenset(words.VALUE_WORDS | {"M"}), _refuse_g)


def parse(text: str) -> Block:
    """A pre-parsed line → `Block` (module doc), or `GcodeError` with GRBL's code."""
    return words.parse(text, True, POLICY)


def run(state: ModalState, block: Block) -> tuple[ModalState, list[Action]]:
    """`execute` the block with GRBL's rules and check its moves (module doc)."""
    state, actions = execute(state, block, RULES)
    if block.g.get("non_modal") not in (280, 300):
        for act in actions:
            if isinstance(act, Move):
                if act.arc is not None:
                    act.exact_arc()
                check_target(act.end, MAX_COORD_MM, MAX_COORD_MM)
    return state, actions
