"""Planner benchmark (issue 20): plan time and segment count of issue 20's circle job under
the issue's four limit sets, of the bundled text example, and the worst "raised limits,
longer plan" ratio over seeded random jobs — for this tree and, side by side, another one.

The circle job: a circle of 100 mm circumference as 1000 chords of 0.1 mm, drawn five times
as one polyline (5000 chords, one pen-down path; `benchmarks.plan_jobs.circle_job`), compiled
as `fivebar convert` does (the chords simplified, `toolpath.simplify`) and with
`--no-simplify` (every 0.1 mm chord a segment), on configs/default.toml with the draw feed,
joint speed and joint acceleration replaced. Printed per limit set: total plan time, its
drawing part, segments. Then the drawing part at 200 against 100 mm/s (15 rad/s, 600 rad/s²),
the text example (examples/fivebar_text.svg, default profile), and the random jobs of
tests/test_plan_monotone.py (`--cases` of them).

Each tree is compiled in its own interpreter (same module names), so that one run compares:

    git worktree add /tmp/plan-old main
    python benchmarks/planner.py --old /tmp/plan-old
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SETS = [(100.0, 15.0, 600.0), (200.0, 30.0, 1200.0), (200.0, 15.0, 600.0),
        (150.0, 15.0, 600.0)]


def _plan_jobs() -> ModuleType:
    """benchmarks/plan_jobs.py of *this* tree, by its path (the other tree may not have it,
    and its package `benchmarks` would shadow this one's)."""
    spec = importlib.util.spec_from_file_location("plan_jobs", HERE / "plan_jobs.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def measure(cases: int) -> dict[str, Any]:
    """Every figure of the module doc, compiled by whichever tree is first on sys.path."""
    pj = _plan_jobs()
    circle_job, compile_file, compiled = pj.circle_job, pj.compile_file, pj.compiled
    draw_s, plan_s, with_limits = pj.draw_s, pj.plan_s, pj.with_limits
    random_job, random_limits = pj.random_job, pj.random_limits
    from fivebar_host.compile import CompileOptions, compile_drawing
    from fivebar_host.config import load_profile
    from fivebar_host.toolpath.svg import read_svg

    prof = load_profile()
    out: dict[str, Any] = {"circle": [], "circle_ns": []}
    svg = circle_job()
    ns = CompileOptions(validate=False, no_simplify=True)
    for feed, w, a in SETS:
        p = with_limits(prof, (feed, prof.motion.travel_feed_mm_s, w, a))
        for key, job in (("circle", compiled(svg, p)),
                         ("circle_ns", compile_drawing(read_svg(svg), p, ns))):
            out[key].append((plan_s(job), draw_s(job), job.n_segments))
    text = compile_file(ROOT / "examples" / "fivebar_text.svg", prof)
    out["text"] = (plan_s(text), draw_s(text), text.n_segments)
    worst = (0.0, -1)
    for seed in range(cases):
        base, raised = random_limits(seed)
        job_svg = random_job(seed)
        t0 = plan_s(compiled(job_svg, with_limits(prof, base)))
        t1 = plan_s(compiled(job_svg, with_limits(prof, raised)))
        worst = max(worst, (t1 / t0, seed))
    out["worst"] = worst
    return out


def run_tree(tree: Path, cases: int) -> dict[str, Any]:
    """`measure` in a fresh interpreter with `tree` first on the import path."""
    res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child",
                          str(cases)], env=dict(os.environ, PYTHONPATH=str(tree)), cwd=tree,
                         check=True, capture_output=True, text=True)
    return dict(json.loads(res.stdout.splitlines()[-1]))


def report(got: dict[str, dict[str, Any]], cases: int) -> None:
    """Print the tables of the module doc, one column per tree."""
    names = list(got)
    print("issue 20 circle job (5 × 1000 chords of 0.1 mm, 500 mm drawn): plan s / drawing s "
          "/ segments")
    for key, label in (("circle", "as convert compiles it"),
                       ("circle_ns", "--no-simplify")):
        print(f"  {label}:")
        print(f"  {'feed mm/s, rad/s, rad/s²':>26s}" + "".join(f"{n:>24s}" for n in names))
        for i, (f, w, a) in enumerate(SETS):
            row = "".join("{:10.2f} /{:6.2f} /{:5d}".format(*got[n][key][i]) for n in names)
            print(f"  {f'{f:g} / {w:g} / {a:g}':>26s}{row}")
    for n in names:
        c = got[n]["circle"]
        print(f"{n}: drawing part 200 vs 100 mm/s (15 rad/s, 600 rad/s²) = "
              f"{c[2][1] / c[0][1]:.3f}; --no-simplify "
              f"{got[n]['circle_ns'][2][1] / got[n]['circle_ns'][0][1]:.3f}")
    for n in names:
        t = got[n]["text"]
        print(f"{n}: examples/fivebar_text.svg (default profile): plan {t[0]:.3f} s, drawing "
              f"{t[1]:.3f} s, {t[2]} segments")
    for n in names:
        r, seed = got[n]["worst"]
        print(f"{n}: {cases} random jobs, worst plan(raised limits) / plan(base) = {r:.4f} "
              f"(seed {seed})")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--old", type=Path, default=Path("/tmp/plan-old"),
                    help="a worktree of the planner to compare with (e.g. main)")
    ap.add_argument("--cases", type=int, default=40, help="random jobs (seeds 0 … n−1)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        # run as a script this folder comes first on sys.path, and benchmarks/kinematics.py
        # would shadow the `kinematics` package
        sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != HERE]
        print(json.dumps(measure(args.child)))
        return
    trees = [("this", ROOT)] + ([("old", args.old)] if args.old.is_dir() else [])
    report({name: run_tree(t, args.cases) for name, t in trees}, args.cases)


if __name__ == "__main__":
    main()
