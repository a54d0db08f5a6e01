"""A maintained GRBL streaming library from PyPI (pygrbl-streamer) drives `fivebar bridge`
through its pseudo-terminal, streaming a Cartesian G-code drawing to the emulated firmware;
the path executed by the step pulses matches the G-code within the tolerance plus one step
quantum (docs/grbl.md)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from grbl_support import ORIGIN, start_bridge, stop_bridge

from fivebar_host.compile.steps import step_angles, step_quantum_mm
from fivebar_host.config import load_profile
from fivebar_host.devices.simtrace import read_trace
from fivebar_host.report.text.executed import merge_axes

pygrbl = pytest.importorskip("pygrbl_streamer")
DRAWING = Path(__file__).resolve().parent / "drawing.nc"
TOLERANCE = 0.05


def reference_path(lines: list[str]) -> list[np.ndarray]:
    """The drawing's laser-on strokes in machine mm, arcs sampled every 0.01 mm (an
    independent reading of G0/G1/G2/G3 X Y I J, absolute mm, as the file is written)."""
    x = y = 0.0
    strokes: list[np.ndarray] = []
    for raw in lines:
        words = dict((w[0], float(w[1:])) for w in raw.split() if w[0] in "GXYIJ")
        g = int(words.get("G", -1))
        nx, ny = words.get("X", x), words.get("Y", y)
        if g in (1, 2, 3) and ("X" in words or "Y" in words):
            if g == 1:
                pts = np.array([[x, y], [nx, ny]])
            else:
                cx, cy = x + words.get("I", 0.0), y + words.get("J", 0.0)
                r = math.hypot(x - cx, y - cy)
                a0, a1 = math.atan2(y - cy, x - cx), math.atan2(ny - cy, nx - cx)
                sweep = a1 - a0
                if g == 2 and sweep >= 0:
                    sweep -= 2 * math.pi
                if g == 3 and sweep <= 0:
                    sweep += 2 * math.pi
                n = max(2, int(abs(sweep) * r / 0.01))
                a = a0 + sweep * np.linspace(0, 1, n)
                pts = np.stack((cx + r * np.cos(a), cy + r * np.sin(a)), axis=1)
            strokes.append(pts + np.array(ORIGIN))
        x, y = nx, ny
    return strokes


def distance_to(points: np.ndarray, strokes: list[np.ndarray]) -> np.ndarray:
    """Distance of each point to the nearest segment of the strokes."""
    a = np.concatenate([s[:-1] for s in strokes])
    b = np.concatenate([s[1:] for s in strokes])
    best = np.full(points.shape[0], np.inf)
    for i in range(0, a.shape[0], 512):
        pa, pb = a[i:i + 512], b[i:i + 512]
        d = pb - pa
        t = np.clip(np.einsum("nkj,kj->nk", points[:, None] - pa[None], d)
                    / np.maximum((d * d).sum(1), 1e-18), 0, 1)
        near = pa[None] + t[..., None] * d[None]
        best = np.minimum(best, np.hypot(*(points[:, None] - near).transpose(2, 0, 1)).min(1))
    return best


@pytest.mark.sim
def test_pygrbl_streamer_draws_through_the_bridge(tmp_path: Path, sim_build: object) -> None:
    run = start_bridge("sim", tmp_path, laser=True, pty=True)
    link = tmp_path / "grbl-tty"
    lines = [s for s in DRAWING.read_text().splitlines() if s]
    try:
        sender = pygrbl.GrblStreamer(str(link), auto_unlock=True)
        sender.connect()
        try:
            assert sender.stream(iter(lines), total=len(lines), completion_timeout=300,
                                 stop_on_error=True)
        finally:
            sender.disconnect()
    finally:
        stop_bridge(run)
    assert run.trace is not None
    tr = read_trace(run.trace)
    t, track = merge_axes(tr.positions("A"), tr.positions("B"))
    on = np.array([tr.laser_on_at(int(c)) for c in t])
    prof = load_profile()
    mot = prof.motors
    th = step_angles(track, mot.home_rad, mot.steps_per_rev)
    fk = prof.geometry.forward_batch(th, prof.kinematics.assembly)
    pts = fk.points[on & fk.valid]
    assert on.sum() > 1000  # the laser drew along thousands of steps
    dev = distance_to(pts, reference_path(lines))
    quantum = step_quantum_mm(prof.geometry.jacobian(th[on], fk.points[on]),
                              mot.rad_per_step).max()
    print(f"executed deviation {dev.max():.4f} mm over {pts.shape[0]} laser-on steps "
          f"(bound {TOLERANCE} + quantum {quantum:.4f} mm)")
    assert dev.max() <= TOLERANCE + quantum
    ref = np.concatenate(reference_path(lines))[::20]
    gaps = [np.hypot(*(pts[None] - r[:, None]).transpose(2, 0, 1)).min(1).max()
            for r in np.array_split(ref, max(1, ref.shape[0] // 256))]
    assert max(gaps) < 0.5  # every part of the drawing was drawn
