"""LaserGRBL-style raster files through `fivebar bridge` (issue 32's bridge goal), on the
default profile and the emulated firmware in real time (`fivebar-sim://?realtime=1`, 115200
baud), streamed by a character-counting GRBL sender (`benchmarks/grbl.py`'s) over TCP.

The file (`benchmarks/lasergrbl.py`): a random image of runs (1 … 20 px, S 0/150 … 900 of
$30 = 1000), `--rows` × `--cols` px at 10 px/mm, F3000, in LaserGRBL's line-to-line form
(`G1 X.. S..` per run, white runs and the step to the next row as `G0 X Y S0`,
alternate rows reversed), once with M3 and once with M4.  From the emulator's pin trace
(step pulses → forward kinematics; the laser pin's PWM), against the file's own runs:

- px/s: the image's pixels (rows × cols, as the issue counts GRBL's 489 px/s) ÷ the time from
  the first laser rise to the last fall; beside it the px/s of the rows' burned stretches
  and the planned turnaround per row (its ramps and the step to the next row);
- boundary coverage: the share of the file's run boundaries where the pin shows a power
  change with the pen within 0.05 mm of the boundary, and the largest such distance;
- power changes inside constant runs; laser-on steps off the file's burning runs.

Also printed: a row's planned cost beyond its burn (the two overscan ramps, the step to the
next row) and the px/s it allows — what limits the rate on a profile.

Run: python benchmarks/bridge_raster.py [--rows 200] [--cols 400] [--config PROFILE]
[--accel RAD_S2] [--no-scanlines]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# Run as a script, this folder comes first on sys.path and benchmarks/kinematics.py would
# shadow the package of that name.
sys.path[:] = [str(ROOT)] + [p for p in sys.path
                             if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

from benchmarks import lasergrbl as lg  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from fivebar_host.devices import register  # noqa: E402
from fivebar_host.devices.sim import toolchain_missing  # noqa: E402
from fivebar_host.raster import motion  # noqa: E402

#: GRBL 1.1h on the same file in the same emulator (issue 32).
GRBL_PX_S = 489.0
ORIGIN = (0.0, 95.0)
FEED = 3000.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=200)
    ap.add_argument("--cols", type=int, default=400)
    ap.add_argument("--config", default=None, help="a machine profile (default: the bundled "
                    "configs/default.toml)")
    ap.add_argument("--accel", type=float, default=None, help="the profile with this "
                    "max_joint_rad_s2 instead (what the joints' acceleration costs)")
    ap.add_argument("--no-scanlines", action="store_true", help="every run its own planned "
                    "move, as before the scanlines (the comparison)")
    args = ap.parse_args()
    register()
    reason = toolchain_missing()
    if reason is not None:
        print(f"emulator unavailable: {reason}")
        return 1
    prof = load_profile(args.config)
    if args.accel is not None:
        prof = replace(prof, motion=replace(prof.motion, max_joint_rad_s2=args.accel))
        args.config = (f"{args.config or 'configs/default.toml'} with max_joint_rad_s2 "
                       f"{args.accel:g}")
    img = lg.image(args.rows, args.cols, seed=7)
    h = 0.1
    print(f"LaserGRBL-style file: {args.rows} rows x {args.cols} px at 10 px/mm, F{FEED:g}, "
          f"{args.config or 'the default profile'} (max_joint_rad_s2 "
          f"{prof.motion.max_joint_rad_s2:g}, ramps at {motion.ACCEL_SHARE:g} of it), "
          f"emulator in real time at {prof.serial.baud} baud")
    ramps, step, burn = lg.turnaround_ms(prof, cols=args.cols, feed_mm_s=FEED / 60)
    print(f"planned a row ({args.cols} px): burn {burn:.0f} ms at F, the two overscan ramps "
          f"{ramps:.1f} ms (joint acceleration), the step to the next row {step:.1f} ms "
          f"(from rest: joint acceleration and junction jump) -> at most "
          f"{args.cols / (burn + ramps + step) * 1e3:.0f} px/s")
    print(f"GRBL 1.1h on such a file (issue 32, Cartesian): {GRBL_PX_S:.0f} px/s; the file's F: "
          f"{FEED / 60 / h:.0f} px/s")
    ok = True
    if args.no_scanlines:
        from fivebar_host.bridge import scanlines

        scanlines.find = lambda chunk: []  # type: ignore[assignment]
        print("scanlines off: every run its own planned move (the comparison)")
    for spindle in (3, 4):
        lines, ref = lg.raster_file(img, 1 / h, FEED, spindle, (0.0, args.rows * h), ORIGIN)
        with tempfile.TemporaryDirectory() as tmp:
            trace = Path(tmp) / "pins.trace"
            run = lg.stream_file(lines, trace, prof, ORIGIN, realtime=True)
            if run.error is not None:
                print(f"M{spindle}: the sender got {run.error}; the bridge said:")
                print("\n".join("  " + s for s in run.log if not s.startswith("'"))[:800])
                ok = False
                continue
            f = lg.burn_figures(trace, prof, ref, run.start)
        image_px = args.rows * args.cols
        rate = image_px / f.seconds
        burn_s = f.pixels * h / (FEED / 60)
        turn_ms = (f.seconds - burn_s) / args.rows * 1e3
        refused = [s for s in run.log if "runs as ordinary" in s]
        print(f"M{spindle}: {len(lines)} G-code lines, last ok {run.ok_s:.1f} s, idle "
              f"{run.idle_s:.1f} s; {len(refused)} raster lines run as ordinary moves; motion "
              f"{f.motion_s:.2f} s executed / {run.planned_s:.2f} s planned")
        checks = [
            (f"px/s >= 1.0 x GRBL's {GRBL_PX_S:.0f}", rate >= GRBL_PX_S,
             f"{rate:.0f} px/s ({rate / GRBL_PX_S:.2f}x; {image_px} px in {f.seconds:.2f} s;"
             f" burned stretches {f.rate:.0f} px/s; {turn_ms:.1f} ms a row beyond the "
             "burn at F)"),
            ("boundary coverage >= 99.9 %", f.coverage >= 0.999,
             f"{100 * f.coverage:.2f} % of {f.boundaries}"),
            ("max boundary distance <= 0.05 mm", f.max_distance_mm <= 0.05,
             f"{f.max_distance_mm:.4f} mm"),
            ("power changes inside constant runs: 0", f.inside_changes == 0,
             f"{f.inside_changes} (of {f.changes} changes)"),
            ("laser-on steps off the runs: 0", f.outside_steps == 0, f"{f.outside_steps}"),
        ]
        for name, good, text in checks:
            ok &= good
            print(f"  {name:40s} {text}  {'ok' if good else 'MISSED'}")
        for r, x, c in f.inside_at[:5]:
            print(f"    a change inside a run: row {r}, x {x:.3f} mm, at {c / 16e6:.4f} s")
    return 0 if ok else 2


if __name__ == "__main__":
    sys.exit(main())
