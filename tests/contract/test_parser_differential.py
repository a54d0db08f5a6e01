"""The mock's line parser against the firmware's, on generated and mutated lines.

Both devices are put into an alarm first (a failed ``$H``): while alarmed every line is
framed and parsed as usual, but nothing moves and nothing is queued, so the replies do
not depend on timing and the two transcripts must be equal line for line.  The lines
come from a seeded generator: commands, words and numbers of every shape, line numbers
and checksums (right, wrong, malformed), comments, whitespace, case, overlong lines and
random byte edits.  ``$H`` and ``$X`` are left out (they would end the alarm).  A plain
``M110`` now and then ends numbered mode (strict framing), so unnumbered lines keep being
parsed, not only refused with ``error:10``.

The line noise of test_line_checksum.py goes through both devices too: one or two bytes of
a numbered G1 line dropped or inserted, one byte or two adjacent ones replaced, and the drops
the CRC-16 alone let through; the firmware must refuse every such line, as the mock does.
"""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from contract_devices import Device, open_mock, open_sim
from line_noise import CRC_ONLY_MISSES, noisy_case, only_blanks_added

from fivebar_host import protocol
from fivebar_host.protocol import AlarmPush, ErrorReply, Message, Ok

pytestmark = pytest.mark.sim

_COMMANDS = ["G1", "g1", "G01", "G0", "G90", "G91", "G92", "G5", "G", "M3", "m5", "M17",
             "M18", "M110", "M999", "M", "$I", "$i", "$$", "$", "$Q", "X", "", "G70000"]
_LETTERS = "ABPSabpsNGMZ"


def _number(rng: random.Random) -> str:
    pick = rng.random()
    if pick < 0.5:
        return str(rng.randint(-300, 300))
    if pick < 0.7:
        return str(rng.choice([100, 99, 100_000_000, 100_000_001, -100_000_001, 255, 256,
                               2147483647, 2147483648, -2147483648, 99999999999, 0, 40000]))
    if pick < 0.8:
        return "+" + str(rng.randint(0, 5000))
    return rng.choice(["1.5", "12#", "", "-", "+", "1e3", "0x10", "--1", "7_"])


def _word(rng: random.Random) -> str:
    return rng.choice(_LETTERS) + _number(rng)


def _body(rng: random.Random) -> str:
    if rng.random() < 0.12:
        n = rng.choice([0, 1, 5, 6, 13, 14, 99, 255, 256, 300])
        return rng.choice([f"${n}={_number(rng)}", f"${n}", f"${n} ={_number(rng)}",
                           f"${n}={_number(rng)}x", f"${n}={_number(rng)} ;c"])
    sep = rng.choice(["", " ", " ", "\t", "  "])
    words = [rng.choice(_COMMANDS)] + [_word(rng) for _ in range(rng.randint(0, 4))]
    body = sep.join(words)
    if rng.random() < 0.15:
        body += rng.choice([" ; comment", ";", "; G1 A5 P1000"])
    return body


def random_line(rng: random.Random) -> bytes:
    """One line (without its newline) of the kinds a parser must tell apart."""
    body = _body(rng)
    if rng.random() < 0.3:
        body = f"N{rng.choice([1, 2, 3, 0, 7, 4294967295, 4294967296])} {body}"
    if rng.random() < 0.05:
        body = rng.choice(["N", "N#", "N-1", "n2"]) + " " + body
    data = body.encode("ascii")
    pick = rng.random()
    if pick < 0.35:
        data += protocol.checksum_field(data)
    elif pick < 0.42:
        field = protocol.checksum_field(data)
        crc, length = field[1:].split(b"/")
        data += rng.choice([b"*" + crc, b"*" + crc + b"/", field + b"0", field[:-1],
                            b"*0" + crc + b"/" + length, b"*" + crc + b"/0" + length,
                            field + b" \t", field + b"/" + length, b"*" + crc + b" /" + length])
    elif pick < 0.47:
        data += rng.choice([b"*", b"*65536/3", b"*12x/3", b"*123456/3", b"* 5/3", b"*5/ 3",
                            b"*0/0", b"**1/1", b"*00300/3", b"*5/3 \t", b"*65535/0"])
    if rng.random() < 0.2:
        i = rng.randrange(len(data) + 1)
        byte = bytes([rng.choice([0x01, 0x7F, 0xFF, 0x80, 0x09, 0x0D, 0x20, 0x2A, 0x3B,
                                  rng.randrange(0x20, 0x7F)])])
        data = data[:i] + byte + data[i + 1 if rng.random() < 0.5 else i:]
    if rng.random() < 0.04:
        data += b" " + b"A1" * rng.randint(38, 60)
    data = bytes(b for b in data if b not in protocol.REALTIME_BYTES and b != 0x0A)
    upper = data.upper().replace(b" ", b"").replace(b"\t", b"").replace(b"\r", b"")
    if b"$H" in upper or b"$X" in upper:
        return random_line(rng)
    return data


def transcript(dev: Device, lines: list[bytes]) -> list[list[Message]]:
    """Put the device into an alarm, then send each line and keep what came back."""
    s = dev.session
    for setting in ("$7=1", "$8=40000", "$12=1"):
        assert s.send(setting) == Ok()
    dev.port.write(b"$H\n")
    assert s.read_reply() == ErrorReply(31)
    assert s.messages == [AlarmPush(31)]
    out = []
    for line in lines:
        dev.port.write(line + b"\n")
        got: list[Message] = []
        while not got or not protocol.is_reply(got[-1]):
            got.append(s.read_message())
        out.append(got)
    s.messages.clear()
    assert s.status().state == "Alarm"
    return out


def both_transcripts(lines: list[bytes], tmp_path: Path
                     ) -> tuple[list[list[Message]], list[list[Message]]]:
    """The firmware's (in simavr) and the mock's transcripts of the same lines."""
    mock_dev = open_mock()
    sim_dev = open_sim(tmp_path / "pins.trace")
    try:
        return transcript(sim_dev, lines), transcript(mock_dev, lines)
    finally:
        mock_dev.close()
        sim_dev.close()


@pytest.mark.usefixtures("sim_build")  # built once; skips without the toolchain
def test_the_mock_answers_every_line_like_the_firmware(tmp_path: Path) -> None:
    rng = random.Random(20261121)
    gaps = random.Random(5)
    lines = []
    for _ in range(600):
        if gaps.random() < 0.3:
            lines.append(b"M110")
        lines.append(random_line(rng))
    want, got = both_transcripts(lines, tmp_path)
    codes = {m.code for t in want for m in t if isinstance(m, ErrorReply)}
    assert codes >= {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 14, 17}, "the generator missed a code"
    assert sum(t[-1] == Ok() for t in want) >= 10, "too few lines accepted to be useful"
    for line, w, g in zip(lines, want, got, strict=True):
        assert g == w, f"line {line!r}: firmware {w}, mock {g}"


@pytest.mark.usefixtures("sim_build")
def test_noisy_numbered_lines_are_refused_by_the_firmware_as_by_the_mock(tmp_path: Path) -> None:
    """Each case: ``N<n-1> M110`` (the device now expects line n), the noisy line, then the
    valid line as a probe: it is answered ``error:14`` (accepted, refused by the alarm) when
    the noisy line was refused, ``error:9`` when the noisy line took its number."""
    rng = random.Random(20260301)
    cases = [(201, b"N201 G1 A-706 B-507 P16795 S255*49724/31",
              b"N201 G1 A-76 B-07 P16795 S255*49724/31"), *CRC_ONLY_MISSES]
    cases += [noisy_case(rng.randint) for _ in range(300)]
    lines = []
    for n, line, noisy in cases:
        lines += [protocol.encode_line("M110", n - 1)[:-1], noisy, line]
    want, got = both_transcripts(lines, tmp_path)
    for line, w, g in zip(lines, want, got, strict=True):
        assert g == w, f"line {line!r}: firmware {w}, mock {g}"
    for (n, line, noisy), to_noisy, to_probe in zip(cases, want[1::3], want[2::3], strict=True):
        if only_blanks_added(line, noisy):  # the format allows blanks after the length
            assert (to_noisy[-1], to_probe[-1]) == (ErrorReply(14), ErrorReply(9, resend=n + 1))
        else:
            assert to_noisy[-1] in (ErrorReply(8, resend=n), ErrorReply(10, resend=n)), noisy
            assert to_probe[-1] == ErrorReply(14), noisy
