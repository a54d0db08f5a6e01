"""A raster job interrupted inside a scanline, end to end on the real firmware in simavr:
the emulated controller is reset mid-scan (the Uno's DTR reset, `reset_after=N`), `fivebar
plot … --resume` finishes the job, and the pin trace of both runs (one machine, one trace)
shows what docs/raster.md ("Resume") promises — the job restarted at the start of the
interrupted scanline (its overscan), the laser off from the fault until the pen was back
there, and every pixel's dose over both runs its target's: each pixel burned once, none
twice; the one under way at the fault keeps what it got in the first run (at most once).
Before the resume counted the part of the interrupted segment the firmware got through,
this test found the 4-5 pixels of that part burned twice (dose 2.02×).

The dose is rebuilt from the trace (`raster.dose.dose_grid`: the laser pin's high time per
cell where the pen was, the pen by forward kinematics of the step edges) and compared with
the planned powers (the job compiled here from the same image and options, as the CLI
does).  No timing assertions: the emulator runs in real time only so that the fault lands
in the same place on a loaded machine (the host fills the firmware's buffer long before
the scan needs it, so the N-th line is sent at the same point of the job)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from fivebar_host.cli import main
from fivebar_host.config import load_profile
from fivebar_host.devices import simport
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.options import defaults
from fivebar_host.raster import dose
from fivebar_host.raster import job as rjob
from fivebar_host.run.resume import ResumePoint, resume_path

pytestmark = [
    pytest.mark.sim,
    pytest.mark.skipif(toolchain_missing() is not None,
                       reason=f"emulator unavailable: {toolchain_missing()}"),
]

#: A dose within this fraction of its target is the target (the PWM's 16 µs period on a
#: 5 ms pixel and the cell edges' share of a step: the 5 % of the issue's grey patch goal).
DOSE_TOL = 0.05


@pytest.fixture(autouse=True)
def _clean_machines() -> Iterator[None]:
    simport.forget_machines()
    yield
    simport.forget_machines()


def run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return res.exit_code, res.output


def test_reset_inside_a_scanline_resumes_it_burning_each_pixel_once(
        tmp_path: Path, quick_profile: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    img = tmp_path / "ramp.png"
    a = np.tile(np.linspace(60, 200, 160).astype(np.uint8), (3, 1))  # each its own power
    Image.fromarray(a).save(img)
    prof = load_profile(quick_profile)
    v = defaults()
    v.update(width_mm=16.0)  # 0.1 mm pixels: 3 G7 lines a scanline
    job = rjob.compile_raster(img, prof, rjob.raster_options(v, prof))
    r = job.raster
    assert r is not None
    trace = tmp_path / "pins.trace"
    opts = ("--laser", "--yes", "--width", "16mm", "--config", str(quick_profile))
    code, out = run("plot", str(img), "--port",
                    f"fivebar-sim://?machine=rr&trace={trace}&realtime=1&reset_after=20", *opts)
    assert code == 3 and "the firmware restarted" in out, out
    rp = ResumePoint.load(resume_path(img))
    assert rp.position is not None and rp.segments == job.duration_us.shape[0]
    stop = rp.next_segment
    line = r.line_of(stop)
    assert line >= 0 and r.g7[stop], f"the fault landed outside a scan (segment {stop})"
    sl = r.lines[line]
    # inside the scanline's pixels: some changes came before the stop, some after
    reached = float(job.duration_us[sl.first:stop].astype(np.int64).sum()) * 16
    n_before = int((sl.change_t[:-1] < reached).sum())
    assert 0 < n_before < sl.c1 - sl.c0, (n_before, sl.c0, sl.c1)

    code, out = run("plot", str(img), "--port", "fivebar-sim://?machine=rr", "--resume", *opts)
    assert code == 0, out
    simport.machine("rr").stop()  # the trace of both runs, complete
    pt = dose.read_pins(trace)
    mo = dose.motion_of(pt)
    steps = mo.step_cycles()

    # the fault: the longest pause of the steps; then the travel back to the scanline's
    # start (its overscan's first point), with the laser off all the way
    k = int(np.argmax(np.diff(steps)))
    t_fault = steps[k]
    after = steps[k + 1:]
    # (a motor's position at its step edge is half a step from the step it reaches)
    at = mo.at(after)
    back = (np.abs(at - job.steps[sl.first]) <= 0.5).all(axis=1)
    assert back.any(), "the resumed run never went back to the scanline's start"
    t_back = after[int(np.argmax(back))]
    rise, fall = dose.high_intervals(pt)
    # the pixel under way burns on until the reset drives the pin low (within a pixel's
    # time of the last step), then the laser stays off until the pen is back
    nxt = np.concatenate((rise[1:], [np.iinfo(np.int64).max]))
    t_off = fall[(fall >= t_fault) & (nxt - fall > 2 * dose.PWM_PERIOD)].min()
    assert t_off - t_fault <= dose.pixel_cycles(r)
    assert not ((rise > t_off) & (rise < t_back)).any(), "laser on during the travel back"

    # every pixel's dose over both runs: its target once (the one under way at the fault:
    # at most once), none twice, none skipped
    burned = dose.dose_grid(job, prof, pt, mo) * 255.0 / dose.pixel_cycles(r)
    target = r.target.astype(np.float64)
    lit = target > 0
    ratio = np.where(lit, burned / np.where(lit, target, 1.0), 0.0)
    assert float(burned[~lit].max(initial=0.0)) == 0.0
    # the pixels under way at the fault: where the pen stood after its last step, and the one
    # before it in the scan's direction, whose time the laser's timeline may still be in when
    # that step has just crossed into the next pixel (the timeline trails the steps by a few
    # µs; which of the two the resume counts as under way depends on where the fault falls)
    s_f, _ = dose.grid_coords(r, dose.pen_at(job, prof, mo, np.array([t_fault])))
    col = int(np.floor(s_f[0] / r.pitch_mm))
    under_way = np.zeros_like(lit)
    for c in (col, col - sl.sign):
        if 0 <= c < lit.shape[1]:  # else the fault was in the overscan
            under_way[sl.row, c] = True
    inner = lit & ~under_way
    # the end cells share their edge steps with the overscan (measured up to 1.057 of their
    # target once): held to twice the tolerance both ways (a pixel burned twice is 2×)
    inner[:, [0, -1]] = False
    assert np.abs(ratio[inner] - 1.0).max() <= DOSE_TOL, ratio.round(3)
    assert ratio[lit & ~under_way].max() <= 1.0 + 2 * DOSE_TOL  # none twice, the end cells too
    assert ratio[lit & ~under_way].min() >= 1.0 - 2 * DOSE_TOL  # none skipped, ends too
    # the pixels under way: at most once, plus what the resume burns twice by design
    # (run.moves._steps_into: it restarts at the time the interrupted segment had surely
    # reached, its major motor's last step, so the burn from there until the reset drove
    # the pin low, at most about a step's time, can come again): measured from the trace
    # (0.35–0.36 of a 5 ms pixel here; a pixel it fell in measured 1.28) — far below a
    # second burn (2×)
    d = job.steps[stop + 1] - job.steps[stop]
    major = int(np.argmax(np.abs(d)))
    t_major = float(mo.t[major][mo.t[major] <= t_fault].max())
    again = float(t_off - t_major) / dose.pixel_cycles(r)
    assert again <= 1.0, again  # a step's time, well under a pixel's
    assert (ratio[under_way] <= 1.0 + again + 2 * DOSE_TOL).all(), (again, ratio.round(3))
