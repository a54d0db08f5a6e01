"""Planned time of issue 20's job under four limit sets, this tree's planner against another's.

The job: a circle of 100 mm circumference as 1000 chords of 0.1 mm, drawn five times (5000
segments, one pen-down path), on the bundled profile with the draw feed, joint speed and
joint acceleration replaced. Printed per limit set: total plan time and its drawing part
(the draw segments' durations) for each tree. Before the fix raising the limits lengthened
the plan (7.8 s at 100 mm/s, 15 rad/s, 600 rad/s² → 11.1 s at 200 / 30 / 1200; main, which
now also simplifies dense polylines, 6.2 s → 29.6 s).
Then the drawing part against the feed with joint limits far above need (100 rad/s,
10⁴ rad/s²), where the feed binds up to ~50 mm/s. Last, the bundled examples on their
profiles (as tests/test_job_timing.py compiles them): plan time and segments per tree.

Each tree is compiled in its own interpreter (same module names), side by side in one run:

    git worktree add --detach /tmp/plan-old main
    python benchmarks/planner.py --old /tmp/plan-old
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SETS = [(100.0, 15.0, 600.0), (200.0, 30.0, 1200.0), (200.0, 15.0, 600.0),
        (150.0, 15.0, 600.0)]
FEEDS = [25.0, 50.0, 100.0, 200.0]
EXAMPLES: list[tuple[str, str, dict[str, object]]] = [
    ("fivebar_text.svg", "default.toml", {}),
    ("simple.svg", "default.toml", {"tolerance_mm": 0.2}),
    ("mode_change.gcode", "default.toml", {"origin_mm": (0.0, 0.0), "mode": "auto"}),
    ("underside_machine_coords.gcode", "underside.toml", {"origin_mm": (0.0, 0.0),
                                                          "mode": "++"}),
]


def issue_svg(path: Path, turns: int = 5, chords: int = 1000, circ_mm: float = 100.0) -> None:
    """Write the job: `turns` × `chords` chords of circ_mm/chords mm on one polyline."""
    r = circ_mm / (2 * math.pi)
    pts = " ".join(f"{15 + r * math.cos(2 * math.pi * k / chords):.5f},"
                   f"{15 + r * math.sin(2 * math.pi * k / chords):.5f}"
                   for k in range(turns * chords + 1))
    path.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="30mm" height="30mm" '
                    f'viewBox="0 0 30 30"><polyline points="{pts}" fill="none" '
                    'stroke="black"/></svg>')


def measure(svg: Path, limits: list[tuple[float, float, float]]) -> list[tuple[float, float]]:
    """(total s, drawing s) per limit set, compiled by whichever tree is on sys.path."""
    import dataclasses

    from fivebar_host.compile import CompileOptions, compile_job
    from fivebar_host.config import load_profile

    base = load_profile()
    out = []
    for feed, w, a in limits:
        motion = dataclasses.replace(base.motion, draw_feed_mm_s=feed, max_joint_rad_s=w,
                                     max_joint_rad_s2=a)
        job = compile_job(svg, dataclasses.replace(base, motion=motion),
                          CompileOptions(validate=False))
        out.append((float(job.duration_us.sum()) * 1e-6,
                    float(job.duration_us[job.draw].sum()) * 1e-6))
    return out


def measure_examples(tree: Path) -> list[tuple[float, float]]:
    """(plan s, segments) of each of `EXAMPLES`, compiled by the tree on sys.path."""
    from fivebar_host.compile import CompileOptions, compile_job
    from fivebar_host.config import load_profile

    out = []
    for name, config, kw in EXAMPLES:
        prof = load_profile(tree / "configs" / config)
        job = compile_job(tree / "examples" / name, prof, CompileOptions(**kw))  # type: ignore[arg-type]
        out.append((float(job.duration_us.sum()) * 1e-6, float(job.n_segments)))
    return out


def run_tree(tree: Path, svg: Path, limits: list[tuple[float, float, float]]
             ) -> list[tuple[float, float]]:
    """`measure` in a fresh interpreter with `tree` first on the import path."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", str(svg),
                          json.dumps(limits)], env=env, cwd=tree, check=True,
                         capture_output=True, text=True)
    return [(float(x[0]), float(x[1])) for x in json.loads(res.stdout)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", type=Path, default=Path("/tmp/plan-old"),
                    help="a worktree of the planner to compare with (e.g. main)")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != HERE]
        rows = measure(Path(args.child[0]), json.loads(args.child[1]))
        print(json.dumps(rows + measure_examples(Path.cwd())))
        return
    trees = [("this", HERE.parent)] + ([("old", args.old)] if args.old.is_dir() else [])
    fast = [(f, 100.0, 1e4) for f in FEEDS]
    with tempfile.TemporaryDirectory() as tmp:
        svg = Path(tmp) / "circle5.svg"
        issue_svg(svg)
        got = {name: run_tree(t, svg, SETS + fast) for name, t in trees}
    report([n for n, _ in trees], got, SETS + fast)
    report_examples([n for n, _ in trees], {n: g[len(SETS) + len(fast):] for n, g in got.items()})


def report(names: list[str], got: dict[str, list[tuple[float, float]]],
           limits: list[tuple[float, float, float]]) -> None:
    """Print the table (total / drawing part per tree) and the feed-doubling ratios."""
    print("issue 20 job: 5 × 1000 chords of 0.1 mm (500 mm drawn); plan time in s "
          "(total / drawing part)")
    print(f"{'feed mm/s, rad/s, rad/s²':>26s}" + "".join(f"{n:>20s}" for n in names))
    for i, (f, w, a) in enumerate(limits):
        if i == len(SETS):
            print("feed alone (joint limits far above need):")
        row = "".join(f"{got[n][i][0]:11.2f} /{got[n][i][1]:6.2f}" for n in names)
        print(f"{f'{f:g} / {w:g} / {a:g}':>26s}{row}")
    for n in names:
        d = {f: got[n][len(SETS) + k][1] for k, f in enumerate(FEEDS)}
        print(f"{n}: drawing part 50 vs 25 mm/s = {d[50.0] / d[25.0]:.3f}, "
              f"200 vs 100 mm/s = {d[200.0] / d[100.0]:.3f}")



def report_examples(names: list[str], got: dict[str, list[tuple[float, float]]]) -> None:
    """Print plan time and segments of the bundled examples per tree."""
    print("bundled examples on their profiles: plan s (segments)")
    for i, (name, _, _) in enumerate(EXAMPLES):
        row = "".join(f"{got[n][i][0]:11.2f} ({got[n][i][1]:5.0f})" for n in names)
        print(f"{name:>32s}{row}")


if __name__ == "__main__":
    main()
