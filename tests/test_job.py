"""Job compilation end to end: bundled examples within tolerance + one step quantum when
measured from the quantised steps, geometry unchanged by ordering, refusals that name the path,
the source line and the point in both frames, --mode auto, steps and durations."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, compile_job, deviations, encode_lines
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import load_profile
from fivebar_host.errors import JobError
from fivebar_host.toolpath.svg import read_svg

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
CONFIGS = Path(__file__).resolve().parent.parent / "configs"
PROF = load_profile()
#: The default machine built in the other assembly mode (pen below the elbows).
UNDERSIDE = load_profile(CONFIGS / "underside.toml")


def svg_file(tmp_path: Path, body: str, w: float = 60, h: float = 30) -> Path:
    f = tmp_path / "d.svg"
    f.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" '
                 f'viewBox="0 0 {w} {h}">\n{body}\n</svg>\n')
    return f


@pytest.mark.parametrize("name", ["simple.svg", "fivebar_text.svg", "square.gcode"])
def test_examples_within_tolerance_plus_one_quantum(name: str) -> None:
    job = compile_job(EXAMPLES / name, PROF)
    assert job.mode == "+-"
    assert job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
    # a denser independent measurement (16 samples per segment) agrees
    dist, _ = deviations(job, PROF, samples=16)
    assert dist.max() <= job.tolerance_mm + job.step_quantum_mm
    # relative steps reproduce the absolute ones; the job starts and ends at home
    assert np.array_equal(np.cumsum(job.relative_steps, axis=0), job.steps[1:])
    assert job.steps[0].tolist() == [0, 0] and job.steps[-1].tolist() == [0, 0]
    # laser/pen only while drawing; durations positive integers
    assert (job.power[~job.draw] == 0).all() and (job.power[job.draw] > 0).all()
    assert job.duration_us.dtype.kind == "i" and (job.duration_us > 0).all()
    assert job.total_time_s > 0 and job.draw_length_mm > 0
    assert (np.degrees(job.min_margin_rad[:2]) >= 5.0 - 1e-9).all()
    assert math.degrees(job.min_margin_rad[2]) >= 15.0 - 1e-9


def test_ordering_keeps_geometry(tmp_path: Path) -> None:
    body = "".join(f'<path d="M{5 + 9 * i} {5 + (i % 3) * 8} l 6 2 l -2 5" stroke="k"/>'
                   for i in range(6))
    f = svg_file(tmp_path, body)
    job = compile_job(f, PROF)
    kept = compile_job(f, PROF, CompileOptions(keep_order=True))
    assert job.travel_after_mm <= job.travel_before_mm
    # the drawn geometry (requested segment end points, as unordered sets per path) is equal
    def drawn(j: object) -> set[tuple[float, ...]]:
        jj = j  # type: ignore[assignment]
        out: set[tuple[float, ...]] = set()
        for a, b in zip(jj.seg_ca, jj.seg_cb, strict=True):  # type: ignore[attr-defined]
            key = tuple(np.round(np.concatenate(sorted([a, b], key=tuple)), 9))
            out.add(key)
        return out

    assert drawn(job) == drawn(kept)
    assert job.draw_length_mm == pytest.approx(kept.draw_length_mm, rel=1e-12)


def test_unreachable_drawing_names_path_and_point(tmp_path: Path) -> None:
    f = svg_file(tmp_path, '<line x1="5" y1="5" x2="20" y2="5" stroke="k"/>\n'
                           '<line id="far" x1="5" y1="25" x2="200" y2="25" stroke="k"/>')
    with pytest.raises(JobError) as ei:
        compile_job(f, PROF, CompileOptions(origin_mm=(-10.0, 100.0), keep_order=True))
    e = ei.value
    assert e.where is not None and e.where.path_index == 1 and e.where.path_id == "far"
    assert e.where.source_line == 3
    mx, my = e.where.machine_xy  # type: ignore[misc]
    dx, dy = e.where.drawing_xy  # type: ignore[misc]
    assert (mx + 10.0, my - 100.0) == pytest.approx((dx, 30.0 - dy), abs=1e-9)
    assert dy == pytest.approx(25.0)  # SVG page coordinates, y down
    assert 'path #1 (id "far")' in str(e) and "machine (" in str(e) and "drawing (" in str(e)
    assert e.reason in ("reach", "joint_limit", "type1_margin", "type2_margin")


def test_too_big_drawing_says_size_and_available_area(tmp_path: Path) -> None:
    f = svg_file(tmp_path, '<rect x="0" y="0" width="200" height="100" stroke="k"/>',
                 w=200, h=100)
    with pytest.raises(JobError, match=r"the drawing is 200\.\d × 100\.\d mm; the largest "
                                       r"safe area of that shape in mode \+- is .*try --fit "
                                       r"or --scale 0\.\d+"):
        compile_job(f, PROF)
    job = compile_job(f, PROF, CompileOptions(fit=True))
    assert job.placement.scale < 0.5 and job.max_dev_mm <= 0.05 + job.step_quantum_mm


def test_too_close_to_singularity_is_refused(tmp_path: Path) -> None:
    # a line down the middle into the bottom of the +- safe region
    f = svg_file(tmp_path, '<line x1="10" y1="0" x2="10" y2="60" stroke="k"/>', w=20, h=60)
    with pytest.raises(JobError) as ei:
        compile_job(f, PROF, CompileOptions(origin_mm=(10.0, 40.0)))
    assert ei.value.reason in ("type1_margin", "type2_margin", "joint_limit")
    assert ei.value.where is not None and ei.value.where.machine_xy is not None


def test_gcode_error_names_source_line() -> None:
    g = EXAMPLES / "underside_machine_coords.gcode"
    with pytest.raises(JobError) as ei:
        compile_job(g, PROF, CompileOptions(origin_mm=(0.0, 0.0), mode="+-", keep_order=True))
    assert ei.value.where is not None and ei.value.where.source_line == 12
    assert "underside_machine_coords.gcode:12" in str(ei.value)


def test_mode_auto_picks_a_mode_that_passes_and_says_which() -> None:
    g = EXAMPLES / "underside_machine_coords.gcode"
    job = compile_job(g, UNDERSIDE, CompileOptions(origin_mm=(0.0, 0.0), mode="auto"))
    assert job.mode != "+-" and job.assembly == -1
    assert job.notes[0].startswith(f"--mode auto chose {job.mode}")
    assert any("+-:" in n for n in job.notes)
    assert job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
    # every executed pose (quantised steps, interpolated) is in the configured assembly
    th = step_angles(job.steps, job.home_rad, job.steps_per_rev)
    q = th[:-1] + 0.5 * np.diff(th, axis=0)
    fk = UNDERSIDE.geometry.forward_batch(np.concatenate((th, q)), "-")
    assert fk.valid.all()
    assert (UNDERSIDE.geometry.assembly_of(np.concatenate((th, q)), fk.points) == -1).all()


def test_drawing_only_reachable_in_the_other_assembly_is_refused() -> None:
    """The default machine is built in assembly "+"; the underside drawing needs "-": every
    working mode refuses it, and the ones that reach it within the joint limits say why."""
    g = EXAMPLES / "underside_machine_coords.gcode"
    with pytest.raises(JobError) as ei:
        compile_job(g, PROF, CompileOptions(origin_mm=(0.0, 0.0), mode="++", keep_order=True))
    assert ei.value.reason == "assembly"
    assert "only reachable in assembly -" in str(ei.value)
    assert "built in assembly + ([kinematics] assembly)" in str(ei.value)
    assert ei.value.where is not None and ei.value.where.source_line == 12
    with pytest.raises(JobError, match=r"no working mode clears every check") as ei:
        compile_job(g, PROF, CompileOptions(origin_mm=(0.0, 0.0), mode="auto"))
    assert "only reachable in assembly -" in str(ei.value)


def test_executed_path_from_steps_matches_targets() -> None:
    job = compile_job(EXAMPLES / "simple.svg", PROF)
    th = step_angles(job.steps, job.home_rad, job.steps_per_rev)
    fk = PROF.geometry.forward_batch(th, "+").points
    # each quantised target is within one step quantum of its ideal target
    assert np.hypot(*(fk - job.points_mm).T).max() <= job.step_quantum_mm + 1e-9


def test_tolerance_option_changes_segment_count() -> None:
    coarse = compile_job(EXAMPLES / "fivebar_text.svg", PROF, CompileOptions(tolerance_mm=0.5))
    fine = compile_job(EXAMPLES / "fivebar_text.svg", PROF, CompileOptions(tolerance_mm=0.01))
    assert fine.draw.sum() > coarse.draw.sum()
    assert fine.max_dev_mm <= 0.01 + fine.step_quantum_mm
    assert coarse.max_dev_mm <= 0.5 + coarse.step_quantum_mm


def _g1_words(lines: list[str]) -> list[dict[str, int]]:
    """The words of every G1 line, parsed independently of the encoder."""
    out = []
    for ln in lines:
        if ln.startswith("G1 "):
            assert re.fullmatch(r"G1 A-?\d+ B-?\d+ P\d+ S\d+", ln), ln
            out.append({w[0]: int(w[1:]) for w in ln.split()[1:]})
    return out


def _firmware_acceptable(lines: list[str]) -> None:
    """docs/protocol.md section 5: printable ASCII (or tab), at most 80 bytes per line."""
    for ln in lines:
        assert len(ln.encode()) <= 80 and all(0x20 <= ord(c) <= 0x7E or c == "\t"
                                              for c in ln), ln


def test_pen_mode_never_sends_power_and_brackets_strokes_with_m3_m5() -> None:
    job = compile_job(EXAMPLES / "simple.svg", PROF)
    assert (job.power[job.draw] > 0).all()  # what --laser would send
    lines = encode_lines(job, PROF)  # no laser: a pen plot
    _firmware_acceptable(lines)
    words = _g1_words(lines)
    assert len(words) == job.n_segments and all(w["S"] == 0 for w in words)
    assert not any(re.search(r"S[1-9]", ln) for ln in lines if not ln.startswith(";"))
    # Pen state from M3 / M5 as the firmware would track it: down exactly on drawing segments.
    down, state = False, []
    for ln in lines:
        if ln.startswith("M3"):
            assert ln == "M3 S0" and not down
            down = True
        elif ln == "M5":
            down = False
        elif ln.startswith("G1 "):
            state.append(down)
    assert np.array_equal(np.array(state), job.draw)
    assert lines[-1] == "M5" and not down
    # as many pen-down runs as M3 lines
    runs = int(np.count_nonzero(np.diff(np.concatenate(([0], job.draw.astype(int)))) == 1))
    assert sum(ln == "M3 S0" for ln in lines) == runs


def test_laser_mode_sends_the_profile_power_on_drawing_segments_only() -> None:
    job = compile_job(EXAMPLES / "underside_machine_coords.gcode", UNDERSIDE,
                      CompileOptions(origin_mm=(0.0, 0.0), mode="++"))
    lines = encode_lines(job, UNDERSIDE, laser=True)
    _firmware_acceptable(lines)
    words = _g1_words(lines)
    s = np.array([w["S"] for w in words])
    assert np.array_equal(s, job.power)
    assert (s[~job.draw] == 0).all() and (s[job.draw] > 0).all()
    # the file's S200 frame and S255 circle: fractions of the file's largest S × profile power
    assert set(s[job.draw].tolist()) == {round(200 / 255 * UNDERSIDE.laser.power),
                                         UNDERSIDE.laser.power}
    assert lines[lines.index("G90") + 1] == f"{UNDERSIDE.laser.on_command} S0"
    assert lines[-1] == "M5"


def test_encode_lines_absolute_and_relative() -> None:
    job = compile_job(EXAMPLES / "square.gcode", PROF)
    ab = encode_lines(job, PROF)
    rel = encode_lines(job, PROF, relative=True)
    assert "G90" in ab and "G91" in rel and ab[-1] == "M5" and rel[-1] == "M5"
    moves = [ln for ln in rel if ln.startswith("G1 ")]
    assert len(moves) == job.n_segments
    a = np.array([[int(w[1:]) for w in ln.split()[1:3]] for ln in moves])
    assert np.array_equal(a.sum(axis=0), [0, 0])  # back home
    first = next(ln for ln in ab if ln.startswith("G1 ")).split()
    assert first[1] == f"A{job.steps[1, 0]}" and first[3] == f"P{job.duration_us[0]}"


def test_layer_selection(tmp_path: Path) -> None:
    job = compile_job(EXAMPLES / "fivebar_text.svg", PROF, CompileOptions(layers=("underline",)))
    d = read_svg(EXAMPLES / "fivebar_text.svg", ["underline"])
    assert job.n_paths == d.n_strokes == 1


def test_nbar_second_opinion_agrees() -> None:
    from fivebar_host.compile import nbar_opinion

    job = compile_job(EXAMPLES / "fivebar_text.svg", PROF)
    op = nbar_opinion(job, PROF)
    assert op is not None and op.poses == op.total_poses
    assert op.max_disagreement_mm < 1e-8
    assert op.max_dev_mm == pytest.approx(job.max_dev_mm, abs=1e-8)
    part = nbar_opinion(job, PROF, max_poses=300)
    assert part is not None and part.poses == 300 and "first 300" in part.describe()


def test_fit_uses_the_machines_assembly() -> None:
    """Mode "++" has a larger safe rectangle below the motors (assembly "-") than above
    them; the default machine is built in "+", so --fit must use the "+" one."""
    from kinematics.workspace import find_page_rectangle

    k = PROF.kinematics
    job = compile_job(EXAMPLES / "simple.svg", PROF, CompileOptions(mode="++", fit=True))
    x0, y0, x1, y1 = job.placement.drawing_bbox
    aspect = (x1 - x0) / (y1 - y0)
    args = (PROF.geometry, "++", k.min_type1_margin_rad, k.min_type2_margin_rad,
            PROF.motors.limits_rad, aspect)
    plus = find_page_rectangle(*args, assembly="+").rect
    minus = find_page_rectangle(*args, assembly="-").rect
    assert minus.area > plus.area  # the other assembly would have offered more room
    area = job.placement.area
    assert area is not None
    assert (area.x0, area.y0, area.width, area.height) == pytest.approx(
        (plus.x0, plus.y0, plus.width, plus.height))
    assert job.assembly == 1 and job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
