"""The servo build of the firmware in the emulator (`make -C firmware SERVO=1`).

The servo build (firmware/fivebar/board_servo.c) drives the arm servos from Timer1's
hardware compares: a joint's position, in the same protocol's "steps", is its pulse width
in ticks of 0.5 µs (3000 = 1500 µs), and every 20 ms frame sends each arm one pulse of the
width the joint has at the frame's start. The harness traces those pins as ``svA`` and
``svB`` (fbsim ``-V``); `frame_pulses` reads them back as (frame start, width µs).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from fivebar_host.devices.sim import (
    BuildPaths,
    Emulator,
    EmulatorError,
    SimDevice,
    boot,
    firmware_dir,
    toolchain_missing,
)
from fivebar_host.devices.simtrace import Trace

#: Position units (pulse ticks) per µs of the servo build (config.h CFG_SERVO_TICKS_US).
TICKS_PER_US = 2
#: The emulated clock, Hz.
F_CPU = 16_000_000
#: The arm servos' trace names, joint A then B.
SERVO_PINS = ("svA", "svB")


def ensure_servo_built(directory: Path | None = None) -> BuildPaths:
    """Build the servo firmware (build/servo/) and the harness with make (a no-op when up to
    date). Raises EmulatorError when the toolchain is missing or the build fails."""
    reason = toolchain_missing()
    if reason:
        raise EmulatorError(reason)
    fw = directory or firmware_dir()
    out = []
    for args in (["SERVO=1", "all"], ["sim"]):
        proc = subprocess.run(["make", "-s", "-C", str(fw), *args], capture_output=True,
                              text=True, check=False)
        if proc.returncode != 0:
            raise EmulatorError(f"servo firmware build failed:\n{proc.stdout}\n{proc.stderr}")
        out.append(proc.stdout)
    servo = fw / "build" / "servo"
    return BuildPaths(servo / "fivebar.elf", servo / "fivebar.hex", fw / "build" / "fbsim",
                      out[0])


def start_servo_device(build: BuildPaths, trace_path: Path, timeout: float = 10.0,
                       realtime: bool = False) -> SimDevice:
    """Start the harness on the servo build with its arm servo pins traced, open its pty and
    read the boot banner."""
    emu = Emulator(build.elf, build.harness, trace_path, realtime=realtime, extra=("-V",))
    return boot(emu, trace_path, timeout)


def frame_pulses(trace: Trace, joint: int) -> list[tuple[int, float]]:
    """(rising-edge cycle, width µs) of every complete pulse of arm servo `joint` (0, 1)."""
    return [(c, w * 1e6 / F_CPU) for c, w in trace.pulses(SERVO_PINS[joint])]
