"""`fivebar flash` against real Arduino bootloaders in the emulator: Optiboot at 115200 and
the old ATmegaBOOT at 57600 self-program the emulated ATmega328P's flash (simavr's SPM), the
flash is compared with the hex, and the new firmware must answer. Each failure a maker meets
is provoked and its one-line message checked; avrdude (Debian's) programs the same emulated
bootloader as the cross-check that it behaves like the real one."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.devices import simport
from fivebar_host.devices.sim import ARDUINO_BOOTLOADERS, BuildPaths
from fivebar_host.flash.hexfile import read_hex

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(not (ARDUINO_BOOTLOADERS / "optiboot").exists(),
                                reason="arduino-core-avr (the bootloaders) not installed")


@pytest.fixture(autouse=True)
def _machines() -> object:
    simport.forget_machines()
    yield
    simport.forget_machines()


def flash(url: str, *args: str) -> tuple[int, str]:
    """Run `fivebar flash --port URL` in this process (named machines outlive it)."""
    res = CliRunner().invoke(main, ["flash", "--port", url, *args])
    return res.exit_code, res.output


def check_flashed(name: str, build: BuildPaths, boot_start: int) -> bytes:
    """The named machine's flash holds the hex, erased up to the bootloader; its EEPROM."""
    flash_bytes, eeprom = simport.machine(name).flash_image()
    image = read_hex(build.hex).data
    assert flash_bytes[:len(image)] == image
    assert set(flash_bytes[len(image):boot_start]) <= {0xFF}
    return eeprom


@pytest.mark.parametrize(("bootloader", "baud", "boot_start", "name"), [
    ("optiboot", 115200, 0x7E00, "Optiboot 4.4"),
    ("atmegaboot", 57600, 0x7800, "ATmegaBOOT")])
def test_flash_writes_verifies_and_the_firmware_answers(
        sim_build: BuildPaths, bootloader: str, baud: int, boot_start: int, name: str) -> None:
    url = f"fivebar-sim://?bootloader={bootloader}&machine=fl-{bootloader}&usb=1a86:7523"
    code, out = flash(url)
    print(out)
    assert code == 0, out
    assert "board: a CH340 USB serial adapter" in out
    assert f"bootloader: {name}" in out and f"at {baud} baud" in out
    assert "written and verified" in out and "the firmware answers: fivebar" in out
    check_flashed(f"fl-{bootloader}", sim_build, boot_start)
    emulated = float(out.split("s of emulated time")[0].rsplit("; ", 1)[1])
    if baud == 115200:
        assert emulated <= 8.0  # the goal for the whole image at 115200


def test_flash_writes_the_pen_park_pulse_into_the_eeprom(sim_build: BuildPaths) -> None:
    code, out = flash("fivebar-sim://?bootloader=optiboot&machine=fl-pen",
                      "--config", str(ROOT / "configs" / "pen-servo.toml"))
    assert code == 0, out
    park = int(out.split("EEPROM: $14=")[1].split()[0])
    eeprom = check_flashed("fl-pen", sim_build, 0x7E00)
    value = int.from_bytes(eeprom[0:2], "little")
    assert value == park and int.from_bytes(eeprom[2:4], "little") == park ^ 0xFFFF


@pytest.mark.parametrize(("url", "expected"), [
    ("fivebar-sim://?bootloader=optiboot&held=1",
     "no reply from a bootloader at 115200 baud nor 57600 baud"),
    ("fivebar-sim://", "answered as the fivebar firmware"),
    ("fivebar-sim://?bootloader=optiboot&chip=atmega168",
     "signature is 1E 94 06 (ATmega168), not the ATmega328P's 1E 95 0F"),
    ("fivebar-sim://?bootloader=optiboot&stuck_page=3",
     "verify failed: flash byte 0x0180"),
    ("fivebar-sim://?bootloader=optiboot&usb=2341:1002", "Arduino UNO R4"),
    ("fivebar-sim://?bootloader=optiboot&usb=2341:0058", "Nano Every (ATmega4809"),
])
def test_each_failure_is_one_line_with_cause_and_fix(sim_build: BuildPaths, url: str,
                                                     expected: str) -> None:
    code, out = flash(url)
    print(out)
    assert code == 3
    err = [ln for ln in out.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and expected in err[0]


def test_a_busy_port_is_named_as_such(sim_build: BuildPaths) -> None:
    import serial

    held = serial.serial_for_url("fivebar-sim://?bootloader=optiboot&machine=fl-busy",
                                 timeout=0.1)
    try:
        code, out = flash("fivebar-sim://?bootloader=optiboot&machine=fl-busy")
    finally:
        held.close()
    assert code == 3 and "the port is in use by another program" in out


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to become another user")
def test_permission_denied_names_the_dialout_group() -> None:
    """A user outside the port's group: a child process drops root for `nobody` and opens
    a root-owned 0600 pty, as /dev/ttyUSB0 (root:dialout 0660) is for a user not in
    dialout; the real EACCES goes through `flash_board`."""
    from fivebar_host.config import load_profile
    from fivebar_host.flash.failures import FlashError
    from fivebar_host.flash.flasher import flash_board

    image = read_hex(ROOT / "firmware" / "build" / "fivebar.hex")
    profile = load_profile(None)
    master, slave = os.openpty()
    read_end, write_end = os.pipe()
    tty = os.ttyname(slave)
    os.chmod(tty, 0o600)
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        msg = "no error"
        try:
            os.setgroups([])
            os.setgid(65534)
            os.setuid(65534)
            flash_board(tty, image, profile)
        except FlashError as e:
            msg = f"{e.exit_code} {e}"
        except BaseException as e:
            msg = f"unexpected {e!r}"
        os.write(write_end, msg.encode())
        os._exit(0)
    os.close(write_end)
    os.waitpid(pid, 0)
    msg = os.read(read_end, 4096).decode()
    for fd in (read_end, master, slave):
        os.close(fd)
    assert msg.startswith("3 ") and "permission denied" in msg and "dialout" in msg, msg


@pytest.mark.skipif(shutil.which("avrdude") is None, reason="avrdude not installed")
def test_avrdude_programs_the_same_emulated_bootloader(sim_build: BuildPaths,
                                                       tmp_path: Path) -> None:
    from fivebar_host.devices.sim import Emulator

    boot = sim_build.harness.parent / "boot" / "optiboot_atmega328.hex"
    dump = tmp_path / "flash.bin"
    emu = Emulator(Path("-"), sim_build.harness, realtime=True,
                   extra=["-B", str(boot), "-F", str(dump)])
    emu.dump_path = dump
    pty = emu.start()
    try:
        proc = subprocess.run(["avrdude", "-c", "arduino", "-p", "m328p", "-P", pty, "-b",
                               "115200", "-U", f"flash:w:{sim_build.hex}:i"],
                              capture_output=True, text=True, timeout=120, check=False)
        print(proc.stderr[-1500:])
        emu.control("dump")
    finally:
        emu.stop()
    assert proc.returncode == 0
    assert "bytes of flash verified" in proc.stderr
    image = read_hex(sim_build.hex).data
    assert dump.read_bytes()[:len(image)] == image
