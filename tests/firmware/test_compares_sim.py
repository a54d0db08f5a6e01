"""No compare of Timer1 is ever armed behind the timer, on every kind of job.

The firmware places each step (OCR1A) and each pixel change (OCR1B) by a compare of the
free-running timer; one written at or behind the count waits a whole timer period, 4.1 ms
(devices/simtimers.py).  The harness logs every write with the count at that instant
(`fivebar-sim://?timers=FILE`, fbsim -D), so each job here is checked write by write: a
drawing, a raster on the default profile (its G7 blocks on the step interrupt's C path, the
pixel interrupt nested in it), a raster on configs/raster-fast.toml (the fast path's pixel
windows), and holds at random instants (test_hold_timeline_sim.py: a resume re-armed its
compares 64 cycles on, which a step due at the hold had already passed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from fivebar_host.cli import main as cli_main
from fivebar_host.devices.sim import toolchain_missing
from fivebar_host.devices.simtimers import late_compares, read_writes
from fivebar_host.devices.simtrace import TraceError

needs_emulator = pytest.mark.skipif(toolchain_missing() is not None,
                                    reason=f"emulator unavailable: {toolchain_missing()}")

ROOT = Path(__file__).resolve().parents[2]


def _grey(path: Path) -> Path:
    """An 8×30 grey patch with a darker band: power changes inside every line."""
    a = np.full((8, 30), 128, dtype=np.uint8)
    a[:, 10:20] = 64
    Image.fromarray(a).save(path)
    return path


def _args(job: str, tmp: Path) -> list[str]:
    if job == "drawing":
        return [str(ROOT / "examples" / "simple.svg")]
    config = "default.toml" if job == "raster-default" else "raster-fast.toml"
    return [str(_grey(tmp / "grey.png")), "--laser", "--width", "6mm", "--config",
            str(ROOT / "configs" / config)]


@needs_emulator
@pytest.mark.parametrize("job", ["drawing", "raster-default", "raster-fast"])
def test_every_compare_is_armed_ahead_of_the_timer(tmp_path: Path, job: str) -> None:
    log = tmp_path / "timers.log"
    res = CliRunner().invoke(cli_main, [
        "plot", *_args(job, tmp_path), "--yes", "--preview", str(tmp_path / "p.png"),
        "--port", f"fivebar-sim://?state=off&timers={log}"])
    assert res.exit_code == 0, res.output
    writes = read_writes(log)
    units = {w.register for w in writes}
    assert units == ({"OCR1A"} if job == "drawing" else {"OCR1A", "OCR1B"}), units
    late = late_compares(log)
    assert not late, f"{len(late)} of {len(writes)} compares armed behind the timer: {late[:5]}"


def test_the_log_reader_counts_leads_across_the_wrap_and_names_a_bad_line(
        tmp_path: Path) -> None:
    log = tmp_path / "t.log"
    log.write_text("10 r 5 3\n20 w 5 65530\n30 b 100 100\n40 w 65530 5\n")
    assert [w.lead for w in read_writes(log)] == [11, 0, -11]
    assert [w.cycle for w in late_compares(log)] == [30, 40]
    log.write_text("10 w 5 3\n20 x 5 3\n")
    with pytest.raises(TraceError, match=r"t.log:2: '20 x 5 3'"):
        read_writes(log)
