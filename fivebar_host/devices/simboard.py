"""The chip, its bootloader and the machine between runs, for `fivebar-sim://`
(`devices/simport.py`): the URL options `bootloader=`, `chip=`, `app=`, `held=`,
`stuck_page=`, `usb=`, `state=`, `power_loss=`, `fresh=`, `stack=` and the harness options
they become (firmware/sim/fbsim.c: -m, -B, -F, -H, -X, -S, -L, -P)."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import serial

from fivebar_host.devices.sim import Emulator, EmulatorError

if TYPE_CHECKING:
    from fivebar_host.devices.simport import SimOptions

SCHEME = "fivebar-sim"
#: The bootloaders the emulator boots: hex file (firmware/build/boot/) per chip.
BOOTLOADERS = {("optiboot", "atmega328p"): "optiboot_atmega328.hex",
               ("optiboot", "atmega168"): "optiboot_atmega168.hex",
               ("atmegaboot", "atmega328p"): "ATmegaBOOT_168_atmega328.hex"}
CHIPS = ("atmega328p", "atmega168")
#: Where machines are kept between runs unless `state=` or $FIVEBAR_SIM_STATE says.
STATE_ENV = "FIVEBAR_SIM_STATE"
#: The application flash at the start with a bootloader: erased, or the firmware on it.
APPS = ("empty", "firmware")


def _flag(value: str, key: str, url: str) -> bool:
    if value not in ("0", "1"):
        raise ValueError(f"{url}: {key} must be 0 or 1, got {value!r}")
    return value == "1"


def parse_board_option(opts: SimOptions, key: str, value: str, url: str) -> bool:
    """The chip, bootloader and between-runs options; False for an unknown key."""
    if key == "bootloader":
        if value not in ("optiboot", "atmegaboot"):
            raise ValueError(f"{url}: bootloader must be optiboot or atmegaboot, got {value!r}")
        opts.bootloader = value
    elif key == "chip":
        if value not in CHIPS:
            raise ValueError(f"{url}: chip must be one of {', '.join(CHIPS)}, got {value!r}")
        opts.chip = value
    elif key == "app":
        if value not in APPS:
            raise ValueError(f"{url}: app must be {' or '.join(APPS)}, got {value!r}")
        opts.app = value
    elif key in ("held", "power_loss", "fresh"):
        setattr(opts, key, _flag(value, key, url))
    elif key == "stuck_page":
        if not value.isdigit() or int(value) >= 256:
            raise ValueError(f"{url}: stuck_page must be a flash page 0-255, got {value!r}")
        opts.stuck_page = int(value)
    elif key == "usb":
        m = re.fullmatch(r"([0-9a-fA-F]{4}):([0-9a-fA-F]{4})", value)
        if m is None:
            raise ValueError(f"{url}: usb must be VID:PID in hex (2341:0043), got {value!r}")
        opts.usb = (int(m.group(1), 16), int(m.group(2), 16))
    elif key == "servo":
        opts.servo = _flag(value, key, url)
    elif key == "deadband":
        try:
            da, db = (float(v) for v in value.split(","))
        except ValueError:
            da = db = -1.0
        if not (0.0 <= da <= 30.0 and 0.0 <= db <= 30.0):
            raise ValueError(f"{url}: deadband must be two angles A,B in 0..30 degrees, got "
                             f"{value!r}")
        opts.deadband = (da, db)
    elif key in ("stack", "timers"):
        path = Path(value)
        if not value or path.is_dir() or not path.parent.is_dir():
            raise ValueError(f"{url}: {key} must be a file to write in an existing "
                             f"directory, got {value!r}")
        setattr(opts, key, path)
    elif key == "state":
        if not value:
            raise ValueError(f"{url}: state must be a directory or off")
        opts.state = value
    else:
        return False
    return True


def state_path(opts: SimOptions) -> Path | None:
    """The file a machine is kept in between runs (module doc), or None (`state=off`)."""
    where = opts.state or os.environ.get(STATE_ENV) or str(
        Path(os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state")
        / SCHEME.split("-")[0] / "sim")
    if where == "off":
        return None
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", opts.machine or "default")
    kind = (f"{opts.bootloader}-{opts.chip}" if opts.bootloader
            else "servo" if opts.servo else "firmware")
    return Path(where).expanduser() / f"{name}-{kind}.state"


def harness_args(opts: SimOptions, work: Path) -> tuple[list[str], bool]:
    """The harness options for the chip, bootloader, faults and state of ``opts``, and
    whether the firmware is loaded as the application."""
    from fivebar_host.devices.sim import firmware_dir

    args: list[str] = []
    app = True
    if opts.bootloader is not None:
        boot = firmware_dir() / "build" / "boot" / BOOTLOADERS[(opts.bootloader, opts.chip)]
        args += ["-m", opts.chip, "-B", str(boot), "-F", str(work / "flash.bin")]
        app = opts.app == APPS[1]
    if opts.held:
        args.append("-H")
    if opts.stuck_page is not None:
        args += ["-X", str(opts.stuck_page)]
    state = state_path(opts)
    if state is not None:
        state.parent.mkdir(parents=True, exist_ok=True)
        if opts.fresh:
            state.unlink(missing_ok=True)
        args += ["-S", str(state), *(["-L"] if opts.power_loss else [])]
    if opts.stack is not None:
        # the cycle profile, written when the harness stops: its "# min_sp" line is the
        # lowest stack pointer of the run (devices/simstack.py reads it)
        args += ["-P", str(opts.stack)]
    if opts.timers is not None:
        # Timer1's compare reads and writes (devices/simtimers.py checks them)
        args += ["-D", str(opts.timers)]
    return args, app


def dump_memories(emu: Emulator, opts: SimOptions) -> tuple[bytes, bytes]:
    """The flash and EEPROM of a harness with a bootloader (its `dump` command)."""
    path = emu.dump_path
    if opts.bootloader is None or path is None:
        raise serial.SerialException(f"{SCHEME}: reading the flash needs bootloader=")
    try:
        emu.control("dump")
    except EmulatorError as e:
        raise serial.SerialException(f"{SCHEME}: {e}") from e
    return path.read_bytes(), Path(str(path) + ".eeprom").read_bytes()
