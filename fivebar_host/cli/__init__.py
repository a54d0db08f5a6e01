"""The `fivebar` command line: thin click wrappers over the pipeline modules.

Only this package imports click. One module per command group (vpype's library/CLI split):
`common` (the group, errors, the generated job options), `plot` (convert, plot), `remote`
(plot --server), `machine` (home, jog, frame), `pen` (pen up|down|toggle, motors off), `pose`
(config check, ik, fk), `design` (workspace, design, linkage), `calibrate` (pattern, fit,
check), `bridge` (the GRBL front door), `grbl` (`--controller grbl`,
grbl-settings), `serve` (the daemon), `flash` (the firmware onto a board) and `doctor`
(`wiring`, `doctor`: the first hour's checks). Each command parses units at
the edge, calls pure functions, and turns fivebar's errors into one line and a non-zero exit.
"""

from fivebar_host.cli import (  # noqa: F401  (commands)
    bridge,
    calibrate,
    design,
    doctor,
    flash,
    grbl,
    machine,
    pen,
    plot,
    pose,
    serve,
    text,
)
from fivebar_host.cli.common import main

__all__ = ["main"]
