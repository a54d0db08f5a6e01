"""Mechanism files and simulation results on disk: load, write CSV / JSON, draw.

Pure functions around `kinematics.nbar` (which has no I/O): the CLI's `fivebar linkage` group
and the benchmark use them. The picture uses matplotlib's object API with the Agg canvas, so it
needs no display and leaves pyplot's global state alone.
"""

from __future__ import annotations

import csv
import json
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from kinematics.nbar import Mechanism, MechanismError, Simulation, Status, build_mechanism

FloatArray = NDArray[np.float64]


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


def _link_polylines(mech: Mechanism, coords: FloatArray) -> list[FloatArray]:
    """Each moving link as the closed polygon through its point joints (k ≥ 3) or a segment;
    the ground is shown by its joints only."""
    out = []
    for link in mech.links:
        if link.name == mech.ground:
            continue
        idx = [mech.index(j) for j in link.joints if not mech.joints[mech.index(j)].is_line]
        if len(idx) < 2:
            continue
        pts = coords[idx, : mech.dim]
        if len(idx) >= 3:
            pts = np.vstack((pts, pts[:1]))
        out.append(pts)
    return out


def _slerp(a: FloatArray, b: FloatArray, n: int = 24) -> FloatArray:
    """Great-circle arc from a to b on the unit sphere."""
    om = math.acos(float(np.clip(a @ b, -1.0, 1.0)))
    if om < 1e-9:
        return np.vstack((a, b))
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.asarray((np.sin((1 - t) * om) * a + np.sin(t * om) * b) / math.sin(om))


def _draw_planar(ax: Axes, sim: Simulation, poses: list[int]) -> None:
    mech = sim.mechanism
    solved = np.flatnonzero(sim.solved)
    pts = sim.coords[solved][:, ~mech.is_line, :2].reshape(-1, 2)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.08 * float(np.max(hi - lo) or 1.0)
    lo, hi = lo - pad, hi + pad
    for n, k in enumerate(poses):
        alpha = 1.0 if n == 0 else 0.25
        c = sim.coords[k]
        for poly in _link_polylines(mech, c):
            ax.plot(poly[:, 0], poly[:, 1], "-", color="tab:blue", lw=2 if n == 0 else 1,
                    alpha=alpha, marker="o", ms=4 if n == 0 else 2)
        for i, j in enumerate(mech.joints):
            if not j.is_line:
                continue
            a, b, off = c[i]
            if abs(b) > abs(a):
                xs = np.array([lo[0], hi[0]])
                ys = -(a * xs + off) / b
            else:
                ys = np.array([lo[1], hi[1]])
                xs = -(b * ys + off) / a
            ax.plot(xs, ys, "--", color="tab:gray", lw=1, alpha=alpha)
    fixed = [i for i, j in enumerate(mech.joints) if mech.fixed[i] and not j.is_line]
    c0 = sim.coords[poses[0]]
    ax.plot(c0[fixed, 0], c0[fixed, 1], "^", color="black", ms=9, label="fixed joints")
    for name in mech.tracers:
        p = sim.path(name)
        ax.plot(p[:, 0], p[:, 1], "-", color="tab:red", lw=1.5, label=f"tracer {name}")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    unit = f" ({mech.units})" if mech.units else ""
    ax.set_xlabel(f"x{unit}")
    ax.set_ylabel(f"y{unit}")


def _draw_3d(ax: Any, sim: Simulation, poses: list[int]) -> None:
    mech = sim.mechanism
    sphere = mech.kind == "spherical"
    if sphere:
        u, v = np.mgrid[0: 2 * np.pi: 25j, 0: np.pi: 13j]
        ax.plot_wireframe(np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v),
                          color="0.85", lw=0.5)
    for n, k in enumerate(poses):
        alpha = 1.0 if n == 0 else 0.25
        c = sim.coords[k]
        for poly in _link_polylines(mech, c):
            if sphere:
                arc = np.vstack([_slerp(poly[i], poly[i + 1]) for i in range(len(poly) - 1)])
            else:
                arc = poly
            ax.plot(arc[:, 0], arc[:, 1], arc[:, 2], "-", color="tab:blue", alpha=alpha,
                    lw=2 if n == 0 else 1)
            ax.scatter(poly[:, 0], poly[:, 1], poly[:, 2], color="tab:blue", s=8, alpha=alpha)
        if sphere:
            for i, j in enumerate(mech.joints):
                if j.is_line:
                    nrm = c[i] / np.linalg.norm(c[i])
                    e1 = np.cross(nrm, np.eye(3)[int(np.argmin(np.abs(nrm)))])
                    e1 /= np.linalg.norm(e1)
                    e2 = np.cross(nrm, e1)
                    t = np.linspace(0, 2 * np.pi, 90)[:, None]
                    circ = np.cos(t) * e1 + np.sin(t) * e2
                    ax.plot(circ[:, 0], circ[:, 1], circ[:, 2], "--", color="tab:gray",
                            lw=0.8, alpha=alpha)
    fixed = [i for i, j in enumerate(mech.joints) if mech.fixed[i] and not j.is_line]
    c0 = sim.coords[poses[0]]
    for inp in mech.inputs:
        if inp.between is not None:
            a, b = (mech.index(j) for j in inp.between)
            seg = c0[[a, b]]
            ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], "--", color="tab:green", lw=2,
                    label=f"actuator {inp.name}")
    ax.scatter(c0[fixed, 0], c0[fixed, 1], c0[fixed, 2], marker="^", color="black", s=40,
               label="fixed joints")
    for name in mech.tracers:
        p = sim.path(name)
        ax.plot(p[:, 0], p[:, 1], p[:, 2], "-", color="tab:red", lw=1.5, label=f"tracer {name}")
    pts = sim.coords[sim.solved][:, ~mech.is_line, :].reshape(-1, 3)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0)) if not sphere else np.zeros(3)
    half = 1.05 if sphere else 0.55 * float(np.max(pts.max(axis=0) - pts.min(axis=0)) or 1.0)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")


def plot_simulation(sim: Simulation, path: str | Path, poses: int = 5) -> Path:
    """Draw the mechanism (initial pose bold, `poses` − 1 later ones faint) and the tracer
    curves; planar in 2-D, spherical on the unit sphere, spatial in 3-D. Writes a PNG/SVG/PDF
    by suffix."""
    p = Path(path)
    solved = np.flatnonzero(sim.solved)
    if not solved.size:
        raise ValueError("nothing to draw: no step was solved")
    picks = sorted({int(solved[round(t)])
                    for t in np.linspace(0, solved.size - 1, max(poses, 1))})
    fig = Figure(figsize=(7.0, 6.0))
    FigureCanvasAgg(fig)
    mech = sim.mechanism
    if mech.planar:
        ax = fig.add_subplot(1, 1, 1)
        _draw_planar(ax, sim, picks)
    else:
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        _draw_3d(ax, sim, picks)
    status = "complete" if sim.completed else "; ".join(
        f"{lim.kind} at step {lim.row}" for lim in sim.limits)
    ax.set_title(f"{mech.name}\n{len(sim.status)} steps, {status}", fontsize=10)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    return p
