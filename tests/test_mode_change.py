"""Working-mode changes in a job (`--mode auto` when no single mode clears every check,
thesis Sec. 7.2): the bundled example compiles, is drawn within tolerance + one step quantum,
every executed pose keeps the machine's assembly and joint limits, each change drives an arm
through its type-1 singularity with the pen up, and the dry-run report lists every change."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import kinematics.modes
from fivebar_host.cli import main
from fivebar_host.compile import (
    CompileOptions,
    compile_job,
    deviations,
    encode_lines,
    read_drawing,
)
from fivebar_host.compile.chords import prepare_chords
from fivebar_host.compile.modes import break_paths
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import load_profile
from fivebar_host.errors import JobError
from fivebar_host.report.text.dryrun import report_lines
from fivebar_host.toolpath.geometry import LINE, evaluate, flatten
from fivebar_host.toolpath.segment import wrap_to_limits
from kinematics.fivebar import WORKING_MODES

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "mode_change.gcode"
PROF = load_profile()
AUTO = CompileOptions(origin_mm=(0.0, 0.0), mode="auto")


#: A short line at the top ("+-") and one low on the right ("++"): the straight joint-space
#: moves between them and back home pass too close to the type-2 singularity, so the planned
#: pen-up moves go through waypoints.
WAYPOINTS = "G21 G90\nG0 X25 Y131\nG1 X29 Y131 F1200\nG0 X76 Y12\nG1 X78 Y12\n"


@pytest.fixture(scope="module", params=["example", "waypoints"])
def job(request, tmp_path_factory):  # type: ignore[no-untyped-def]
    if request.param == "example":
        return compile_job(EXAMPLE, PROF, AUTO)
    f = tmp_path_factory.mktemp("wp") / "waypoints.gcode"
    f.write_text(WAYPOINTS)
    return compile_job(f, PROF, AUTO)


def _executed(job, step_rad: float = math.radians(0.25)):  # type: ignore[no-untyped-def]
    """Joint angles of the whole executed job (quantised steps, linear interpolation),
    sampled at most `step_rad` apart, with the segment each sample belongs to."""
    th = step_angles(job.steps, job.home_rad, job.steps_per_rev)
    d = np.diff(th, axis=0)
    n = np.maximum(1, np.ceil(np.abs(d).max(axis=1) / step_rad)).astype(int)
    seg = np.repeat(np.arange(d.shape[0]), n)
    s = (np.arange(seg.shape[0]) - np.repeat(np.cumsum(n) - n, n)) / n[seg]
    return th[seg] + s[:, None] * d[seg], seg


def test_no_single_mode_draws_the_example() -> None:
    for m in WORKING_MODES:
        with pytest.raises(JobError):
            compile_job(EXAMPLE, PROF, CompileOptions(origin_mm=(0.0, 0.0), mode=m))


def test_example_is_drawn_within_tolerance_in_several_modes(job) -> None:  # type: ignore[no-untyped-def]
    assert len(set(job.path_modes)) >= 2 and len(job.mode_changes) >= 2
    # at least one change between two drawn paths, not only a move from or to home
    assert any(0 < mc.path < job.n_paths for mc in job.mode_changes)
    bound = job.tolerance_mm + job.step_quantum_mm
    assert job.max_dev_mm <= bound
    dist, _ = deviations(job, PROF, samples=16)  # denser, independent of the report
    assert dist.max() <= bound
    # nothing left out: square 4·10 mm + line 52 mm + circle 2π·6 mm (flattened to 0.025 mm)
    want = (40.0 + 52.0 + 2 * math.pi * 6.0) if Path(job.file) == EXAMPLE else 4.0 + 2.0
    assert job.draw_length_mm == pytest.approx(want, abs=0.15)
    assert np.array_equal(np.cumsum(job.relative_steps, axis=0), job.steps[1:])
    assert job.steps[0].tolist() == [0, 0] and job.steps[-1].tolist() == [0, 0]


def test_every_executed_pose_keeps_assembly_limits_and_margins(job) -> None:  # type: ignore[no-untyped-def]
    fb, k = PROF.geometry, PROF.kinematics
    q, seg = _executed(job)
    fk = fb.forward_batch(q, "+")
    assert fk.valid.all()
    assert (fb.assembly_of(q, fk.points) == 1).all()  # the machine is built in "+"
    _, ok1, ok2 = wrap_to_limits(q, PROF.motors.limits_rad)
    assert ok1.all() and ok2.all()
    marg = fb.singularity_margins(q, fk.points)
    # type 2 everywhere (pen up or down); rounding to whole steps costs a few hundredths
    assert marg[:, 2].min() >= k.min_type2_margin_rad - math.radians(0.1)
    # while drawing: every sample is in its path's working mode, clear of type 1
    draw = job.draw[seg]
    modes = np.array(job.path_modes)[job.path[seg][draw]]
    sign = np.stack([np.where(np.char.startswith(modes, "+"), 1.0, -1.0),
                     np.where(np.char.endswith(modes, "+"), 1.0, -1.0)], axis=1)
    assert (marg[draw, :2] * sign).min() >= k.min_type1_margin_rad - math.radians(0.1)


def test_each_change_is_pen_up_through_a_type1_singularity(job) -> None:  # type: ignore[no-untyped-def]
    fb = PROF.geometry
    th = step_angles(job.steps, job.home_rad, job.steps_per_rev)
    pts = fb.forward_batch(th, "+").points
    laser = encode_lines(job, PROF, laser=True)
    s = np.array([int(ln.rsplit("S", 1)[1]) for ln in laser if ln.startswith("G1 ")])
    q, seg = _executed(job)
    qp = fb.forward_batch(q, "+").points
    marg = fb.singularity_margins(q, qp)
    for mc in job.mode_changes:
        part = slice(mc.first_seg, mc.end_seg)
        assert not job.draw[part].any() and (s[part] == 0).all()  # laser off
        # the working mode before and after, from the executed poses
        for idx, want in ((mc.first_seg, mc.from_mode), (mc.end_seg, mc.to_mode)):
            sg = fb.mode_of(pts[idx:idx + 1], th[idx:idx + 1])[0]
            assert "".join("+" if v > 0 else "-" for v in sg) == want
        assert np.hypot(*(pts[mc.first_seg] - mc.lift_mm)) <= job.step_quantum_mm
        # each arm whose sign differs passes its type-1 singularity (margin changes sign),
        # where the report says
        inside = (seg >= mc.first_seg) & (seg < mc.end_seg)
        for arm in (0, 1):
            flips = np.flatnonzero(np.diff(np.sign(marg[inside, arm])) != 0)
            listed = [c for c in mc.crossings if c[0] == arm + 1]
            assert len(flips) == len(listed)
            for f, (_, kind, cx, cy) in zip(flips, listed, strict=True):
                assert np.hypot(*(qp[inside][f] - (cx, cy))) < 2.0
                r = math.hypot(cx - (0.0 if arm == 0 else fb.w), cy)
                full = (fb.a1 + fb.b1) if arm == 0 else (fb.a2 + fb.b2)
                assert (kind == "stretched") == (abs(r - full) < 1.0)
        if mc.from_mode[0] != mc.to_mode[0] or mc.from_mode[1] != mc.to_mode[1]:
            assert mc.crossings
        assert mc.min_type2_rad >= PROF.kinematics.min_type2_margin_rad - math.radians(0.1)
        assert mc.duration_s == pytest.approx(job.duration_us[part].sum() * 1e-6)


def test_planned_waypoints_are_executed_exactly(job) -> None:  # type: ignore[no-untyped-def]
    """The waypoint drawing's changes are not straight in joint space; the example's middle
    change splits the top line where both modes are safe (the same point, two poses)."""
    th = step_angles(job.steps, job.home_rad, job.steps_per_rev)
    if Path(job.file) == EXAMPLE:
        inner = [mc for mc in job.mode_changes if 0 < mc.path < job.n_paths]
        assert any(mc.lift_mm == pytest.approx(mc.land_mm) for mc in inner)
        return
    bent = 0
    for mc in job.mode_changes:
        d = np.diff(th[mc.first_seg:mc.end_seg + 1], axis=0)
        u = d / np.abs(d).max(axis=1, keepdims=True)
        bent += int((np.abs(np.diff(u, axis=0)).max(axis=1) > 0.2).any())
    assert bent >= 1
    # the park move is planned too: back into the homed pose's mode
    assert job.mode_changes[-1].path == job.n_paths
    assert job.mode_changes[-1].to_mode == job.home_mode


def test_transition_targets_follow_the_planned_polyline() -> None:
    from fivebar_host.compile.modes import transition_targets

    corners = np.array([[0.2, 0.3], [0.9, 0.35], [1.0, 1.4], [0.4, 1.5]])
    dense = np.concatenate([np.linspace(p, q, 40)[(1 if i else 0):]
                            for i, (p, q) in enumerate(itertools.pairwise(corners))])
    tg = transition_targets(dense, corners[0], corners[-1], 0.05)
    allp = np.concatenate((corners[:1], tg))
    assert np.abs(np.diff(allp, axis=0)).max() <= 0.05 + 1e-12
    for c in corners:  # every corner is a target (the firmware turns exactly there)
        assert np.abs(allp - c).max(axis=1).min() < 1e-12
    # every target lies on the polyline
    for q in tg:
        dmin = min(np.hypot(*(q - (p + np.clip(np.dot(q - p, r - p) / np.dot(r - p, r - p),
                                                 0, 1) * (r - p))))
                   for p, r in itertools.pairwise(corners))
        assert dmin < 1e-12
    with pytest.raises(JobError, match="internal"):
        transition_targets(dense, corners[0] + 0.1, corners[-1], 0.05)


def test_report_lists_every_change(job, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    lines = report_lines(job)
    changes = [ln for ln in lines if ln.startswith("mode change")]
    assert len(changes) == len(job.mode_changes)
    for n, (ln, mc) in enumerate(zip(changes, job.mode_changes, strict=True), start=1):
        assert ln.startswith(f"mode change {n} {mc.from_mode} → {mc.to_mode}")
        assert f"pen up at ({mc.lift_mm[0]:.1f}, {mc.lift_mm[1]:.1f}) mm" in ln
        for arm, kind, cx, cy in mc.crossings:
            assert f"arm {arm} {kind} at ({cx:.1f}, {cy:.1f}) mm" in ln
    head = next(ln for ln in lines if ln.startswith("working mode"))
    assert "→" in head and f"{len(job.mode_changes)} pen-up working-mode change" in head
    # the same through the command line, with the preview written
    png = tmp_path / "p.png"
    res = CliRunner().invoke(main, ["plot", job.file, "--origin", "0,0", "--mode", "auto",
                                    "--dry-run", "--preview", str(png)])
    assert res.exit_code == 0, res.output
    assert [ln for ln in res.output.splitlines() if ln.startswith("mode change")] == changes
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_one_mode_suffices_no_changes_and_same_job() -> None:
    simple = ROOT / "examples" / "simple.svg"
    auto = compile_job(simple, PROF, CompileOptions(mode="auto"))
    fixed = compile_job(simple, PROF, CompileOptions(mode=auto.mode))
    assert auto.mode_changes == () and set(auto.path_modes) == {auto.mode}
    assert np.array_equal(auto.steps, fixed.steps)
    assert np.array_equal(auto.duration_us, fixed.duration_us)
    assert not any(ln.startswith("mode change") for ln in report_lines(auto))


def test_point_safe_in_no_mode_is_refused_with_each_modes_reason() -> None:
    g = ROOT / "examples" / "underside_machine_coords.gcode"
    with pytest.raises(JobError) as ei:
        compile_job(g, PROF, AUTO)
    text = str(ei.value)
    assert ei.value.reason == "no_mode"
    assert "with pen-up working-mode changes" in text
    assert "no working mode is safe at this point in assembly +" in text
    for m in WORKING_MODES:
        assert f"{m}: " in text
    assert "underside_machine_coords.gcode:" in text and "machine (" in text


def test_impossible_transition_is_refused_naming_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """If no pen-up path exists (here: the joint-space planner finds none), the job is
    refused with the planner's reason and the point, not drawn in part."""
    monkeypatch.setattr(kinematics.modes, "plan_joint_move", lambda *a, **k: None)
    with pytest.raises(JobError) as ei:
        compile_job(EXAMPLE, PROF, AUTO)
    text = str(ei.value)
    assert "working-mode change impossible: no pen-up path from working mode" in text
    assert "keeps the type-2 margin and joint limits" in text
    assert "before point (" in text and ") mm" in text


def test_break_paths_keeps_geometry_and_parameters() -> None:
    """Breaking paths inside chords and at vertices: the points in order are the old ones
    with the break points inserted (twice: end and start), every new chord lies on its
    source chord, and its primitive parameters map to its own end points."""
    drawing = read_drawing(ROOT / "examples" / "simple.svg")
    poly = flatten(drawing, 0.05)
    ch = prepare_chords(drawing, poly, 0.1, 0.05, np.array([0.0, 0.0]), True)
    rng = np.random.default_rng(3)
    nchord = ch.chord_from.shape[0]
    bc = rng.choice(nchord, 12, replace=False)
    bf = np.where(rng.random(12) < 0.4, 1.0, rng.uniform(0.1, 0.9, 12))
    # a vertex break only inside a path (not at its last vertex)
    last = np.isin(ch.chord_from[bc] + 1, ch.offsets[1:] - 1)
    bf[last] = 0.5
    new = break_paths(ch, bc, bf)
    assert new.offsets.shape[0] - 1 == ch.offsets.shape[0] - 1 + 12
    # points: drop the duplicate start of every broken part → old points plus interior ones
    starts = new.offsets[:-1]
    dup = np.zeros(new.pts.shape[0], bool)
    for s0 in starts[1:]:
        if np.array_equal(new.pts[s0], new.pts[s0 - 1]):
            dup[s0] = True
    kept = new.pts[~dup]
    assert kept.shape[0] == ch.pts.shape[0] + int((bf < 1.0).sum())
    old_in_new = np.isin(kept.view([("", kept.dtype)] * 2),
                         ch.pts.view([("", ch.pts.dtype)] * 2)).ravel()
    assert old_in_new.sum() >= ch.pts.shape[0]
    # every new chord: end points on the source chord, parameters evaluate to them
    a = new.chord_from
    kind, params = drawing.kind[new.prim], drawing.params[new.prim]
    lines = new.prim >= 0
    p_lo = evaluate(kind[lines], params[lines], np.where(new.rev, new.thi, new.tlo)[lines])
    p_hi = evaluate(kind[lines], params[lines], np.where(new.rev, new.tlo, new.thi)[lines])
    on_line = drawing.kind[new.prim[lines]] == LINE
    # straight primitives: the chord ends are exactly the primitive at the mapped parameters
    assert np.allclose(p_lo[on_line], new.pts[a[lines]][on_line], atol=1e-9)
    assert np.allclose(p_hi[on_line], new.pts[a[lines] + 1][on_line], atol=1e-9)
    # curves: within the flattening tolerance
    assert np.hypot(*(p_lo - new.pts[a[lines]]).T).max() < 0.06
    assert np.hypot(*(p_hi - new.pts[a[lines] + 1]).T).max() < 0.06
    # provenance: each new path comes from an old one, in order
    assert set(new.path_source.tolist()) == set(ch.path_source.tolist())
    assert np.all(np.diff(new.path_of_chord) >= 0)


def test_convert_names_the_modes_and_writes_firmware_lines(tmp_path: Path) -> None:
    out = tmp_path / "job.gcode"
    res = CliRunner().invoke(main, ["convert", str(EXAMPLE), "--origin", "0,0", "--mode",
                                    "auto", "-o", str(out)])
    assert res.exit_code == 0, res.output
    job = compile_job(EXAMPLE, PROF, AUTO)
    seq = " → ".join(m for i, m in enumerate(job.path_modes)
                     if i == 0 or job.path_modes[i - 1] != m)
    assert f"mode {seq} ({len(job.mode_changes)} pen-up mode changes)" in res.output
    lines = out.read_text().splitlines()
    assert all(len(ln) <= 80 and ln.isascii() for ln in lines)
    assert any(ln.startswith("; working mode ") and "->" in ln for ln in lines)
    assert sum(ln.startswith("G1 ") for ln in lines) == job.n_segments
