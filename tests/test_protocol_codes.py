"""The Python protocol table equals firmware/fivebar/status.h, and the codec works."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fivebar_host import protocol, wire
from fivebar_host.protocol import (
    AlarmPush,
    Banner,
    ErrorReply,
    Ok,
    ProtocolError,
    SettingLine,
    StatusReport,
)

ROOT = Path(__file__).resolve().parents[1]
STATUS_H = ROOT / "firmware" / "fivebar" / "status.h"
DEFINE = re.compile(r"#define FB_(ERR|ALARM)_(\w+)\s+(\d+)\s*/\*\s*(.*?)\s*\*/")


def firmware_codes() -> dict[int, protocol.Code]:
    codes = {}
    for kind, name, number, text in DEFINE.findall(STATUS_H.read_text()):
        code = int(number)
        assert code not in codes, f"code {code} defined twice in status.h"
        codes[code] = protocol.Code(code, name, text, alarm=kind == "ALARM")
    return codes


def test_code_table_matches_status_h() -> None:
    fw = firmware_codes()
    assert len(fw) >= 20
    assert fw == protocol.CODES


def crc16_bitwise(data: bytes) -> int:
    """The firmware's loop (fb_proto.c), bit by bit, MSB first: the host's former
    implementation and the reference for `protocol.crc16` (now binascii.crc_hqx)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_crc16_check_value() -> None:
    """CRC-16/CCITT-FALSE's catalogue check value, and the empty input (the init value)."""
    assert protocol.crc16(b"123456789") == 0x29B1
    assert protocol.crc16(b"") == 0xFFFF


@pytest.mark.parametrize("data", [
    b"A", b"G90", b"N1 G90", b"N201 G1 A-706 B-507 P16795 S255",
    b"N201 G1 A-76 B-07 P16795 S255", b"\x00", b"\xff" * 80, bytes(range(256)),
])
def test_crc16_matches_an_independent_implementation(data: bytes) -> None:
    """protocol.crc16 (binascii.crc_hqx started at 0xFFFF) equals the firmware's bitwise
    CRC-16/CCITT-FALSE loop, written out here."""
    assert protocol.crc16(data) == crc16_bitwise(data)


@given(st.binary(max_size=300))
def test_crc16_matches_the_reference_on_any_bytes(data: bytes) -> None:
    assert protocol.crc16(data) == crc16_bitwise(data)


def test_protocol_version_is_the_firmware_s_and_the_document_s() -> None:
    config = (ROOT / "firmware" / "fivebar" / "config.h").read_text()
    m = re.search(r"#define FB_PROTOCOL\s+(\d+)", config)
    assert m is not None and int(m[1]) == protocol.PROTOCOL_VERSION
    title = (ROOT / "docs" / "protocol.md").read_text().splitlines()[0]
    assert title.endswith(f"(version {protocol.PROTOCOL_VERSION})"), title


def test_encode_line_with_number_and_checksum() -> None:
    line = protocol.encode_line("G1 A10 P1000", line_number=7)
    text = line.decode()
    assert text.startswith("N7 G1 A10 P1000*") and text.endswith("\n")
    body, field = text[:-1].rsplit("*", 1)
    crc, length = field.split("/")
    assert int(crc) == crc16_bitwise(body.encode())
    assert int(length) == len(body) == len("N7 G1 A10 P1000")
    assert protocol.encode_line("G90") == b"G90\n"
    assert protocol.encode_line("G90", checksum=True) == b"G90*56831/3\n"
    assert protocol.checksum_field(b"") == b"*65535/0"


@pytest.mark.parametrize("body", ["G1 A1 P100 ?", "M3!", "G1*", "G1 ; x", "G1\x01"])
def test_encode_refuses_reserved_characters(body: str) -> None:
    with pytest.raises(ProtocolError):
        protocol.encode_line(body)


def test_g1_ranges() -> None:
    assert wire.g1(5, -3, 1000, 255) == "G1 A5 B-3 P1000 S255"
    assert wire.g1(None, 2, 100) == "G1 B2 P100"
    for args in [(0, 0, 99), (0, 0, 100_000_001), (100_000_001, 0, 1000)]:
        with pytest.raises(ProtocolError):
            wire.g1(*args)
    with pytest.raises(ProtocolError):
        wire.g1(0, 0, 1000, 256)


def test_parse_every_message_kind() -> None:
    assert protocol.parse_message("ok\r\n") == Ok()
    assert protocol.parse_message("error:4\r\n") == ErrorReply(4)
    assert protocol.parse_message("error:8 resend:12") == ErrorReply(8, 12)
    alarm_error = protocol.parse_message("error:30")
    assert isinstance(alarm_error, ErrorReply) and alarm_error.info.alarm
    assert protocol.parse_message("<Hold:1|A:-5,B:7|Q:3|Ln:10,12|L:0|U:2|H:0>") == StatusReport(
        "Hold", 1, -5, 7, 3, 10, 12, 0, 2, homed=False
    )
    run = protocol.parse_message("<Run|A:0,B:0|Q:0|Ln:0,0|L:255|U:0|H:1>")
    assert isinstance(run, StatusReport) and run.state == "Run" and run.homed
    assert protocol.parse_message("fivebar 1.0.0 proto:2 rx:128 queue:16 line:80") == Banner(
        "1.0.0", 2, 128, 16, 80
    )
    assert protocol.parse_message("ALARM:31") == AlarmPush(31)
    assert protocol.parse_message("$12=-40") == SettingLine(12, -40)


@pytest.mark.parametrize(("line", "banner"), [
    ("ofivebar 1.0.0 proto:2 rx:128 queue:16 line:80", Banner("1.0.0", 2, 128, 16, 80)),
    ("<Run|A:12fivebar 1.0.0 proto:2 rx:128 queue:16 line:80\r\n",
     Banner("1.0.0", 2, 128, 16, 80)),
    ("fivebar 1.0.0 proto:2 rx:12fivebar 2.0 proto:3 rx:64 queue:8 line:40",
     Banner("2.0", 3, 64, 8, 40)),
    ("fivebar 1.0.0 proto:2 rx:128 queue:16 line:80", Banner("1.0.0", 2, 128, 16, 80)),
    ("ofivebar 1.0.0 proto:2 rx:128 queue:16 line:80x", None),
    ("fivebar 1.0.0 proto:2 rx:128 queue:16", None),
    ("okay", None),
])
def test_trailing_banner(line: str, banner: Banner | None) -> None:
    """A reset that cuts a line on the wire glues the banner to the cut piece."""
    assert protocol.trailing_banner(line) == banner


@pytest.mark.parametrize(
    "line",
    [
        "okay",
        "ofivebar 1.0.0 proto:2 rx:128 queue:16 line:80",  # the link's business, not the codec's
        "error:8",
        "error:4 resend:3",
        "<Idle:1|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:0>",
        "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0>",  # H: is mandatory
        "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:2>",
        "<Hold|A:0>",
        "",
    ],
)
def test_parse_refuses_malformed(line: str) -> None:
    with pytest.raises(ProtocolError):
        protocol.parse_message(line)



def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n#", start + len(heading))
    return text[start:end if end >= 0 else None]


def test_doc_order_of_line_checks_matches_firmware_and_mock() -> None:
    """docs/protocol.md 5.2 lists the line checks in the order fb_main.c and the mock
    apply them: a receive overflow (error:18) is reported before "too long" (error:2)."""
    doc = _section((ROOT / "docs" / "protocol.md").read_text(), "### 5.2")
    steps = re.findall(r"^\d+\. (.*)$", doc, flags=re.M)
    first_codes = [m.group(1) for s in steps if (m := re.search(r"`error:(\d+)", s))]
    assert first_codes[:2] == ["18", "2"], steps[:2]
    fw = (ROOT / "firmware" / "fivebar" / "fb_main.c").read_text()
    handle = fw[fw.index("static void handle_line"):]
    assert handle.index("FB_ERR_RX_OVERFLOW") < handle.index("FB_ERR_LINE_TOO_LONG")
    mock = (ROOT / "fivebar_host" / "devices" / "mock" / "firmware.py").read_text()
    handle = mock[mock.index("def _handle_line"):]
    assert handle.index("E_RX_OVERFLOW") < handle.index("E_LINE_TOO_LONG")
