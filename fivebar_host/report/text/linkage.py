"""Mechanism files and simulation results on disk: load, write CSV / JSON, summarise.

Pure functions around `kinematics.nbar` (which has no I/O): the CLI's `fivebar linkage` group
and the benchmarks use them. The picture of a simulation is `fivebar_host.report.linkage`
(kept apart so that loading a mechanism loads no plotting library).
"""

from __future__ import annotations

import csv
import json
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from kinematics.nbar import Mechanism, MechanismError, Simulation, Status, build_mechanism


def load_mechanism(path: str | Path) -> Mechanism:
    """Read and build a mechanism file; errors name the file."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            spec = tomllib.load(f)
    except OSError as e:
        raise MechanismError(f"{p}: cannot read ({e.strerror})") from None
    except tomllib.TOMLDecodeError as e:
        raise MechanismError(f"{p}: not valid TOML: {e}") from None
    try:
        return build_mechanism(spec)
    except MechanismError as e:
        raise MechanismError(f"{p}: {e}") from None


def _coord_names(mech: Mechanism) -> list[tuple[str, int, list[str]]]:
    """(joint, index, column suffixes): x, y(, z) for points, a, b, c for lines / planes."""
    out = []
    for i, j in enumerate(mech.joints):
        if j.is_line:
            out.append((j.name, i, ["a", "b", "c"]))
        else:
            out.append((j.name, i, ["x", "y"] if mech.planar else ["x", "y", "z"]))
    return out


def table(sim: Simulation) -> tuple[list[str], list[list[Any]]]:
    """Header and rows: step, status, iterations, sub-steps, residual, inputs, coordinates."""
    mech = sim.mechanism
    header = ["step", "status", "iterations", "substeps", "residual"]
    header += [f"input_{inp.name}" for inp in mech.inputs]
    cols = _coord_names(mech)
    for name, _, suffixes in cols:
        header += [f"{name}_{s}" for s in suffixes]
    rows: list[list[Any]] = []
    names = sim.status_names
    for k in range(len(sim.status)):
        row: list[Any] = [k, names[k], int(sim.iterations[k]), int(sim.substeps[k]),
                          float(sim.residual[k])]
        row += [float(v) for v in sim.inputs[k]]
        for _, i, suffixes in cols:
            row += [float(v) for v in sim.coords[k, i, : len(suffixes)]]
        rows.append(row)
    return header, rows


def _json_number(v: float) -> float | None:
    return None if not math.isfinite(v) else v


def to_json(sim: Simulation) -> dict[str, Any]:
    """A JSON-ready dict: mechanism summary, per-step records, limits (NaN → null)."""
    mech = sim.mechanism
    steps = []
    for k in range(len(sim.status)):
        joints = {}
        for name, i, suffixes in _coord_names(mech):
            joints[name] = [_json_number(float(v)) for v in sim.coords[k, i, : len(suffixes)]]
        steps.append({
            "step": k,
            "status": sim.status_names[k],
            "inputs": [float(v) for v in sim.inputs[k]],
            "iterations": int(sim.iterations[k]),
            "substeps": int(sim.substeps[k]),
            "residual": _json_number(float(sim.residual[k])),
            "joints": joints,
        })
    return {
        "mechanism": {"name": mech.name, "kind": mech.kind, "source": mech.source,
                      "units": mech.units, "tracers": list(mech.tracers),
                      "inputs": [{"name": i.name, "kind": i.kind, "unit": i.unit,
                                  "initial": i.value0} for i in mech.inputs],
                      "joints": [{"name": j.name, "type": j.type,
                                  "coords": list(sfx)}
                                 for j, (_, _, sfx) in zip(mech.joints, _coord_names(mech),
                                                           strict=True)],
                      "adjustments": list(mech.adjustments)},
        "completed": sim.completed,
        "limits": [{"kind": lim.kind, "step": lim.row, "reached": lim.reached.tolist(),
                    "failed": lim.failed.tolist(), "reason": lim.reason} for lim in sim.limits],
        "steps": steps,
    }


def write_result(sim: Simulation, path: str | Path) -> Path:
    """Write the simulation as CSV or JSON, chosen by the file suffix."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".csv":
        header, rows = table(sim)
        with p.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(header)
            w.writerows(rows)
    elif suffix == ".json":
        p.write_text(json.dumps(to_json(sim), indent=1, allow_nan=False) + "\n")
    else:
        raise ValueError(f"{p}: output must end in .csv or .json")
    return p


def summary(sim: Simulation) -> str:
    """A few lines for the terminal: what ran, how it went, where it stopped and why."""
    mech = sim.mechanism
    solved = sim.solved
    counts = {s.name.lower(): int((sim.status == s).sum()) for s in Status
              if (sim.status == s).any()}
    res = float(np.nanmax(sim.residual)) if solved.any() else math.nan
    moving = sim.iterations[1:] if len(sim.iterations) > 1 else sim.iterations
    lines = [
        f"{mech.name} ({mech.kind}): {mech.system.n_u} unknowns, {mech.system.m} equations"
        + (" (least squares)" if mech.overdetermined else ""),
        f"steps: {len(sim.status)} rows, " + ", ".join(f"{v} {k}" for k, v in counts.items()),
        f"max residual {res:.2g} (relative to size {mech.size:.4g}), "
        f"{float(np.mean(moving)):.2f} Newton iterations per step",
    ]
    lines += [f"adjusted: {a}" for a in mech.adjustments]
    lines += [str(lim) for lim in sim.limits]
    for name in mech.tracers:
        pts = sim.path(name)[solved]
        if pts.size:
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            span = ", ".join(f"[{a:.4g}, {b:.4g}]" for a, b in zip(lo, hi, strict=True))
            lines.append(f"tracer {name}: range {span}")
    return "\n".join(lines)
