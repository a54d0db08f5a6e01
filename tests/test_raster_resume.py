"""A raster job resumed inside a scanline restarts at that scanline's start (its overscan:
at scan speed again before the next pixel), with the pixels it had already reached at power
0 and the later ones at their own power: nothing burned twice, nothing skipped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from fivebar_host import wire
from fivebar_host.config import load_profile
from fivebar_host.options import defaults
from fivebar_host.program import Kind
from fivebar_host.raster import job as rjob
from fivebar_host.run.moves import build_program


def test_resume_inside_a_scanline_restarts_it_without_burning_twice(tmp_path: Path) -> None:
    prof = load_profile(None)
    p = tmp_path / "grey.png"
    Image.fromarray(np.full((4, 40), 100, dtype=np.uint8)).save(p)
    v = defaults()
    v.update(width_mm=10.0)
    job = rjob.compile_raster(p, prof, rjob.raster_options(v, prof))
    r = job.raster
    assert r is not None
    sl = r.lines[1]
    g7 = [g for g in range(sl.first, sl.end) if r.run[g] >= 0]
    assert len(g7) >= 3
    k = g7[len(g7) // 2] + 1  # stopped inside a G7 line in the middle of the scanline
    pos = job.steps[k]
    prog = build_program(job, prof, True, k, pos)
    kind, a, b, s, seg = prog.kind, prog.a, prog.b, prog.s, prog.segment
    raster = np.flatnonzero(kind == Kind.RASTER)
    first = int(raster[0])
    # the restart: a travel to the scanline's start, then its first segment, from its run
    assert int(seg[first]) == sl.first and s[first] >= 0
    moves = np.flatnonzero(kind[:first] == Kind.MOVE)
    last = int(moves[-1])
    assert (a[last], b[last]) == tuple(job.steps[sl.first].tolist())
    # every G7 line is written from a run of its own (never runs[-1])
    lines = [i for i in raster.tolist() if s[i] >= 0]
    assert lines[0] == first
    raw, _ = wire.g7_line(prog, first, 1)
    assert b"G7:" in raw
    # the scanline's pixels: 0 up to the stop, the image's power after it
    powers = b"".join(prog.runs[int(s[i])].powers for i in lines
                      if r.line_of(int(seg[i])) == 1)
    want = int(r.target.max())
    got = np.frombuffer(powers, dtype=np.uint8)
    assert got[0] == 0 and got[-2] == want  # the last change is the exit's 0
    n_zero = int(np.argmax(got != 0))
    start = np.concatenate(([0], np.cumsum(job.duration_us[sl.first:k].astype(np.int64))))
    reached = float(start[-1]) * 16
    assert (sl.change_t[:n_zero] < reached).all() and sl.change_t[n_zero] >= reached
    assert set(got[n_zero:-1].tolist()) == {want}


def test_a_fresh_start_is_the_job_itself_and_rate_comes_first(tmp_path: Path) -> None:
    """From the home pose at segment 0 nothing is restarted or added (segment 0 is the move
    to the first scanline, not a scan); on a profile whose raster is faster than the boot
    step rate the `$0` setting comes before every move, resumed or not (it needs the
    machine idle: error:13 otherwise)."""
    from fivebar_host.compile.emit import job_program

    root = Path(__file__).resolve().parents[1]
    prof = load_profile(root / "configs" / "raster-fast.toml")
    p = tmp_path / "grey.png"
    Image.fromarray(np.full((4, 40), 100, dtype=np.uint8)).save(p)
    v = defaults()
    v.update(width_mm=10.0, line_interval_mm=0.1)
    job = rjob.compile_raster(p, prof, rjob.raster_options(v, prof))
    r = job.raster
    assert r is not None and not r.g7[0]
    fresh = build_program(job, prof, True, 0, job.steps[0])
    body = job_program(job, prof, True, 0)
    assert np.array_equal(fresh.kind[-len(body):], body.kind)
    assert np.array_equal(fresh.a[-len(body):], body.a)
    k = r.lines[2].first + 3
    for prog in (fresh, build_program(job, prof, True, k, job.steps[k])):
        text = np.flatnonzero(prog.kind == Kind.TEXT)
        moves = np.flatnonzero(np.isin(prog.kind, (Kind.MOVE, Kind.RASTER)))
        assert text.size == 1 and prog.texts[int(prog.s[text[0]])].startswith("$0=")
        assert text[0] < moves[0]


def test_resume_from_inside_a_segment_counts_what_it_got_through(tmp_path: Path) -> None:
    """Stopped part of the way through a segment (the firmware's exact position after a
    reset), the pixels changed before the last step it issued are at 0 too, not only those
    before the segment's start (the emulator showed them burned twice: test_raster_resume_
    sim.py); the time it surely reached is its last step's DDA time, (i − ½)/n."""
    prof = load_profile(None)
    p = tmp_path / "grey.png"
    Image.fromarray(np.full((2, 80), 100, dtype=np.uint8)).save(p)
    v = defaults()
    v.update(width_mm=8.0)
    job = rjob.compile_raster(p, prof, rjob.raster_options(v, prof))
    r = job.raster
    assert r is not None
    sl = r.lines[0]
    g7 = [g for g in range(sl.first, sl.end) if r.g7[g]]
    k = g7[len(g7) // 2]
    d = job.steps[k + 1] - job.steps[k]
    i = int(np.argmax(np.abs(d)))
    n = abs(int(d[i]))
    assert n >= 4
    done = n // 2
    pos = job.steps[k].copy()
    pos[i] += done * int(np.sign(d[i]))  # the dominant motor half way (the other: its start)
    prog = build_program(job, prof, True, k, pos)
    powers = b"".join(prog.runs[int(s)].powers for s, kind, seg in
                      zip(prog.s, prog.kind, prog.segment, strict=True)
                      if kind == Kind.RASTER and s >= 0 and r.line_of(int(seg)) == 0)
    got = np.frombuffer(powers, dtype=np.uint8)
    start = float(job.duration_us[sl.first:k].astype(np.int64).sum())
    stop = (start + (done - 0.5) / n * float(job.duration_us[k])) * 16
    zero = sl.change_t[:-1] < stop
    assert zero.any() and not zero.all()
    assert (got[:-1][zero] == 0).all() and (got[:-1][~zero] > 0).all()
    # more than the segment-start rule zeroed: the half segment counts
    assert int(zero.sum()) > int((sl.change_t[:-1] < start * 16).sum())
