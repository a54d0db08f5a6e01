"""GRBL's `$` system commands on the bridge: `$`, `$$`, `$#`, `$G`, `$I`, `$N`, `$C`, `$X`,
`$H`, `$J=`, `$RST=`, `$SLP` and `$<n>=<value>`, with GRBL's errors (system.c's rules: a
command that needs an idle machine answers `error:8` otherwise; an unknown one `error:3`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fivebar_host.bridge import codes, policy, views
from fivebar_host.bridge.codes import GrblError
from fivebar_host.gcode import NUMBER, ModalState
from fivebar_host.gcode import errors as gcode_errors

if TYPE_CHECKING:
    from fivebar_host.bridge.controller import Bridge


def run_system(bridge: Bridge, line: str) -> None:
    """Execute a pre-parsed `$` line; output goes to the sender, errors raise `GrblError`."""
    cmd = line[1:]
    state = bridge.grbl_state()
    idle = state in ("Idle", "Alarm") or state == "Check"
    if cmd in ("", "$", "G", "C", "X"):
        _simple(bridge, cmd, state)
    elif cmd.startswith("J="):
        if state not in ("Idle", "Jog"):
            raise GrblError(codes.NOT_IDLE, "jog needs Idle or Jog")
        bridge.jog(cmd[2:])
    elif not idle:
        raise GrblError(codes.NOT_IDLE, f"${cmd} needs an idle machine")
    elif cmd == "#":
        for text in views.parameters(bridge.modal, bool(bridge.settings.values[13])):
            bridge.send(text)
    elif cmd == "H":
        bridge.home()
    elif cmd.startswith("I"):
        _info(bridge, cmd)
    elif cmd.startswith("N"):
        _startup(bridge, cmd)
    elif cmd.startswith("RST="):
        _restore(bridge, cmd[4:])
    else:
        _setting(bridge, cmd)


def _simple(bridge: Bridge, cmd: str, state: str) -> None:
    if cmd == "":
        bridge.send(views.HELP)
    elif cmd == "$":
        if state.startswith(("Run", "Hold", "Jog")):
            raise GrblError(codes.NOT_IDLE, "$$ during a cycle")
        for text in bridge.settings.listing():
            bridge.send(text)
    elif cmd == "G":
        bridge.send(views.parser_state(bridge.modal))
    elif cmd == "C":
        if bridge.check_mode:
            bridge.send("[MSG:Disabled]")
            bridge.request_reset()
        elif state != "Idle":
            raise GrblError(codes.NOT_IDLE, "$C needs Idle")
        else:
            bridge.check_mode = True
            bridge.send("[MSG:Enabled]")
    elif cmd == "X":
        bridge.unlock()


def _info(bridge: Bridge, cmd: str) -> None:
    if cmd == "I":
        for text in views.build_info(bridge.settings):
            bridge.send(text)
    elif cmd.startswith("I="):
        bridge.settings.build_info = cmd[2:]
    else:
        raise GrblError(codes.INVALID_STATEMENT, f"${cmd}")


def _startup(bridge: Bridge, cmd: str) -> None:
    if cmd == "N":
        for i, text in enumerate(bridge.settings.startup):
            bridge.send(f"$N{i}={text}")
        return
    if len(cmd) < 3 or cmd[1] not in "01" or cmd[2] != "=":
        raise GrblError(codes.INVALID_STATEMENT, f"${cmd}")
    text = cmd[3:]
    if text:
        policy.parse(text)  # refuse a line GRBL's parser would refuse
    bridge.settings.startup[int(cmd[1])] = text


def _restore(bridge: Bridge, what: str) -> None:
    if what not in ("$", "#", "*"):
        raise GrblError(codes.INVALID_STATEMENT, f"$RST={what}")
    if what in ("$", "*"):
        bridge.settings.values = dict(bridge.default_settings)
    if what in ("#", "*"):
        fresh = ModalState()
        bridge.modal = ModalState(position=bridge.modal.position, g28=bridge.home_point,
                                  g30=bridge.home_point, offsets=bridge.default_offsets,
                                  feed=bridge.modal.feed, z_seen=bridge.modal.z_seen,
                                  wcs=fresh.wcs)
    if what == "*":
        bridge.settings.startup = ["", ""]
        bridge.settings.build_info = ""


def _setting(bridge: Bridge, cmd: str) -> None:
    """`$<n>=<value>`: GRBL's number parse, then `=`, then the value."""
    m = NUMBER.match(cmd)
    if m is None:
        raise GrblError(gcode_errors.BAD_NUMBER_FORMAT if cmd[:1].isdigit() or cmd[:1] in "+-."
                        else codes.INVALID_STATEMENT, f"${cmd}")
    rest = cmd[m.end():]
    if not rest.startswith("="):
        raise GrblError(codes.INVALID_STATEMENT, f"${cmd}")
    v = NUMBER.fullmatch(rest[1:])
    if v is None:
        raise GrblError(gcode_errors.BAD_NUMBER_FORMAT, f"${cmd}")
    number, value = float(m.group()), float(v.group())
    if number != int(number) or int(number) not in views.DEFAULTS:
        raise GrblError(codes.INVALID_STATEMENT, f"no setting ${m.group()}")
    if value < 0:
        raise GrblError(gcode_errors.NEGATIVE_VALUE, f"${m.group()}={v.group()}")
    n = int(number)
    if n in views.INTEGER:
        value = float(int(value))
    if n in views.BOOLEAN:
        value = 1.0 if value else 0.0
    if n in (30, 110, 111) and value <= 0:
        raise GrblError(gcode_errors.NEGATIVE_VALUE, f"${n} must be positive")
    bridge.settings.values[n] = value
