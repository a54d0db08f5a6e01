"""The dose reconstruction (`raster.dose`) on an analytic case: a pin trace written here
from a compiled job as an ideal firmware would make it — each motor's steps evenly spread
over its segment, the laser's PWM (256-cycle period, high for `power` cycles from each
period's start) restarted at every planned change — must give back the planned burn:
every cell of a flat grey patch at its power within the PWM's quantisation, the pixel
crossings at the planned change times, no laser-on step outside the image."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fivebar_host.compile.model import Job
from fivebar_host.config import load_profile
from fivebar_host.options import defaults
from fivebar_host.raster import dose, schedule
from fivebar_host.raster import job as rjob

PERIOD = 256


def _job(tmp_path: Path, level: int, shape: tuple[int, int], width: float, speed: float
         ) -> Job:
    p = tmp_path / "grey.png"
    Image.fromarray(np.full(shape, level, dtype=np.uint8)).save(p)
    prof = load_profile(None)
    v = defaults()
    v.update(width_mm=width, draw_feed_mm_s=speed)
    return rjob.compile_raster(p, prof, rjob.raster_options(v, prof))


def _events(t: np.ndarray, pin: int, level: np.ndarray) -> tuple[np.ndarray, ...]:
    return t.astype(np.int64), np.full(t.shape[0], pin), level.astype(np.int64)


def ideal_trace(job: Job) -> dose.PinTrace:
    """The trace an ideal firmware makes of the job (module docstring)."""
    r = job.raster
    assert r is not None
    steps = np.asarray(job.steps, dtype=np.int64)
    dur = np.asarray(job.duration_us, dtype=np.int64) * 16
    seg_start = np.concatenate(([0], np.cumsum(dur)))
    parts = []
    for axis in range(2):
        d = np.diff(steps[:, axis])
        n = np.abs(d)
        seg = np.repeat(np.arange(d.shape[0]), n)
        k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        t = seg_start[seg] + ((k + 0.5) / n[seg] * dur[seg]).astype(np.int64)
        parts.append(_events(t, 2 * axis, np.ones_like(t)))  # step rise
        parts.append(_events(t + 2, 2 * axis, np.zeros_like(t)))  # step fall
        live = np.flatnonzero(n)
        parts.append(_events(seg_start[live] + 1 - 1, 2 * axis + 1, (d[live] > 0)))  # dir
    rises, falls = [], []
    for sl in r.lines:
        at = seg_start[sl.first] + sl.change_t.round().astype(np.int64)
        for a, b, p in zip(at[:-1], at[1:], sl.change_power[:-1].tolist(), strict=True):
            if p == 0:
                continue
            starts = np.arange(a, b, PERIOD)
            rises.append(starts)
            falls.append(np.minimum(starts + p, b))
    rise, fall = np.concatenate(rises), np.concatenate(falls)
    parts.append(_events(rise, 4, np.ones_like(rise)))
    parts.append(_events(fall, 4, np.zeros_like(fall)))
    cycle = np.concatenate([p[0] for p in parts])
    pin = np.concatenate([p[1] for p in parts])
    level = np.concatenate([p[2] for p in parts])
    order = np.lexsort((pin, cycle))
    return dose.PinTrace(cycle[order], level[order], pin[order],
                         ("stepA", "dirA", "stepB", "dirB", "laser"))


def test_laser_on_merges_pwm_lows_only() -> None:
    rise = np.array([0, 256, 512, 2000])
    fall = np.array([100, 356, 612, 2100])
    at = np.array([50.0, 150.0, 600.0, 700.0, 1500.0, 2050.0, 2150.0])
    got = dose.laser_on(rise, fall, at)
    assert got.tolist() == [True, True, True, False, False, True, False]


def test_flat_grey_patch_comes_back_flat(tmp_path: Path) -> None:
    job = _job(tmp_path, 128, (6, 24), 6.0, 10.0)  # 0.25 mm pixels at 10 mm/s: 25 ms
    prof = load_profile(None)
    r = job.raster
    assert r is not None
    pt = ideal_trace(job)
    mo = dose.motion_of(pt)
    burned = dose.dose_grid(job, prof, pt, mo) * 255.0 / dose.pixel_cycles(r)
    want = int(r.target.max())
    assert 120 <= want <= 136
    inner = burned[:, 1:-1]  # the end cells share their edge steps with the overscan
    expect = 255.0 * want / PERIOD
    assert float(inner.mean()) == pytest.approx(expect, rel=0.01)
    assert float((inner.max() - inner.min()) / inner.mean()) <= 0.05
    # the crossings found from the steps are the planned change times
    seg_start = np.concatenate(([0], np.cumsum(np.asarray(job.duration_us) * 16)))
    pix = dose.pixel_cycles(r)
    for sl, (_, tau) in zip(r.lines, dose.crossings(job, prof, mo), strict=True):
        planned = seg_start[sl.first] + sl.change_t
        assert np.isfinite(tau[1:-1]).all()
        err = np.abs(tau - planned)
        # inside the image steps are dense: the crossing to a hundredth of a pixel; at the
        # image's ends the short ramps' few steps leave it to about a step's travel
        assert float(np.nanmax(err[1:-1])) <= 0.01 * pix
        assert float(np.nanmax(err)) / 16e6 * r.speed_mm_s <= 0.03
    rise, fall = dose.high_intervals(pt)
    on = dose.laser_on(rise, fall, mo.step_cycles())
    s, _ = dose.grid_coords(r, dose.pen_at(job, prof, mo, mo.step_cycles()[on]))
    h = r.pitch_mm
    assert float(s.min()) >= -0.5 * h and float(s.max()) <= r.target.shape[1] * h + 0.5 * h


def _seg_start(job: Job) -> np.ndarray:
    return np.concatenate(([0], np.cumsum(np.asarray(job.duration_us, dtype=np.int64) * 16)))


def test_schedule_fit_recovers_segment_starts(tmp_path: Path) -> None:
    """The fit (`schedule.fit_schedule`) takes each segment's start from its own edges: on
    the ideal trace (every step at its DDA time, cut to a cycle) it is the true start
    within a cycle (the firmware's own cut, fb_fast.h), and it stays so when edges come
    late (an interrupt held off), since an edge is never early."""
    job = _job(tmp_path, 128, (4, 16), 4.0, 10.0)
    mo = dose.motion_of(ideal_trace(job))
    sched = schedule.fit_schedule(job, mo.t)
    assert sched is not None
    start = _seg_start(job)[:-1]
    moving = np.abs(np.diff(np.asarray(job.steps), axis=0)).sum(axis=1) > 0
    assert np.abs(sched.start[moving] - start[moving]).max() <= 1.0
    rng = np.random.default_rng(1)
    delays = [np.where(rng.random(t.shape[0]) < 0.3, rng.integers(1, 300, t.shape[0]), 0)
              for t in mo.t]
    got = schedule.fit_schedule(job, (mo.t[0] + delays[0], mo.t[1] + delays[1]))
    assert got is not None
    # segments keeping an on-time edge: exact; the others (all their edges late): late
    on_time = np.zeros(start.shape[0], dtype=bool)
    n = np.abs(np.diff(np.asarray(job.steps, dtype=np.int64), axis=0))
    for i in range(2):
        seg = np.repeat(np.arange(n.shape[0]), n[:, i])
        on_time[seg[delays[i] == 0]] = True
    err = got.start[moving] - start[moving]
    assert np.abs(err[on_time[moving]]).max() <= 1.0
    assert (err >= -1.0).all()
    # a trace with fewer steps than the job is not this job's
    assert schedule.fit_schedule(job, (mo.t[0][:-5], mo.t[1])) is None


def test_crossings_on_the_schedule_match_the_plan(tmp_path: Path) -> None:
    """The crossings solved on the fitted schedule (forward kinematics of the exact motor
    positions, Newton on the pen's along-track distance) against the planner's own change
    times (a quartic through five samples a piece, `raster.pixels`): two methods, within
    a µs at every boundary, the image's ends too (where the edges alone were loose)."""
    job = _job(tmp_path, 128, (4, 16), 4.0, 10.0)
    prof = load_profile(None)
    r = job.raster
    assert r is not None
    mo = dose.motion_of(ideal_trace(job))
    sched = schedule.fit_schedule(job, mo.t)
    assert sched is not None
    exact = dose.Motion(sched.t, sched.x)
    samples = np.unique(np.concatenate((mo.step_cycles(), sched.t[0])))
    seg_start = _seg_start(job)
    for sl, (_, tau) in zip(r.lines, dose.crossings(job, prof, exact, samples), strict=True):
        planned = seg_start[sl.first] + sl.change_t
        assert np.isfinite(tau).all()
        assert float(np.abs(tau - planned).max()) <= 16.0  # cycles: 1 µs


def test_power_writes_are_timed_against_the_crossings(tmp_path: Path) -> None:
    """With the firmware's power writes in the trace (`lwrite`, fbsim -t), every change to a
    new power is timed by its write: writes put at the planned times plus known offsets
    come back as those offsets (within the crossing's µs), and a change the firmware
    skips (the same power again) is not counted."""
    job = _job(tmp_path, 128, (4, 16), 4.0, 10.0)  # its crossings are the plan's (above)
    prof = load_profile(None)
    r = job.raster
    assert r is not None
    base = ideal_trace(job)
    seg_start = _seg_start(job)
    rng = np.random.default_rng(7)
    at, want = [], []
    for sl in r.lines:
        before = np.concatenate(([0], sl.change_power[:-1]))
        new = sl.change_power != before
        off = rng.uniform(-15.0, 15.0, new.sum())  # µs
        at.append(seg_start[sl.first] + sl.change_t[new] + off * 16)
        want.append(off)
    w = np.round(np.concatenate(at)).astype(np.int64)
    cycle = np.concatenate((base.cycle, w))
    pin = np.concatenate((base.pin, np.full(w.shape[0], len(base.names))))
    level = np.concatenate((base.level, np.ones_like(w)))
    order = np.lexsort((pin, cycle))
    pt = dose.PinTrace(cycle[order], level[order], pin[order], (*base.names, "lwrite"))
    fig = dose.figures(job, prof, pt)
    b = fig.boundaries
    offsets = np.concatenate(want)
    assert b.clean == offsets.shape[0] == b.found
    assert np.abs(np.sort(b.dt_us) - np.sort(offsets)).max() <= 1.0
    assert fig.change_us == pytest.approx(float(np.abs(offsets).max()), abs=1.0)


def test_stalls_near_the_emulators_lag_are_told_apart() -> None:
    """`lagging_at`: a stall from a lag event (fbsim -R fell behind the wall clock) to
    `LAG_AFTER_S` after it counts as the emulator's; before it, or later, not."""
    f = dose.F_CPU
    lag = int(1.0 * f)
    pt = dose.PinTrace(np.array([lag, lag]), np.array([1, 0]), np.array([0, 0]), ("lag",))
    at = np.array([0.5, 0.999, 1.0, 1.0 + 0.5 * dose.LAG_AFTER_S, 1.0 + 2 * dose.LAG_AFTER_S]) * f
    assert dose.lagging_at(pt, at).tolist() == [False, False, True, True, False]
    none = dose.PinTrace(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), ())
    assert not dose.lagging_at(none, at).any()
