"""A raster end to end on the real firmware in simavr: `fivebar plot IMAGE --laser --port
fivebar-sim://` prints the `raster:` line after `done:`, and the burn rebuilt from the pin
trace (`raster.dose`) has every pixel in place, no laser-on step outside the image, and a
flat grey patch's dose flat (no timing assertions: the emulator runs unthrottled)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from fivebar_host.cli import main
from fivebar_host.devices.sim import toolchain_missing

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")

LINE = re.compile(r"^raster: (\d+) px in [\d.]+ s = \d+ px/s, \d+ underruns; burned image from "
                  r"the step pulses: pixel placement max ([\d.]+) mm, power changes within "
                  r"[\d.]+ µs of the pixel boundaries, laser on outside the image (\d+) steps$",
                  re.MULTILINE)


def test_grey_patch_burned_in_place_and_flat(tmp_path: Path) -> None:
    img = tmp_path / "grey.png"
    a = np.full((8, 30), 128, dtype=np.uint8)
    a[:, 10:20] = 64  # a darker band: power changes inside the lines
    Image.fromarray(a).save(img)
    pv = tmp_path / "pv.png"
    r = CliRunner().invoke(main, ["plot", str(img), "--laser", "--yes", "--width", "6mm",
                                  "--port", "fivebar-sim://", "--preview", str(pv)])
    assert r.exit_code == 0, r.output
    assert "done:" in r.output
    m = LINE.search(r.output)
    assert m is not None, r.output
    assert int(m[1]) == 8 * 30
    assert float(m[2]) <= 0.05
    assert int(m[3]) == 0
    dose = np.load(pv.with_name("pv.burned.npz"))["dose"]
    target = np.where(a == 128, 127.5, 191.25)  # grayscale: 255 · darkness
    inner = (dose / target)[:, 1:-1]  # the end cells share edge steps with the overscan
    assert float(inner.mean()) == pytest.approx(1.0, abs=0.02)
    assert float(inner.max() - inner.min()) <= 0.05  # the 5 % goal


def test_fast_profile_changes_on_time(tmp_path: Path) -> None:
    """configs/raster-fast.toml: scans start on the C path (slow ramp pieces) and cruise on
    the fast path, a change at every pixel.  The changes found in the pin trace (the
    firmware's traced power writes) against the pen's crossings fitted to the step pulses:
    the issue's 20 µs.  Before the timeline followed its blocks' form, a third of the
    changes came ~7 µs late (99th percentile 11.7 µs, the first pixels 21.6 µs); before
    the fast path's windows, 27 µs.  An underrun (a busy machine starves the unthrottled
    emulator) restarts a scan late, so then only the percentile is held."""
    rng = np.random.default_rng(1)
    img = tmp_path / "noise.png"
    Image.fromarray(rng.integers(0, 256, (24, 120), dtype=np.uint8)).save(img)
    pv = tmp_path / "pv.png"
    cfg = Path(__file__).resolve().parents[1] / "configs" / "raster-fast.toml"
    r = CliRunner().invoke(main, ["plot", str(img), "--laser", "--yes", "--width", "12mm",
                                  "--config", str(cfg), "--image-mode", "floyd",
                                  "--port", "fivebar-sim://", "--preview", str(pv)])
    assert r.exit_code == 0, r.output
    m = re.search(r"(\d+) underruns", r.output)
    assert m is not None, r.output
    dt = np.abs(np.load(pv.with_name("pv.burned.npz"))["dt_us"])
    assert dt.size > 1000
    assert float(np.percentile(dt, 99)) <= 10.0
    if int(m[1]) == 0:
        assert float(dt.max()) <= 20.0
