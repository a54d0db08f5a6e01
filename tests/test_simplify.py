"""Line simplification of dense input (`toolpath.simplify`) and its place in the tolerance
budget: the simplified polyline and the original are within ε of each other both ways
(checked by brute force, independently of the algorithm), and a compiled dense drawing's
executed pen path (forward kinematics of the quantised steps) stays within tol + one step
quantum of the ORIGINAL dense lines, on random dense curves and on an analytic circle."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, Job, compile_job, steps
from fivebar_host.config import load_profile
from fivebar_host.toolpath.geometry import LINE, Polylines
from fivebar_host.toolpath.simplify import simplify_polylines

PROF = load_profile()
#: Inside the default machine's safe square (54.7 mm at (−7.2, 85.5) in working mode +-).
CENTRE = (20.0, 113.0)


def _brute_distance(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance of every point p[i] to the polyline `poly` (all its segments), by brute
    force in chunks."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    ll = np.maximum((ab * ab).sum(1), 1e-300)
    out = np.empty(p.shape[0])
    for s in range(0, p.shape[0], 512):
        q = p[s:s + 512, None, :]
        u = np.clip(((q - a) * ab).sum(2) / ll, 0.0, 1.0)
        out[s:s + 512] = np.hypot(*np.moveaxis(q - a - u[..., None] * ab, 2, 0)).min(axis=1)
    return out


def _poly_of(points: list[np.ndarray]) -> tuple[Polylines, np.ndarray]:
    """Polylines of straight lines as `flatten` makes them (one chord per LINE primitive)."""
    offs = np.concatenate(([0], np.cumsum([q.shape[0] for q in points])))
    pts = np.concatenate(points)
    m = pts.shape[0]
    prim = np.zeros(m, np.int64)
    start = np.zeros(m, bool)
    start[offs[:-1]] = True
    k = np.cumsum(~start) - 1  # the line index of each non-start vertex
    prim[~start] = k[~start]
    prim[start] = np.minimum(k[start] + 1, max(int((~start).sum()) - 1, 0))
    t = np.where(start, 0.0, 1.0)
    poly = Polylines(pts, offs.astype(np.int64), prim, t, np.zeros(m),
                     np.arange(len(points), dtype=np.int64))
    return poly, np.full(int((~start).sum()), LINE, np.int8)


def _random_curve(rng: np.random.Generator, n: int, noise: float) -> np.ndarray:
    """A smooth random curve (a few random sinusoids) sampled at n points, plus noise."""
    s = np.linspace(0.0, 1.0, n)
    xy = np.zeros((n, 2))
    for f in range(1, 5):
        amp = rng.normal(0, 8.0 / f, (2, 2))
        xy += amp[:, 0] * np.sin(2 * np.pi * f * s)[:, None] + \
            amp[:, 1] * np.cos(2 * np.pi * f * s)[:, None]
    return xy + rng.normal(0, noise, xy.shape) + np.array(CENTRE)


@pytest.mark.parametrize("seed", range(6))
def test_simplified_and_original_are_within_eps_both_ways(seed: int) -> None:
    rng = np.random.default_rng(seed)
    eps = float(rng.choice([0.01, 0.025, 0.1]))
    curves = [_random_curve(rng, int(rng.integers(50, 1500)), float(rng.choice([0, 0.005, 0.05])))
              for _ in range(3)]
    poly, kind = _poly_of(curves)
    simp = simplify_polylines(poly, kind, eps)
    out = simp.poly
    assert simp.removed > 0 and out.offsets.shape == poly.offsets.shape
    for i, orig in enumerate(curves):
        new = out.points[out.offsets[i]:out.offsets[i + 1]]
        # ends kept, vertices a subset of the original ones in order
        assert np.array_equal(new[0], orig[0]) and np.array_equal(new[-1], orig[-1])
        # every original vertex (so, by convexity, every original point) within eps
        assert _brute_distance(orig, new).max() <= eps * (1 + 1e-9)
        # every point of every simplified chord within eps of the original polyline
        u = np.linspace(0.0, 1.0, 41)
        chord_pts = (new[:-1, None, :] + u[None, :, None] * (new[1:] - new[:-1])[:, None, :])
        assert _brute_distance(chord_pts.reshape(-1, 2), orig).max() <= eps * (1 + 1e-9)
    # the primitive ranges cover the lines each chord replaced
    first, last = simp.prim_first, out.prim
    body = np.ones(out.points.shape[0], bool)
    body[out.offsets[:-1]] = False
    covered = np.concatenate([np.arange(f, la + 1) for f, la in
                               zip(first[body], last[body], strict=True)])
    assert np.array_equal(covered, np.arange(kind.shape[0]))


def test_curve_chords_are_kept() -> None:
    """A flattened curve's vertices are not simplified (only runs of input lines are)."""
    pts = _random_curve(np.random.default_rng(1), 200, 0.0)
    poly, kind = _poly_of([pts])
    kind[:] = 1  # CUBIC: these chords come from flattening a curve
    simp = simplify_polylines(poly, kind, 0.1)
    assert simp.removed == 0 and np.array_equal(simp.poly.points, pts)


def _write_gcode(path: Path, curves: list[np.ndarray]) -> None:
    out = ["G21 G90"]
    for q in curves:
        out.append(f"G0 X{q[0, 0]:.6f} Y{q[0, 1]:.6f}")
        out += [f"G1 X{x:.6f} Y{y:.6f}" for x, y in q[1:]]
    path.write_text("\n".join(out) + "\n")


def _executed_draw_points(job: Job, samples: int = 8) -> np.ndarray:
    """Pen points along every draw segment of the job, from the quantised steps (joint-space
    interpolation, then the closed-form forward kinematics)."""
    th = steps.step_angles(job.steps, job.home_rad, job.steps_per_rev)
    di = np.flatnonzero(job.draw)
    s = np.arange(samples + 1) / samples
    q = th[di, None, :] + s[None, :, None] * (th[di + 1] - th[di])[:, None, :]
    fk = PROF.geometry.forward_batch(q.reshape(-1, 2), "+")
    assert fk.valid.all()
    return np.asarray(fk.points)


@pytest.mark.parametrize("seed", range(3))
def test_dense_random_curves_stay_within_tolerance_of_the_original(tmp_path: Path,
                                                                  seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    curves = []
    for _ in range(2):
        c = _random_curve(rng, 4000, 0.002)
        c = CENTRE + (c - CENTRE) * (18.0 / np.abs(c - CENTRE).max())  # inside the safe area
        curves.append(c)
    f = tmp_path / "dense.gcode"
    _write_gcode(f, curves)
    job = compile_job(f, PROF)
    dense = compile_job(f, PROF, CompileOptions(no_simplify=True))
    assert job.n_segments < dense.n_segments / 2
    e = _executed_draw_points(job)
    dist = np.minimum(_brute_distance(e, curves[0]), _brute_distance(e, curves[1]))
    assert dist.max() <= job.tolerance_mm + job.step_quantum_mm
    # the job's own validation measures against the original lines too
    assert job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
    assert job.max_dev_mm == pytest.approx(dist.max(), abs=job.step_quantum_mm)


def test_dense_circle_against_the_analytic_circle(tmp_path: Path) -> None:
    """A circle of radius 20 mm sampled every ~0.05 mm: every executed pen point is within
    tol + one step quantum of the dense polygon, so within that plus the polygon's sagitta
    r(1 − cos(π/n)) of the analytic circle; and it plans about as fast as the arc itself,
    in a twentieth of the unsimplified polygon's lines (which now plans about as fast too:
    the staircase's acceleration is the path speed's, compile.staircase)."""
    r, n = 20.0, 2513
    a = np.linspace(0.0, 2 * np.pi, n + 1)
    circle = np.stack((CENTRE[0] + r * np.cos(a), CENTRE[1] + r * np.sin(a)), axis=1)
    f = tmp_path / "circle.gcode"
    _write_gcode(f, [circle])
    job = compile_job(f, PROF)
    e = _executed_draw_points(job)
    radial = np.abs(np.hypot(e[:, 0] - CENTRE[0], e[:, 1] - CENTRE[1]) - r)
    sagitta = r * (1 - math.cos(math.pi / n))
    assert radial.max() <= job.tolerance_mm + job.step_quantum_mm + sagitta
    arc = tmp_path / "arc.gcode"
    arc.write_text(f"G21 G90\nG0 X{CENTRE[0] + r} Y{CENTRE[1]}\n"
                   f"G3 X{CENTRE[0] + r} Y{CENTRE[1]} I{-r} J0\n")
    ref = compile_job(arc, PROF)
    slow = compile_job(f, PROF, CompileOptions(no_simplify=True))
    # planned durations (deterministic figures of the plan, not wall time)
    assert job.total_time_s <= 1.1 * ref.total_time_s <= 1.1 * slow.total_time_s
    assert 20 * job.n_segments < slow.n_segments
