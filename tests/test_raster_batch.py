"""The raster planner's batched and shortened paths (issue 32's CPU goal) against the
general or one-at-a-time computations they replace: every value bit for bit the same, and
an error from a batch the error of the first failing item on its own.

- `wrap_to_limits` against Python's own float remainder, element by element;
- `raster.travel.joint_moves` against `joint_move` one move at a time, and each move's
  durations against `compile.staircase.staircase_ratios` (from rest to rest, ≤ 1);
- `raster.travel.check_moves`: the refusal names the first failing move;
- `raster.motion.staircase_ok` against a plain loop over the boundaries on planned
  scanlines at accelerations that pass and that fail;
- `raster.linegeo.solve_bounds` / `max_gain` against `LineGeo` one scanline at a time;
- `raster.lines._fit_line`'s residual against max |r − u| computed directly.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fivebar_host.compile import staircase
from fivebar_host.compile.steps import absolute_steps, step_angles
from fivebar_host.config import Profile, load_profile
from fivebar_host.errors import JobError
from fivebar_host.raster import grid as gridmod
from fivebar_host.raster import job as rjob
from fivebar_host.raster import linegeo, lines, motion, pixels, travel
from fivebar_host.toolpath.segment import wrap_to_limits

PROF = load_profile(None)


def _ctx(prof: Profile, powers: np.ndarray, pitch: float = 0.1,
         v: float | None = None) -> motion.RasterCtx:
    """A raster context for a grid of `powers` centred on the profile's page."""
    mode = rjob.raster_mode(prof, "test")
    top_left = rjob._top_left(prof, mode, (powers.shape[1] * pitch, powers.shape[0] * pitch),
                              None, "test")
    grid = gridmod.scan_grid(powers.astype(np.uint8), (pitch, pitch), top_left, 0.0)
    return motion.RasterCtx(prof, rjob._checker(prof, mode), grid,
                            v if v is not None else prof.motion.draw_feed_mm_s,
                            rjob.CHORD_SHARE * prof.motion.tolerance_mm, rjob.K_MAX)


def test_wrap_to_limits_is_the_remainder_element_by_element() -> None:
    """In range (no remainder taken), out of range, and at lo + 2π − 1e-13 (wrapped to lo)."""
    rng = np.random.default_rng(1)
    limits = PROF.motors.limits_rad
    lo = [limits[0][0], limits[1][0]]
    cases = [rng.uniform(0.0, 2 * math.pi - 1e-9, (200, 2)) + lo,  # already in range
             rng.uniform(-20.0, 20.0, (200, 2)),
             np.array([[lo[0] + 2 * math.pi - 1e-13, lo[1]], [lo[0], lo[1] - 1e-15]])]
    for th in cases:
        got, ok1, ok2 = wrap_to_limits(th, limits)
        for i in range(th.shape[0]):
            for j in range(2):
                t = lo[j] + (float(th[i, j]) - lo[j]) % (2 * math.pi)
                if t - lo[j] >= 2 * math.pi - 1e-12:
                    t = lo[j]
                assert got[i, j] == t, (th[i, j], got[i, j], t)
                assert (ok1, ok2)[j][i] == (t <= limits[j][1] + 1e-12)


def _moves(prof: Profile, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Start and end steps of n moves near the homed pose: short and long, one motionless,
    one motor only."""
    rng = np.random.default_rng(7)
    home = absolute_steps(np.asarray(prof.motors.home_rad).reshape(1, 2),
                          prof.motors.home_rad, prof.motors.steps_per_rev)[0]
    a = home + rng.integers(-300, 300, (n, 2))
    b = a + rng.integers(-400, 400, (n, 2)) * rng.integers(0, 2, (n, 1))
    b[0] = a[0]  # no motion
    b[1] = a[1] + [250, 0]  # one motor
    b[2] = a[2] + [1, -1]  # a step
    return a, b


def test_joint_moves_are_each_move_on_its_own() -> None:
    a, b = _moves(PROF, 40)
    batch = travel.joint_moves(PROF, a, b)
    alpha, jump = PROF.motion.max_joint_rad_s2, PROF.motion.junction_jump_rad_s
    mo = PROF.motors
    for i in range(a.shape[0]):
        tg, du = travel.joint_move(PROF, a[i], b[i])
        assert np.array_equal(batch[i][0], tg) and np.array_equal(batch[i][1], du)
        if not (a[i] != b[i]).any():
            assert tg.shape[0] == 0
            continue
        assert np.array_equal(tg[-1], b[i])
        th = step_angles(np.concatenate((a[i:i + 1], tg)), mo.home_rad, mo.steps_per_rev)
        jr, ar = staircase.staircase_ratios(np.diff(th, axis=0), du, None, alpha, jump)
        assert jr.max() <= 1.0 + 1e-9 and ar.max() <= 1.0 + 1e-9


def test_check_moves_names_the_first_failing_move() -> None:
    a, b = _moves(PROF, 6)
    travel.check_moves(PROF, rjob._checker(PROF, rjob.raster_mode(PROF, "t")), a, b,
                       lambda i: f"move {i}")
    far = b.copy()
    far[3] = a[3] + [0, PROF.motors.steps_per_rev // 2]  # half a turn of motor B
    far[5] = far[3]
    ck = rjob._checker(PROF, rjob.raster_mode(PROF, "t"))
    with pytest.raises(JobError) as batch:
        travel.check_moves(PROF, ck, a, far, lambda i: f"move {i}")
    assert str(batch.value).startswith("move 3: ")
    with pytest.raises(JobError) as alone:
        travel.check_move(PROF, ck, a[3], far[3], "move 3")
    assert str(batch.value) == str(alone.value)


def _joint_by_joint(dth: np.ndarray, us: np.ndarray, alpha: float, jump: float
                    ) -> tuple[float, float]:
    """Worst jump and average-acceleration ratios joint by joint (raster.motion's rule), by
    a plain loop over the boundaries of one run from rest to rest."""
    t = us * 1e-6
    w = dth / t[:, None]
    worst_j, worst_a = 0.0, 0.0
    for i in range(len(t)):
        for side in (i == 0, i == len(t) - 1):
            if side:
                m = float(np.abs(w[i]).max())
                worst_j, worst_a = max(worst_j, m / jump), max(worst_a, m / (alpha * t[i] / 2))
        if i:
            m = float(np.abs(w[i] - w[i - 1]).max())
            worst_j = max(worst_j, m / jump)
            worst_a = max(worst_a, m / (alpha * (t[i] + t[i - 1]) / 2))
    return worst_j, worst_a


def test_staircase_ok_is_the_joint_by_joint_staircase() -> None:
    """Accepted and refused accelerations alike: the verdict of a plain loop over the
    boundaries (the jump and each joint's average acceleration, from rest to rest)."""
    rng = np.random.default_rng(3)
    ctx = _ctx(PROF, rng.integers(1, 255, (6, 80)), v=60.0)
    mot = PROF.motion
    verdicts = set()
    for sl in gridmod.scanlines(ctx.grid, True, 1):
        geo = motion.LineGeo(ctx, sl)
        a0 = motion.ramp_accel(geo)
        for f in (4.0, 1.0, 0.8, 0.5, 0.2):
            sm = motion.plan_scanline(geo, 20, a0 * f)
            th = step_angles(sm.steps, ctx.home, ctx.spr)
            jr, ar = _joint_by_joint(np.diff(th, axis=0), sm.duration_us,
                                     mot.max_joint_rad_s2, mot.junction_jump_rad_s)
            rate = np.abs(np.diff(th, axis=0)).max(axis=1) / (sm.duration_us * 1e-6)
            want = bool(jr <= 1 and ar <= 1 + 1e-12
                        and rate.max() <= mot.max_joint_rad_s * (1 + 1e-9))
            assert motion.staircase_ok(ctx, sm) == want
            verdicts.add(want)
    assert verdicts == {True, False}


def test_solve_bounds_and_max_gain_are_each_scanline_on_its_own() -> None:
    rng = np.random.default_rng(4)
    powers = rng.integers(0, 255, (30, 120))
    powers[:, :rng.integers(0, 40)] = 0  # ragged scanline ends
    ctx = _ctx(PROF, powers)
    sls = gridmod.scanlines(ctx.grid, True, 2)
    old = linegeo.BOUNDS_BLOCK
    try:
        linegeo.BOUNDS_BLOCK = 500  # several blocks
        pre = linegeo.solve_bounds(ctx, sls)
        g = linegeo.max_gain(ctx, sls)
    finally:
        linegeo.BOUNDS_BLOCK = old
    for sl, b in zip(sls, pre, strict=True):
        assert b is not None and np.array_equal(b, motion.LineGeo(ctx, sl).bounds)
    assert g == max(motion.gains(ctx, sl, 0.0, (sl.c1 - sl.c0) * ctx.grid.pitch)[0]
                    for sl in sls)


def test_batched_solvers_name_the_unreachable_scanline() -> None:
    """A grid reaching out of the workspace: no bounds for the lines that leave it, and the
    speed cap's error is the first such line's own."""
    ctx = _ctx(PROF, np.full((4, 4000), 200), pitch=0.1)  # 400 mm wide
    sls = gridmod.scanlines(ctx.grid, True, 1)
    assert linegeo.solve_bounds(ctx, sls) == [None] * len(sls)
    with pytest.raises(JobError) as batch:
        linegeo.max_gain(ctx, sls)
    with pytest.raises(JobError) as alone:
        motion.gains(ctx, sls[0], 0.0, (sls[0].c1 - sls[0].c0) * ctx.grid.pitch)
    assert str(batch.value) == str(alone.value)
    assert f"row {sls[0].row}" in str(batch.value)


def test_fit_residual_is_the_largest_offset() -> None:
    """Each G7 line's residual is max |change − (U + i·T)| over its changes, computed here
    from the changes and the line's U and T."""
    rng = np.random.default_rng(9)
    ctx = _ctx(PROF, rng.integers(1, 255, (4, 150)), v=80.0)
    seen = 0
    for sl in gridmod.scanlines(ctx.grid, True, 1):
        from fivebar_host.raster import speed

        sm, ch = speed.plan_line(ctx, sl)
        start = np.concatenate(([0], np.cumsum(sm.duration_us * pixels.CYCLES_PER_US)))
        at = 0
        for gr in lines.groups(sm, ch):
            n = len(gr.powers)
            t = ch.t[at:at + n] - start[gr.first]
            want = float(np.abs(t - (gr.u + gr.t * np.arange(n))).max()) if n else 0.0
            assert gr.residual == want
            at += n
            seen += 1
    assert seen > 8
