"""`--fill scan` (docs/fill.md): a drawing's filled shapes burned by scanlines through the
raster machinery. Checked against regions built here from the SVGs' own coordinates (not
through the fill stage): the burned cells' area within perimeter × half a cell of the exact
area, every lit cell's centre inside, scanlines only on rows with lit cells, the vector
job's placement, the refusals, and the dry run's report and strokes note."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import shapely
from click.testing import CliRunner
from shapely.geometry.base import BaseGeometry

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, Job, compile_job, read_drawing
from fivebar_host.config import load_profile
from fivebar_host.errors import JobError, OptionError
from fivebar_host.options import compile_values, defaults
from fivebar_host.raster.fill import compile_fill_scan, place_fill

ROOT = Path(__file__).resolve().parents[1]
CELL = 0.2  # mm: --line-interval of these tests

STAR = [(50, 5), (76.5, 86.5), (7.2, 36.1), (92.8, 36.1), (23.5, 86.5)]


def _square(x0: float, y0: float, x1: float, y1: float) -> shapely.Polygon:
    return shapely.box(x0, y0, x1, y1)


def _star_region() -> BaseGeometry:
    """The even-odd pentagram: the star's points without its inner pentagon."""
    ring = shapely.LineString([*STAR, STAR[0]])
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(shapely.union_all(
        [ring]))))
    # even-odd: a face is filled when a ray from its inside crosses the ring an odd number
    # of times; the inner pentagon is the face touching no vertex of the star
    tips = shapely.MultiPoint(STAR)
    return shapely.union_all([f for f in faces if f.intersects(tips)])


#: name → (SVG body in a 100×100 viewBox, the region it paints in SVG units, its bbox)
CASES: dict[str, tuple[str, BaseGeometry, tuple[float, float, float, float]]] = {
    "star_evenodd": (
        '<path d="M50 5 L76.5 86.5 L7.2 36.1 L92.8 36.1 L23.5 86.5 Z" fill="black" '
        'fill-rule="evenodd"/>', _star_region(), (7.2, 5, 92.8, 86.5)),
    "nested_holes": (
        '<path d="M5 5 H95 V95 H5 Z M15 15 V85 H85 V15 Z M25 25 H45 V45 H25 Z '
        'M55 55 H75 V75 H55 Z" fill="black"/>',
        shapely.union_all([_square(5, 5, 95, 95).difference(_square(15, 15, 85, 85)),
                           _square(25, 25, 45, 45), _square(55, 55, 75, 75)]),
        (5, 5, 95, 95)),
    "white_over_black": (
        '<rect x="10" y="10" width="80" height="80" fill="#111"/>'
        '<rect x="30" y="20" width="40" height="40" fill="white"/>'
        '<rect x="40" y="50" width="20" height="30" fill="black" stroke="red"/>'
        '<path d="M10 95 H90" stroke="black" fill="none"/>',
        _square(10, 10, 90, 90).difference(_square(30, 20, 70, 60))
        .union(_square(40, 50, 60, 80)), (10, 10, 90, 95)),
}


def _svg(tmp_path: Path, name: str) -> Path:
    p = tmp_path / f"{name}.svg"
    p.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="40mm" '
                 f'viewBox="0 0 100 100">{CASES[name][0]}</svg>')
    return p


def _values(**kw: Any) -> dict[str, Any]:
    v = defaults()
    v.update(laser=True, fill="scan", line_interval_mm=CELL)
    v.update(kw)
    return v


def _machine_region(job: Job, name: str) -> BaseGeometry:
    """The case's region mapped SVG units → machine mm by the job's placement box (the
    drawing's bbox there; SVG y down, machine y up; no rotation)."""
    _, region, (bx0, by0, bx1, by1) = CASES[name]
    x0, y0, x1, y1 = job.placement.machine_bbox
    k = (x1 - x0) / (bx1 - bx0)
    assert (y1 - y0) / (by1 - by0) == pytest.approx(k, rel=1e-6)
    return shapely.transform(region, lambda xy: np.stack(
        (x0 + k * (xy[:, 0] - bx0), y1 - k * (xy[:, 1] - by0)), axis=1))


@pytest.mark.parametrize("angle", [0.0, 30.0])
@pytest.mark.parametrize("name", sorted(CASES))
def test_burned_cells_are_the_painted_region(tmp_path: Path, name: str, angle: float) -> None:
    prof = load_profile(None)
    job = compile_fill_scan(_svg(tmp_path, name), prof, _values(scan_angle_deg=angle))
    r = job.raster
    assert r is not None
    ref = _machine_region(job, name)
    lit = r.target > 0
    assert r.pitch_mm == r.interval_mm == CELL
    area = float(lit.sum()) * CELL * CELL
    assert abs(area - ref.area) <= ref.length * CELL / 2, (area, ref.area)
    c = r.cell_centres()[lit]
    assert shapely.contains_xy(ref.buffer(1e-6), c[:, 0], c[:, 1]).all()
    # the scanlines: exactly the rows with lit cells, each from its first to last lit cell
    rows = {s.row for s in r.lines}
    assert rows == set(np.flatnonzero(lit.any(axis=1)).tolist())
    for s in r.lines:
        assert lit[s.row, s.c0] and lit[s.row, s.c1 - 1]
    assert len({s.sign for s in r.lines}) == 2  # bidirectional by default


def test_placement_is_the_vector_jobs(tmp_path: Path) -> None:
    prof = load_profile(None)
    p = _svg(tmp_path, "white_over_black")
    for extra in ({}, {"scale": 0.5}, {"fit": True}, {"origin_mm": (0.0, 95.0)}):
        v = _values(**extra)
        vec = compile_job(p, prof, CompileOptions(**compile_values(v)))
        if extra.get("fit"):  # the whole safe area: the overscan leaves the reach
            pl, _ = place_fill(read_drawing(p, (), None, prof), prof, v, vec.mode)
        else:
            pl = compile_fill_scan(p, prof, v).placement
        np.testing.assert_allclose(pl.matrix, vec.placement.matrix)
        np.testing.assert_allclose(pl.offset, vec.placement.offset)


def test_one_way_and_passes(tmp_path: Path) -> None:
    prof = load_profile(None)
    job = compile_fill_scan(_svg(tmp_path, "nested_holes"), prof,
                            _values(one_way=True, passes=2, line_interval_mm=0.5))
    r = job.raster
    assert r is not None
    assert {s.sign for s in r.lines} == {1}
    assert {s.pass_no for s in r.lines} == {0, 1}


def test_refusals(tmp_path: Path) -> None:
    prof = load_profile(None)
    p = _svg(tmp_path, "star_evenodd")
    with pytest.raises(OptionError, match="--laser"):
        compile_fill_scan(p, prof, _values(laser=False))
    with pytest.raises(OptionError, match="--hatch"):
        compile_fill_scan(p, prof, _values(hatch_mm=0.4))
    with pytest.raises(OptionError, match="G-code"):
        compile_fill_scan(ROOT / "examples" / "square.gcode", prof, _values())
    outline = tmp_path / "outline.svg"
    outline.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="40mm" '
                       'viewBox="0 0 100 100"><path d="M10 10 H90 V90" fill="none" '
                       'stroke="black"/></svg>')
    with pytest.raises(JobError) as ei:
        compile_fill_scan(outline, prof, _values())
    assert ei.value.reason == "nothing_filled"
    servo = load_profile(ROOT / "configs" / "plotclock.toml")
    with pytest.raises(JobError) as ei:
        compile_fill_scan(p, servo, _values())
    assert ei.value.reason == "servo_joints"
    for args in (["--fill", "scan"], ["--laser", "--fill", "scan", "--hatch", "0.4mm"]):
        res = CliRunner().invoke(main, ["plot", str(p), "--dry-run", *args])
        assert res.exit_code == 2, res.output
        assert "--fill" in res.output


def test_dry_run_prints_the_raster_report_and_the_strokes_note(tmp_path: Path) -> None:
    p = _svg(tmp_path, "white_over_black")
    res = CliRunner().invoke(main, ["plot", str(p), "--laser", "--fill", "scan", "--dry-run",
                                    "--line-interval", "0.25mm", "--preview",
                                    str(tmp_path / "pv.png")])
    assert res.exit_code == 0, res.output
    assert "scanlines" in res.output and "burn" in res.output
    # the stroked rect and the stroke-only line are left out, and said so
    assert "2 stroked elements not engraved" in res.output


def test_the_daemon_compiles_a_scan_fill(tmp_path: Path) -> None:
    from fivebar_host.server.jobs import JobOptions, SubmitError, compile_upload

    prof = load_profile(None)
    data = _svg(tmp_path, "star_evenodd").read_bytes()
    opts = JobOptions.from_values({"laser": True, "fill": "scan", "line_interval_mm": 0.5})
    job = compile_upload(data, "star.svg", opts, prof).job
    assert job.raster is not None and (job.raster.target > 0).any()
    with pytest.raises(SubmitError) as ei:
        compile_upload(data, "star.svg", JobOptions.from_values({"fill": "scan"}), prof)
    assert ei.value.code == "bad_option"
