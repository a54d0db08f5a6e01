"""`fivebar-sim://` — a pyserial port that is the real firmware running in simavr.

Opening the port builds the firmware and the harness if needed (`make -C firmware all sim`),
starts the harness (which holds the CPU until a client opens its pty, so the boot banner is not
lost) and opens the pty. Closing stops the harness, which flushes its pin trace.

URL options: `fivebar-sim://?trace=PATH&realtime=1&endstops=A,B&machine=NAME&reset_after=N`
- `trace`: where the harness records every step, direction and laser pin change (default: a
  temporary file, available as `port.trace_path` after close; None for a named machine,
  whose trace spans every open: `machine(NAME).trace_path`);
- `realtime=1`: throttle emulation to wall-clock speed (otherwise it runs 6–8× faster);
- `endstops=A,B`: simulated endstop switch positions in steps (enables homing tests); either
  may be empty (no switch);
- `machine=NAME`: the harness outlives the port: ports opened with the same name within this
  Python process drive one emulated machine, and opening it again is a DTR reset of the AVR
  (its RAM kept, docs/protocol.md section 7), as the Uno's auto-reset does.  The pin trace
  accumulates over all opens; `machine(NAME)` gives its `trace_path`, `trace()` (flushed and
  parsed while the harness runs) and `power_cut()`, and `forget_machines()` stops them all
  (their trace files stay).  A second open while the first port is open fails as a busy port.
  The machine's harness options (`trace`, `realtime`, `endstops`) are those of its first open;
  a later open may repeat them but not change them;
- `disconnect_after=N`: after the N-th line (the N-th `\\n` written to this port) every read and
  write raises `serial.SerialException`; the emulated firmware runs on (it finishes its queue,
  or holds it when its laser silence timeout strikes);
- `reset_after=N`: after the N-th line the AVR resets with its RAM kept, as by a glitch;
- `power_cut_after=N`: after the N-th line the AVR loses power and boots again: its RAM comes
  back random (position, `H` and `Ln` done are lost); the motors stay where they are;
- `stall_after=N`: after the N-th line the firmware hangs (the harness's `hang`: it spins with
  interrupts off, no replies, no motion, pins unchanged) until its watchdog resets it, about
  256 ms of emulated time later: laser off, banner, the position, `H` and `Ln` done kept, as
  after a DTR reset;
- `true=a1,b1,a2,b2,w,home1,home2` (mm, degrees): the machine as really built, where it
  differs from the profile; the executed-path report after `fivebar plot` then measures where
  that machine draws (calibration tests: docs/calibration.md);
- `backlash=A,B` (steps): each motor's real slack (gears, belts), where it differs from the
  profile's `[motors] backlash_steps`; the executed-path report draws through it
  (`compile.backlash.play`; docs/backlash.md);
- `bootloader=optiboot|atmegaboot`: the chip boots a real bootloader (firmware/Makefile
  `bootloaders`: Optiboot at 115200 built from Debian's arduino-core-avr source, the old
  ATmegaBOOT at 57600) at its boot section, as an Uno or an old Nano does, with its
  application flash erased (`app=firmware`: already holding the fivebar firmware); `fivebar
  flash` and avrdude program it over the pty, `port.flash_image()` reads the flash back.
  Emulation then runs in real time (the bootloaders' timeouts are in wall-clock terms for
  the programmer). `chip=atmega168` puts Optiboot on an ATmega168 (another signature);
- `held=1`: the chip is held in reset (a shield or a wire on RESET): it never answers;
  `stuck_page=N`: flash page N (128 bytes) does not take a write (worn or locked flash);
  `usb=VID:PID` (hex): the USB ids the port reports, as a real adapter's (`fivebar flash`
  and `doctor` read them: `fivebar_host.flash.boards`);
- the machine between runs: a harness keeps its controller and arms in a state file when
  it stops (`$FIVEBAR_SIM_STATE`, default `~/.local/state/fivebar/sim/`; `state=DIR`, or
  `off` for a new machine every time, as the tests use): the next run (another command,
  another process) finds the controller powered as it was (its RAM: position, `H`, `Ln`
  done, as after the DTR reset of opening a port) and the arms where they stopped, as a
  real machine that stayed on. `power_loss=1`: the controller lost power since (its RAM
  is random, the arms stay); `fresh=1`: a new machine at the home pose;
- `stack=FILE`: the harness records, per flash address, the emulated cycles spent there and
  the lowest stack pointer seen, and the lowest of all (`# min_sp`), written to FILE when it
  stops (fbsim `-P`: it then emulates one instruction a step, slower);
  `devices.simstack.read_stack` turns it into the stack's headroom at its deepest (bytes
  above the static RAM's end; `python benchmarks/stack.py`);
- `timers=FILE`: the harness logs every write of Timer1's compares with the timer's count
  then (fbsim `-D`); `devices.simtimers.late_compares` finds a compare armed at or behind
  the timer (which waits a whole timer period, 4.1 ms; tests/firmware/test_compares_sim.py);
- `drop=P`, `corrupt=P`, `seed=N`: line noise, as on the mock: each host→device byte other than
  a real-time byte is lost with probability P, or replaced by another printable byte that is
  not a real-time byte (seeded generator, default seed 0); line counting for the options
  above counts the newlines the host wrote.

For the three glitches the bytes written up to the N-th line reach the AVR first and the rest of
that write is lost; each fault fires once per port.  A DTR edge (`port.dtr = False`, then
`True`, as `Link.hardware_reset` does) resets the AVR with its RAM kept.  The harness applies a
reset or a hang where the firmware has interrupts enabled (firmware/sim/fbsim.c).

The harness dies with the thread that started it (`PR_SET_PDEATHSIG`): open a named machine
for the first time from a thread that lives as long as the machine should.
"""

from __future__ import annotations

import atexit
import math
import random
import tempfile
import threading
import urllib.parse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import serial

from fivebar_host.devices.sim import Emulator, EmulatorError, ensure_built
from fivebar_host.devices.simboard import (
    BOOTLOADERS,
    dump_memories,
    harness_args,
    parse_board_option,
)
from fivebar_host.devices.simtrace import Trace, read_trace

SCHEME = "fivebar-sim"

#: Options that configure the harness process (fixed by a machine's first open).
HARNESS_OPTIONS = ("trace", "realtime", "endstops", "bootloader", "chip", "app", "held",
                   "stuck_page", "state", "servo", "stack", "timers")
#: Fault options: what happens after the N-th line, and the harness command for it.
FAULTS = {"disconnect_after": None, "reset_after": "reset", "power_cut_after": "power",
          "stall_after": "hang"}
#: Line noise options (per-byte probabilities) and the seed of their generator.
NOISE = ("drop", "corrupt")
_KNOWN = (*HARNESS_OPTIONS, "machine", *FAULTS, *NOISE, "seed", "true", "backlash", "usb",
          "power_loss", "fresh", "deadband")
#: Real-time bytes pass untouched; a corruption never produces one (docs/protocol.md 2).
_REALTIME = frozenset(b"?!~\x18")
_CORRUPT_BYTES = bytes(c for c in range(0x20, 0x7F) if c not in _REALTIME)


@dataclass
class SimOptions:
    """The options of a `fivebar-sim://` URL (see the module docstring)."""

    trace: Path | None = None
    realtime: bool = False
    endstops: tuple[int | None, int | None] = (None, None)
    machine: str | None = None
    faults: dict[str, int] | None = None
    drop: float = 0.0
    corrupt: float = 0.0
    seed: int = 0
    #: The machine as really built (a1, b1, a2, b2, w mm, home1, home2 degrees), where it
    #: differs from the profile: the executed-path report measures what it really draws.
    true: tuple[float, ...] | None = None
    #: Each motor's real slack in steps, where it differs from the profile's backlash.
    backlash: tuple[int, int] | None = None
    #: The servo build (`servo=1`, docs/protocol.md 6.5; the servo controller adds it) and
    #: the true servos' dead band, degrees per joint (`deadband=A,B`), where it differs
    #: from none: the executed-path report reads the arms' pulses through them.
    servo: bool = False
    deadband: tuple[float, float] | None = None
    bootloader: str | None = None
    chip: str = "atmega328p"
    app: str = "empty"
    held: bool = False
    stuck_page: int | None = None
    usb: tuple[int, int] | None = None
    #: Where the harness writes its cycle profile and lowest stack pointer (`stack=FILE`,
    #: fbsim -P) when it stops: the stack's deepest point over the run (devices/simstack.py).
    stack: Path | None = None
    #: Where the harness logs Timer1's compare writes (`timers=FILE`, fbsim -D): every
    #: compare armed ahead of the timer (devices/simtimers.py).
    timers: Path | None = None
    state: str | None = None  # a directory, "off", or None: $FIVEBAR_SIM_STATE or the default
    power_loss: bool = False
    fresh: bool = False
    given: frozenset[str] = frozenset()  # the harness options the URL names


def parse_true_geometry(text: str, url: str) -> tuple[float, ...]:
    """`true=a1,b1,a2,b2,w,home1,home2` (mm, degrees): seven finite numbers, positive
    lengths, home angles within ±360°."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if (len(vals) != 7 or not all(math.isfinite(v) for v in vals)
            or any(v <= 0 for v in vals[:5]) or any(abs(v) > 360 for v in vals[5:])):
        raise ValueError(f"{url}: true must be a1,b1,a2,b2,w,home1,home2 (positive mm, "
                         f"degrees within ±360), got {text!r}")
    return vals


def parse_backlash(text: str, url: str) -> tuple[int, int]:
    """`backlash=A,B`: each motor's real slack, two whole steps in 0–10000."""
    parts = text.split(",")
    if len(parts) != 2 or not all(p.strip().isdigit() and int(p) <= 10_000 for p in parts):
        raise ValueError(f"{url}: backlash must be two step counts A,B in 0..10000, got "
                         f"{text!r}")
    return int(parts[0]), int(parts[1])


def parse_sim_url(url: str) -> SimOptions:
    """Options of a `fivebar-sim://` URL; unknown or malformed options raise ValueError."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != SCHEME:
        raise ValueError(f"expected a {SCHEME}:// URL, got {url!r}")
    opts = SimOptions(faults={})
    given = set()
    for key, values in urllib.parse.parse_qs(parts.query, keep_blank_values=True).items():
        value = values[-1]
        given.add(key)
        if key == "trace":
            opts.trace = Path(value)
        elif key == "realtime":
            if value not in ("0", "1"):
                raise ValueError(f"{url}: realtime must be 0 or 1, got {value!r}")
            opts.realtime = value == "1"
        elif key == "endstops":
            try:
                a, b = (int(v) if v else None for v in value.split(","))
            except ValueError:
                raise ValueError(f"{url}: endstops must be two step counts 'A,B' (either may "
                                 f"be empty), got {value!r}") from None
            opts.endstops = (a, b)
        elif key == "machine":
            if not value:
                raise ValueError(f"{url}: machine needs a name")
            opts.machine = value
        elif key in FAULTS:
            if not value.isdigit() or int(value) < 1:
                raise ValueError(f"{url}: {key} must be a line count >= 1, got {value!r}")
            assert opts.faults is not None
            opts.faults[key] = int(value)
        elif key in NOISE:
            try:
                prob = float(value)
            except ValueError:
                prob = -1.0
            if not 0.0 <= prob < 1.0:
                raise ValueError(f"{url}: {key} must be a probability in [0, 1), got {value!r}")
            setattr(opts, key, prob)
        elif key == "seed":
            if not value.isdigit():
                raise ValueError(f"{url}: seed must be a whole number >= 0, got {value!r}")
            opts.seed = int(value)
        elif key == "true":
            opts.true = parse_true_geometry(value, url)
        elif key == "backlash":
            opts.backlash = parse_backlash(value, url)
        elif not parse_board_option(opts, key, value, url):
            raise ValueError(f"{url}: unknown option {key!r} (known: {', '.join(_KNOWN)})")
    if opts.bootloader is None and (opts.chip != "atmega328p" or "app" in given):
        raise ValueError(f"{url}: chip and app describe a chip with a bootloader: add "
                         "bootloader=optiboot or bootloader=atmegaboot")
    if opts.bootloader is not None and (opts.bootloader, opts.chip) not in BOOTLOADERS:
        raise ValueError(f"{url}: no {opts.bootloader} for the {opts.chip} here (known: "
                         + ", ".join(f"{b} on {c}" for b, c in BOOTLOADERS) + ")")
    opts.given = frozenset(given & set(HARNESS_OPTIONS))
    return opts


class SimMachine:
    """A named emulated machine: one harness that outlives the ports opened on it."""

    def __init__(self, name: str, emulator: Emulator, trace_path: Path, options: SimOptions
                 ) -> None:
        self.name = name
        self.emulator = emulator
        self.trace_path = trace_path
        self.options = options
        self.port: Serial | None = None  # the port open on it now

    @property
    def running(self) -> bool:
        """True while its harness runs."""
        return self.emulator.running

    def flush(self) -> None:
        """Write the trace file out (nothing to do once the harness stopped)."""
        if self.running:
            self.emulator.control("flush")

    def trace(self) -> Trace:
        """The pin trace of every open so far (flushed first while the harness runs; it may
        write on meanwhile, so a running harness's trace ends at its last complete line)."""
        live = self.running
        self.flush()
        return read_trace(self.trace_path, live=live)

    def flash_image(self) -> tuple[bytes, bytes]:
        """Its chip's flash and EEPROM now (with `bootloader=`)."""
        return dump_memories(self.emulator, self.options)

    def power_cut(self) -> None:
        """Cut the controller's power and power it up: its RAM comes back random, so the
        firmware boots as at power-on (A:0,B:0, H:0, Ln:0,0); the motors stay where they are.
        With a port open the banner follows on it."""
        if self.running:
            self.emulator.control("power")

    def stop(self) -> str:
        """Stop the harness and forget the machine (its trace file stays); returns the
        harness's statistics.  A later open of the name powers a new machine up."""
        if self.port is not None:
            self.port.close()
        with _MACHINES_LOCK:
            if _MACHINES.get(self.name) is self:
                del _MACHINES[self.name]
        return self.emulator.stop()


_MACHINES: dict[str, SimMachine] = {}
_MACHINES_LOCK = threading.Lock()


def machine(name: str) -> SimMachine:
    """The machine of `fivebar-sim://?machine=NAME`; KeyError before its first open."""
    with _MACHINES_LOCK:
        if name not in _MACHINES:
            raise KeyError(f"no emulated machine {name!r} (open {SCHEME}://?machine={name} first)")
        return _MACHINES[name]


def forget_machines() -> None:
    """Stop every named machine's harness and forget them (their trace files stay)."""
    with _MACHINES_LOCK:
        machines = list(_MACHINES.values())
    for m in machines:
        m.stop()


atexit.register(forget_machines)


def _new_emulator(opts: SimOptions) -> tuple[Emulator, Path]:
    """Build if needed and make (not start) a harness for ``opts``; returns it and its trace
    path."""
    try:
        if opts.servo:
            from fivebar_host.devices.simservo import ensure_servo_built

            build = ensure_servo_built()
        else:
            build = ensure_built(bootloaders=opts.bootloader is not None)
    except EmulatorError as e:
        raise serial.SerialException(f"{SCHEME}: {e}") from e
    work = Path(tempfile.mkdtemp(prefix="fivebar-sim-"))
    trace = opts.trace or work / "pins.trace"
    a, b = opts.endstops
    try:
        extra, app = harness_args(opts, work)
    except OSError as e:
        raise serial.SerialException(f"{SCHEME}: cannot keep the machine's state: {e}") from e
    # a bootloader's timeouts are wall-clock time for its programmer: run in real time
    emu = Emulator(build.elf if app else Path("-"), build.harness, trace, a, b,
                   opts.realtime or opts.bootloader is not None,
                   [*extra, *(["-V"] if opts.servo else [])])
    emu.dump_path = work / "flash.bin"
    return emu, trace


class Serial(serial.SerialBase):  # type: ignore[misc]  # pyserial has no type hints
    """The emulated firmware behind a pyserial interface (delegates to the harness pty)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._inner: serial.Serial | None = None
        self._emu: Emulator | None = None
        self._machine: SimMachine | None = None
        self.options = SimOptions()
        self._rng = random.Random(0)  # line noise (`drop`, `corrupt`), seeded on open
        self.trace_path: Path | None = None
        self.stats = ""
        self._lines = 0
        self._fired: set[str] = set()
        self._broken = ""  # why the link is gone (disconnect_after), or ''
        self._dtr_last = True
        super().__init__(*args, **kwargs)

    @property
    def machine(self) -> SimMachine | None:
        """The named machine this port drives (None without ``machine=``)."""
        return self._machine

    @property
    def usb_id(self) -> tuple[int, int] | None:
        """The USB vendor and product ids the URL's `usb=` gives this port (None: not a USB
        adapter's), as `serial.tools.list_ports` reports a real one's."""
        return self.options.usb

    def flash_image(self) -> tuple[bytes, bytes]:
        """The emulated chip's flash and EEPROM now (with `bootloader=`; the harness's
        `dump`)."""
        return dump_memories(self._emulator(), self.options)

    def emulated_cycle(self) -> int:
        """The emulated CPU's cycle count (its clock: 16 MHz)."""
        try:
            return self._emulator().cycle()
        except EmulatorError as e:
            raise serial.SerialException(f"{SCHEME}: {e}") from e

    def open(self) -> None:
        """Start the harness (or reset the named machine's AVR) and open its pty."""
        if self._port is None:
            raise serial.SerialException("port must be configured before it can be used")
        if self._inner is not None:
            raise serial.SerialException("port already open")
        try:
            opts = parse_sim_url(str(self._port))
        except ValueError as e:
            raise serial.SerialException(str(e)) from e
        self.options = opts
        self._lines, self._fired, self._broken = 0, set(), ""
        self._rng = random.Random(opts.seed)
        if opts.machine is None:
            emu, self.trace_path = _new_emulator(opts)
            self._open_pty(emu, fresh=True)
            self._emu = emu
        else:
            self._open_machine(opts, opts.machine)
        self._dtr_last = self._dtr_state
        self.is_open = True

    def _open_machine(self, opts: SimOptions, name: str) -> None:
        """Claim the named machine (starting its harness on first use) and reset its AVR."""
        with _MACHINES_LOCK:
            m = _MACHINES.get(name)
            if m is not None and m.port is not None:
                raise serial.SerialException(
                    f"could not open port {self._port}: [Errno 16] Device or resource busy "
                    f"(machine {name!r} is open)")
            if m is not None and not m.running:
                m = None  # its harness died: power it up again
            fresh = m is None
            if m is None:
                emu, trace = _new_emulator(opts)
                m = SimMachine(name, emu, trace, opts)
                _MACHINES[name] = m
            else:
                for key in opts.given:
                    if getattr(opts, key) != getattr(m.options, key):
                        raise serial.SerialException(
                            f"{SCHEME}: machine {name!r} runs with {key}="
                            f"{getattr(m.options, key)}; a reopen cannot change it")
            m.port = self
        self._machine = m
        self.trace_path = None  # the machine's trace is not this port's alone
        try:
            self._open_pty(m.emulator, fresh)
        except serial.SerialException:
            m.port = None
            self._machine = None
            if fresh:
                with _MACHINES_LOCK:
                    _MACHINES.pop(name, None)
            raise

    def _open_pty(self, emu: Emulator, fresh: bool) -> None:
        """Open the harness's pty; a fresh harness starts now, a running one is reset (DTR)."""
        try:
            pty = emu.start() if fresh else emu.pty
            assert pty is not None
            self._inner = serial.Serial(pty, baudrate=self._baudrate, timeout=self._timeout,
                                        write_timeout=self._write_timeout)
            if not fresh:
                emu.control("open")
        except (EmulatorError, serial.SerialException, OSError) as e:
            if self._inner is not None:
                self._inner.close()
                self._inner = None
            if fresh:
                emu.stop()
            raise serial.SerialException(f"{SCHEME}: cannot start the emulator: {e}") from e

    def close(self) -> None:
        """Close the pty; stop the harness unless it belongs to a named machine (idempotent)."""
        if self._inner is not None:
            self._inner.close()
            self._inner = None
        if self._emu is not None:
            self.stats = self._emu.stop()
            self._emu = None
        if self._machine is not None:
            if self._machine.port is self:
                self._machine.port = None
            self._machine = None
        self.is_open = False

    def _emulator(self) -> Emulator:
        emu = self._emu or (self._machine.emulator if self._machine else None)
        if emu is None:
            raise serial.PortNotOpenError()
        return emu

    def _reconfigure_port(self, force_update: bool = False) -> None:
        """Timeouts, and the baud rate: the pty's speed, which the harness compares with
        the UART's (firmware/sim/fbsim.c: at another rate every byte is lost)."""
        if self._inner is not None:
            self._inner.baudrate = self._baudrate
            self._inner.timeout = self._timeout
            self._inner.write_timeout = self._write_timeout

    def _update_dtr_state(self) -> None:
        """DTR going active resets the AVR with its RAM kept, like the Uno's auto-reset."""
        rising = self._dtr_state and not self._dtr_last
        self._dtr_last = self._dtr_state
        if self.is_open and rising:
            self._port_or_fail()
            try:
                self._emulator().control("reset")
            except EmulatorError as e:
                raise serial.SerialException(f"{SCHEME}: {e}") from e

    def _update_rts_state(self) -> None:
        """RTS is not connected."""

    def _update_break_state(self) -> None:
        """A break does nothing to the device."""

    def _port_or_fail(self) -> serial.Serial:
        if self._inner is None:
            raise serial.PortNotOpenError()
        if self._broken:
            raise serial.SerialException(self._broken)
        return self._inner

    @property
    def in_waiting(self) -> int:
        return int(self._port_or_fail().in_waiting)

    def read(self, size: int = 1) -> bytes:
        return bytes(self._port_or_fail().read(size))

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Write to the pty, firing a fault option once its line has been written."""
        inner = self._port_or_fail()
        raw = bytes(data)
        fault, cut = self._next_fault(raw)
        if fault is None:
            inner.write(self._noisy(raw))
            self._lines += raw.count(b"\n")
            return len(raw)
        inner.write(self._noisy(raw[:cut]))
        inner.flush()
        self._lines += raw[:cut].count(b"\n")
        self._fired.add(fault)
        n_option = (self.options.faults or {})[fault]
        command = FAULTS[fault]
        if command is None:
            self._broken = (f"{SCHEME}: device disconnected (disconnect_after={n_option})")
            raise serial.SerialException(self._broken)
        try:
            self._emulator().control(command)
        except EmulatorError as e:
            raise serial.SerialException(f"{SCHEME}: {e}") from e
        return len(raw)  # the rest of the write is lost, as on the mock

    def _noisy(self, raw: bytes) -> bytes:
        """`raw` after the URL's line noise (`drop`, `corrupt`); real-time bytes pass."""
        drop, corrupt = self.options.drop, self.options.corrupt
        if not drop and not corrupt:
            return raw
        rng = self._rng
        out = bytearray()
        for c in raw:
            if c not in _REALTIME:
                if drop and rng.random() < drop:
                    continue
                if corrupt and rng.random() < corrupt:
                    c = rng.choice([b for b in _CORRUPT_BYTES if b != c])
            out.append(c)
        return bytes(out)

    def _next_fault(self, raw: bytes) -> tuple[str | None, int]:
        """The first fault whose line ends in ``raw``, and the length up to that newline."""
        best: tuple[str | None, int] = (None, len(raw))
        for fault, n in (self.options.faults or {}).items():
            k = n - self._lines  # that line's newline is the k-th in raw
            if fault in self._fired or k < 1:
                continue
            cut = -1
            for _ in range(k):
                cut = raw.find(b"\n", cut + 1)
                if cut < 0:
                    break
            if cut >= 0 and (best[0] is None or cut + 1 < best[1]):
                best = (fault, cut + 1)
        return best

    def flush(self) -> None:
        self._port_or_fail().flush()

    def reset_input_buffer(self) -> None:
        self._port_or_fail().reset_input_buffer()

    def reset_output_buffer(self) -> None:
        self._port_or_fail().reset_output_buffer()
