"""The firmware's deepest stack in the emulator: what `fivebar-sim://?stack=FILE` records.

On the Uno the stack grows down from the top of the 2 KB SRAM towards the static RAM (.data,
.bss, .noinit: avr-nm's `_end`); nothing stops it there, so an overflow silently corrupts
.bss.  `avr-size` shows the static RAM only.  The harness's profile (firmware/sim/fbsim.c
`-P`) keeps the lowest stack pointer the run reached (its "# min_sp SP at PC" line; a
frame's two-instruction SP update is not counted as a dip); the headroom is that less
`_end`: the bytes still free below the deepest frame (SP points at the next free byte, so
one more is free in fact: the figure errs low, as segcost.py's).  The harness also keeps the
stack's bytes at that moment ("# min_stack"): the return addresses among them name the
calls and interrupts that were on top of each other there (`return_chain`).
"""

from __future__ import annotations

import bisect
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

from fivebar_host.devices.sim import EmulatorError

#: avr-nm prints data addresses with this offset (the AVR's separate data space).
DATA_OFFSET = 0x800000


@dataclass(frozen=True)
class StackDepth:
    """One run's deepest stack: the lowest SP (a data address), the flash byte address of
    the instruction after the one that reached it, the function holding it (avr-nm's text
    symbol at or below; LTO inlines most of the firmware into `main`), the end of the static
    RAM and the headroom between them, bytes."""

    min_sp: int
    pc: int
    function: str
    ram_end: int
    headroom: int
    #: the functions the return addresses on the stack go back to, deepest first
    chain: tuple[str, ...] = ()


def _nm(elf: Path) -> list[str]:
    try:
        proc = subprocess.run(["avr-nm", "-n", str(elf)], capture_output=True, text=True,
                              check=True)
    except (OSError, subprocess.CalledProcessError) as e:
        raise EmulatorError(f"avr-nm {elf}: {e}") from e
    return proc.stdout.splitlines()


def ram_end(elf: Path) -> int:
    """The end of the static RAM of `elf` (`_end`), a data-space address."""
    for line in _nm(elf):
        if line.endswith(" _end"):
            return int(line.split()[0], 16) - DATA_OFFSET
    raise EmulatorError(f"{elf}: no _end symbol")


def _text_symbols(elf: Path) -> tuple[list[int], list[str]]:
    """The text symbols of `elf`: their start addresses, ascending, and their names."""
    starts: list[int] = []
    names: list[str] = []
    for line in _nm(elf):
        parts = line.split()
        if len(parts) == 3 and parts[1].lower() == "t":
            starts.append(int(parts[0], 16))
            names.append(parts[2])
    return starts, names


def _symbol_at(symbols: tuple[list[int], list[str]], pc: int) -> str:
    k = bisect.bisect_right(symbols[0], pc) - 1
    return symbols[1][k] if k >= 0 else "?"


def function_at(elf: Path, pc: int) -> str:
    """The text symbol of `elf` at or below flash byte address `pc` ('?' before the first)."""
    return _symbol_at(_text_symbols(elf), pc)


def return_chain(elf: Path, stack: bytes) -> tuple[str, ...]:
    """The functions that the return addresses in `stack` (the bytes from SP + 1 up, as
    the harness copied them at the deepest point) go back to, deepest first.  A call
    pushes its return address high byte below low byte (a word address); a pair counts
    when the instruction before that address is a call (`call`, `rcall`, `icall`), so an
    interrupt's return address (any instruction) shows only when it follows a call, and a
    stale pair left by an earlier call can show too: a reading aid, not a proof."""
    try:
        dis = subprocess.run(["avr-objdump", "-d", str(elf)], capture_output=True, text=True,
                             check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        raise EmulatorError(f"avr-objdump {elf}: {e}") from e
    after_call: set[int] = set()
    for m in re.finditer(r"^\s*([0-9a-f]+):\s+(?:[0-9a-f]{2} )+\s*\t(call|rcall|icall)\b",
                         dis, re.MULTILINE):
        after_call.add(int(m.group(1), 16) + (4 if m.group(2) == "call" else 2))
    symbols = _text_symbols(elf)
    pairs = (2 * (stack[i] << 8 | stack[i + 1]) for i in range(len(stack) - 1))
    return tuple(_symbol_at(symbols, addr) for addr in pairs if addr in after_call)


def read_stack(profile: Path, elf: Path) -> StackDepth:
    """The deepest stack of the run whose harness wrote `profile` (`stack=` / `-P`), on the
    firmware `elf` it ran.  EmulatorError when the file has no min_sp line (the harness did
    not stop cleanly) or the run never moved the stack."""
    try:
        text = profile.read_text()
    except OSError as e:
        raise EmulatorError(f"stack profile {profile}: {e}") from e
    stack = bytes(int(b, 16) for line in text.splitlines() if line.startswith("# min_stack")
                  for b in line.split()[2:])
    for line in text.splitlines():
        if line.startswith("# min_sp "):
            parts = line.split()  # "# min_sp SP at PC"
            sp, pc = int(parts[2]), int(parts[4])
            if sp >= 0xFFFF:
                raise EmulatorError(f"stack profile {profile}: no instruction was run")
            end = ram_end(elf)
            return StackDepth(sp, pc, function_at(elf, pc), end, sp - end,
                              return_chain(elf, stack) if stack else ())
    raise EmulatorError(f"stack profile {profile}: no '# min_sp' line (harness not stopped?)")
