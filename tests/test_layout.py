"""Layout: --origin/--scale/--rotate map exactly; default centring and --fit land inside the
largest singularity-safe rectangle of the working mode; bad combinations are refused."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.config import load_profile
from fivebar_host.toolpath.geometry import flatten
from fivebar_host.toolpath.layout import place
from fivebar_host.toolpath.svg import read_svg
from kinematics.workspace import point_safety

PROF = load_profile()
KIN = PROF.kinematics
ARGS = (PROF.geometry, "+-", KIN.min_type1_margin_rad, KIN.min_type2_margin_rad,
        PROF.motors.limits_rad)
SVG = (b'<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="20mm" '
       b'viewBox="0 0 40 20"><rect x="0" y="0" width="40" height="20"/>'
       b'<circle cx="10" cy="10" r="5"/></svg>')


def test_origin_scale_rotate_exact() -> None:
    d = read_svg(SVG)
    pl = place(d, *ARGS, origin_mm=(10.0, 100.0), scale=0.5, rotate_deg=90.0)
    # drawing (40, 0) (page bottom-right) → scaled (20, 0) → rotated (0, 20) → + origin
    assert np.allclose(pl.to_machine(np.array([[40.0, 0.0]])), [[10.0, 120.0]])
    assert np.allclose(pl.to_drawing(pl.to_machine(np.array([[3.0, 7.0]]))), [[3.0, 7.0]])
    w, h = pl.size_mm
    assert (w, h) == pytest.approx((10.0, 20.0), abs=1e-3)


def test_default_centres_in_safe_rect_and_every_point_is_safe() -> None:
    d = read_svg(SVG)
    pl = place(d, *ARGS)
    assert pl.area is not None and pl.how == "centred"
    bx = pl.machine_bbox
    assert ((bx[0] + bx[2]) / 2, (bx[1] + bx[3]) / 2) == pytest.approx(pl.area.center, abs=1e-9)
    pts = flatten(d.transformed(pl.matrix, pl.offset), 0.01).points
    assert point_safety(PROF.geometry, "+-", pts, *ARGS[2:]).all()


def test_fit_fills_the_rectangle() -> None:
    d = read_svg(SVG)
    pl = place(d, *ARGS, fit=True, rotate_deg=30.0)
    assert pl.area is not None
    w, h = pl.size_mm
    assert w <= pl.area.width + 1e-6 and h <= pl.area.height + 1e-6
    assert max(w / pl.area.width, h / pl.area.height) == pytest.approx(1.0, abs=1e-6)
    pts = flatten(d.transformed(pl.matrix, pl.offset), 0.01).points
    assert point_safety(PROF.geometry, "+-", pts, *ARGS[2:]).all()
    assert math.isclose(pl.rotate_deg, 30.0)


@pytest.mark.parametrize(("kw", "msg"), [
    ({"fit": True, "scale": 2.0}, "--fit and --scale"),
    ({"fit": True, "origin_mm": (0.0, 0.0)}, "--fit and --origin"),
    ({"scale": -1.0}, "--scale must be a positive"),
    ({"rotate_deg": math.inf}, "--rotate must be"),
])
def test_bad_combinations(kw: dict[str, object], msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        place(read_svg(SVG), *ARGS, **kw)  # type: ignore[arg-type]


# --------------------------------------------------------------------- G-code placement
GCODE_SQUARE = b"G21 G90\nG0 X5 Y95\nG1 X35 Y95\nG1 X35 Y125\nG1 X5 Y125\nG1 X5 Y95\n"


def test_gcode_is_drawn_at_its_own_coordinates_by_default() -> None:
    from fivebar_host.toolpath.gcode import read_gcode
    d = read_gcode(GCODE_SQUARE, "sq.gcode")
    pl = place(d, *ARGS)
    assert pl.how == "as written" and pl.area is None
    assert np.allclose(pl.to_machine(np.array([[5.0, 95.0], [35.0, 125.0]])),
                       [[5.0, 95.0], [35.0, 125.0]])
    # --fit and --origin still place it elsewhere
    assert place(d, *ARGS, fit=True).how == "fit"
    po = place(d, *ARGS, origin_mm=(1.0, 2.0))
    assert np.allclose(po.to_machine(np.array([[5.0, 95.0]])), [[6.0, 97.0]])
    # an SVG is still centred
    assert place(read_svg(SVG), *ARGS).how == "centred"


def test_gcode_out_of_reach_is_refused_naming_point_line_and_remedy(tmp_path: Path) -> None:
    from fivebar_host.compile import CompileOptions, compile_job
    from fivebar_host.errors import FivebarError, JobError
    f = tmp_path / "corner.gcode"
    f.write_bytes(b"G21 G90\nG0 X0 Y0\nG1 X5 Y0\nG1 X5 Y5\n")
    with pytest.raises(JobError) as ei:
        compile_job(f, PROF)
    msg = str(ei.value)
    assert isinstance(ei.value, FivebarError)
    assert "corner.gcode:3" in msg and "machine (0.000, 0.000) mm" in msg
    assert "drawn at its own coordinates" in msg and "use --fit or --origin" in msg
    job = compile_job(f, PROF, CompileOptions(fit=True))
    assert job.placement.how == "fit" and job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
    job = compile_job(f, PROF, CompileOptions(origin_mm=(10.0, 100.0)))
    assert job.placement.how == "origin"
