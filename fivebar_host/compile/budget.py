"""How long a compile will take, said before the long work starts.

A million tiny paths is a 35 MB SVG that compiles for over a minute: that should not look
like a hang. Before reading a large file and again once the drawing is read (its paths and
primitives counted), the time ahead is estimated from per-byte and per-primitive costs
measured with `python benchmarks/tiny_paths.py` on the 2-core development machine, and said
through `fivebar_host.progress` (the terminal shows it, the daemon's page shows it with the
submission's `compiling` state) when it is over `TELL_ABOVE_S`.

The estimate informs; the limits that refuse work are the reader's segment cap
(`--max-segments`, 2 M by default) and the daemon's upload size (8 MiB by default: about
230,000 tiny paths), which bound the time: 1 M tiny paths (36 MB) compile in about 1.5
minutes at 1.4 GB peak on that machine (the path order's local search: about 1 min of it).
"""

from __future__ import annotations

from pathlib import Path

from fivebar_host import progress
from fivebar_host.toolpath.geometry import Drawing

#: Reading an SVG, s per byte (the XML parser, the CSS cascade, path data), measured.
READ_S_PER_BYTE = 1.7e-6
#: The pipeline after reading, s per primitive and per separate path (ordering, travel),
#: measured; the path order's local search (`toolpath.tour`) adds about 35 µs per path on
#: large drawings (300,000 random paths: 16 s against 5 s for the nearest-neighbour order).
COMPILE_S_PER_PRIMITIVE = 10e-6
COMPILE_S_PER_PATH = 65e-6
#: Estimates above this are told, s.
TELL_ABOVE_S = 5.0


def duration_text(seconds: float) -> str:
    """"40 s", "3 min" (rounded: it is an estimate)."""
    if seconds < 90:
        return f"{max(5, round(seconds / 5) * 5):.0f} s"
    return f"{seconds / 60:.0f} min"


def before_reading(path: Path) -> None:
    """Tell the time reading a large SVG takes (nothing for other files or small ones)."""
    if path.suffix.lower() != ".svg" or not progress.listening():
        return
    try:
        size = path.stat().st_size
    except OSError:
        return
    told(size * READ_S_PER_BYTE, f"reading {size / 1e6:.0f} MB of SVG")


def before_compiling(drawing: Drawing) -> None:
    """Tell the size of the drawing and the time compiling it takes, when long."""
    if not progress.listening():
        return
    prims, paths = int(drawing.kind.shape[0]), drawing.n_strokes
    seconds = prims * COMPILE_S_PER_PRIMITIVE + paths * COMPILE_S_PER_PATH
    told(seconds, f"{paths:,} paths of {prims:,} lines and curves")


def told(seconds: float, what: str) -> None:
    """`what` and its time, when the time is worth telling."""
    if seconds >= TELL_ABOVE_S:
        progress.estimate(f"{what}: about {duration_text(seconds)}")
