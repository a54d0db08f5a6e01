"""The firmware's stack never comes within 32 bytes of the static RAM, on every kind of job.

Each job (benchmarks/stack.py: G6 segments at 1 Mbaud, a raster on the default profile whose
G7 blocks run on the step interrupt's C path with the pixel interrupt nested in it, a raster
on configs/raster-fast.toml, a pen-servo drawing, the servo build, a raster under line noise)
runs the real firmware in simavr with the harness's profile on (`fivebar-sim://?stack=FILE`,
fbsim -P), which records the lowest stack pointer instruction by instruction; the headroom is
that less avr-nm's `_end`, both read from the files the toolchain and the harness wrote.

Why 32: the deepest point a run reaches depends on where the interrupts happen to land, so a
run can miss the worst coincidence by one interrupt frame.  The deepest code the C path runs
with interrupts enabled is mo_event() (event_px_nested(), board_avr_step.c), and there only
the pixel interrupt (TIMER1_COMPB) can come in; its frame, from the disassembly
(`avr-objdump -d build/fivebar.elf`, __vector_12): the return address 2 bytes, 22 saved
registers, 4 bytes of locals, 2 more for its call of advance(): 30 bytes.  32 leaves room for
it on top of any measured point, plus the one byte by which the figure errs low
(devices/simstack.py) and one spare.  The figures can fail: before the C form was prepared
outside the fast attempt's frame (fb_motion.c mo_prepare_fast) and px_start/fast_start left
the C path's frame (board_avr_step.c), the default profile's raster and the pen servo
measured 30 and the raster under noise 0 to 30 (firmware/README.md "The stack").
"""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import stack
from fivebar_host.devices.sim import toolchain_missing

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")


def test_g6_segments_at_1mbaud(tmp_path: Path) -> None:
    depth, what = stack.g6_job(tmp_path, 600)
    assert depth.ram_end > 0x100 and depth.min_sp <= 0x8FF - 64, depth  # a real run
    assert depth.headroom >= stack.MIN_HEADROOM, (depth, what)
    # the harness kept the stack's bytes there: their return addresses lead back to main
    assert "main" in depth.chain and depth.chain.index("main") > 0, depth


@pytest.mark.parametrize("job", sorted(stack.JOBS))
def test_job_headroom(tmp_path: Path, job: str) -> None:
    depth, what = stack.JOBS[job](tmp_path)
    assert depth.min_sp <= 0x8FF - 64, depth  # the run really moved the stack
    assert depth.headroom >= stack.MIN_HEADROOM, (depth, what)
    if job == "raster-noise":
        assert not what.endswith(" 0 resends"), what  # the noise really damaged lines


def test_stack_option_refuses_an_unwritable_place(tmp_path: Path) -> None:
    from fivebar_host.devices.simport import parse_sim_url

    for bad in ("", str(tmp_path), str(tmp_path / "no" / "such" / "x.txt")):
        with pytest.raises(ValueError, match="stack must be a file to write"):
            parse_sim_url(f"fivebar-sim://?stack={bad}")
    assert parse_sim_url(f"fivebar-sim://?stack={tmp_path / 'p.txt'}").stack == tmp_path / "p.txt"
