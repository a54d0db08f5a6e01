"""Backlash on the emulated firmware: `fivebar-sim://?backlash=8,8` is a machine with 8 steps
of slack per motor; the executed-path report, measured from the firmware's step pulses, puts
the square and the circle within the bound with `[motors] backlash_steps = [8, 8]` and fails
the run (exit 3) without."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.devices.sim import toolchain_missing

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")

SQUARE = Path(__file__).resolve().parent.parent / "examples" / "square.gcode"


def _plot(tmp_path: Path, lash: int) -> tuple[int, float, float, str]:
    cfg = tmp_path / f"lash{lash}.toml"
    cfg.write_text(f"[motors]\nbacklash_steps = [{lash}, {lash}]\n")
    res = CliRunner().invoke(main, [
        "plot", str(SQUARE), "--config", str(cfg), "--port",
        "fivebar-sim://?backlash=8,8&state=off", "--yes", "--preview",
        str(tmp_path / f"p{lash}.png")])
    line = next(ln for ln in res.output.splitlines() if ln.startswith("executed path"))
    dev = float(line.split("max deviation ")[1].split(" mm")[0])
    bound = float(line.split("(bound ")[1].split(" +")[0]) + float(
        line.split("step quantum ")[1].split(" mm")[0])
    return res.exit_code, dev, bound, res.output


def test_emulated_backlash_within_the_bound_only_with_compensation(tmp_path: Path) -> None:
    code, dev, bound, out = _plot(tmp_path, 8)
    assert code == 0 and dev <= bound, out
    assert "backlash= machine" in out
    code, dev, bound, out = _plot(tmp_path, 0)
    assert code == 3 and dev > 2 * bound, out
    assert "backlash_steps" in out  # the error names the cure
