"""One run of the benchmark: every section measured in order, its chart drawn, the report
written; and the command line (`main`) behind `python -m benchmarks.speed_accuracy`."""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchmarks import approx
from benchmarks.pipeline import make_svg
from benchmarks.speed_accuracy.approaches import chart_approaches, run_approaches, variant_scene
from benchmarks.speed_accuracy.config import ROOT, Config
from benchmarks.speed_accuracy.examples import chart_examples, example_rows
from benchmarks.speed_accuracy.jobs import chart_jobs, job_rows, validation_cost
from benchmarks.speed_accuracy.kinematics_chart import chart_tradeoff
from benchmarks.speed_accuracy.methods import build_methods, kinematics_rows
from benchmarks.speed_accuracy.nbar_forward import nbar_kinematics_rows
from benchmarks.speed_accuracy.report import write_report
from benchmarks.speed_accuracy.results import Results
from benchmarks.speed_accuracy.scene import make_scene, sample_sets
from benchmarks.speed_accuracy.stability import chart_stability, stability_map
from benchmarks.speed_accuracy.steps import chart_steps, step_rows
from benchmarks.speed_accuracy.timing import machine_info
from fivebar_host.config import Profile

#: The command's one-line description (`--help`).
DESCRIPTION = "Speed against accuracy, charted; stability where methods fail (issue 7)."


def run(cfg: Config, out_dir: Path, profile: Profile | None = None) -> Results:
    """Run every item, draw the charts into out_dir/img and write out_dir/performance.md."""
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    info = machine_info()
    img = out_dir / "img"
    img.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(2026)

    def lap(name: str, t0: float) -> None:
        timings[name] = time.perf_counter() - t0
        print(f"  {name}: {timings[name]:.1f} s", flush=True)

    t0 = time.perf_counter()
    sc = make_scene(profile)
    sets = sample_sets(sc, cfg.n_near, rng)
    lap("setup", t0)
    t0 = time.perf_counter()
    methods = build_methods(sc, cfg)
    kin = kinematics_rows(sc, cfg, sets, methods)
    nbar = nbar_kinematics_rows(sc, cfg, sets)
    lin = approx.fit_linear(sc.fb, sc.mode, sc.region_pts, "similarity")
    chart_tradeoff(kin, nbar, sc.tol_mm, img / "perf_kinematics.png")
    lap("1 kinematics", t0)
    t0 = time.perf_counter()
    examples, note = example_rows(cfg)
    chart_examples(examples, img / "perf_nbar.png")
    lap("2 n-bar examples", t0)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        strokes = Path(tmp) / "strokes.svg"
        strokes.write_text(make_svg(cfg.random_paths))
        every = {"text": ROOT / "examples" / "fivebar_text.svg",
                 "shapes": ROOT / "examples" / "simple.svg", "random strokes": strokes}
        scenes = {k: every[k] for k in cfg.job_scenes}
        jobs = job_rows(sc, cfg, scenes)
        first = cfg.job_scenes[0]
        vcost = validation_cost(sc, scenes[first], first, cfg.job_repeats)
    chart_jobs(jobs, img / "perf_jobs.png")
    lap("3 jobs", t0)
    t0 = time.perf_counter()
    steps = step_rows(sc, cfg, rng)
    chart_steps(sc, steps, img / "perf_steps.png", max(cfg.map_pitch_mm, 1.0))
    lap("4 steps", t0)
    t0 = time.perf_counter()
    smap = stability_map(sc, cfg)
    appr = run_approaches(sc, cfg)
    var = variant_scene(sc)
    if var is not None:
        appr += run_approaches(var, cfg, ("type 2: Mode 1a",),
                               f"b1 = b2 = {var.fb.b1:g} mm")
    chart_stability(sc, smap, img / "perf_stability.png")
    chart_approaches(appr, sc.tol_mm, img / "perf_approach.png")
    lap("5 stability", t0)
    timings["total"] = time.perf_counter() - t_start
    load = os.getloadavg() if hasattr(os, "getloadavg") else (math.nan,) * 3
    info["load_end"] = f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"
    res = Results(info, cfg, sc, sets, lin, kin, nbar, examples, note, jobs, vcost, steps,
                  smap, appr, timings)
    write_report(res, out_dir)
    return res


def main(argv: Sequence[str] | None = None) -> None:
    """The command line: `--quick` or the full sizes, the report and charts into `--out-dir`."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.speed_accuracy",
                                 description=DESCRIPTION)
    ap.add_argument("--out-dir", type=Path, default=ROOT / "docs",
                    help="where performance.md and img/ go (default: docs/)")
    ap.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    args = ap.parse_args(argv)
    cfg = Config.quick() if args.quick else Config.full()
    print(f"speed/accuracy benchmark ({'quick' if args.quick else 'full'}) → {args.out_dir}")
    res = run(cfg, args.out_dir)
    print(f"wrote {args.out_dir / 'performance.md'} in {res.timings['total']:.0f} s")
