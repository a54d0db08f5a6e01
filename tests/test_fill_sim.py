"""The hatch at the paper, end to end on the real firmware in simavr: the example logo plotted
with `--hatch 0.4mm --hiding`, its executed pen points measured from the step pulses through
forward kinematics (`fivebar plot --port fivebar-sim://` writes them beside the preview):
the spacing between neighbouring hatch lines is the nominal one within 1 % (mean and
median; pair by pair the step quantum, 7 % of the spacing, spreads it), and no executed
hatch segment leaves its element's fill region by more than the tolerance + step quantum
(`benchmarks/fillspacing.py`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from benchmarks.fillspacing import spacing_figures
from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions
from fivebar_host.config import load_profile
from fivebar_host.devices.sim import toolchain_missing

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")


def test_hatch_spacing_at_the_paper_from_the_executed_steps(tmp_path: Path) -> None:
    profile = ROOT / "configs" / "pen-servo.toml"
    file = ROOT / "examples" / "fill_logo.svg"
    preview = tmp_path / "p.png"
    res = CliRunner().invoke(main, ["plot", str(file), "--hatch", "0.4mm", "--hiding",
                                    "--config", str(profile), "--port", "fivebar-sim://",
                                    "--yes", "--preview", str(preview)])
    assert res.exit_code == 0, res.output
    sf = spacing_figures(preview.with_name("p.executed.csv"), file,
                         CompileOptions(hatch_mm=0.4, hiding=True), load_profile(profile))
    rel = sf.gaps / sf.nominal - 1.0
    print(f"{sf.gaps.size} pairs: mean {100 * np.mean(rel):+.3f} %, median "
          f"{100 * np.median(rel):+.3f} %, 5–95 % {100 * np.percentile(rel, 5):+.2f} … "
          f"{100 * np.percentile(rel, 95):+.2f} %; outside {sf.outside} of {sf.segments}")
    assert sf.gaps.size > 100
    assert abs(np.mean(rel)) < 0.01 and abs(np.median(rel)) < 0.01
    assert np.percentile(np.abs(rel), 90) < 0.05  # the step quantum's spread, bounded
    assert sf.outside == 0 and sf.segments > 1000
