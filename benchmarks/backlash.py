"""Backlash compensation: where a machine with real slack draws, with and without take-up.

The pattern of UGS's backlash work, a square and a circle (examples/square.gcode), plotted
on the mock device (`fivebar-mock://?backlash=B,B`: the true machine has B steps of slack per
motor) with the default profile, once with `[motors] backlash_steps = [B, B]` (compensated:
a take-up segment at every reversal, compile/backlash.py) and once with 0 (uncompensated).
The executed-path report (fivebar_host/report/text/executed.py) turns the mock's recorded
motor counts into the joints' steps through the slack model (Eq. B1) and measures each
drawing event against the requested curve. Prints, per B and setting: the largest executed
deviation, the bound (tolerance + step quantum), the take-up segments and the planned time.

Run from the repository root: python -m benchmarks.backlash [--lash 8] [--lash 16]
[--file examples/square.gcode]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]
from click.testing import CliRunner  # noqa: E402

from fivebar_host.cli import main  # noqa: E402
from fivebar_host.compile import CompileOptions, compile_job  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from fivebar_host.devices import mock  # noqa: E402
from fivebar_host.report.text.executed import executed_path, ledger_track  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def measure(drawing: Path, true_lash: int, profile_lash: int, tmp: Path) -> dict[str, float]:
    """Plot `drawing` on a mock machine with `true_lash` steps of real slack per motor and a
    profile that compensates `profile_lash`; the executed path's figures."""
    cfg = tmp / f"lash{profile_lash}.toml"
    cfg.write_text(f"[motors]\nbacklash_steps = [{profile_lash}, {profile_lash}]\n")
    name = f"bench{true_lash}_{profile_lash}"
    url = f"fivebar-mock://?machine={name}&speed=0&backlash={true_lash},{true_lash}"
    res = CliRunner().invoke(main, ["plot", str(drawing), "--config", str(cfg), "--port", url,
                                    "--yes"])
    if res.exit_code != 0:
        raise SystemExit(f"plot failed: {res.output}")
    prof = load_profile(cfg)
    job = compile_job(drawing, prof, CompileOptions())
    m = mock.machine(name)
    t, track = ledger_track(m.ledger)
    ex = executed_path(job, prof, t, track, backlash=m.backlash)
    joint = np.diff(job.joint_steps, axis=0)
    motor = np.diff(job.steps.astype(np.int64), axis=0)
    piece = (joint == 0).all(axis=1) & (motor != 0).any(axis=1)  # pieces of take-ups
    take = int(piece[0]) + int((piece[1:] & ~piece[:-1]).sum())  # take-ups (runs of pieces)
    return {"dev": ex.max_deviation_mm, "bound": job.tolerance_mm + job.step_quantum_mm,
            "takeups": take, "time": job.total_time_s}


def main_cli() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--lash", type=int, action="append", help="true slack, steps (repeat)")
    ap.add_argument("--file", type=Path, default=ROOT / "examples" / "square.gcode")
    args = ap.parse_args()
    lashes = args.lash or [8]
    print(f"drawing {args.file.name}; mock true machine with B steps of slack per motor")
    print(f"{'B':>3} {'profile':>12} {'max dev mm':>11} {'bound mm':>9} {'within':>7} "
          f"{'take-ups':>9} {'time s':>8}")
    with tempfile.TemporaryDirectory() as d:
        for lash in lashes:
            for comp in (lash, 0):
                mock.forget_machines()
                r = measure(args.file, lash, comp, Path(d))
                label = "compensated" if comp else "none"
                ok = "yes" if r["dev"] <= r["bound"] else "NO"
                print(f"{lash:>3} {label:>12} {r['dev']:>11.4f} {r['bound']:>9.4f} {ok:>7} "
                      f"{int(r['takeups']):>9} {r['time']:>8.3f}")


if __name__ == "__main__":
    main_cli()
