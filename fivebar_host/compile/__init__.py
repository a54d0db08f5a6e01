"""Compiling drawings into jobs: read → layout → flatten/segment → inverse kinematics +
checks → plan → steps → validate → encode (docs/architecture.md, "Data flow").

The public API, for the CLI, the sender, the server, the previews, the benchmarks and tests:

- `model`: `CompileOptions`, `Job`, `PathStats`, `ModeChange` (the data model);
- `job`: `compile_job`, `compile_drawing`, `read_drawing`, `gcode_tool` (the pipeline);
- `validate`: `deviations`, `validate`, `nbar_opinion`, `distance_to_request`;
- `program`: `Program`, `Kind`, `job_program`, `setup`, `pen_item` (the typed program);
- `encode`: `encode_lines`, `mode_sequence`, `write_atomic` (the file of `fivebar convert`).
"""

from fivebar_host.compile.encode import (
    MAX_LINE_BYTES,
    encode_lines,
    mode_sequence,
    write_atomic,
)
from fivebar_host.compile.job import (
    GCODE_SUFFIXES,
    compile_drawing,
    compile_job,
    gcode_tool,
    read_drawing,
)
from fivebar_host.compile.model import (
    AUTO_ORDER,
    MAX_STEP_RAD,
    CompileOptions,
    Job,
    ModeChange,
    PathStats,
)
from fivebar_host.compile.validate import (
    NBAR_MAX_POSES,
    NbarOpinion,
    deviations,
    distance_to_request,
    nbar_opinion,
    validate,
)

__all__ = [
    "AUTO_ORDER",
    "GCODE_SUFFIXES",
    "MAX_LINE_BYTES",
    "MAX_STEP_RAD",
    "NBAR_MAX_POSES",
    "CompileOptions",
    "Job",
    "ModeChange",
    "NbarOpinion",
    "PathStats",
    "compile_drawing",
    "compile_job",
    "deviations",
    "distance_to_request",
    "encode_lines",
    "gcode_tool",
    "mode_sequence",
    "nbar_opinion",
    "read_drawing",
    "validate",
    "write_atomic",
]
