"""Live feed and laser-power overrides: the line rewrite, where a feed change may start, the
stream applying them to lines not yet written only (on the mock device), an exact resume
after an override, and the terminal key reader."""

from __future__ import annotations

import io
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from runs import run_with

from fivebar_host import protocol, wire
from fivebar_host.cli.keys import KeyReader, apply_keys, override_keys
from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.controllers.fivebar.stream import StreamProgress
from fivebar_host.devices import mock
from fivebar_host.run.errors import SendError
from fivebar_host.run.moves import build_program
from fivebar_host.run.overrides import Overrides, scaled

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(autouse=True)
def _clean_machines(clean_mock: None) -> None:
    """Every test here starts and ends with no named mock machine left over."""


def scale_body(body: str, feed_pct: int, power_pct: int) -> str:
    """One line read into an item, scaled, and written again."""
    prog = wire.read_lines([body])
    p, s = scaled(prog, 0, feed_pct, power_pct)
    return wire.body(prog, 0, p, s)


def starts_at_rest(bodies: list[str], i: int) -> bool:
    return bool(wire.read_lines(bodies).starts_at_rest()[i])


def test_scale_body_slows_moves_scales_power_and_keeps_the_rest() -> None:
    assert scale_body("G1 A10 B-4 P1001 S200", 50, 50) == "G1 A10 B-4 P2002 S100"
    assert scale_body("G1 A10 P1000 S255", 30, 100) == "G1 A10 P3334 S255"  # rounded up
    assert scale_body("G1 P500000 S200", 10, 50) == "G1 P500000 S100"  # a dwell keeps its time
    assert scale_body("G1 A1 P90000000 S0", 10, 0) == f"G1 A1 P{protocol.P_MAX_US} S0"
    assert scale_body("M280 S1500 R200 D100", 10, 0) == "M280 S1500 R200 D100"
    assert scale_body("G1 A1 B2 P300 S9", 100, 100) == "G1 A1 B2 P300 S9"


def test_feed_changes_start_only_at_rests() -> None:
    bodies = ["G90", "M3 S0", "G1 A1 B1 P500 S0", "G1 A2 B2 P500 S0", "G1 A3 B3 P500 S200",
              "G1 A4 B4 P500 S200", "G1 P1000 S200", "G1 A5 B5 P500 S200", "M5"]
    rest = [starts_at_rest(bodies, i) for i in range(len(bodies))]
    assert rest == [True, True, True, False, True, False, True, True, True]


def test_overrides_clamp_to_their_ranges() -> None:
    ov = Overrides()
    ov.step(feed=-20, power=-20)
    assert ov.values() == (10, 0)
    ov.step(feed=30, power=30)
    assert ov.values() == (100, 100)
    ov.set(feed_pct=55)
    assert ov.text() == "feed 55% power 100%"


def test_keys_from_a_fake_terminal() -> None:
    ov = Overrides()
    assert apply_keys("--x[", ov) and ov.values() == (80, 90)
    assert not apply_keys("q?", ov)
    r, w = os.pipe()
    try:
        reader = KeyReader(r, ov)
        assert not reader.poll()  # nothing waiting: returns at once
        os.write(w, b"+]]-=")
        assert reader.poll() and ov.values() == (90, 100)
        with reader.paused():
            os.write(w, b"---")
            assert not reader.poll()  # paused for a prompt: keys wait
        assert reader.poll() and ov.values() == (60, 100)
    finally:
        os.close(r)
        os.close(w)


def test_override_keys_needs_a_terminal() -> None:
    with override_keys(Overrides(), io.StringIO()) as keys:
        assert keys is None
    r, w = os.pipe()
    try:
        with os.fdopen(os.dup(r)) as pipe, override_keys(Overrides(), pipe) as keys:
            assert keys is None  # a pipe is not a terminal: no cbreak, no keys
    finally:
        os.close(r)
        os.close(w)


def _words(body: str) -> dict[str, int]:
    return {w[0]: int(w[1:]) for w in body.split()[1:]}


def test_stream_applies_overrides_to_later_lines_only() -> None:
    prof = load_profile()
    job = compile_job(EXAMPLES / "simple.svg", prof, CompileOptions(validate=False))
    prog = build_program(job, prof, True, 0, (0, 0))
    ov = Overrides()
    changed_at: list[int] = []

    def on_progress(p: StreamProgress) -> None:
        if not changed_at and p.acked >= 40:
            changed_at.append(p.sent)  # lines written so far keep their values
            ov.set(feed_pct=50, power_pct=50)

    with Link.open("fivebar-mock://?machine=ov&speed=0") as link:
        first = link.next_line
        link.stream(prog, on_progress=on_progress, overrides=ov)
        link.wait_idle(30.0)
    assert changed_at
    bodies = wire.bodies(prog)
    seen = {e.line - first: e for e in mock.machine("ov").ledger if e.kind == "G1"}
    scaled_p, scaled_s = [], []
    for i, e in sorted(seen.items()):
        w = _words(bodies[i])
        moving = "A" in w or "B" in w
        scaled_p.append((i, e.duration_us != w["P"] if moving else None))
        scaled_s.append((i, e.power != w["S"] if w["S"] else None))
    # no line written before the change is altered
    assert not any(x for i, x in scaled_p + scaled_s if i < changed_at[0])
    # power: every later line with S > 0 at half power
    later_s = [(i, seen[i].power, _words(bodies[i])["S"]) for i, x in scaled_s
               if x is not None and i >= changed_at[0]]
    assert later_s and all(p == s // 2 for _, p, s in later_s)
    # feed: from the first rest after the change, every move takes twice as long
    start = next(i for i in range(changed_at[0], len(bodies))
                 if starts_at_rest(bodies, i))
    slowed = 0
    for i, x in scaled_p:
        if x is None or i < changed_at[0]:
            continue
        w = _words(bodies[i])
        want = 2 * w["P"] if i >= start else w["P"]
        assert seen[i].duration_us == want, (i, start)
        slowed += i >= start
    assert slowed > 50


@pytest.mark.parametrize("when", [12, 20])  # wire lines of about 28 (G6 lines up to 127 B)
def test_resume_after_an_override_is_exact(tmp_path: Path, when: int) -> None:
    drawing = tmp_path / "simple.svg"
    shutil.copy(EXAMPLES / "simple.svg", drawing)
    prof = load_profile()
    job = compile_job(drawing, prof, CompileOptions(validate=False))
    ov = Overrides(feed_pct=40, power_pct=70)
    url = f"fivebar-mock://?machine=rs&speed=50&disconnect_after={when}"
    with Link.open(url) as link, pytest.raises(SendError):
        run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda _: True,
                overrides=ov)
    with Link.open("fivebar-mock://?machine=rs&speed=50") as link:
        run_with(link, job, prof, drawing=drawing, laser=True, confirm=lambda _: True,
                resume=True, overrides=Overrides())
    m = mock.machine("rs")
    drawn = np.zeros(2, dtype=np.int64)
    for e in m.ledger:
        if e.kind == "G1" and e.power > 0:
            drawn += np.abs(np.asarray(e.steps))
    planned = np.abs(np.diff(job.steps, axis=0))[job.draw].sum(axis=0)
    assert np.array_equal(drawn, planned)  # nothing lost, nothing drawn twice
    assert m.phys == [0, 0]
    powers = {e.power for e in m.ledger if e.kind == "G1" and e.power > 0}
    assert powers == {prof.laser.power * 70 // 100, prof.laser.power}  # before / after


def test_override_keys_on_a_terminal_cbreak_then_restored() -> None:
    import termios
    import time

    ov = Overrides()
    master, slave = os.openpty()
    try:
        with os.fdopen(os.dup(slave)) as tty_in:
            before = termios.tcgetattr(slave)
            with override_keys(ov, tty_in) as keys:
                assert keys is not None
                assert not termios.tcgetattr(slave)[3] & termios.ICANON  # keys at once
                assert termios.tcgetattr(slave)[3] & termios.ISIG  # Ctrl-C still signals
                os.write(master, b"-[")
                deadline = time.monotonic() + 2.0
                while ov.values() != (90, 90) and time.monotonic() < deadline:
                    keys.poll()
                assert ov.values() == (90, 90)
                with keys.paused():
                    assert termios.tcgetattr(slave)[3] & termios.ICANON  # a prompt's mode
                assert not termios.tcgetattr(slave)[3] & termios.ICANON
            assert termios.tcgetattr(slave) == before
    finally:
        os.close(master)
        os.close(slave)
