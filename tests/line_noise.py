"""Line noise on numbered G1 lines, for the checksum tests on the mock (test_line_checksum.py)
and on the emulated firmware (contract/test_parser_differential.py).

A valid line is what the host sends: ``N<n> G1 ...*<crc16>/<len>`` (protocol.encode_line).
Noise edits it anywhere, the checksum field included.  The edits the checksum field is
guaranteed to catch (docs/protocol.md 5.1) are ``GUARANTEED``: one or two bytes dropped, one
or two bytes inserted, one byte or two adjacent bytes replaced; the line is refused, unless
the only change is spaces or tabs added at its end, which the format allows after the
length.  Two bytes replaced apart are caught only as the CRC-16 catches them, with the odds
of a random 16-bit match (two_replacements).

Inserted and replacing bytes are any but the newline (which would split the line), a
carriage return and the real-time bytes (the device drops those from the line, so they are
drops, with side effects of their own).  The functions draw from any integer source: a
seeded ``random.Random`` or a hypothesis draw, so both tests draw the same kind of case.
"""

from __future__ import annotations

from collections.abc import Callable

from fivebar_host import protocol, wire

#: Bytes noise may put into a line.
NOISE_BYTES = bytes(b for b in range(256)
                    if b not in (0x0A, 0x0D) and b not in protocol.REALTIME_BYTES)

#: Draws an integer in [lo, hi], both included (random.Random.randint, or a hypothesis draw).
DrawInt = Callable[[int, int], int]

#: The kinds of noise the checksum field refuses every time (docs/protocol.md 5.1).
GUARANTEED = ("drop 1", "drop 2", "insert 1", "insert 2", "replace 1", "replace 2 adjacent")


def _miss(valid: bytes, noisy: bytes) -> tuple[int, bytes, bytes]:
    """A case as noisy_case returns it, from a valid body and its noisy body (the noise
    left the checksum field alone)."""
    field = protocol.checksum_field(valid)
    assert protocol.crc16(noisy) == protocol.crc16(valid)
    return int(valid[1:valid.index(b" ")]), valid + field, noisy + field


#: Drops the CRC-16 alone cannot catch: each noisy line lost one or two bytes of its valid
#: line, kept its CRC-16, and would parse as a valid G1 with the expected line number.
#: Found by enumerating every 1- and 2-byte drop of 40,000 random host lines: about one
#: drop in 10^5.  A CRC is guaranteed to catch a burst of up to 16 bits in a message of
#: unchanged length; a drop changes the length, which the checksum field's length catches.
CRC_ONLY_MISSES: tuple[tuple[int, bytes, bytes], ...] = (
    _miss(b"N65726 G1 A-6020 B-15004 P74824 S132", b"N65726 G1 A-6020 B15004 P74824 S132"),
    _miss(b"N27559 G1 A8140 B-8138 P98890 S165", b"N27559 G1 A8140 B-8138 P9889 S165"),
    _miss(b"N19311 G1 A-11807 B2341 P15132 S193", b"N19311 G1 A-1107 B2341 P5132 S193"),
)


def valid_line(draw: DrawInt) -> tuple[int, bytes]:
    """A numbered G1 line as the host encodes it (without its newline), and its number."""
    n = draw(1, 0xFFFFFFFF)
    a = draw(-protocol.POS_LIMIT - 1, protocol.POS_LIMIT)
    b = draw(-protocol.POS_LIMIT - 1, protocol.POS_LIMIT)
    p = draw(protocol.P_MIN_US, protocol.P_MAX_US)
    s = draw(-1, protocol.POWER_MAX)
    body = wire.g1(a if a >= -protocol.POS_LIMIT else None,
                       b if b >= -protocol.POS_LIMIT else None, p, s if s >= 0 else None)
    return n, protocol.encode_line(body, n)[:-1]


def _noise_byte(draw: DrawInt, other_than: bytes = b"") -> int:
    """A byte noise may put in, other than ``other_than``'s."""
    pool = bytes(b for b in NOISE_BYTES if b not in other_than)
    return pool[draw(0, len(pool) - 1)]


def add_noise(line: bytes, kind: str, draw: DrawInt) -> bytes:
    """``line`` after one edit of a ``GUARANTEED`` kind, at places and with bytes drawn.

    Two drops remove two distinct bytes; two insertions go in one after the other, the
    second anywhere in the line the first left; a replacement puts in another byte, and
    two adjacent replacements do so at two neighbouring places.
    """
    if kind in ("drop 1", "drop 2"):
        noisy = line
        for _ in range(int(kind[-1])):
            at = draw(0, len(noisy) - 1)
            noisy = noisy[:at] + noisy[at + 1:]
        return noisy
    if kind in ("insert 1", "insert 2"):
        noisy = line
        for _ in range(int(kind[-1])):
            at = draw(0, len(noisy))
            noisy = noisy[:at] + bytes([_noise_byte(draw)]) + noisy[at:]
        return noisy
    if kind in ("replace 1", "replace 2 adjacent"):
        width = 1 if kind == "replace 1" else 2
        at = draw(0, len(line) - width)
        replaced = bytearray(line)
        for k in range(at, at + width):
            replaced[k] = _noise_byte(draw, line[k:k + 1])
        return bytes(replaced)
    raise ValueError(f"unknown noise kind {kind!r}")


def only_blanks_added(line: bytes, noisy: bytes) -> bool:
    """Whether ``noisy`` is ``line`` with spaces or tabs added at its end: the one edit the
    format accepts (blanks may follow the length)."""
    return (len(noisy) > len(line) and noisy.startswith(line)
            and not noisy[len(line):].strip(b" \t"))


def noisy_case(draw: DrawInt) -> tuple[int, bytes, bytes]:
    """A line number, its valid G1 line and the line after noise of a guaranteed kind."""
    n, line = valid_line(draw)
    kind = GUARANTEED[draw(0, len(GUARANTEED) - 1)]
    return n, line, add_noise(line, kind, draw)


def two_replacements(draw: DrawInt) -> tuple[int, bytes, bytes]:
    """A line number, its valid G1 line and the line with two bytes replaced that are not
    adjacent (at least one byte between them): noise the CRC-16 catches only by the odds."""
    n, line = valid_line(draw)
    first = draw(0, len(line) - 3)
    second = draw(first + 2, len(line) - 1)
    noisy = bytearray(line)
    for at in (first, second):
        noisy[at] = _noise_byte(draw, line[at:at + 1])
    return n, line, bytes(noisy)
