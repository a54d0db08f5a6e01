"""The picture of a linkage simulation (`fivebar linkage simulate --plot`).

The mechanism at its initial pose (bold) and a few later ones (faint) with the tracer curves:
planar in 2-D, spherical on the unit sphere, spatial in 3-D. It uses matplotlib's object API
with the Agg canvas, so it needs no display and leaves pyplot's global state alone. The
simulation itself is `kinematics.nbar`; files and text are `fivebar_host.report.text.linkage`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from kinematics.arrays import FloatArray
from kinematics.nbar import Mechanism, Simulation


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


def _planar_view(sim: Simulation) -> tuple[FloatArray, FloatArray]:
    """Lower-left and upper-right corners of the view: every solved point joint, 8 % room."""
    mech = sim.mechanism
    solved = np.flatnonzero(sim.solved)
    pts = sim.coords[solved][:, ~mech.is_line, :2].reshape(-1, 2)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.08 * float(np.max(hi - lo) or 1.0)
    return lo - pad, hi + pad


def _line_joint(ax: Axes, line: FloatArray, lo: FloatArray, hi: FloatArray,
                alpha: float) -> None:
    """A line joint a·x + b·y + c = 0 across the view, dashed."""
    a, b, off = line
    if abs(b) > abs(a):
        xs = np.array([lo[0], hi[0]])
        ys = -(a * xs + off) / b
    else:
        ys = np.array([lo[1], hi[1]])
        xs = -(b * ys + off) / a
    ax.plot(xs, ys, "--", color="tab:gray", lw=1, alpha=alpha)


def _draw_planar(ax: Axes, sim: Simulation, poses: list[int]) -> None:
    mech = sim.mechanism
    lo, hi = _planar_view(sim)
    for n, k in enumerate(poses):
        alpha = 1.0 if n == 0 else 0.25
        c = sim.coords[k]
        for poly in _link_polylines(mech, c):
            ax.plot(poly[:, 0], poly[:, 1], "-", color="tab:blue", lw=2 if n == 0 else 1,
                    alpha=alpha, marker="o", ms=4 if n == 0 else 2)
        for i, j in enumerate(mech.joints):
            if j.is_line:
                _line_joint(ax, c[i], lo, hi, alpha)
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


def _great_circle(ax: Any, normal: FloatArray, alpha: float) -> None:
    """A plane joint of a spherical mechanism: its great circle on the unit sphere."""
    nrm = normal / np.linalg.norm(normal)
    e1 = np.cross(nrm, np.eye(3)[int(np.argmin(np.abs(nrm)))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(nrm, e1)
    t = np.linspace(0, 2 * np.pi, 90)[:, None]
    circ = np.cos(t) * e1 + np.sin(t) * e2
    ax.plot(circ[:, 0], circ[:, 1], circ[:, 2], "--", color="tab:gray", lw=0.8, alpha=alpha)


def _pose_3d(ax: Any, mech: Mechanism, c: FloatArray, bold: bool, sphere: bool) -> None:
    """One pose in 3-D: the links (great-circle arcs on the sphere) and the plane joints."""
    alpha = 1.0 if bold else 0.25
    for poly in _link_polylines(mech, c):
        if sphere:
            arc = np.vstack([_slerp(poly[i], poly[i + 1]) for i in range(len(poly) - 1)])
        else:
            arc = poly
        ax.plot(arc[:, 0], arc[:, 1], arc[:, 2], "-", color="tab:blue", alpha=alpha,
                lw=2 if bold else 1)
        ax.scatter(poly[:, 0], poly[:, 1], poly[:, 2], color="tab:blue", s=8, alpha=alpha)
    if sphere:
        for i, j in enumerate(mech.joints):
            if j.is_line:
                _great_circle(ax, c[i], alpha)


def _ground_3d(ax: Any, sim: Simulation, c0: FloatArray) -> None:
    """Actuators and fixed joints at the first pose c0, and the tracer curves."""
    mech = sim.mechanism
    fixed = [i for i, j in enumerate(mech.joints) if mech.fixed[i] and not j.is_line]
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


def _frame_3d(ax: Any, sim: Simulation, sphere: bool) -> None:
    """A cube around the solved points (the unit sphere for a spherical mechanism)."""
    mech = sim.mechanism
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


def _draw_3d(ax: Any, sim: Simulation, poses: list[int]) -> None:
    mech = sim.mechanism
    sphere = mech.kind == "spherical"
    if sphere:
        u, v = np.mgrid[0: 2 * np.pi: 25j, 0: np.pi: 13j]
        ax.plot_wireframe(np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v),
                          color="0.85", lw=0.5)
    for n, k in enumerate(poses):
        _pose_3d(ax, mech, sim.coords[k], n == 0, sphere)
    _ground_3d(ax, sim, sim.coords[poses[0]])
    _frame_3d(ax, sim, sphere)


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
