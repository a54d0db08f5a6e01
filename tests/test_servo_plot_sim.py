"""Issue 38's goal on the emulator: `fivebar plot examples/fivebar_text.svg --config
configs/plotclock.toml --fit --port fivebar-sim:// --yes` runs the Plotclock's servo profile
on the servo build of the firmware (`servo=1`, added by the servo controller), and the
executed path, measured from the arms' servo pulses through the true servos (the profile's
curve and the profile's 1° dead band, which the run compensates), lies within the stated
bound; so does it with the dead band given in the URL (`?deadband=1,1`, issue 38's dead-band
command); true servos with no dead band (`?deadband=0,0`: the compensation overshoots) or a
2° one (`?deadband=2,2`: half of it left) draw off it and fail the run (exit 3)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.devices.sim import toolchain_missing

pytestmark = pytest.mark.skipif(toolchain_missing() is not None,
                                reason=f"emulator unavailable: {toolchain_missing()}")

ROOT = Path(__file__).resolve().parent.parent


def _plot(tmp_path: Path, query: str) -> tuple[int, float, float, str]:
    res = CliRunner().invoke(main, [
        "plot", str(ROOT / "examples" / "fivebar_text.svg"), "--config",
        str(ROOT / "configs" / "plotclock.toml"), "--fit", "--port",
        f"fivebar-sim://?state=off{query}", "--yes", "--preview", str(tmp_path / "p.png")])
    line = next(ln for ln in res.output.splitlines() if ln.startswith("executed path"))
    assert "servo pulses" in line, res.output
    dev = float(line.split("max deviation ")[1].split(" mm")[0])
    # the Plotclock plans on a grid of pulse ticks: the bound is the tolerance plus the pulse
    # quantum, computed here independently from the curve's slope and the Jacobian
    assert "(bound 0.1 + pulse quantum " in line, line
    bound = 0.1 + float(line.split("pulse quantum ")[1].split(" mm")[0])
    assert bound - 0.1 == pytest.approx(_pulse_quantum_mm(tmp_path / "p.executed.csv"),
                                        rel=0.03), line
    return res.exit_code, dev, bound, res.output


def _pulse_quantum_mm(csv: Path) -> float:
    """The pen displacement of a whole 0.5 µs tick on each arm, largest over the poses the
    run passed (the executed CSV's steps on the profile's grid): by finite differences of
    forward kinematics, not the report's Jacobian."""
    import math

    import numpy as np

    from fivebar_host.config import load_profile

    prof = load_profile(ROOT / "configs" / "plotclock.toml")
    tick = math.radians(0.5 / 11.345)  # the profile's straight line: 11.345 µs per degree
    rows = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(1, 2), ndmin=2)
    th = np.asarray(prof.motors.home_rad) + rows * prof.motors.rad_per_step
    p0 = prof.geometry.forward_batch(th, "+")
    q = np.zeros(th.shape[0])
    for j in (0, 1):
        d = np.zeros(2)
        d[j] = tick
        q += np.hypot(*(prof.geometry.forward_batch(th + d, "+").points - p0.points).T)
    return float(q[p0.valid].max())


def test_plotclock_servo_run_within_its_bound(tmp_path: Path) -> None:
    code, dev, bound, out = _plot(tmp_path, "")
    assert code == 0 and 0.0 < dev <= bound, out
    csv = (tmp_path / "p.executed.csv").read_text().splitlines()
    assert len(csv) > 500  # one row per moving frame of the 32 s job


def test_dead_band_compensated_within_its_bound(tmp_path: Path) -> None:
    code, dev, bound, out = _plot(tmp_path, "&deadband=1,1")
    assert code == 0 and 0.0 < dev <= bound, out
    assert "deadband= machine" in out


@pytest.mark.parametrize("band", ["0,0", "2,2"])
def test_true_servos_with_another_dead_band_draw_off_the_bound(tmp_path: Path,
                                                               band: str) -> None:
    code, dev, bound, out = _plot(tmp_path, f"&deadband={band}")
    assert code == 3 and dev > bound, out
    assert "deadband= machine" in out
