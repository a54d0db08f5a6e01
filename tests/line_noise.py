"""Line noise on numbered G1 lines, for the checksum tests on the mock (test_line_checksum.py)
and on the emulated firmware (contract/test_parser_differential.py).

A valid line is what the host sends: ``N<n> G1 ...*<crc16>`` (protocol.encode_line).  Noise
is one or two edits anywhere in it, the checksum included: a byte dropped, or replaced by
another byte.  Replacement bytes are any but the newline (which would split the line), a
carriage return and the real-time bytes (the device drops those from the line, so they are
drops, with side effects of their own).  One function draws a case from any integer source:
a seeded ``random.Random`` or a hypothesis draw, so both tests draw the same kind of case.
"""

from __future__ import annotations

from collections.abc import Callable

from fivebar_host import protocol

#: Bytes noise may put in place of a line byte.
NOISE_BYTES = bytes(b for b in range(256)
                    if b not in (0x0A, 0x0D) and b not in protocol.REALTIME_BYTES)

#: Draws an integer in [lo, hi], both included (random.Random.randint, or a hypothesis draw).
DrawInt = Callable[[int, int], int]



def _miss(valid: bytes, noisy: bytes) -> tuple[int, bytes, bytes]:
    """A case as noisy_case returns it, from a valid body and its noisy body (the noise
    left the checksum alone)."""
    tail = b"*" + str(protocol.crc16(valid)).encode()
    return int(valid[1:valid.index(b" ")]), valid + tail, noisy + tail


#: Noise CRC-16 cannot catch: each noisy line lost one or two bytes of its valid line, kept
#: its CRC-16, and parses as a valid G1 with the expected line number.  Found by
#: enumerating every 1- and 2-byte drop of 40,000 random host lines: about one drop in
#: 10^5 gets through.  A CRC is guaranteed to catch a burst of up to 16 bits in a message
#: of unchanged length; a drop changes the length, and is caught only with the odds of a
#: random 16-bit match.
KNOWN_MISSES: tuple[tuple[int, bytes, bytes], ...] = (
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
    body = protocol.g1(a if a >= -protocol.POS_LIMIT else None,
                       b if b >= -protocol.POS_LIMIT else None, p, s if s >= 0 else None)
    return n, protocol.encode_line(body, n)[:-1]


def add_noise(line: bytes, draw: DrawInt) -> bytes:
    """``line`` with one or two edits, each a drop or a replacement by another byte.

    Each edit applies to the line as the edits before it left it; a replacement puts
    another byte in place.  Should two edits cancel out, the noise is drawn again.
    """
    noisy = line
    while noisy == line:
        noisy = line
        for _ in range(draw(1, 2)):
            at = draw(0, len(noisy) - 1)
            if draw(0, 1):
                noisy = noisy[:at] + noisy[at + 1:]
            else:
                others = NOISE_BYTES.replace(noisy[at:at + 1], b"")
                noisy = noisy[:at] + bytes([others[draw(0, len(others) - 1)]]) + noisy[at + 1:]
    return noisy


def noisy_case(draw: DrawInt) -> tuple[int, bytes, bytes]:
    """A line number, its valid G1 line and the line as noise left it."""
    n, line = valid_line(draw)
    return n, line, add_noise(line, draw)
