"""The pen off the joint (kinematics/extension.py) on Plotclock's geometry: how exact the
closed form is, checked three ways that share no code with it.

Prints, for configs/plotclock.toml's geometry: per working mode, over random points of the
reach box, how many are reachable, the largest IK∘FK round-trip error and the largest error
of any link length or of the rigid pen triangle in the solved poses; the general n-bar
solver's deviation from the closed form along a circle in the safe region; the time of the
closed-form inverse per point; and the dry run of examples/fivebar_text.svg (--fit): its
deviation against the bound and the n-bar solver's second opinion.

Run from the repository root: python -m benchmarks.extension [--points 20000]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]
from fivebar_host.compile import CompileOptions, compile_job  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from kinematics.extension import ExtendedFiveBar  # noqa: E402
from kinematics.fivebar import WORKING_MODES  # noqa: E402
from kinematics.nbar import validate_fivebar_path  # noqa: E402
from kinematics.workspace import point_safety  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def link_error(fb: ExtendedFiveBar, th: np.ndarray, p: np.ndarray) -> float:
    """Largest error of a link length or of the pen triangle (e, γ) in solved poses, mm."""
    r1, r2 = fb.elbows(th)
    j = fb.joints(th, p)
    u = j - r1
    ang = math.cos(fb.extension_angle), math.sin(fb.extension_angle)
    pen = j + fb.extension * np.stack((ang[0] * u[:, 0] - ang[1] * u[:, 1],
                                       ang[1] * u[:, 0] + ang[0] * u[:, 1]), axis=1) / fb.b1
    errs = [np.hypot(*r1.T) - fb.a1, np.hypot(r2[:, 0] - fb.w, r2[:, 1]) - fb.a2,
            np.hypot(*(j - r1).T) - fb.b1, np.hypot(*(j - r2).T) - fb.b2,
            np.hypot(*(pen - p).T)]
    return float(max(np.abs(e).max() for e in errs))


def main_cli() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=20000)
    args = ap.parse_args()
    prof = load_profile(ROOT / "configs" / "plotclock.toml")
    fb = prof.geometry
    assert isinstance(fb, ExtendedFiveBar)
    print(f"Plotclock: a1={fb.a1:g} b1={fb.b1:g} a2={fb.a2:g} b2={fb.b2:g} w={fb.w:g} mm, pen "
          f"{fb.extension:g} mm beyond the joint at {math.degrees(fb.extension_angle):g}° "
          f"(pen link d = {fb.pen_link:.3f} mm)")
    rng = np.random.default_rng(1)
    hi = fb.reach[0][1]
    pts = np.stack((rng.uniform(-hi, fb.w + hi, args.points), rng.uniform(-hi, hi, args.points)),
                   axis=1)
    for mode in WORKING_MODES:
        t0 = time.perf_counter()
        inv = fb.inverse_batch(pts, mode)
        dt = (time.perf_counter() - t0) / pts.shape[0]
        th, p = inv.angles[inv.valid], pts[inv.valid]
        fw = fb.forward_batch(th, fb.assembly_of(th, p).astype(float))
        rt = float(np.abs(fw.points - p).max())
        print(f"mode {mode}: {int(inv.valid.sum())} of {pts.shape[0]} reachable; IK∘FK max "
              f"{rt:.2e} mm; links and pen triangle max {link_error(fb, th, p):.2e} mm; "
              f"inverse {dt * 1e9:.0f} ns/point")
    safe = pts[point_safety(fb, "+-", pts, math.radians(10), math.radians(20), assembly="+")]
    t = np.linspace(0.0, 2 * math.pi, 360)
    circle = 4.0 * np.stack((np.cos(t), np.sin(t)), axis=1)
    near = safe[np.argsort(np.hypot(*(safe - safe.mean(axis=0)).T))]
    centre = next((c for c in near if point_safety(fb, "+-", c + circle, math.radians(5),
                                                   math.radians(10), assembly="+").all()),
                  None)
    if centre is not None:
        ring = centre + circle
        inv = fb.inverse_batch(ring, "+-")
        rep = validate_fivebar_path(fb, inv.angles, "+")
        print(f"n-bar solver along a 4 mm circle at ({centre[0]:.1f}, {centre[1]:.1f}) mm: "
              f"{rep}; vs the requested circle "
              f"{float(np.abs(rep.nbar_points - ring).max()):.2e} mm")
    job = compile_job(ROOT / "examples" / "fivebar_text.svg", prof, CompileOptions(fit=True))
    print(f"dry run of fivebar_text.svg (--fit): max deviation {job.max_dev_mm:.4f} mm, bound "
          f"{job.tolerance_mm:g} + {job.step_quantum_mm:.4f} = "
          f"{job.tolerance_mm + job.step_quantum_mm:.4f} mm, {job.n_segments} segments")


if __name__ == "__main__":
    main_cli()
