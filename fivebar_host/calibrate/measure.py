"""Reading what the user measured (`measured.csv`) and the pattern's marks (`pattern.json`).

The CSV has the header `id,x_mm,y_mm` and one row per measured mark, in any frame laid on the
paper (the fit finds its rotation and offset); marks may be missing. Everything is checked
here, at the edge, with an error that names the file, the row and the reason: unknown or
duplicate ids, non-numbers and NaN, too few marks, and units that are clearly not mm — the
distances between measured marks are compared with the pattern's (their median ratio must be
within 0.8–1.25: a flatbed scan read in 600-dpi pixels gives 23.6, inches 1/25.4).
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host.calibrate.pattern import FORMAT
from fivebar_host.errors import FivebarError
from kinematics.arrays import FloatArray, IntArray
from kinematics.calibration import MIN_MARKS

HEADER = ("id", "x_mm", "y_mm")
SCALE_RANGE = (0.8, 1.25)


class MeasurementError(FivebarError, ValueError):
    """A marks file or a measurement CSV that cannot be used; names the file, row, reason."""


@dataclass(frozen=True)
class PatternMarks:
    """pattern.json: per mark id, commanded steps and nominal centre; what it was made for."""

    source: str
    ids: IntArray  # (M,)
    steps: IntArray  # (M, 2)
    nominal: FloatArray  # (M, 2) mm, machine frame
    steps_per_rev: float
    assembly: str
    mode: str
    doc: dict[str, Any]


@dataclass(frozen=True)
class Measured:
    """The measured marks: ids (N,), positions (N, 2) mm in the paper frame, and the rows of
    `PatternMarks` they belong to."""

    source: str
    ids: IntArray
    xy: FloatArray
    index: IntArray


def _need(doc: dict[str, Any], key: str, src: str, kind: type | tuple[type, ...]) -> Any:
    if key not in doc:
        raise MeasurementError(f"{src}: missing key {key!r}")
    v = doc[key]
    if not isinstance(v, kind) or isinstance(v, bool):
        raise MeasurementError(f"{src}: key {key!r} has the wrong type ({type(v).__name__})")
    return v


def read_pattern(path: Path) -> PatternMarks:
    """Read and check pattern.json (written by `fivebar calibrate pattern`)."""
    src = str(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise MeasurementError(f"{src}: cannot read: {e.strerror or e}") from e
    except json.JSONDecodeError as e:
        raise MeasurementError(f"{src}: not JSON: {e}") from e
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise MeasurementError(f"{src}: not a fivebar calibration marks file (format "
                               f"{FORMAT!r} expected)")
    marks = _need(doc, "marks", src, list)
    ids, steps, nom = [], [], []
    for i, mk in enumerate(marks):
        where = f"{src}: marks[{i}]"
        if not isinstance(mk, dict):
            raise MeasurementError(f"{where}: must be an object")
        ident = _need(mk, "id", where, int)
        st = _need(mk, "steps", where, list)
        if len(st) != 2 or not all(isinstance(s, int) and not isinstance(s, bool) for s in st):
            raise MeasurementError(f"{where}: steps must be two integers; got {st!r}")
        x, y = (float(_need(mk, k, where, (int, float))) for k in ("x_mm", "y_mm"))
        ids.append(ident)
        steps.append(st)
        nom.append((x, y))
    if len(set(ids)) != len(ids):
        raise MeasurementError(f"{src}: duplicate mark ids")
    return PatternMarks(src, np.array(ids, dtype=np.int64), np.array(steps, dtype=np.int64),
                        np.array(nom, dtype=np.float64),
                        float(_need(doc, "steps_per_rev", src, (int, float))),
                        str(_need(doc, "assembly", src, str)), str(_need(doc, "mode", src, str)),
                        doc)


def _row_values(row: list[str], line: int, src: str) -> tuple[int, float, float]:
    """One CSV row → (id, x, y); names the row and the field on error."""
    if len(row) != 3:
        raise MeasurementError(f"{src}:{line}: expected 3 fields id,x_mm,y_mm; got {len(row)}")
    try:
        ident = int(row[0].strip())
    except ValueError:
        raise MeasurementError(f"{src}:{line}: id {row[0]!r} is not an integer") from None
    vals = []
    for name, text in zip(HEADER[1:], row[1:], strict=True):
        try:
            v = float(text.strip())
        except ValueError:
            raise MeasurementError(f"{src}:{line}: {name} {text!r} is not a number") from None
        if not math.isfinite(v):
            raise MeasurementError(f"{src}:{line}: {name} is {text.strip()} (mark {ident}); "
                                   "every measured coordinate must be a finite number of mm")
        vals.append(v)
    return ident, vals[0], vals[1]


def read_measured(path: Path, pattern: PatternMarks) -> Measured:
    """Read and check measured.csv against the pattern's marks (module doc)."""
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise MeasurementError(f"{src}: cannot read: {e.strerror or e}") from e
    rows = [(n, r) for n, r in enumerate(csv.reader(text.splitlines()), start=1)
            if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    if not rows or tuple(c.strip().lower() for c in rows[0][1]) != HEADER:
        raise MeasurementError(f"{src}:1: the header must be {','.join(HEADER)}")
    known = {int(i): k for k, i in enumerate(pattern.ids)}
    seen: dict[int, int] = {}
    ids, xy, index = [], [], []
    for line, row in rows[1:]:
        ident, x, y = _row_values(row, line, src)
        if ident not in known:
            raise MeasurementError(f"{src}:{line}: mark id {ident} is not in the pattern "
                                   f"{pattern.source} (ids {pattern.ids.min()}–"
                                   f"{pattern.ids.max()})")
        if ident in seen:
            raise MeasurementError(f"{src}:{line}: mark id {ident} measured twice (first on "
                                   f"line {seen[ident]})")
        seen[ident] = line
        ids.append(ident)
        xy.append((x, y))
        index.append(known[ident])
    if len(ids) < MIN_MARKS:
        raise MeasurementError(f"{src}: {len(ids)} marks measured; the fit needs at least "
                               f"{MIN_MARKS}")
    m = Measured(src, np.array(ids, dtype=np.int64), np.array(xy, dtype=np.float64),
                 np.array(index, dtype=np.int64))
    check_units(m, pattern)
    return m


def check_units(m: Measured, pattern: PatternMarks) -> float:
    """Median ratio of measured to nominal distances between marks; MeasurementError when it
    is outside `SCALE_RANGE` (not mm)."""
    nom = pattern.nominal[m.index]
    i, j = np.triu_indices(m.ids.size, 1)
    dn = np.hypot(*(nom[i] - nom[j]).T)
    dm = np.hypot(*(m.xy[i] - m.xy[j]).T)
    ratio = float(np.median(dm[dn > 0] / dn[dn > 0]))
    if not SCALE_RANGE[0] <= ratio <= SCALE_RANGE[1]:
        raise MeasurementError(
            f"{m.source}: the measured marks are {ratio:.3g}× as far apart as the pattern's: "
            "the CSV must be in mm (a 600-dpi scan read in pixels gives 23.6×, inches "
            "0.039×)")
    return ratio
