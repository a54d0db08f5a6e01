"""`--fill scan` end to end on the real firmware in simavr: the `raster:` line after
`done:`, every pixel of the filled shapes burned in place and no laser-on step outside the
image (the burn rebuilt from the pin trace, `raster.dose`; no timing assertions)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.devices.sim import toolchain_missing

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")

LINE = re.compile(r"^raster: (\d+) px in [\d.]+ s = \d+ px/s, \d+ underruns; burned image from "
                  r"the step pulses: pixel placement max ([\d.]+) mm, power changes within "
                  r"[\d.]+ µs of the pixel boundaries, laser on outside the image (\d+) steps$",
                  re.MULTILINE)


def test_even_odd_star_scan_filled_on_the_emulator(tmp_path: Path) -> None:
    p = tmp_path / "star.svg"
    p.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="8mm" height="8mm" '
                 'viewBox="0 0 100 100"><path d="M50 5 L76.5 86.5 L7.2 36.1 L92.8 36.1 '
                 'L23.5 86.5 Z" fill="black" stroke="black" fill-rule="evenodd"/></svg>')
    r = CliRunner().invoke(main, ["plot", str(p), "--laser", "--fill", "scan", "--yes",
                                  "--line-interval", "0.25mm", "--port", "fivebar-sim://",
                                  "--preview", str(tmp_path / "pv.png")])
    assert r.exit_code == 0, r.output
    assert "done:" in r.output
    assert "1 stroked element not engraved" in r.output
    m = LINE.search(r.output)
    assert m is not None, r.output
    assert int(m[1]) > 0
    assert float(m[2]) <= 0.05
    assert int(m[3]) == 0
