"""The firmware's cost per segment in emulated AVR cycles, by function (issue 39).

Streams the issue-20 job of `benchmarks/link.py` (segments of 1–2 steps per motor, laser
off) packed into G6 lines as the host packs them (`wire.pack_line`, lines of at most half
the receive ring), numbered and checksummed, on the emulator with its cycle profile on
(`fbsim -P`: the emulated cycles spent at each flash address, exact), then maps the
addresses to the firmware's functions (`avr-nm`) and prints, per segment, the cycles each
function took: the receive interrupt, the framing (CRC-16, checksum field), the parse, the
G6 checks, the block preparation (divisions), the fast form, the step interrupt.  The
link runs at --baud ($B) and the emulator in real time, as `benchmarks/link.py` runs it,
so the main loop's polling (fb_poll, mo_fold, mo_alive, ...) is the time it waited: for a
slot in a full queue, or for bytes.  LTO inlines most of the firmware into `main`; a -g
build of the same code (build/prof, identical instructions) gives each address its source
line, which names its function.  Also printed: the stack's headroom at its deepest (the
harness's lowest stack pointer over the run, less the end of the static RAM), which
`avr-size` cannot show.

Run: python benchmarks/segcost.py [--segments 1000] [--p-us 250] [--baud 1000000]
     [--top 25] [--lines]
"""

from __future__ import annotations

import argparse
import bisect
import dataclasses
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

_HERE = Path(__file__).resolve().parent
# this folder off the path (benchmarks/kinematics.py would shadow the package), the
# repository on it (benchmarks.link's job)
sys.path[:] = [str(_HERE.parent)] + [p for p in sys.path if Path(p or ".").resolve() != _HERE]
from benchmarks.link import issue_job, step_span_s  # noqa: E402
from fivebar_host import protocol, wire  # noqa: E402
from fivebar_host.devices.sim import (  # noqa: E402
    Emulator,
    FirmwareSession,
    boot,
    ensure_built,
)
from fivebar_host.protocol import StatusReport  # noqa: E402

#: The receive ring the firmware reports (banner rx:), halved: the host's line limit.
LINE_LIMIT = 127


def packed_lines(bodies: list[str], first: int) -> list[bytes]:
    """The job as the host streams it: numbered from `first`, G6 lines after the G90."""
    prog = wire.read_lines(bodies)
    out: list[bytes] = []
    j, number = 0, first
    while j < len(prog):
        raw, count = wire.pack_line(prog, j, number, j > 0, LINE_LIMIT)
        out.append(raw)
        j += count
        number += count
    return out


def debug_build(fw: Path) -> Path:
    """The same firmware built with -g into build/prof (identical code, with line tables:
    LTO inlines most functions into main, so only the line tables can tell them apart)."""
    subprocess.run(["make", "-s", "-C", str(fw), "BUILD=build/prof", "AVR_CC=avr-gcc -g",
                    "AVR_CXX=avr-g++ -g", "build/prof/fivebar.elf"], check=True,
                   capture_output=True)
    return fw / "build" / "prof" / "fivebar.elf"


def text_symbols(elf: Path) -> tuple[list[int], list[str]]:
    """Start addresses (sorted) and names of the firmware's text symbols."""
    text = subprocess.run(["avr-nm", "-n", "--defined-only", str(elf)], capture_output=True,
                          text=True, check=True).stdout
    starts: list[int] = []
    names: list[str] = []
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1].lower() == "t":
            starts.append(int(parts[0], 16))
            names.append(parts[2].split(".")[0])
    return starts, names


_DEF = re.compile(r"^(?:static\s+|BOARD_INLINE\s+|inline\s+|__attribute__\(\(\w+\)\)\s+)*"
                  r"[A-Za-z_][\w\s\*]*?\b(\w+)\s*\(")


def enclosing(path: str, line: int, cache: dict[str, list[str]]) -> str:
    """The C function whose body holds `path`:`line` (the last definition above it)."""
    if path not in cache:
        try:
            cache[path] = Path(path).read_text().splitlines()
        except OSError:
            cache[path] = []
    src = cache[path]
    for k in range(min(line, len(src)) - 1, -1, -1):
        m = _DEF.match(src[k])
        if m and not src[k].rstrip().endswith(";"):
            return m.group(1)
    return Path(path).name


def functions(elf: Path, addrs: list[int], by_line: bool = False) -> dict[int, str]:
    """The function of each flash address: the C function its line-table entry lies in
    (LTO inlines most of the firmware into main and a few callers), libgcc's symbol."""
    starts, names = text_symbols(elf)
    # the step interrupt's assembly (board_avr_step.S: its vector and labels, names no C
    # file has) and libgcc have no line table: they keep their symbols
    src = Path(__file__).resolve().parents[1] / "firmware" / "fivebar"
    c_names = set(re.findall(r"\w+", " ".join(p.read_text() for p in src.glob("*.c"))))
    out: dict[int, str] = {}
    inlined: list[int] = []
    for a in addrs:
        k = bisect.bisect_right(starts, a) - 1
        out[a] = names[k] if k >= 0 else "?"
        if out[a] == "__vector_11" or (out[a] not in c_names and not out[a].startswith("__")):
            out[a] = f"step ISR {out[a]}"
        elif not out[a].startswith("__"):
            inlined.append(a)
    lines = subprocess.run(["avr-addr2line", "-a", "-e", str(elf), *[hex(a) for a in inlined]],
                           capture_output=True, text=True, check=True).stdout.splitlines()
    cache: dict[str, list[str]] = {}
    for k in range(0, len(lines) - 1, 2):
        where = lines[k + 1].split(" ")[0]
        path, _, num = where.rpartition(":")
        if path.endswith((".c", ".h", ".S")) and "fivebar" in path and num.isdigit():
            out[int(lines[k], 16)] = (f"{Path(path).name}:{num}" if by_line
                                      else enclosing(path, int(num), cache))
    return out


@dataclasses.dataclass(frozen=True)
class Profile:
    """One profiled run: cycles per function, all cycles, lines sent, underruns, and the
    stack's headroom at its deepest (bytes between the lowest stack pointer and the end of
    the static RAM, `_end`), and the emulated cycles from the first step to the last (the
    pin trace's: exact whatever the load on the machine)."""

    per: dict[str, int]
    total: int
    lines: int
    underruns: int
    headroom: int
    step_span_cycles: int


def ram_end(elf: Path) -> int:
    """The end of the static RAM (.data, .bss, .noinit): avr-nm's `_end`, a data address."""
    text = subprocess.run(["avr-nm", str(elf)], capture_output=True, text=True,
                          check=True).stdout
    return next(int(ln.split()[0], 16) - 0x800000 for ln in text.splitlines()
            if ln.endswith(" _end"))


def stream(s: FirmwareSession, port: Any, lines: list[bytes], baud: int) -> StatusReport:
    """Switch the link to `baud` ($B), set the position, stream `lines` with character
    counting (the banner's rx:) and wait for the end; the final status report."""
    if not isinstance(s.send(f"$B={baud}"), protocol.Ok):
        raise SystemExit("$B refused")
    time.sleep(0.05)  # the ok has left at the old rate
    port.baudrate = baud
    if not isinstance(s.send("$I"), protocol.Ok):
        raise SystemExit(f"no answer at {baud} baud")
    if not isinstance(s.send("G92 A0 B0"), protocol.Ok):
        raise SystemExit("G92 refused")
    budget = s.banner.rx if s.banner else 128
    in_flight: list[int] = []
    sent = answered = 0
    while answered < len(lines):
        while sent < len(lines) and sum(in_flight) + len(lines[sent]) <= budget:
            port.write(lines[sent])
            in_flight.append(len(lines[sent]))
            sent += 1
        reply = s.read_reply()
        if not isinstance(reply, protocol.Ok):
            raise SystemExit(f"line {answered + 1} refused: {reply}")
        in_flight.pop(0)
        answered += 1
    return s.wait_idle()


def profile(segments: int, p_us: int, baud: int, by_line: bool = False) -> Profile:
    """Stream the job on the emulator in real time with its profile on."""
    build = ensure_built()
    elf = debug_build(build.elf.parent.parent)
    lines = packed_lines(issue_job(segments, p_us), 4)  # after the unnumbered $B, $I, G92
    with tempfile.TemporaryDirectory() as tmp:
        prof = Path(tmp) / "prof.txt"
        emu = Emulator(elf, build.harness, Path(tmp) / "trace.txt", realtime=True,
                       extra=["-P", str(prof)])
        dev = boot(emu, Path(tmp) / "trace.txt", 20.0)
        final = stream(dev.session, dev.port, lines, baud)
        dev.close()
        span = round(step_span_s(Path(tmp) / "trace.txt") * 16e6)
        text = prof.read_text()
        rows = [tuple(map(int, ln.split()[:2])) for ln in text.splitlines()
                if not ln.startswith("#")]
        min_sp = [int(ln.split()[2]) for ln in text.splitlines() if ln.startswith("# min_sp")]
    names = functions(elf, [addr for addr, _ in rows], by_line)
    per: dict[str, int] = {}
    total = 0
    for addr, cyc in rows:
        name = names.get(addr, "?")
        per[name] = per.get(name, 0) + cyc
        total += cyc
    return Profile(per, total, len(lines), final.underruns - 1, min_sp[0] - ram_end(elf),
                   span)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--segments", type=int, default=1000)
    ap.add_argument("--p-us", type=int, default=250)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--baud", type=int, default=1000000, choices=protocol.BAUD_RATES)
    ap.add_argument("--lines", action="store_true", help="by source line, not by function")
    args = ap.parse_args()
    prof = profile(args.segments, args.p_us, args.baud, args.lines)
    n = args.segments
    print(f"{n} segments in {prof.lines} lines (G6 packing, lines of at most {LINE_LIMIT} "
          f"bytes), P = {args.p_us} µs, {args.baud} baud, emulator in real time; emulated "
          f"cycles per segment by {'source line' if args.lines else 'function'} (fbsim -P)")
    for name, cyc in sorted(prof.per.items(), key=lambda kv: -kv[1])[:args.top]:
        print(f"  {name:32s} {cyc / n:9.0f}")
    print(f"  {'(all, idle included)':32s} {prof.total / n:9.0f}")
    print(f"first to last step: {prof.step_span_cycles} emulated cycles, "
          f"{n / (prof.step_span_cycles / 16e6):.0f} segments/s; mid-path underruns "
          f"{prof.underruns}; stack headroom at its deepest {prof.headroom} bytes (lowest "
          f"stack pointer less _end)")


if __name__ == "__main__":
    main()
