"""A compiled raster job against independent checks: every pixel boundary's change time,
run through the segments as the firmware runs them (each motor at a constant rate inside a
segment) and a five-bar forward kinematics written here from the circle intersection, lands
on the boundary's point of the scan grid; the G7 lines' sizes reckoned by `raster.lines`
are the bytes `wire.g7_body` writes; an unreachable image names its row and column."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fivebar_host import wire
from fivebar_host.compile.model import Job
from fivebar_host.config import Profile, load_profile
from fivebar_host.errors import JobError
from fivebar_host.options import defaults
from fivebar_host.raster import job as rjob
from fivebar_host.raster.runs import RasterRuns

F_CPU = 16e6

ROOT = Path(__file__).resolve().parent.parent


def _fk(profile: Profile, th: np.ndarray) -> np.ndarray:
    """Pen (N, 2) of motor angles (N, 2): the floating links' circles intersected, the pen
    left of elbow 1 → elbow 2 (assembly "+")."""
    g = profile.geometry
    r1 = np.stack([g.a1 * np.cos(th[:, 0]), g.a1 * np.sin(th[:, 0])], axis=1)
    r2 = np.stack([g.w + g.a2 * np.cos(th[:, 1]), g.a2 * np.sin(th[:, 1])], axis=1)
    dv = r2 - r1
    d = np.hypot(dv[:, 0], dv[:, 1])
    along = (g.b1 ** 2 - g.b2 ** 2 + d ** 2) / (2 * d)
    h = np.sqrt(g.b1 ** 2 - along ** 2)
    e = dv / d[:, None]
    left = np.stack([-e[:, 1], e[:, 0]], axis=1)
    out: np.ndarray = r1 + along[:, None] * e + h[:, None] * left
    return out


def _compile(tmp_path: Path, profile: Profile, dark: np.ndarray, **values: object) -> Job:
    p = tmp_path / "img.png"
    Image.fromarray((255 * (1 - dark)).round().astype(np.uint8)).save(p)
    v = defaults()
    v.update(values)
    return rjob.compile_raster(p, profile, rjob.raster_options(v, profile))


def _boundary_points(job: Job, profile: Profile) -> tuple[np.ndarray, np.ndarray]:
    """(pen at each change by the segments' timing, the boundary's ideal point)."""
    r = job.raster
    assert isinstance(r, RasterRuns)
    steps = np.asarray(job.steps, dtype=np.float64)
    dur = np.asarray(job.duration_us, dtype=np.float64)
    got, want = [], []
    for sl in r.lines:
        t_us = sl.change_t / F_CPU * 1e6
        start = np.concatenate(([0.0], np.cumsum(dur[sl.first:sl.end])))
        j = np.clip(np.searchsorted(start, t_us, side="right") - 1, 0, sl.end - sl.first - 1)
        lam = (t_us - start[j]) / dur[sl.first + j]
        s = steps[sl.first + j] + lam[:, None] * (steps[sl.first + j + 1] - steps[sl.first + j])
        th = np.asarray(job.home_rad) + s * (2 * math.pi / job.steps_per_rev)
        got.append(_fk(profile, th))
        i = np.arange(sl.change_t.shape[0])
        want.append(np.asarray(sl.p0) + np.outer(i * r.pitch_mm, np.asarray(sl.d)))
    return np.concatenate(got), np.concatenate(want)


@pytest.mark.parametrize("angle", [0.0, 30.0])
def test_every_change_lands_on_its_pixel_boundary(tmp_path: Path, angle: float) -> None:
    prof = load_profile(None)
    rng = np.random.default_rng(3)
    job = _compile(tmp_path, prof, rng.random((12, 40)), width_mm=12.0, scan_angle_deg=angle,
                   line_interval_mm=0.3)
    got, want = _boundary_points(job, prof)
    err = np.hypot(*(got - want).T)
    assert err.shape[0] > 400
    assert float(err.max()) <= 0.05
    # the planned speed is constant along the image: equal pixels, equal times
    r = job.raster
    assert r is not None
    dt = np.diff(r.lines[0].change_t) / F_CPU
    assert dt == pytest.approx(r.pitch_mm / r.speed_mm_s, rel=0.03)


def test_line_sizes_are_the_wire_bytes(tmp_path: Path) -> None:
    """`raster.lines.groups` reckons each G7 line's bytes; `wire.g7_body` writes them."""
    from fivebar_host.raster import lines, motion, speed

    prof = load_profile(None)
    rng = np.random.default_rng(5)
    job = _compile(tmp_path, prof, rng.random((4, 60)), width_mm=12.0)
    assert job.raster is not None
    ro = rjob.raster_options({**defaults(), "width_mm": 12.0}, prof)
    # re-plan one scanline the way compile_raster did and write its lines
    from fivebar_host.compile.model import CompileOptions
    from fivebar_host.compile.place import setup
    from fivebar_host.raster import grid as gridmod
    from fivebar_host.raster import image

    g = image.load(tmp_path / "img.png")
    su = setup(prof, CompileOptions(), prof.kinematics.working_mode)
    mode = su.mode if su.mode != "auto" else "+-"
    grid = rjob._grid(str(tmp_path / "img.png"), g, ro, prof, mode)
    ctx = motion.RasterCtx(prof, rjob._checker(prof, mode), grid, job.raster.speed_mm_s,
                           rjob.CHORD_SHARE * prof.motion.tolerance_mm, rjob.K_MAX)
    checked = 0
    for sl in gridmod.scanlines(grid, True, 1):
        sm, ch = speed.plan_line(ctx, sl)
        p_prev: int | None = None
        t_prev: int | None = None
        for gr in lines.groups(sm, ch):
            d = np.diff(sm.steps[gr.first:gr.first + gr.count + 1], axis=0)
            items = [(int(p), int(a), int(b)) for p, (a, b) in
                     zip(sm.duration_us[gr.first:gr.first + gr.count].tolist(), d.tolist(),
                         strict=True)]
            body = wire.g7_body(items, gr.u, gr.t, gr.powers, p_prev, t_prev)
            assert wire.g7_line_bytes(body) == gr.nbytes
            assert gr.nbytes <= lines.LINE_LIMIT
            p_prev = items[-1][0]
            if len(gr.powers) > 1:
                t_prev = gr.t
            checked += 1
    assert checked > 4


def test_out_of_reach_names_row_and_column(tmp_path: Path) -> None:
    prof = load_profile(None)
    with pytest.raises(JobError) as ei:
        _compile(tmp_path, prof, np.ones((4, 10)), width_mm=40.0, origin_mm=(300.0, 300.0))
    assert "row" in str(ei.value) and "column" in str(ei.value)


def test_passes_and_one_way(tmp_path: Path) -> None:
    prof = load_profile(None)
    job = _compile(tmp_path, prof, np.full((3, 10), 0.5), width_mm=5.0, passes=2,
                   one_way=True)
    r = job.raster
    assert r is not None
    assert len(r.lines) == 6 and {s.sign for s in r.lines} == {1}
    assert {s.pass_no for s in r.lines} == {0, 1}


def _firmware_refusals(job: Job, profile: Profile) -> list[str]:
    """The G7 lines of the job's program that fb_exec.c g7_check would refuse: more
    pixels than the ring holds, T under 400 cycles, a change past the line's segments."""
    from fivebar_host import protocol
    from fivebar_host.compile.emit import job_program
    from fivebar_host.program import Kind

    prog = job_program(job, profile, True)
    kind, _a, _b, p, s = (np.asarray(x) for x in prog.rows)
    modal_t: int | None = None
    out = []
    for st in np.flatnonzero((kind == Kind.RASTER) & (s >= 0)).tolist():
        raw, n = wire.g7_line(prog, st, 1)
        g = protocol.read_g7(raw.split(b"G7:", 1)[1].rsplit(b"*", 1)[0])
        modal_t = g.t if g.t is not None else modal_t
        npx, per = len(g.powers), modal_t or 0
        total = int(p[st:st + n].sum()) * 16
        if (npx > 128 - protocol.PX_HEAD or (npx > 1 and per < 400)
                or (npx and (g.u or 0) + (npx - 1) * per >= total)):
            out.append(f"item {st}: {npx} px, U {g.u}, T {per}, {total} cycles")
    return out


def test_every_g7_line_passes_the_firmware_checks() -> None:
    """The photo on the fast profile has long single-piece lines in its light areas, where
    the modal T once put the last change past the segment's end (error:7)."""
    prof = load_profile(Path(__file__).resolve().parents[1] / "configs" / "raster-fast.toml")
    photo = Path(__file__).resolve().parents[1] / "examples" / "photo.png"
    v = defaults()  # the file's 254 dpi: 32 × 32 mm at 10 px/mm
    job = rjob.compile_raster(photo, prof, rjob.raster_options(v, prof))
    assert _firmware_refusals(job, prof) == []


def test_slow_scan_lines_keep_u_non_negative(tmp_path: Path) -> None:
    """At 40 mm/s a 40-pixel piece's crossings sag ~50 cycles below their secant: the fit
    once wanted U < 0 (not on the wire); now the pieces shrink until U ≥ 0 fits."""
    prof = load_profile(None)
    rng = np.random.default_rng(32)
    dark = 1 - rng.integers(20, 236, (100, 400)) / 255
    job = _compile(tmp_path, prof, dark, width_mm=40.0, line_interval_mm=0.1)
    assert job.raster is not None
    assert job.raster.fit_residual_cycles <= 40
    assert _firmware_refusals(job, prof) == []


def test_servo_joints_refuse_a_raster(tmp_path: Path) -> None:
    """The servo build has no pixel interrupt and refuses G7: a raster on a servo profile
    is refused before anything is planned, naming why."""
    prof = load_profile(ROOT / "configs" / "plotclock.toml")
    assert prof.joints is not None
    with pytest.raises(JobError) as ei:
        _compile(tmp_path, prof, np.ones((4, 10)), width_mm=10.0)
    assert ei.value.reason == "servo_joints" and "stepper joints" in str(ei.value)


def test_without_laser_every_pixel_is_sent_at_power_zero(tmp_path: Path) -> None:
    """As a pen job without --laser sends S0 on every line, a raster without --laser sends
    every pixel at 0 (and no M3): only --laser puts a power above 0 on the wire."""
    from fivebar_host.compile.emit import raster_program
    from fivebar_host.program import Kind

    prof = load_profile(None)
    job = _compile(tmp_path, prof, np.random.default_rng(3).random((3, 30)), width_mm=6.0)
    burn, rehearse = raster_program(job, prof, True), raster_program(job, prof, False)
    assert any(any(r.powers) for r in burn.runs)
    assert rehearse.runs and not any(any(r.powers) for r in rehearse.runs)
    assert [len(r.powers) for r in rehearse.runs] == [len(r.powers) for r in burn.runs]
    assert Kind.TOOL_ON in burn.kind.tolist() and Kind.TOOL_ON not in rehearse.kind.tolist()


@pytest.mark.parametrize(("baud", "half"), [(1000000, True), (115200, False)])
def test_fast_scans_leave_the_ring_room_for_the_next_line(tmp_path: Path, baud: int,
                                                          half: bool) -> None:
    """A scan the joints allow above `lines.HALF_RING_PX_S` on a link that carries it
    (configs/raster-fast.toml, 8,000 px/s, at 1000000 baud): every G7 line's record (its
    10-byte head and its powers) takes at most half the firmware's 128-byte pixel ring, so
    the next line's record fits beside it and its segments are queued while the line
    burns; where the link sets the speed (115200 baud) lines may fill the ring (fewer bytes
    a pixel)."""
    from fivebar_host.raster import lines

    root = Path(__file__).resolve().parent.parent
    text = (root / "configs" / "raster-fast.toml").read_text()
    cfg = tmp_path / "fast.toml"
    cfg.write_text(text.replace("# link_baud = 500000", f"link_baud = {baud}"))
    prof = load_profile(cfg)
    img = tmp_path / "noise.png"
    rng = np.random.default_rng(3)
    Image.fromarray(rng.integers(20, 236, (4, 400)).astype(np.uint8)).save(img)
    v = defaults()
    v.update(width_mm=40.0, line_interval_mm=0.1)
    job = rjob.compile_raster(img, prof, rjob.raster_options(v, prof))
    r = job.raster
    assert r is not None
    record = max(10 + len(run.powers) for run in r.runs)
    if half:
        assert record <= lines.PX_RING // 2
    else:
        assert lines.PX_RING // 2 < record <= lines.PX_RING
