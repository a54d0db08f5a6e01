"""A profile whose joints step faster than the firmware's boot `$0` (configs/raster-fast.toml:
20 rad/s = 40,744 steps/s against 20,000): the bridge raises `$0` once, as `fivebar plot`
does per job, so a G0 at the profile's 800 mm/s travel feed runs instead of being refused by
the firmware (error:12, which the sender saw as an alarm before)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from grbl_client import mpos
from grbl_support import ORIGIN, start_bridge, stop_bridge

from fivebar_host.compile.emit import firmware_rate
from fivebar_host.config import load_profile

FAST = Path(__file__).resolve().parents[2] / "configs" / "raster-fast.toml"


@pytest.mark.parametrize("kind", ["mock", pytest.param("sim", marks=pytest.mark.sim)])
def test_fast_travel_runs_on_a_fast_profile(kind: str, tmp_path: Path,
                                            request: pytest.FixtureRequest) -> None:
    if kind == "sim":
        request.getfixturevalue("sim_build")
    prof = load_profile(FAST)
    need = prof.motion.max_joint_rad_s / prof.motors.rad_per_step
    assert need > 20000  # the case: beyond the firmware's boot step rate
    r = start_bridge(kind, tmp_path, profile=FAST)
    try:
        assert r.core.compiler.max_rate_steps_s == firmware_rate(need)
        c = r.client()
        assert c.command("$X")[1] == "ok"
        for x, y in ((30.0, 40.0), (0.0, 0.0), (30.0, 0.0)):
            assert c.command(f"G0 X{x:g} Y{y:g}")[1] == "ok"
        st = c.wait_state("Idle")
        assert "Alarm" not in st
        px, py, _ = mpos(st)
        assert math.hypot(px - (ORIGIN[0] + 30), py - ORIGIN[1]) < 0.05 + 0.03, st
        c.close()
    finally:
        stop_bridge(r)
