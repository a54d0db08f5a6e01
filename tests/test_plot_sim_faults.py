"""Faults mid-job on the real firmware in simavr, one per injected fault: `fivebar plot`
stops with exit code 3, names the fault and the position, the laser pin ends off, and
`--resume` completes the job so that the step pulses on the pins over both runs equal the
plan (nothing lost, nothing doubled).

The emulated machine (`fivebar-sim://?machine=NAME`) outlives the port: its pin trace spans
both runs, and opening the port again is the Uno's DTR reset, which keeps the firmware's
position, H and Ln done (docs/protocol.md section 7).  The same faults on the mock are in
test_plot_mock.py."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from sim_plot import all_steps, compiled_copy, laser_steps, planned_draw_steps, planned_steps

from fivebar_host.cli import main
from fivebar_host.devices import simport
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.devices.simtrace import Trace, read_trace
from fivebar_host.run.resume import ResumePoint, resume_path

pytestmark = [
    pytest.mark.sim,
    pytest.mark.skipif(toolchain_missing() is not None,
                       reason=f"emulator unavailable: {toolchain_missing()}"),
]


@pytest.fixture(autouse=True)
def _clean_machines() -> Iterator[None]:
    simport.forget_machines()
    yield
    simport.forget_machines()


def run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return res.exit_code, res.output


def laser_on_at_end(tr: Trace) -> bool:
    """The level the laser pin was last set to."""
    changes = tr.pin("laser")
    return bool(changes and changes[-1][1])


def settled_trace(machine: simport.SimMachine, timeout: float = 10.0) -> Trace:
    """The trace once the firmware, cut off from its host, stopped moving (its queue ran
    out, or its laser silence timeout held it)."""
    deadline = time.monotonic() + timeout
    last = machine.trace()
    while True:
        time.sleep(0.1)
        tr = machine.trace()
        if tr.last_cycle() == last.last_cycle():
            return tr
        assert time.monotonic() < deadline, "the cut-off firmware never stopped"
        last = tr


@pytest.mark.parametrize(("fault", "says"), [
    ("disconnect_after=12", ("device gone", "position not known yet")),
    ("reset_after=16", ("the firmware restarted", "stopped at A = ")),
    # the firmware hangs; its watchdog resets it (docs/protocol.md 9), the host sees the banner
    # (wire lines are counted: G6 packs several segments in one, so every fault comes early;
    # the job is about 270 segments in about 28 lines of up to 127 bytes)
    ("stall_after=10", ("the firmware restarted", "stopped at A = ")),
])
def test_fault_then_resume_draws_every_step_once(tmp_path: Path, quick_profile: Path,
                                                 monkeypatch: pytest.MonkeyPatch, fault: str,
                                                 says: tuple[str, str]) -> None:
    monkeypatch.chdir(tmp_path)  # whatever the command writes beside its working directory
    drawing, _, job = compiled_copy(tmp_path, "simple.svg")
    name = fault.split("_")[0]
    trace = tmp_path / "pins.trace"
    code, out = run("plot", str(drawing), "--port",
                    f"fivebar-sim://?machine={name}&trace={trace}&{fault}", "--laser", "--yes",
                    "--config", str(quick_profile))
    assert code == 3, out
    assert all(word in out for word in says), out
    rp = ResumePoint.load(resume_path(drawing))
    if rp.position is not None:
        assert f"A = {rp.position[0]}, B = {rp.position[1]}" in out
    assert 0 < rp.next_segment < rp.segments
    machine = simport.machine(name)
    tr = settled_trace(machine)
    assert not laser_on_at_end(tr), "the laser pin is on after the fault"
    assert 0 < all_steps(tr).sum() < planned_steps(job).sum()  # stopped mid-job

    code, out = run("plot", str(drawing), "--port", f"fivebar-sim://?machine={name}",
                    "--laser", "--yes", "--resume", "--config", str(quick_profile))
    assert code == 0, out
    assert not resume_path(drawing).exists()
    machine.stop()  # the trace of both runs, complete
    tr = read_trace(trace)
    assert not laser_on_at_end(tr)
    assert np.array_equal(laser_steps(tr), planned_draw_steps(job))  # nothing lost, no doubles
    assert np.array_equal(all_steps(tr), planned_steps(job))  # no travel back either
    assert (tr.positions("A")[-1][1], tr.positions("B")[-1][1]) == (0, 0)  # home again


def test_line_noise_is_absorbed_by_resends(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                           ) -> None:
    """Bytes lost and corrupted on the way to the real firmware: every damaged line is refused
    and sent again, so the job completes in one run and the laser-on pulses equal the plan."""
    monkeypatch.chdir(tmp_path)
    drawing, _, job = compiled_copy(tmp_path, "simple.svg")
    trace = tmp_path / "pins.trace"
    code, out = run("plot", str(drawing), "--port",
                    f"fivebar-sim://?machine=noisy&trace={trace}&drop=0.002&corrupt=0.002&seed=7",
                    "--laser", "--yes")
    assert code == 0, out
    resends = int(out.split(" resends")[0].rsplit(",", 1)[1])
    assert resends > 0, out  # the noise did damage lines
    simport.machine("noisy").stop()
    tr = read_trace(trace)
    assert not laser_on_at_end(tr)
    assert np.array_equal(laser_steps(tr), planned_draw_steps(job))
    assert np.array_equal(all_steps(tr), planned_steps(job))


def test_resume_yes_after_a_power_cut_is_refused(tmp_path: Path, quick_profile: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 16.2 on the real firmware: after a power cut `--resume --yes` refuses (exit 3),
    says to home first, and not one step pulse follows the refusal; after `fivebar home`
    the resume completes and every planned drawing step was drawn."""
    monkeypatch.chdir(tmp_path)
    drawing, _, job = compiled_copy(tmp_path, "simple.svg")
    trace = tmp_path / "pins.trace"
    cfg = ("--config", str(quick_profile))
    code, out = run("plot", str(drawing), "--port",
                    f"fivebar-sim://?machine=pc&trace={trace}&power_cut_after=16", "--laser",
                    "--yes", *cfg)
    assert code == 3 and "position unknown" in out, out
    machine = simport.machine("pc")
    before = settled_trace(machine)
    assert not laser_on_at_end(before)
    code, out = run("plot", str(drawing), "--port", "fivebar-sim://?machine=pc", "--laser",
                    "--yes", "--resume", *cfg)
    assert code == 3, out
    assert "lost power" in out and "fivebar home --port fivebar-sim://" in out, out
    after = settled_trace(machine)
    assert np.array_equal(all_steps(after), all_steps(before))  # nothing moved
    assert not laser_on_at_end(after)
    assert resume_path(drawing).exists()
    # The arms stopped mid-job: a person brings them home (here: the emulator's count is the
    # physical pose, so jog them back) and confirms with `fivebar home`.
    a = after.positions("A")[-1][1] if after.positions("A") else 0
    b = after.positions("B")[-1][1] if after.positions("B") else 0
    for motor, steps in (("A", -a), ("B", -b)):
        if steps:
            code, out = run("jog", "--port", "fivebar-sim://?machine=pc", "--motor", motor,
                            "--steps", str(steps), *cfg)
            assert code == 0, out
    code, out = run("home", "--port", "fivebar-sim://?machine=pc", "--yes", *cfg)
    assert code == 0, out
    code, out = run("plot", str(drawing), "--port", "fivebar-sim://?machine=pc", "--laser",
                    "--yes", "--resume", *cfg)
    assert code == 0, out
    machine.stop()
    tr = read_trace(trace)
    assert not laser_on_at_end(tr)
    assert np.all(laser_steps(tr) >= planned_draw_steps(job))  # nothing lost
