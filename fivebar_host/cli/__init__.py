"""The `fivebar` command line: thin click wrappers over the pipeline modules.

Only this package imports click. One module per command group (vpype's library/CLI split):
`common` (the group, errors, the generated job options), `plot` (convert, plot), `remote`
(plot --server), `machine` (home, jog, frame), `pose` (config check, ik, fk), `design`
(workspace, design, linkage), `calibrate` (pattern, fit, check) and `serve` (the daemon).
Each command parses units at the edge, calls pure functions, and turns fivebar's errors into
one line and a non-zero exit.
"""

from fivebar_host.cli import calibrate, design, machine, plot, pose, serve  # noqa: F401
from fivebar_host.cli.common import main

__all__ = ["main"]
