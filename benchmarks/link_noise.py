"""Miss rates of G6 lines under line noise (docs/protocol.md 16), through the mock's parser.

The mock's parser is a port of the firmware's (fb_proto.c; tests/contract/
test_parser_differential.py keeps them equal), so what it accepts the firmware accepts.
Random drawing-like jobs are packed into G6 lines by the host's own packer (`wire.pack_line`),
then damaged two ways, as in the protocol-2 figures of section 14:

- the mock's noisy link (`fivebar-mock://?drop=P&corrupt=P`): each byte of the line is lost
  with probability P, else replaced with probability P by a printable byte that is not a
  real-time byte (MockSerial.write); lines that came through undamaged are not counted;
- exactly two bytes replaced, not adjacent (any byte but newline, carriage return and the
  real-time bytes): the edit the CRC-16 catches only by the odds (section 5.1).

Each damaged line is classified: refused with a resend (the line number unchanged: the
host resends it), refused with another error (a job is held, section 9), or accepted:
then "harmless" if it executes exactly what the undamaged line would, else a miss (a
valid wrong line). Printed per 10^5 damaged lines.

Run: python benchmarks/link.py --noise [--noise-lines 200000]
"""

from __future__ import annotations

import random
from collections import Counter

from fivebar_host import protocol, wire
from fivebar_host.devices.mock.codes import OK
from fivebar_host.devices.mock.parser import parse_line

#: What the mock's corruption puts in (fivebar_host/devices/mock/port.py).
CORRUPT_BYTES = bytes(c for c in range(0x20, 0x7F) if c not in protocol.REALTIME_BYTES)
#: What any noise may put in (tests/line_noise.py NOISE_BYTES).
NOISE_BYTES = bytes(b for b in range(256)
                    if b not in (0x0A, 0x0D) and b not in protocol.REALTIME_BYTES)


def job_bodies(rng: random.Random, n: int) -> list[str]:
    """A drawing-like run of G1 bodies: small steps, a duration that changes now and then."""
    a, b, p = rng.randint(-3000, 3000), rng.randint(-3000, 3000), rng.randint(500, 3000)
    s = rng.choice((0, 0, 128, 255))
    out = []
    for _ in range(n):
        a += rng.randint(-3, 3)
        b += rng.randint(-3, 3)
        if rng.random() < 0.2:
            p = rng.randint(100, 100_000)
        out.append(wire.g1(a, b, p, s))
    return out


def g6_lines(rng: random.Random, count: int) -> list[tuple[int, bytes]]:
    """`count` packed G6 lines (number, line without its newline), 64-byte limit as the
    streamer uses with the firmware's 128-byte receive buffer."""
    out: list[tuple[int, bytes]] = []
    while len(out) < count:
        prog = wire.read_lines(job_bodies(rng, 40))
        number = rng.randint(1, 2**31)
        j = 0
        while j < len(prog) and len(out) < count:
            line, used = wire.pack_line(prog, j, number + j, True, 64)
            if used > 1:
                out.append((number + j, line[:-1]))
            j += used
    return out


def link_noise(rng: random.Random, line: bytes, p: float) -> bytes:
    """The mock port's per-byte drop and corruption."""
    out = bytearray()
    for c in line:
        if rng.random() < p:
            continue
        if rng.random() < p:
            c = rng.choice([x for x in CORRUPT_BYTES if x != c])
        out.append(c)
    return bytes(out)


def two_apart(rng: random.Random, line: bytes) -> bytes:
    """Two bytes replaced with at least one byte between them."""
    first = rng.randint(0, len(line) - 3)
    second = rng.randint(first + 2, len(line) - 1)
    noisy = bytearray(line)
    for at in (first, second):
        noisy[at] = rng.choice([x for x in NOISE_BYTES if x != line[at]])
    return bytes(noisy)


def classify(number: int, line: bytes, noisy: bytes) -> str:
    """What the firmware does with `noisy` where `line` (numbered `number`) was sent."""
    want = parse_line(number - 1, line, True)
    got = parse_line(number - 1, noisy, True)
    if got.status in protocol.RESEND_CODES and got.last == number - 1:
        return "refused, resent"
    if got.status != OK:
        return f"refused, error:{got.status} (job held)"
    same = (got.last == want.last and got.command.words == want.command.words
            and got.command.items == want.command.items)
    return "accepted, harmless" if same else "accepted, MISS"


def measure(kind: str, lines: int, seed: int, p: float = 0.003) -> tuple[int, Counter[str]]:
    """(damaged lines tried, outcomes) for `lines` G6 lines under noise `kind`."""
    rng = random.Random(seed)
    out: Counter[str] = Counter()
    damaged = 0
    for number, line in g6_lines(rng, lines):
        noisy = link_noise(rng, line, p) if kind == "link" else two_apart(rng, line)
        if noisy == line:
            continue
        damaged += 1
        out[classify(number, line, noisy)] += 1
    return damaged, out


def report(lines: int, seed: int = 1) -> None:
    """Print the miss-rate table."""
    print(f"G6 lines under noise: {lines} random packed lines per kind (mock parser = "
          "firmware parser), per 10^5 damaged lines")
    for kind, name in (("link", "mock noisy link drop=0.003&corrupt=0.003"),
                       ("two", "two bytes replaced, not adjacent")):
        damaged, out = measure(kind, lines, seed)
        print(f"  {name}: {damaged} damaged lines")
        for outcome, count in sorted(out.items()):
            print(f"    {outcome:34s} {count:9d}  {count / damaged * 1e5:10.1f} per 10^5")
        if "accepted, MISS" not in out:
            print(f"    {'accepted, MISS':34s} {0:9d}  {0:10.1f} per 10^5")
