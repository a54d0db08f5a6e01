"""GRBL 1.1 protocol contract of `fivebar bridge`: the same sender-side scenarios against the
bridge in front of the mock and in front of the emulated firmware (docs/grbl.md)."""

from __future__ import annotations

import math
import re
import time

import pytest
from grbl_client import GrblClient, mpos
from grbl_support import ORIGIN, Running

HOME = (20.0, 126.795)  # pen at the default profile's homed pose, machine mm


def test_boot_is_locked_until_unlock(bridge: Running) -> None:
    c = bridge.client()
    c.wait_for(lambda s: s == "[MSG:'$H'|'$X' to unlock]")
    assert c.status().startswith("<Alarm|MPos:20.000,126.795,0.000")
    assert c.command("G0 X1")[1] == "error:9"
    lines, reply = c.command("$X")
    assert (lines, reply) == (["[MSG:Caution: Unlocked]"], "ok")
    assert c.status().startswith("<Idle|")
    c.close()


def test_banner_again_after_ctrl_x(grbl: GrblClient) -> None:
    n = len(grbl.lines)
    grbl.write(b"G1 X1")  # a partial line: discarded by the reset
    grbl.write(b"\x18")
    grbl.wait_for(lambda s: s == "Grbl 1.1h ['$' for help]", start=n)
    assert grbl.command("G0 X0 Y0") == ([], "ok")


def test_views(grbl: GrblClient) -> None:
    lines, reply = grbl.command("$$")
    assert reply == "ok" and "$10=1" in lines and "$32=1" in lines
    assert all(re.fullmatch(r"\$\d+=[\d.]+", s) for s in lines)
    assert grbl.command("$G")[0] == ["[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]"]
    params = grbl.command("$#")[0]
    assert params[0] == f"[G54:{ORIGIN[0]:.3f},{ORIGIN[1]:.3f},0.000]"
    assert params[-1] == "[PRB:0.000,0.000,0.000:0]"
    assert grbl.command("$I")[0] == ["[VER:1.1h.20190830:]", "[OPT:V,15,128]"]
    assert grbl.command("$")[0][0].startswith("[HLP:")
    st = grbl.status()
    assert re.fullmatch(r"<Idle\|MPos:[-\d.]+,[-\d.]+,[-\d.]+\|FS:\d+,\d+(\|(WCO|Ov):[^|>]+)*>",
                        st), st


def test_settings_are_grbl_shaped(grbl: GrblClient) -> None:
    assert grbl.command("$10=3")[1] == "ok"
    assert "|Bf:15,128|" in grbl.status()
    assert grbl.command("$10=0")[1] == "ok"
    assert grbl.status().startswith("<Idle|WPos:15.000,31.795,0.000")
    assert grbl.command("$100=80")[1] == "ok"  # accepted and kept, no effect on the firmware
    assert "$100=80.000" in grbl.command("$$")[0]
    assert grbl.command("$99=1")[1] == "error:3"
    assert grbl.command("$110=-5")[1] == "error:4"
    assert grbl.command("$1x")[1] == "error:3"
    assert grbl.command("$FOO")[1] == "error:3"


@pytest.mark.parametrize(("line", "code"), [
    ("G0 X1 A2", 20),  # unsupported axis word
    ("G38.2 X1", 20),  # probing
    ("G0 G1 X1", 21),  # two motion commands
    ("G0 X1 X2", 25),  # repeated word
    ("G1 X5", 22),  # no feed rate yet
    ("G2 X5 Y5 F100", 35),  # arc without offsets
    ("G0 X1 I2", 36),  # unused word
    ("X", 2),  # bad number
    ("1G0", 1),  # expected a letter
    ("G4", 28),  # G4 without P
    ("G53 G2 X1 Y1 I1", 30),
    ("G0 " + "X1.0000" * 12, 11),  # longer than GRBL's 80-byte line
    ("M6", 20),
    ("G1.5 X1", 23),  # G1 takes no decimal
    ("G1 F-3", 4),
])
def test_gcode_errors(grbl: GrblClient, line: str, code: int) -> None:
    assert grbl.command(line)[1] == f"error:{code}"
    assert grbl.wait_state("Idle", 5).startswith("<Idle|MPos:20.000,126.795")


def test_binary_garbage_never_crashes(grbl: GrblClient) -> None:
    junk = bytes(range(256)).replace(b"\x18", b"") * 3
    grbl.write(junk + b"\n")
    time.sleep(0.3)
    grbl.status()
    assert grbl.command("G0 X10 Y10") == ([], "ok")
    grbl.wait_state("Idle")


def _draw(grbl: GrblClient) -> list[str]:
    return (["G21 G90 G54", "M4 S800", "G0 X5 Y5", "G1 X25 Y5 F900", "G3 X25 Y25 I0 J10",
             "G1 X5 Y25", "G2 X5 Y5 R10", "M5", "G0 X15 Y15"])


def test_streaming_by_character_counting(grbl: GrblClient) -> None:
    replies = grbl.stream(_draw(grbl))
    assert replies == ["ok"] * len(_draw(grbl))
    st = grbl.wait_state("Idle")
    x, y, _ = mpos(st)
    assert math.hypot(x - (ORIGIN[0] + 15), y - (ORIGIN[1] + 15)) < 0.05 + 0.02


def test_unreachable_target_alarms_before_moving(grbl: GrblClient) -> None:
    lines, reply = grbl.command("G0 X200 Y0")
    assert reply == "error:9"
    assert lines[0] == "ALARM:2"
    assert lines[1].startswith("[MSG:Refused reach at machine (205.000, 95.000) mm")
    assert grbl.status().startswith("<Alarm|MPos:20.000,126.795")
    assert grbl.command("G0 X1 Y1")[1] == "error:9"
    assert grbl.command("$X")[1] == "ok"
    assert grbl.command("G0 X10 Y10")[1] == "ok"


def test_target_near_singularity_is_refused(grbl: GrblClient) -> None:
    # reachable, but arm 2 would be 4.4 deg from stretched (the profile's minimum is 5 deg)
    lines, reply = grbl.command("G53 G1 X-8 Y142 F600")
    assert (reply, lines[0]) == ("error:9", "ALARM:2")
    assert "type1 margin" in lines[1] and "singularity" in lines[1], lines[1]
    assert grbl.status().startswith("<Alarm|MPos:20.000,126.795")


def test_hold_and_resume(grbl: GrblClient) -> None:
    assert grbl.command("G1 X0 Y0 F60")[1] == "ok"  # 1 mm/s: long enough to hold
    grbl.wait_state("Run", 5)
    grbl.write(b"!")
    held = grbl.wait_state("Hold", 5)
    time.sleep(0.3)
    assert mpos(grbl.wait_state("Hold", 5))[:2] == mpos(held)[:2]
    grbl.write(b"~")
    grbl.wait_state("Run", 5)
    grbl.write(b"\x18")
    grbl.wait_for(lambda s: s.startswith("Grbl"), start=len(grbl.lines) - 1)


def test_jog_and_jog_cancel(grbl: GrblClient) -> None:
    assert grbl.command("$J=G91 X5 F600")[1] == "ok"
    x, y, _ = mpos(grbl.wait_state("Idle"))
    assert abs(x - 25.0) < 0.05 and abs(y - 126.795) < 0.05
    assert grbl.command("$J=X5")[1] == "error:22"  # F is required
    assert grbl.command("$J=G1 X5 F100")[1] == "error:16"
    assert grbl.command("$J=G53 X500 F100")[1] == "error:15"  # no alarm for a jog
    assert grbl.command("$J=G91 Y-30 F30")[1] == "ok"
    deadline = time.monotonic() + 10
    while mpos(grbl.wait_state("Jog", 5))[1] > 126.5 and time.monotonic() < deadline:
        time.sleep(0.02)
    grbl.write(b"\x85")
    x, y, _ = mpos(grbl.wait_state("Idle", 10))
    assert 96.0 < y < 126.7


def test_overrides_reported(grbl: GrblClient) -> None:
    grbl.write(b"\x91\x91\x9b")
    for _ in range(12):
        st = grbl.status()
        if "Ov:" in st:
            break
    assert "Ov:120,100,90" in st


def test_check_mode_moves_nothing(grbl: GrblClient) -> None:
    assert grbl.command("$C") == (["[MSG:Enabled]"], "ok")
    assert grbl.status().startswith("<Check|")
    assert grbl.command("G0 X10 Y10")[1] == "ok"
    time.sleep(0.3)
    assert grbl.status().startswith("<Check|MPos:20.000,126.795")
    n = len(grbl.lines)
    assert grbl.command("$C")[1] == "ok"
    grbl.wait_for(lambda s: s.startswith("Grbl"), start=n)


def _wait_machine(bridge: Running, state: str, timeout: float = 5.0) -> str:
    deadline = time.monotonic() + timeout
    while bridge.core.machine.status.state != state and time.monotonic() < deadline:
        time.sleep(0.05)
    return bridge.core.machine.status.state


def test_disconnect_in_mid_line_holds_with_laser_off(bridge: Running) -> None:
    c = bridge.client()
    c.command("$X")
    c.stream(["M3 S1000", "G1 X0 Y0 F60"])
    c.wait_state("Run", 5)
    c.write(b"G1 X5")  # a broken line: the sender died while writing it
    c.close()
    assert _wait_machine(bridge, "Hold") == "Hold"
    assert bridge.core.machine.status.laser == 0
    c2 = bridge.client()
    assert c2.status().startswith("<Hold:0|")
    c2.close()


def test_close_after_complete_lines_finishes_them(bridge: Running) -> None:
    """GRBL's stream.py and every fire-and-forget streamer close the port after the last
    line: GRBL runs what it received, and so does the bridge."""
    c = bridge.client()
    c.command("$X")
    c.write(b"M3 S1000\nG1 X0 Y0 F300\nG1 X5 Y5\nM5\n")
    c.close()
    _wait_machine(bridge, "Run")
    assert _wait_machine(bridge, "Idle", 60) == "Idle"
    c2 = bridge.client()
    x, y, _ = mpos(c2.wait_state("Idle", 30))
    assert math.hypot(x - (ORIGIN[0] + 5), y - (ORIGIN[1] + 5)) < 0.05 + 0.02
    c2.close()


def test_hold_on_disconnect_keeps_the_old_behaviour(bridge: Running) -> None:
    bridge.core.hold_on_disconnect = True
    c = bridge.client()
    c.command("$X")
    c.stream(["M3 S1000", "G1 X0 Y0 F60"])
    c.wait_state("Run", 5)
    c.close()
    assert _wait_machine(bridge, "Hold") == "Hold"
    assert bridge.core.machine.status.laser == 0
