"""The plan never asks more than the serial link carries (`compile.linkrate`, issue 20).

Checked against the real thing, not the floor's own arithmetic: the bodies `fivebar plot`
would send are packed into wire lines by `run.pack` (what the streamer sends), each line's
arrival is timed at the emulator's byte rate, and every segment must have arrived by the
time the plan starts it. Without the floor the dense job below fails that check (it asked
~1000 segments/s of ~15 bytes at 115200 baud and ran with ~100 underruns); with it, it passes,
and on the emulator in real time it runs with no mid-path underrun.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.link import SIMAVR_BPS, WOBBLE_MM, planned_job
from fivebar_host import protocol, wire
from fivebar_host.compile import CompileOptions, compile_job, linkrate
from fivebar_host.config import load_profile
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.program import Kind, Program
from fivebar_host.report.text.dryrun import report_lines

#: The firmware starts moving once this many blocks are queued (config.h
#: CFG_START_BLOCKS), or CFG_START_DELAY_MS after the first.
START_BLOCKS, START_DELAY_S = 4, 0.020
#: The firmware's segment queue (CFG_QUEUE_SIZE) and receive buffer (CFG_RX_SIZE).
QUEUE_BLOCKS, RX_BYTES = 16, 128


def wire_lines(prog: Program) -> list[tuple[int, int]]:
    """(bytes, segments) of every wire line the streamer builds from `prog`."""
    absolute = wire.absolute_known(prog)
    out, j = [], 0
    while j < len(prog):
        raw, n = wire.pack_line(prog, j, 10_000 + j, bool(absolute[j]), 64)
        out.append((len(raw), n))
        j += n
    return out


def late_segments(prog: Program, bytes_per_s: float, host_latency_s: float = 0.0) -> int:
    """Underruns of the plan on a model of the link: the host sends a line once the bytes
    it has sent and not yet seen taken fit the firmware's receive buffer (character
    counting, `RX_BYTES`) — when it had to wait for a reply, `host_latency_s` after the
    reply (a host that is slow to answer: a loaded machine) —, the line arrives at
    `bytes_per_s`, the firmware takes it once its
    queue of `QUEUE_BLOCKS` has room for its segments, and runs each segment for its `P`
    from when the one before ends, or from when it was taken if that is later — an
    underrun. Motion starts as the firmware starts it (`START_BLOCKS`, `START_DELAY_S`)."""
    timed = (prog.kind == Kind.MOVE) | (prog.kind == Kind.DWELL)
    dur = np.where(timed, prog.p_us * 1e-6, 0.0).tolist()
    taken: list[float] = []  # per block: when the firmware took its line
    ends: list[float] = []  # per block: when it ended (known once motion started)
    sent: list[tuple[float, int]] = []  # (taken at, bytes) of every line sent
    wire, t0 = 0.0, float("inf")
    late = 0
    for size, n in wire_lines(prog):
        while sum(b for t, b in sent if t > wire) + size > RX_BYTES:
            wire = min(t for t, b in sent if t > wire) + host_latency_s  # an answer
        wire += size / bytes_per_s
        at = wire
        if len(taken) + n > QUEUE_BLOCKS:  # wait for room in the queue
            at = max(at, ends[len(taken) + n - QUEUE_BLOCKS - 1])
        sent.append((at, size))
        taken += [at] * n
        if t0 == float("inf") and (len(taken) >= START_BLOCKS or len(taken) == len(prog)
                                   or at >= taken[0] + START_DELAY_S):
            t0 = min(at, taken[0] + START_DELAY_S)
        while t0 < float("inf") and len(ends) < len(taken):
            k = len(ends)
            prev = ends[-1] if ends else t0
            if k and dur[k] > 0 and taken[k] > prev + 1e-9:
                late += 1
            ends.append(max(prev, taken[k]) + dur[k])
    return late


def dense(baud: int = protocol.BASE_BAUD) -> tuple[list[str], int, float]:
    """The benchmark's wobbly line: 1000 chords of ~0.1 mm at 300 mm/s, 2000 rad/s²."""
    bodies, segments, on_line, _ = planned_job(2000.0, 300.0, WOBBLE_MM, baud)
    return bodies, segments, on_line


def test_the_wire_keeps_ahead_of_the_plan() -> None:
    bodies, _, on_line = dense()
    assert late_segments(bodies, SIMAVR_BPS) == 0
    assert on_line > 550  # the floor takes what the wire carries, not much less


def test_without_the_floor_the_plan_outruns_the_wire(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(linkrate, "raise_to_link", lambda *a, **k: None)
    monkeypatch.setattr(linkrate, "link_floor_us",
                        lambda steps, *a, **k: np.zeros(steps.shape[0] - 1, dtype=np.int64))
    bodies, _, on_line = dense()
    assert on_line > 900
    assert late_segments(bodies, SIMAVR_BPS) > 50


@pytest.mark.parametrize("baud", protocol.BAUD_RATES)
def test_faster_links_plan_faster_within_the_firmware_floor(baud: int) -> None:
    bodies, _, on_line = dense(baud)
    assert late_segments(bodies, baud / 10 * (SIMAVR_BPS / 11520)) == 0
    assert on_line <= 1e6 / linkrate.FIRMWARE_SEGMENT_US + 1
    if baud > protocol.BASE_BAUD:
        assert on_line > dense()[2] * 1.15


def test_the_byte_estimate_matches_the_packer() -> None:
    """The floor's bytes against the bytes `wire.pack_line` really builds (its text, not
    the model's arithmetic)."""
    for wobble, feed in ((0.0, 100.0), (WOBBLE_MM, 300.0), (0.2, 200.0)):
        prog, _, _, _ = planned_job(2000.0, feed, wobble)
        packed = sum(size for size, _ in wire_lines(prog))
        steps, power, dur = [], [], []
        pos = (0, 0)
        for i in np.flatnonzero(prog.kind == Kind.MOVE):
            steps.append(pos)
            pos = (int(prog.a[i]), int(prog.b[i]))
            power.append(int(prog.s[i]))
            dur.append(int(prog.p_us[i]))
        steps.append(pos)
        est = wire.segment_bytes(np.array(steps), np.array(power), np.array(dur), 0,
                                     len(dur))
        assert abs(float(est.sum()) / packed - 1.0) < 0.12, (wobble, est.sum(), packed)


def test_floor_levels_round_up_onto_a_shared_grid() -> None:
    f, r = linkrate.FIRMWARE_SEGMENT_US, linkrate.LEVEL_RATIO
    us = np.array([10.0, f, f + 1.0, f * r - 0.5, f * r + 1.0, 50.0 * f])
    got = linkrate.floor_levels(us)
    assert (got >= np.maximum(us, f)).all()
    assert got[0] == got[1] == f and got[2] == got[3] == int(np.ceil(f * r)) and got[4] > got[3]
    assert (got <= np.maximum(us, f) * r + 1).all()


#: How late the modelled host answers each reply it waited for, s: a host far behind (a
#: loaded machine; `fivebar plot`'s stream loop answers within a millisecond or two).
HOST_LATENCY_S = 0.010


def test_the_dense_job_keeps_ahead_of_a_slow_host_in_emulated_time() -> None:
    """The real-time question — does the queue run empty? — asked in the model's time with
    a slow host, so that it holds on a machine at any load. The real-time figure (the
    emulator in wall-clock time, host and emulator sharing the cores) is a benchmark:
    `python benchmarks/link.py --dense --repeat 5` (the median of the runs)."""
    bodies, _, _ = dense()
    assert late_segments(bodies, SIMAVR_BPS, HOST_LATENCY_S) == 0
    assert late_segments(bodies, SIMAVR_BPS, 8 * HOST_LATENCY_S) > 0  # the model can tell


@pytest.mark.skipif(bool(toolchain_missing()), reason="emulator unavailable")
def test_the_dense_job_runs_exactly_on_the_emulator() -> None:
    """The firmware takes every packed line of the dense job and ends where the plan ends
    (the emulator runs as fast as it can: nothing here depends on the machine's load)."""
    bodies, segments, _ = dense()
    link = Link.open("fivebar-sim://")
    try:
        link.command("G92 A0 B0")
        res = link.stream(bodies)
        final = link.wait_idle(120.0, last_line=link.next_line - 1)
    finally:
        link.close()
    moves = np.flatnonzero(bodies.kind == Kind.MOVE)
    assert (final.a, final.b) == (int(bodies.a[moves[-1]]), int(bodies.b[moves[-1]]))
    assert final.accepted_line == link.next_line - 1  # every line taken, and run (Idle)
    assert res.resends == 0 and segments > 1000


def test_the_dry_run_says_where_the_link_sets_the_pace(tmp_path: Path) -> None:
    prof = load_profile()
    fast = dataclasses.replace(prof, motion=dataclasses.replace(
        prof.motion, max_joint_rad_s2=2000.0, max_joint_rad_s=50.0))
    x0, y0 = -40.0, 101.6
    src = tmp_path / "dense.gcode"
    moves = [f"G1 X{x0 + 0.1 * k + WOBBLE_MM * math.sin(k):.3f} Y{y0:.3f}"
             for k in range(1, 301)]
    src.write_text("\n".join(["G21", "G90", f"G0 X{x0} Y{y0}", *moves]) + "\n")
    opts = CompileOptions(no_simplify=True, draw_feed_mm_s=300.0)
    link = [ln for ln in report_lines(compile_job(src, fast, opts), profile=fast)
            if ln.startswith("link")]
    assert len(link) == 1 and "115200 baud" in link[0] and "link_baud = 250000" in link[0]
    # at 1 Mbaud the wire carries it all: the firmware's own floor sets the pace, and a
    # faster link is no advice
    mbaud = dataclasses.replace(fast, serial=dataclasses.replace(fast.serial,
                                                                  link_baud=1_000_000))
    job = compile_job(src, mbaud, opts)
    n, wire_n = linkrate.bound_segments(job.steps, job.power, job.duration_us, mbaud)
    link = [ln for ln in report_lines(job, profile=mbaud) if ln.startswith("link")]
    assert n > 50 and wire_n == 0 and len(link) == 1
    per_s = 1e6 / linkrate.FIRMWARE_SEGMENT_US
    assert f"what the firmware (≤ {per_s:.0f} segments/s) carries" in link[0]
    assert "baud" not in link[0] and "link_baud" not in link[0]
    slow_opts = CompileOptions(no_simplify=True)  # the profile's 40 mm/s: 400 segments/s
    slow = [ln for ln in report_lines(compile_job(src, prof, slow_opts), profile=prof)
            if ln.startswith("link")]
    assert slow == []
