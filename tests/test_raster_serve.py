"""The daemon takes an image like the CLI: its raster options (declared once in
`fivebar_host.options`) reach `compile_raster`, the dry run answers the raster report and
the burn's preview, and a bad image is the CLI's named error, nothing compiled."""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest
from PIL import Image

from fivebar_host.config import load_profile
from fivebar_host.options import parse_query
from fivebar_host.server.dryrun import dry_run_upload
from fivebar_host.server.jobs import JobOptions, SubmitError, compile_upload


def _png(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(a.astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def test_image_upload_compiles_a_raster_with_its_options() -> None:
    prof = load_profile(None)
    data = _png(np.tile(np.linspace(0, 255, 30), (8, 1)))
    values = parse_query([("laser", "true"), ("width", "6mm"), ("image_mode", "threshold"),
                          ("power_max", "120"), ("passes", "2")])
    opts = JobOptions.from_values(values)
    job = compile_upload(data, "logo.png", opts, prof).job
    r = job.raster
    assert r is not None
    assert r.pitch_mm == pytest.approx(6.0 / 30)
    assert set(np.unique(r.target).tolist()) == {0, 120}
    assert {s.pass_no for s in r.lines} == {0, 1}
    out = dry_run_upload(data, "logo.png", opts, prof)
    assert any(line.startswith("burn ") for line in out.report)
    assert base64.b64decode(out.preview_png)[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_image_upload_is_an_input_error() -> None:
    prof = load_profile(None)
    opts = JobOptions.from_values(parse_query([("laser", "true")]))
    with pytest.raises(SubmitError) as ei:
        compile_upload(_png(np.zeros((4, 4)))[:30], "cut.png", opts, prof)
    assert ei.value.code == "input_error" and "cut.png" in str(ei.value)
