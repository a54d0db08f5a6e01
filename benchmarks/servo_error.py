"""Where the servo run's executed error comes from (issue 38): the Plotclock text on the
servo build, its parts measured one by one.

    PYTHONPATH=. python benchmarks/servo_error.py [--runs 3]

For configs/plotclock.toml (planned on a grid of pulse ticks) and the same profile on the
3200-step grid it had before, prints:
  - plan: the joint-space lines between the quantised targets against the text (the dry
    run's `deviation` line);
  - tick lines: the lines the firmware interpolates — the targets as pulse ticks (T1,
    controllers/fivebar/servo.py), straight in ticks, through the profile's curve and the
    true servo's dead band (each joint short of its command by w/2 on the side it came
    from) — sampled at 41 points a segment;
  - runs on the emulator (`fivebar plot examples/fivebar_text.svg --config … --fit --port
    fivebar-sim:// --yes`): the executed path as the report measures it (the widths as
    traced), and as it measured them before (rounded to 0.5 µs, a one-quantum flicker
    held), on the same trace; and the bound (tolerance + pulse quantum).
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from click.testing import CliRunner

import fivebar_host.cli.session as session
import fivebar_host.report.text.executed_servo as es
from fivebar_host.cli import main as cli
from fivebar_host.compile import CompileOptions, Job, compile_job, distance_to_request
from fivebar_host.config import Profile, load_profile
from fivebar_host.controllers.fivebar.servo import TICKS_PER_US, ServoMap
from fivebar_host.devices.simtrace import read_trace
from kinematics.servo import hysteresis

ROOT = Path(__file__).resolve().parents[1]
TEXT = ROOT / "examples" / "fivebar_text.svg"
PLOTCLOCK = ROOT / "configs" / "plotclock.toml"
S = np.linspace(0.0, 1.0, 41)


def tick_lines_mm(job: Job, prof: Profile) -> float:
    """Max distance of the tick lines through the true servo from the text (module doc)."""
    assert prof.joints is not None
    sm = ServoMap.of(prof.joints, prof)
    tk = np.stack([sm.ticks(j, job.steps[:, j]) for j in (0, 1)], axis=1).astype(float)
    js = job.joint_steps
    rank = np.cumsum(job.draw) - 1
    half = np.array([j.dead_band_rad for j in prof.joints.joints]) / 2.0
    worst = 0.0
    for k in np.flatnonzero(job.draw & (js[1:] != js[:-1]).any(axis=1)):  # no take-ups
        t = tk[k] + S[:, None] * (tk[k + 1] - tk[k])
        th = np.stack([prof.joints.joints[j].curve.angle(t[:, j] / TICKS_PER_US)
                       for j in (0, 1)], axis=1)
        th -= np.where(job.slack[k + 1] > 0, half, -half)  # slack B: it last moved up
        p = prof.geometry.forward_batch(th, "+" if job.assembly > 0 else "-").points
        worst = max(worst, float(distance_to_request(job, p, np.full(S.size, rank[k]),
                                                     S).max()))
    return worst


def held_angles(trace: Any, prof: Profile) -> tuple[np.ndarray, np.ndarray]:
    """`executed_servo.servo_angles` as it was: widths rounded to 0.5 µs, a 1 µs hold."""
    assert prof.joints is not None
    times, angles = [], []
    for j, name in enumerate(es.PINS):
        pul = np.array([(c, w) for c, w in trace.pulses(name) if c > 0], dtype=float)
        us = hysteresis(np.rint(pul[1:, 1] * 1e6 / trace.freq / 0.5) * 0.5, 1.0)
        th = prof.joints.joints[j].curve.angle(us)
        th = hysteresis(th, prof.joints.joints[j].dead_band_rad)
        times.append(pul[:-1, 0] + pul[:-1, 1])
        angles.append(th)
    return es.merge_arms(times, angles)


def run_once(cfg: Path, tmp: Path) -> tuple[float, float, float]:
    """One emulator run: (executed as traced, executed held, bound) mm."""
    got: dict[str, Any] = {}
    orig = session.write_executed

    def keep(job: Job, prof: Profile, rec: Any, preview: Path, report: Any) -> None:
        shutil.copy(rec.path, tmp / "run.trace")
        got.update(job=job, prof=prof, first=report.start_segment)
        orig(job, prof, rec, preview, report)

    session.write_executed = keep
    try:
        res = CliRunner().invoke(cli, ["plot", str(TEXT), "--config", str(cfg), "--fit",
                                       "--port", "fivebar-sim://", "--yes", "--preview",
                                       str(tmp / "p.png")])
    finally:
        session.write_executed = orig
    if "job" not in got:
        raise SystemExit(f"the run did not finish:\n{res.output}")
    job, prof = got["job"], got["prof"]
    tr = read_trace(tmp / "run.trace")
    now = es.executed_servo_path(job, prof, tr, got["first"]).max_deviation_mm
    traced = es.servo_angles
    es.servo_angles = lambda trace, profile, band: held_angles(trace, profile)
    try:
        held = es.executed_servo_path(job, prof, tr, got["first"]).max_deviation_mm
    finally:
        es.servo_angles = traced
    bound = job.tolerance_mm + max(es.pulse_quantum_mm(job, prof), job.step_quantum_mm)
    return now, held, bound


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="emulator runs per profile")
    runs = ap.parse_args().runs
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        old = tmp / "plotclock3200.toml"
        old.write_text(PLOTCLOCK.read_text().replace(
            "microsteps = 1\ngear_ratio = 40.842", "microsteps = 16\ngear_ratio = 1.0"))
        for name, cfg in (("grid of ticks (configs/plotclock.toml)", PLOTCLOCK),
                          ("3200-step grid (before)", old)):
            prof = load_profile(cfg)
            job = compile_job(TEXT, prof, CompileOptions(fit=True))
            grid = math.degrees(prof.motors.rad_per_step)
            print(f"{name}: {job.n_segments} segments, grid {grid:.5f}°")
            print(f"  plan (joint lines of the quantised targets): {job.max_dev_mm:.4f} mm")
            print(f"  tick lines through the true servo: {tick_lines_mm(job, prof):.4f} mm")
            for i in range(runs):
                now, held, bound = run_once(cfg, tmp)
                print(f"  run {i + 1}: executed {now:.4f} mm as traced, {held:.4f} mm rounded "
                      f"and held; bound {bound:.4f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
