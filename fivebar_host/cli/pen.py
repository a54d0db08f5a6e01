"""Pen and motor commands: `fivebar pen up|down|toggle` and `fivebar motors off`.

For setting a pen plotter up by hand: try the profile's pen positions (`pen down` to set the
pen's height in its holder), and switch the motors off so that the arms can be moved to the
home pose. The pen lines are the firmware's `M280` (docs/protocol.md 6.2) with the profile's
[pen] values and the same overrides as `plot`; `motors off` is `M18`.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import (
    click_option,
    config_option,
    controller_option,
    fail,
    handle_errors,
    load,
    machine,
    main,
    port_option,
)
from fivebar_host.config import Profile, with_pen_overrides
from fivebar_host.options import BY_NAME, PEN_NAMES


def _pen_options(fn: Any) -> Any:
    """The pen overrides of `plot` (--pen-pos-up …), generated from fivebar_host.options."""
    for name in reversed(PEN_NAMES):
        fn = click_option(BY_NAME[name])(fn)
    return fn


def _wanted(action: str, prof: Profile, pulse_now: int | None) -> bool:
    """True to lower the pen: `down`, or `toggle` from a pen nearer its up position."""
    if action != "toggle":
        return action == "down"
    if pulse_now is None:
        fail("the firmware reports no pen (flash the current firmware/build/fivebar.hex)", 3)
    assert prof.pen is not None and pulse_now is not None
    if pulse_now == 0:  # no pulses yet: the firmware's pen was never set up
        return True
    up = prof.pen.pulse_us(prof.pen.up_position)
    down = prof.pen.pulse_us(prof.pen.down_position)
    return abs(pulse_now - up) <= abs(pulse_now - down)


@main.command("pen")
@click.argument("action", type=click.Choice(["up", "down", "toggle"]))
@port_option
@click.option("--hold", "hold_s", type=click.FloatRange(min=0.0), default=0.0,
              show_default=True, metavar="SECONDS",
              help="Keep the link alive this long afterwards: the firmware raises a lowered "
              "pen after the profile's silence timeout without host traffic.")
@_pen_options
@controller_option
@config_option
@handle_errors
def pen_cmd(action: str, port: str | None, hold_s: float, controller: str,
            config_path: Path | None,
            **pen_values: Any) -> None:
    """Move the servo pen up, down, or to the other position (the profile's [pen])."""
    prof = with_pen_overrides(load(config_path), pen_values)
    if prof.pen is None:
        fail(f"{prof.source}: no [pen] table: this profile's tool is a laser")
    c = machine(port, controller, prof)
    try:
        st = c.status()
        if st.state not in ("Idle", "Hold"):
            fail(f"the machine is {st.state}: the pen moves only when it is idle", 3)
        down = _wanted(action, prof, st.pen_us)
        st = c.pen(down)
        end = time.monotonic() + hold_s
        while time.monotonic() < end:
            time.sleep(min(0.25, max(0.0, end - time.monotonic())))
            st = c.status()
    finally:
        c.close()
    where = "down" if down else "up"
    note = ("; it goes up again after the silence timeout without host traffic"
            if down and not hold_s else "")
    click.echo(f"pen {where}: servo pulse {st.pen_us} µs{note}")


@main.group("motors")
def motors() -> None:
    """Stepper driver commands."""


@motors.command("off")
@port_option
@controller_option
@config_option
@handle_errors
def motors_off(port: str | None, controller: str, config_path: Path | None) -> None:
    """Switch the stepper drivers off (M18) so that the arms can be moved by hand.

    Moving them loses the position: home again afterwards (`fivebar home`)."""
    c = machine(port, controller, load(config_path))
    try:
        st = c.motors_off()
    finally:
        c.close()
    a, b = st.position
    click.echo(f"motors off at A = {a}, B = {b} steps; move the arms by hand, then run "
               "`fivebar home`")
