"""`fivebar calibrate pattern|fit` on a servo profile: the pattern's ticks come into their
marks from the planned sides, and a fit of ticks drawn by a known true servo machine (its
curves bowed, a 1° and 1.5° dead band) writes a profile whose curves and dead bands are the
truth's within the reported uncertainty."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host.calibrate.servo import servo_nominal
from fivebar_host.cli import main
from fivebar_host.config import ConfigError, load_profile
from kinematics.calibration import rotation
from kinematics.servo_calibration import ServoMachine

ROOT = Path(__file__).resolve().parent.parent
PLOTCLOCK = ROOT / "configs" / "plotclock.toml"


def run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return res.exit_code, res.output


def truth() -> ServoMachine:
    base = servo_nominal(load_profile(PLOTCLOCK))
    g = np.array(base.geometry)
    g[:5] += [0.25, -0.3, -0.2, 0.3, 0.2]
    co = base.coeffs.copy()
    co[:, 0] += np.radians([0.8, -1.0])
    co[:, 2] += np.radians([1.5, -2.0])
    co[:, 3] += np.radians([-2.0, 1.0])
    return ServoMachine(tuple(g), co, base.centre_us, (math.radians(1.0), math.radians(1.5)))


def test_servo_pattern_and_fit(tmp_path: Path) -> None:
    svg, marks = tmp_path / "pat.svg", tmp_path / "pat.json"
    code, out = run("calibrate", "pattern", "--config", str(PLOTCLOCK), "-o", str(svg),
                    "--marks", str(marks), "--count", "40")
    assert code == 0, out
    assert "--keep-order" in out
    doc = json.loads(marks.read_text())
    p = np.array([m["pulses_us"] for m in doc["marks"]])
    s = np.array([m["approach"] for m in doc["marks"]])
    # every joint comes into the marks from both sides
    assert {tuple(r) for r in s.tolist()} == {(1, 1), (-1, -1), (1, -1), (-1, 1)}
    true = truth()
    rng = np.random.default_rng(3)
    y = true.pen_points(p, s, "+")
    assert np.isfinite(y).all()
    y = y @ rotation(-0.4).T + [100.0, 30.0] + rng.normal(0.0, 0.05, y.shape)
    csv = tmp_path / "measured.csv"
    csv.write_text("id,x_mm,y_mm\n" + "".join(
        f"{m['id']},{x:.4f},{v:.4f}\n" for m, (x, v) in zip(doc["marks"], y, strict=True)))
    fitted = tmp_path / "fitted.toml"
    code, out = run("calibrate", "fit", str(csv), "--marks", str(marks), "--config",
                    str(PLOTCLOCK), "-o", str(fitted), "--sigma", "0.05")
    assert code == 0, out
    assert "dead band 1" in out
    prof = load_profile(fitted)
    assert prof.joints is not None
    dead = [math.degrees(j.dead_band_rad) for j in prof.joints.joints]
    np.testing.assert_allclose(dead, [1.0, 1.5], atol=0.2)
    # the written curves match the truth over the measured pulses within 3 reported σ (plus
    # the 9-node table's interpolation, < 0.05°)
    sig = [float(v) for v in re.findall(r"curve over .*\(1σ ≤ ([0-9.]+)°\)", out)]
    assert len(sig) == 2
    for k, j in enumerate(prof.joints.joints):
        q = np.linspace(p[:, k].min(), p[:, k].max(), 7)
        want = true.curve_angles(np.column_stack((q, q)))[:, k]
        np.testing.assert_allclose(np.degrees(j.curve.angle(q)), np.degrees(want),
                                   atol=3.0 * sig[k] + 0.05)
    # the lengths within 3 reported σ
    for name, want in zip(("a1", "b1", "a2", "b2", "w"), true.geometry[:5], strict=True):
        m = re.search(rf"{name}\s+=\s+([0-9.]+) mm ± ([0-9.]+) mm", out)
        assert m is not None
        assert abs(float(m.group(1)) - want) <= 3.0 * float(m.group(2))
        assert getattr(prof.geometry, name) == pytest.approx(float(m.group(1)), abs=1e-4)


def test_cnc_shield_profile_loads_and_dry_runs(tmp_path: Path) -> None:
    """configs/servo-cnc-shield.toml: a servo profile whose wiring comment names the pins the
    servo build drives (firmware/fivebar/config.h), and it dry-runs an example."""
    path = ROOT / "configs" / "servo-cnc-shield.toml"
    prof = load_profile(path)
    assert prof.joints is not None
    cfg = (ROOT / "firmware" / "fivebar" / "config.h").read_text()
    text = path.read_text()
    for macro in ("PIN_SERVO_A_BIT", "PIN_SERVO_B_BIT", "PIN_SERVO_BIT"):
        m = re.search(rf"#define {macro}\s+\d+\s+/\* (D\d+)", cfg)
        assert m is not None and m.group(1) in text, macro
    # the curve covers the joint limits (every pose the profile allows has a pulse)
    for j, (lo, hi) in zip(prof.joints.joints, prof.motors.limits_rad, strict=True):
        a, b = j.curve.range_rad
        assert a <= lo and hi <= b
    code, out = run("plot", str(ROOT / "examples" / "fivebar_text.svg"), "--config",
                    str(path), "--fit", "--dry-run", "--preview", str(tmp_path / "p.png"))
    assert code == 0, out
    assert "servo joints" in out


def test_servo_dead_band_is_the_profile_slack(tmp_path: Path) -> None:
    """A servo profile's dead bands are its backlash_steps (1° on the Plotclock's grid of
    0.5 µs pulse ticks, 0.04407°: 23 steps),
    and ServoMap sends each count less half of it: a count m is the command m − B/2, whose
    output band [command − w/2, command + w/2] is the play [m − B, m] (to the grid's
    rounding of w); T2∘T1 stays the identity."""
    from fivebar_host.controllers.fivebar.servo import ServoMap

    prof = load_profile(PLOTCLOCK)
    assert prof.joints is not None
    assert prof.motors.backlash_steps == (23, 23)
    smap = ServoMap.of(prof.joints, prof)
    q = prof.motors.rad_per_step
    steps = np.arange(-300, 301, 7)
    for j in range(2):
        ticks = smap.ticks(j, steps)
        want = prof.joints.joints[j].curve.pulse(prof.motors.home_rad[j] + (steps - 11.5) * q)
        np.testing.assert_allclose(ticks / 2.0, want, atol=0.25)
        assert [smap.steps(j, int(t)) for t in ticks] == steps.tolist()
    bad = tmp_path / "bad.toml"
    bad.write_text(PLOTCLOCK.read_text().replace("endstops = false",
                                                 "endstops = false\nbacklash_steps = [4, 4]"))
    with pytest.raises(ConfigError, match="dead_band_deg"):
        load_profile(bad)


def _measure(doc: dict, true: ServoMachine, rng: np.random.Generator, turn: float,
             csv: Path) -> None:
    """Where `true` draws each tick of a marks file, on a sheet turned by `turn` rad, with
    0.05 mm noise, written as the measured CSV."""
    p = np.array([m["pulses_us"] for m in doc["marks"]])
    s = np.array([m["approach"] for m in doc["marks"]])
    y = true.pen_points(p, s, "+")
    keep = np.isfinite(y).all(axis=1)
    y = y @ rotation(turn).T + [50.0, -20.0] + rng.normal(0.0, 0.05, y.shape)
    csv.write_text("id,x_mm,y_mm\n" + "".join(
        f"{m['id']},{x:.4f},{v:.4f}\n"
        for m, (x, v), k in zip(doc["marks"], y, keep, strict=True) if k))


def test_servo_two_rounds(tmp_path: Path) -> None:
    """`calibrate pattern --second-round` draws the first round's marks again with the first
    fit's pulses (the same centres, the pulses the truth needs there: nearer the truth's than
    the profile's), and `calibrate fit --also` fits both rounds, each sheet placed on its
    own: the dead bands and curves of the truth within the reported uncertainty."""
    true = truth()
    rng = np.random.default_rng(4)
    pat1, pat2 = tmp_path / "p1.svg", tmp_path / "p2.svg"
    m1, m2 = tmp_path / "p1.json", tmp_path / "p2.json"
    csv1, csv2 = tmp_path / "m1.csv", tmp_path / "m2.csv"
    fit1, fit2 = tmp_path / "fit1.toml", tmp_path / "fit2.toml"
    code, out = run("calibrate", "pattern", "--config", str(PLOTCLOCK), "-o", str(pat1),
                    "--marks", str(m1), "--count", "30")
    assert code == 0, out
    doc1 = json.loads(m1.read_text())
    _measure(doc1, true, rng, 0.3, csv1)
    code, out = run("calibrate", "fit", str(csv1), "--marks", str(m1), "--config",
                    str(PLOTCLOCK), "-o", str(fit1), "--sigma", "0.05")
    assert code == 0, out
    code, out = run("calibrate", "pattern", "--config", str(fit1), "-o", str(pat2),
                    "--marks", str(m2), "--second-round", str(m1))
    assert code == 0, out
    doc2 = json.loads(m2.read_text())
    c1 = {(round(m["x_mm"], 3), round(m["y_mm"], 3)) for m in doc1["marks"]}
    c2 = {(round(m["x_mm"], 3), round(m["y_mm"], 3)) for m in doc2["marks"]}
    assert len(c2) >= 20 and c2 <= c1  # the first round's centres
    # the second round's pulses are those the truth needs there (up to the turn of the
    # drawing the placement absorbs): far closer than the first's
    first = {(round(m["x_mm"], 3), round(m["y_mm"], 3)): m for m in doc1["marks"]}
    xy = np.array([[m["x_mm"], m["y_mm"]] for m in doc2["marks"]])
    s2 = np.array([m["approach"] for m in doc2["marks"]])
    th = true.fivebar().inverse_batch(xy, "+-").angles
    need = true.pulses_for(th + 0.5 * s2 * np.array(true.dead_band))
    p1 = np.array([first[(round(x, 3), round(y, 3))]["pulses_us"] for x, y in xy])
    p2 = np.array([m["pulses_us"] for m in doc2["marks"]])
    off1, off2 = np.abs(p1 - need).max(axis=0), np.abs(p2 - need).max(axis=0)
    assert np.all(off2 < off1 / 3.0), (off1, off2)
    _measure(doc2, true, rng, -0.5, csv2)
    code, out = run("calibrate", "fit", str(csv2), "--marks", str(m2), "--config", str(fit1),
                    "-o", str(fit2), "--sigma", "0.05", "--also", str(csv1), str(m1))
    assert code == 0, out
    assert "in 2 rounds" in out
    prof = load_profile(fit2)
    assert prof.joints is not None
    for k, j in enumerate(prof.joints.joints):
        line = next(ln for ln in out.splitlines() if f"dead band {k + 1}" in ln)
        val, sd = (float(v) for v in line.split("=")[1].replace("°", "").split("±"))
        assert abs(val - math.degrees(true.dead_band[k])) <= 3.0 * sd
        assert math.degrees(j.dead_band_rad) == pytest.approx(val, abs=1e-3)
    # --also with a stepper profile is refused, nothing written
    code, out = run("calibrate", "fit", str(csv2), "--marks", str(m2), "--config",
                    str(ROOT / "configs" / "default.toml"), "-o", str(tmp_path / "x.toml"),
                    "--also", str(csv1), str(m1))
    assert code != 0 and not (tmp_path / "x.toml").exists()
