"""The machine panel's actions: home, jog, pen, motors off, clear alarm.

Each is a request to the machine thread (server.requests), carried out between jobs
(server.manual); the answer is the machine afterwards, or why it could not be done.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, Query

from fivebar_host.server.context import Context, Ctx
from fivebar_host.server.models import ApiError, ErrorOut, MachineOut
from fivebar_host.server.state import ActionError, machine_view

#: Largest jog: pen move per axis, mm; motor move, steps.
MAX_JOG_MM = 100.0
MAX_JOG_STEPS = 20000

#: The refusal of a manual action.
RESPONSES: dict[int | str, dict[str, Any]] = {
    409: {"model": ErrorOut, "description": "A job runs, the machine is not connected "
          "or in alarm, the position is unknown, or the move is not safe."}}

router = APIRouter()


def machine_action(ctx: Context, act: Callable[[], Any]) -> MachineOut:
    """Run a manual machine action on the machine thread; its outcome as the API answers
    it: the machine afterwards, or 409 (not now: a job runs, alarm, unknown pose, unsafe),
    504 (did not finish in time) or 502 (a link fault, whose message says what happened)."""
    try:
        act()
    except ActionError as e:
        raise ApiError(409, "conflict", str(e)) from e
    except TimeoutError as e:
        raise ApiError(504, "timeout", "the machine did not finish in time") from e
    except Exception as e:  # a link fault: the message says what happened
        raise ApiError(502, "machine_error", str(e)) from e
    return MachineOut(**machine_view(ctx.worker.snapshot(), ctx.profile))


@router.post("/api/machine/home", response_model=MachineOut, tags=["machine"],
             responses={409: {"model": ErrorOut, "description": "A job runs, or the arms' "
                              "position must be confirmed."}})
def home(ctx: Ctx, at_home: bool = Query(False, description="Without endstops: the person "
                                         "confirms the arms are at the profile's home "
                                         "pose.")) -> MachineOut:
    """Home: `$H` with endstops, else set the position to the home pose (G92 A0 B0)."""
    return machine_action(ctx, lambda: ctx.worker.home(at_home))


@router.post("/api/machine/jog", response_model=MachineOut, tags=["machine"],
             responses=RESPONSES)
def jog(ctx: Ctx,
        dx: float = Query(0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, description="Pen move, mm."),
        dy: float = Query(0.0, ge=-MAX_JOG_MM, le=MAX_JOG_MM, description="Pen move, mm."),
        motor: str | None = Query(None, pattern="^[AB]$", include_in_schema=False),
        steps: int = Query(0, ge=-MAX_JOG_STEPS, le=MAX_JOG_STEPS, include_in_schema=False),
        ) -> MachineOut:
    """Jog the pen by dx, dy mm as `fivebar jog` (laser off; checked, needs a known
    position: 409 where the move is not safe). A motor jog is `/api/machine/jog_motor`
    (the `motor` and `steps` parameters here, which the web page sends, are the same)."""
    if motor is not None and (dx or dy):
        raise ApiError(422, "bad_option", "give motor with steps, or dx/dy, not both")
    return machine_action(ctx, lambda: ctx.worker.jog(motor=motor, steps=steps)
                          if motor is not None else ctx.worker.jog(dxy_mm=(dx, dy)))


@router.post("/api/machine/jog_motor", response_model=MachineOut, tags=["machine"],
             responses=RESPONSES)
def jog_motor(ctx: Ctx,
              motor: str = Query(..., pattern="^[AB]$", description="Motor A or B."),
              steps: int = Query(..., ge=-MAX_JOG_STEPS, le=MAX_JOG_STEPS,
                                 description="Motor steps (unchecked before homing).")
              ) -> MachineOut:
    """Jog one motor by steps as `fivebar jog --motor` (laser off)."""
    return machine_action(ctx, lambda: ctx.worker.jog(motor=motor, steps=steps))


@router.post("/api/machine/motors_off", response_model=MachineOut, tags=["machine"],
             responses=RESPONSES)
def motors_off(ctx: Ctx) -> MachineOut:
    """Switch the motors off (M18): the arms move by hand; home before the next job."""
    return machine_action(ctx, ctx.worker.motors_off)


@router.post("/api/machine/pen", response_model=MachineOut, tags=["machine"],
             responses=RESPONSES)
def pen(ctx: Ctx, down: bool = Query(..., description="true: lower the pen; false: raise "
                                     "it.")) -> MachineOut:
    """Lower or raise the servo pen (pen machines only; the machine must be idle)."""
    return machine_action(ctx, lambda: ctx.worker.pen(down))


@router.post("/api/machine/clear_alarm", response_model=MachineOut, tags=["machine"],
             responses=RESPONSES)
def clear_alarm(ctx: Ctx) -> MachineOut:
    """Clear the machine's alarm (`$X`, position kept)."""
    return machine_action(ctx, ctx.worker.clear_alarm)
