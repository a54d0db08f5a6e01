"""The CRC-16 line checksum on the mock: the two-byte drop CRC-8 let through, and line noise
on numbered G1 lines (docs/protocol.md 5.1, "Changes in version 2").

The same noisy lines go through the emulated firmware in
contract/test_parser_differential.py.
"""

from __future__ import annotations

import time

import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st
from line_noise import KNOWN_MISSES, NOISE_BYTES, noisy_case

from fivebar_host import protocol
from fivebar_host.devices import mock, urls
from fivebar_host.protocol import ErrorReply, Message, Ok

#: The line the flaky noisy-plot test caught: ``A-706`` and ``B-507`` each lost a byte, and
#: the CRC-8 (32) of the result equalled the valid line's, so protocol 1 ran the wrong
#: segment.  Its CRC-16 is 49724; the noisy line's is 45618.
VALID = b"N201 G1 A-706 B-507 P16795 S255"
NOISY = b"N201 G1 A-76 B-07 P16795 S255"


def reply(port: serial.SerialBase, line: bytes) -> Message:
    """Send one line; its reply (the mock answers at once)."""
    port.write(line)
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        raw = port.readline()
        if raw:
            msg = protocol.parse_message(raw.decode("ascii", errors="replace"))
            if protocol.is_reply(msg):
                return msg
    raise AssertionError(f"no reply to {line!r}")


def test_the_two_byte_drop_crc8_missed_is_refused_with_a_resend() -> None:
    assert protocol.encode_line("G1 A-706 B-507 P16795 S255", 201) == VALID + b"*49724\n"
    urls.register()
    port = serial.serial_for_url("fivebar-mock://?speed=0", timeout=0.05)
    try:
        assert port.readline().startswith(b"fivebar ")
        assert reply(port, protocol.encode_line("M110", 199)) == Ok()
        assert reply(port, protocol.encode_line("G92 A-700 B-500", 200)) == Ok()
        assert reply(port, NOISY + b"*49724\n") == ErrorReply(8, resend=201)
        assert reply(port, VALID + b"*49724\n") == Ok()
    finally:
        port.close()


def refused(n: int, line: bytes) -> bool:
    """Whether the mock's parser refuses ``line`` (not accepted, counter unchanged) when
    it expects line ``n`` in numbered mode."""
    parsed = mock.parse_line(n - 1, line, numbered=True)
    return not parsed.accepted and parsed.last == n - 1


def test_every_single_byte_replacement_of_that_line_is_refused() -> None:
    """Exhaustive: a CRC catches every error burst no longer than itself."""
    line = VALID + b"*49724"
    for at in range(len(line)):
        for byte in NOISE_BYTES:
            if byte != line[at]:
                noisy = line[:at] + bytes([byte]) + line[at + 1:]
                assert refused(201, noisy), noisy


@settings(max_examples=1500, deadline=None, derandomize=True)
@given(st.data())
def test_one_or_two_dropped_or_replaced_bytes_are_refused(data: st.DataObject) -> None:
    """Random valid numbered G1 lines with one or two bytes dropped or replaced, anywhere.

    Derandomized: the property does not hold for every such line (KNOWN_MISSES, about
    one drop in 10^5 keeps the CRC-16), so random runs would fail now and then; this runs
    the same 1500 cases every time.
    """
    n, line, noisy = noisy_case(lambda lo, hi: data.draw(st.integers(lo, hi)))
    assert not refused(n, line)
    assert refused(n, noisy), f"{noisy!r} (from {line!r}) was accepted"


@pytest.mark.xfail(strict=True, reason="CRC-16 misses about one drop in 10^5: these keep it")
@pytest.mark.parametrize(("n", "line", "noisy"), KNOWN_MISSES,
                         ids=[f"N{m[0]}" for m in KNOWN_MISSES])
def test_known_drops_crc16_misses_are_refused(n: int, line: bytes, noisy: bytes) -> None:
    assert not refused(n, line)
    assert refused(n, noisy)
