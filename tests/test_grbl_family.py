"""`--controller grbl` on GRBL's relatives (docs/grbl.md "grblHAL and FluidNC"): the dialect
is found from the banner, the board's settings are read its way (grblHAL: `$$` with its own
numbers too; FluidNC: `$/axes/...` configuration items) and checked; `fivebar plot
examples/fivebar_text.svg` draws exactly on each model; a board at its defaults is refused
with every mismatch listed and nothing moves."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import serial
from click.testing import CliRunner

from fivebar_host.cli.common import main
from fivebar_host.compile.job import compile_job
from fivebar_host.compile.model import CompileOptions
from fivebar_host.config import load_profile
from fivebar_host.controllers.grbl.dialects import FLUIDNC, GRBL, GRBLHAL, detect
from fivebar_host.devices import grblfamily, grblmock, urls
from fivebar_host.report.text.executed import executed_path

ROOT = Path(__file__).resolve().parents[1]
TEXT = ROOT / "examples" / "fivebar_text.svg"
FAMILY = [grblfamily.GRBLHAL_SCHEME, grblfamily.FLUIDNC_SCHEME]


@pytest.fixture(autouse=True)
def _boards() -> None:
    urls.register()
    grblmock.forget_boards()


def _cli(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args))
    return res.exit_code, res.output


def _configure(scheme: str, name: str) -> None:
    """Send `fivebar grbl-settings` (FluidNC: `--fluidnc`) to the board line by line."""
    extra = ["--fluidnc"] if scheme == grblfamily.FLUIDNC_SCHEME else []
    code, out = _cli("grbl-settings", *extra)
    assert code == 0
    port = serial.serial_for_url(f"{scheme}://{name}", timeout=1.0)
    try:
        port.readline(), port.readline()  # banner
        for line in out.splitlines():
            if line.startswith(";"):
                continue
            port.write((line + "\n").encode())
            assert port.readline() == b"ok\r\n", line
    finally:
        port.close()


def test_the_banner_names_the_dialect() -> None:
    assert detect("Grbl 1.1h ['$' for help]") == GRBL
    assert detect("GrblHAL 1.1f ['$' or '$HELP' for help]") == GRBLHAL
    assert detect("Grbl 3.7 [FluidNC v3.7.17 (noradio) '$' for help]") == FLUIDNC
    assert detect("Grbl 0.9j ['$' for help]") is None


@pytest.mark.parametrize("scheme", FAMILY)
def test_plot_draws_exactly_on_each_relative(scheme: str) -> None:
    _configure(scheme, "plot")
    code, out = _cli("plot", str(TEXT), "--controller", "grbl", "--laser", "--yes",
                     "--port", f"{scheme}://plot?speed=50")
    assert code == 0, out
    board = grblfamily.board(scheme, "plot")
    assert board.overflow == 0
    prof = load_profile()
    job = compile_job(TEXT, prof, CompileOptions())
    t, track, laser = grblmock.executed_steps(board.blocks)
    ex = executed_path(job, prof, t, track)
    bound = job.tolerance_mm + job.step_quantum_mm
    print(f"{scheme}: max deviation {ex.max_deviation_mm:.4f} mm (bound {bound:.4f} mm), "
          f"{ex.segments_completed}/{job.n_segments} segments")
    assert ex.segments_completed == job.n_segments
    assert 0.0 < ex.max_deviation_mm <= bound
    on_draw = job.draw[np.maximum(ex.segment, 0)] & (ex.segment >= 0)
    assert not (laser & ~on_draw).any()
    if scheme == grblfamily.FLUIDNC_SCHEME:
        assert "FluidNC: check by hand" in out  # what has no single configuration item


@pytest.mark.parametrize(("scheme", "expected"), [
    (grblfamily.GRBLHAL_SCHEME, ["$100: board 250, needed 35.555556",
                                 "$32: board 0, needed 1", "$120: board 10, needed 3437.747"]),
    (grblfamily.FLUIDNC_SCHEME, ["/axes/x/steps_per_mm: board 80, needed 35.555556",
                                 "/axes/y/max_rate_mm_per_min: board 500, needed 20626.481",
                                 "/axes/x/acceleration_mm_per_sec2: board 10, needed"]),
])
def test_a_board_at_its_defaults_is_refused_listing_each_mismatch(scheme: str,
                                                                  expected: list[str]) -> None:
    grblfamily.board(scheme, "stock")
    code, out = _cli("plot", str(TEXT), "--controller", "grbl", "--laser", "--yes",
                     "--port", f"{scheme}://stock?speed=50")
    assert code == 3, out
    for part in expected:
        assert part in out, (part, out)
    assert grblfamily.board(scheme, "stock").blocks == []


def test_grblhal_homing_mask_is_compared_by_its_enable_bit() -> None:
    _configure(grblfamily.GRBLHAL_SCHEME, "mask")
    b = grblfamily.board(grblfamily.GRBLHAL_SCHEME, "mask")
    b.settings[22] = 2.0  # grblHAL: bit 1 (homing on startup) without bit 0: homing off
    code, out = _cli("status", "--controller", "grbl",
                     "--port", f"{grblfamily.GRBLHAL_SCHEME}://mask?speed=50")
    assert code == 0, out
