"""`fivebar calibrate pattern|fit|check`: the pattern's steps are the plot's, bad input gets a
named error, and the whole loop runs end to end on the mock with a true geometry."""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.report.text.executed import executed_path, ledger_track, true_params
from kinematics.calibration import rotation
from kinematics.calibration_analysis import align

TRUE = (60.4, 89.55, 59.6, 90.45, 40.5, 120.45, 59.5)  # mm, degrees


@pytest.fixture(autouse=True)
def _clean_machines() -> Iterator[None]:
    mock.forget_machines()
    yield
    mock.forget_machines()


def run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return res.exit_code, res.output


@pytest.fixture(scope="module")
def pattern(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:
    d = tmp_path_factory.mktemp("pattern")
    svg, marks = d / "pattern.svg", d / "pattern.json"
    code, out = run("calibrate", "pattern", "-o", str(svg), "--marks", str(marks))
    assert code == 0, out
    return svg, marks, json.loads(marks.read_text())


def _opts(doc: dict) -> CompileOptions:
    return CompileOptions(origin_mm=tuple(doc["origin_mm"]), mode=doc["mode"])


def test_pattern_marks_are_the_steps_the_plot_commands(pattern: tuple[Path, Path, dict]) -> None:
    svg, _, doc = pattern
    assert len(doc["marks"]) >= 25
    assert "<text" not in svg.read_text()
    job = compile_job(svg, load_profile(), _opts(doc))  # as `fivebar plot` compiles it
    for mk in doc["marks"]:
        c = np.array([mk["x_mm"], mk["y_mm"]])
        hit = np.flatnonzero(np.max(np.abs(job.points_mm - c), axis=1) < 1e-9)
        assert hit.size >= 2, mk  # both strokes of the cross pass the centre
        assert all(job.steps[i].tolist() == mk["steps"] for i in hit), mk
    # The marks reach the region's edges: some lie within 3 mm of its boundary.
    prof = load_profile()
    pts = np.array([[m["x_mm"], m["y_mm"]] for m in doc["marks"]])
    from fivebar_host.calibrate.pattern import nominal_params
    from kinematics.calibration_analysis import safe_grid

    k = prof.kinematics
    grid = safe_grid(nominal_params(prof), doc["mode"], k.min_type1_margin_rad,
                     k.min_type2_margin_rad, prof.motors.limits_rad, k.assembly)
    edge = grid.points()[~np.isin(np.arange(grid.mask.sum()),
                                  np.flatnonzero(grid.eroded(1.0).mask[grid.mask]))]
    near = np.min(np.hypot(*(pts[:, None, :] - edge[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert np.sum(near < 3.5) >= 10


def _write_csv(path: Path, rows: list[tuple[object, object, object]]) -> None:
    path.write_text("id,x_mm,y_mm\n" + "".join(f"{a},{b},{c}\n" for a, b, c in rows))


def _good_rows(doc: dict) -> list[tuple[object, object, object]]:
    return [(m["id"], m["x_mm"] + 3, m["y_mm"] - 2) for m in doc["marks"]]


@pytest.mark.parametrize(("edit", "message"), [
    (lambda r: [*r, (999, 1.0, 2.0)], "mark id 999 is not in the pattern"),
    (lambda r: [*r, r[3]], "mark id 4 measured twice"),
    (lambda r: r[:9], "9 marks measured; the fit needs at least 10"),
    (lambda r: [r[0], (r[1][0], "nan", r[1][2]), *r[2:]], "x_mm is nan"),
    (lambda r: [(i, x * 25, y * 25) for i, x, y in r], "25× as far apart"),
    (lambda r: [(i, "12,5", y) for i, _, y in r], "expected 3 fields"),
])
def test_bad_measurements_get_a_named_error(pattern: tuple[Path, Path, dict], tmp_path: Path,
                                            edit: object, message: str) -> None:
    _, marks, doc = pattern
    csv = tmp_path / "m.csv"
    _write_csv(csv, edit(_good_rows(doc)))  # type: ignore[operator]
    out_toml = tmp_path / "fitted.toml"
    code, out = run("calibrate", "fit", str(csv), "--marks", str(marks), "-o", str(out_toml))
    assert code == 2 and message in out and str(csv) in out, out
    assert not out_toml.exists()


def test_a_fit_that_does_not_converge_writes_nothing(pattern: tuple[Path, Path, dict],
                                                     tmp_path: Path) -> None:
    _, marks, doc = pattern
    csv = tmp_path / "m.csv"
    _write_csv(csv, _good_rows(doc))
    out_toml = tmp_path / "fitted.toml"
    code, out = run("calibrate", "fit", str(csv), "--marks", str(marks), "-o", str(out_toml),
                    "--max-iterations", "1")
    assert code == 2 and "did not converge" in out and "nothing was written" in out
    assert not out_toml.exists()


def _plot(svg: Path, doc: dict, url: str, config: Path | None = None) -> None:
    args = ["plot", str(svg), "--origin", "{:g},{:g}".format(*doc["origin_mm"]), "--mode",
            doc["mode"], "--port", url, "--yes"]
    if config is not None:
        args += ["--config", str(config)]
    code, out = run(*args)
    assert code == 0, out


def _drawn_error(svg: Path, doc: dict, name: str, config: Path | None) -> tuple[float, float]:
    """Max shape error (mm) of what the true mock machine drew at the job's drawing targets,
    after the best rigid alignment with the intended points; and the job's step quantum."""
    prof = load_profile(config)
    job = compile_job(svg, prof, _opts(doc))
    m = mock.machine(name)
    t, track = ledger_track(m.ledger)
    ex = executed_path(job, prof, t, track, true=true_params(m.true))
    on_draw = np.flatnonzero(np.isfinite(ex.deviation_mm))
    tgt = {tuple(s): k for k, s in enumerate(job.steps.tolist())}
    rows = [i for i in on_draw if tuple(track[i].tolist()) in tgt]
    intended = job.points_mm[[tgt[tuple(track[i].tolist())] for i in rows]]
    e = align(ex.points[rows], intended)
    return float(np.nanmax(np.hypot(e[:, 0], e[:, 1]))), job.step_quantum_mm


@pytest.mark.slow
def test_end_to_end_pattern_plot_measure_fit_replot(pattern: tuple[Path, Path, dict],
                                                    tmp_path: Path) -> None:
    svg, marks, doc = pattern
    true = ",".join(f"{v:g}" for v in TRUE)
    _plot(svg, doc, f"fivebar-mock://?machine=before&speed=0&true={true}")
    # Measure: the true machine's pen at each mark's centre (from the executed path), in a
    # paper frame rotated by 0.4 rad and shifted, with 0.05 mm noise.
    prof = load_profile()
    job = compile_job(svg, prof, _opts(doc))
    m = mock.machine("before")
    t, track = ledger_track(m.ledger)
    ex = executed_path(job, prof, t, track, true=true_params(m.true))
    rng = np.random.default_rng(22)
    rows = []
    for mk in doc["marks"]:
        hit = np.flatnonzero(np.all(track == mk["steps"], axis=1))
        assert hit.size >= 2  # the machine was there, twice (both strokes)
        p = ex.points[hit[0]] @ rotation(0.4).T + (35.0, -80.0) + rng.normal(0, 0.05, 2)
        rows.append((mk["id"], f"{p[0]:.3f}", f"{p[1]:.3f}"))
    csv = tmp_path / "measured.csv"
    _write_csv(csv, rows)
    fitted = tmp_path / "fitted.toml"
    code, out = run("calibrate", "fit", str(csv), "--marks", str(marks), "-o", str(fitted),
                    "--sigma", "0.05")
    assert code == 0, out
    assert "determined only to" in out and "measurement σ you gave" in out
    doc_t = tomllib.loads(fitted.read_text())
    assert fitted.read_text().startswith("# [geometry] and [motors] home_deg fitted")
    assert "# driving link on motor M1" in fitted.read_text()  # comments kept
    assert doc_t["motion"] == tomllib.loads(Path(prof.source).read_text())["motion"]
    fit_home = doc_t["motors"]["home_deg"]
    assert abs(fit_home[0] - TRUE[5]) < 1.0 and abs(fit_home[1] - TRUE[6]) < 1.0
    # Re-plot the pattern with the fitted profile on the same true machine.
    _plot(svg, doc, f"fivebar-mock://?machine=after&speed=0&true={true}", fitted)
    before, quantum = _drawn_error(svg, doc, "before", None)
    after, _ = _drawn_error(svg, doc, "after", fitted)
    assert before > 0.3
    print(f"end to end: drawn shape error before {before:.3f} mm, after {after:.3f} mm")
    assert after <= 0.1 + quantum and after <= before / 4, (before, after)
    # The check map of the old profile, taking the fitted one as true.
    png = tmp_path / "check.png"
    code, out = run("calibrate", "check", "--config", str(fitted), "--old", prof.source,
                    "-o", str(png), "--marks", str(marks))
    assert code == 0 and png.stat().st_size > 10_000, out
    worst = float(out.split("max ")[1].split(" mm")[0])
    assert abs(worst - before) < 0.5 * before  # the map predicts what the machine did
    assert math.isfinite(float(out.split("median ")[1].split(" mm")[0]))


def test_mock_true_option_is_checked() -> None:
    from fivebar_host.devices.mock import MockURLError, parse_mock_url

    assert parse_mock_url(f"fivebar-mock://?true={','.join(map(str, TRUE))}").true == TRUE
    assert parse_mock_url("fivebar-mock://").true is None
    with pytest.raises(MockURLError, match="a1,b1,a2,b2,w,home1,home2"):
        parse_mock_url("fivebar-mock://?true=1,2,3")
    with pytest.raises(MockURLError, match="positive lengths"):
        parse_mock_url("fivebar-mock://?true=60,90,60,-90,40,120,60")
