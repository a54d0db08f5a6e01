"""Random small drawings and limit pairs for the planner's monotonicity tests
(tests/test_plan_monotone.py) and benchmark (benchmarks/planner.py): seeded, so every case is
the same on every run.

A job is 1–3 paths in a 30 × 30 mm SVG (centred in the profile's safe rectangle by the
compiler), each a random polyline, a cubic Bézier path, a circle of short chords drawn once
or twice, or a zigzag; several paths make the pen go up and down between them (travel).
A limit pair is a base set of (draw feed, travel feed, joint speed, joint acceleration) and
the same set with one or more of them raised by a factor in [1, 4].
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from fivebar_host.compile import CompileOptions, Job, compile_drawing, compile_job
from fivebar_host.config import Profile
from fivebar_host.toolpath.svg import read_svg

#: (draw feed mm/s, travel feed mm/s, joint speed rad/s, joint acceleration rad/s²).
Limits = tuple[float, float, float, float]
OPTS = CompileOptions(validate=False)


def _polyline(rng: np.random.Generator) -> str:
    pts = rng.uniform(2.0, 28.0, (int(rng.integers(2, 13)), 2))
    return '<polyline points="' + " ".join(f"{x:.2f},{y:.2f}" for x, y in pts) + '"/>'


def _curves(rng: np.random.Generator) -> str:
    p = rng.uniform(2.0, 28.0, (1 + 3 * int(rng.integers(1, 5)), 2))
    d = f"M{p[0, 0]:.2f} {p[0, 1]:.2f}" + "".join(
        f" C{a[0]:.2f} {a[1]:.2f} {b[0]:.2f} {b[1]:.2f} {c[0]:.2f} {c[1]:.2f}"
        for a, b, c in zip(p[1::3], p[2::3], p[3::3], strict=True))
    return f'<path d="{d}"/>'


def _circle(rng: np.random.Generator) -> str:
    c, r = rng.uniform(10.0, 20.0, 2), rng.uniform(0.5, 8.0)
    n, turns = int(rng.integers(8, 200)), int(rng.integers(1, 3))
    a = np.arange(turns * n + 1) * (2 * math.pi / n)
    return '<polyline points="' + " ".join(
        f"{c[0] + r * math.cos(t):.4f},{c[1] + r * math.sin(t):.4f}" for t in a) + '"/>'


def _zigzag(rng: np.random.Generator) -> str:
    x0, y0 = rng.uniform(2.0, 10.0), rng.uniform(2.0, 20.0)
    w, h, n = rng.uniform(0.5, 15.0), rng.uniform(0.1, 6.0), int(rng.integers(1, 31))
    return '<polyline points="' + " ".join(
        f"{x0 + w * k / n:.3f},{y0 + (h if k % 2 else 0.0):.3f}" for k in range(n + 1)) + '"/>'


SHAPES = (_polyline, _curves, _circle, _zigzag)


def svg_document(body: str, size_mm: float = 30.0) -> bytes:
    """An SVG of `size_mm` square (1 user unit = 1 mm) with `body` stroked, unfilled."""
    return ('<svg xmlns="http://www.w3.org/2000/svg" '
            f'width="{size_mm:g}mm" height="{size_mm:g}mm" viewBox="0 0 {size_mm:g} '
            f'{size_mm:g}"><g fill="none" stroke="black">{body}</g></svg>').encode()


def random_job(seed: int) -> bytes:
    """Seeded drawing: 1–3 paths of the kinds in `SHAPES`."""
    rng = np.random.default_rng(seed)
    shapes = [SHAPES[int(rng.integers(len(SHAPES)))](rng) for _ in range(rng.integers(1, 4))]
    return svg_document("".join(shapes))


def random_limits(seed: int) -> tuple[Limits, Limits]:
    """Seeded (base, raised): raised has one or more of the four limits times [1, 4]."""
    rng = np.random.default_rng(10_000 + seed)
    base = (rng.uniform(5.0, 150.0), rng.uniform(10.0, 200.0), rng.uniform(1.0, 30.0),
            float(np.exp(rng.uniform(math.log(10.0), math.log(2000.0)))))
    which = rng.random(4) < 0.5
    which[rng.integers(4)] = True
    raised = tuple(b * (rng.uniform(1.0, 4.0) if w else 1.0) for b, w in zip(base, which,
                                                                               strict=True))
    return base, (raised[0], raised[1], raised[2], raised[3])


def with_limits(profile: Profile, limits: Limits) -> Profile:
    """`profile` with its draw feed, travel feed, joint speed and acceleration replaced."""
    feed, travel, w, a = limits
    motion = dataclasses.replace(profile.motion, draw_feed_mm_s=feed, travel_feed_mm_s=travel,
                                 max_joint_rad_s=w, max_joint_rad_s2=a)
    return dataclasses.replace(profile, motion=motion)


def compiled(svg: bytes, profile: Profile) -> Job:
    """The job compiled without validation (timing does not depend on it)."""
    return compile_drawing(read_svg(svg), profile, OPTS)


def plan_s(job: Job) -> float:
    """Planned time of the job's segments, s (integer µs the firmware runs)."""
    return float(job.duration_us.sum()) * 1e-6


def draw_s(job: Job) -> float:
    """Planned time of the job's drawing segments, s."""
    return float(job.duration_us[job.draw].sum()) * 1e-6


# ------------------------------------------------------------ issue 20's job: 5 × 1000 chords
def circle_job(turns: int = 5, chords: int = 1000, circ_mm: float = 100.0) -> bytes:
    """Issue 20's job: a circle of `circ_mm` circumference as `chords` chords, drawn `turns`
    times as one continuous polyline (centred in the safe rectangle by the compiler)."""
    r = circ_mm / (2 * math.pi)
    a = np.arange(turns * chords + 1) * (2 * math.pi / chords)
    pts = " ".join(f"{20 + r * math.cos(t):.5f},{20 + r * math.sin(t):.5f}" for t in a)
    return svg_document(f'<polyline points="{pts}"/>', 40.0)


def compile_file(path: Path, profile: Profile) -> Job:
    """A file compiled as `fivebar convert` does, without validation."""
    return compile_job(path, profile, OPTS)
