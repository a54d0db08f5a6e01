"""The one G-code interpreter of fivebar, behind both front doors that read G-code: the file
reader (`fivebar_host.toolpath.gcode`: a file → a `Drawing`, arcs kept exact) and the GRBL
bridge (`fivebar_host.bridge`: a sender's lines → moves, arcs as chords). Pure, no I/O.

- `words`: a line → its words → a `Block` sorted into GRBL's modal groups (GRBL's serial
  pre-parse or a file's comments and checksums, then one parser of the words).
- `modal`: the modal state and `execute(state, block, rules)` → (next state, actions:
  `Move`, `Dwell`, `ProgramFlow`), transactional.
- `arcs`: arc centre from I/J or R, full circles, direction, checks; exact or as chords.
- `errors`: `GcodeError`, with GRBL's error number and a message naming the word.

What each front door honours, skips or refuses is its own policy, kept in one place on its
side: its `Policy` sees every word `parse` sorts, `Block.words` keeps them, `Rules` holds
where GRBL's reading differs from the file reader's.
"""

from fivebar_host.gcode.arcs import Arc, ArcRules, ArcWords
from fivebar_host.gcode.errors import GcodeError
from fivebar_host.gcode.modal import (
    MM_PER_INCH,
    WCS_NAMES,
    Action,
    Dwell,
    ModalState,
    Move,
    ProgramFlow,
    Rules,
    Vec,
    check_target,
    execute,
)
from fivebar_host.gcode.words import (
    NUMBER,
    Block,
    Policy,
    Word,
    parse,
    preparse,
    shorten,
    strip_file,
    whole_token,
)

__all__ = [
    "MM_PER_INCH", "NUMBER", "WCS_NAMES", "Action", "Arc", "ArcRules", "ArcWords", "Block",
    "Dwell", "GcodeError", "ModalState", "Move", "Policy", "ProgramFlow", "Rules", "Vec", "Word",
    "check_target", "execute", "parse", "preparse", "shorten", "strip_file", "whole_token",
]
