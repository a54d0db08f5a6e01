"""The API's shapes: response models, the error answer, job ids in paths, the job view.

FastAPI derives the OpenAPI description (`GET /openapi.json`) from the routes' signatures
(server.routes) and the models here. Every error answers with `{"error": <stable key>,
"message": <what and why>}` (plus details for refused drawings): a route raises `ApiError`,
and the application's handlers (server.app) write it. A job id in a path is an integer in
decimal digits (else 422); one no job can have is not found (404, `Context.get_rec`).
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from fastapi import Path
from pydantic import BaseModel, BeforeValidator, Field, create_model

from fivebar_host.errors import FivebarError, shorten
from fivebar_host.options import JOB_OPTIONS, Option
from fivebar_host.server import store as st_
from fivebar_host.server.jobs import JobOptions
from fivebar_host.server.security import RETRY_AFTER_S
from fivebar_host.server.state import LiveView
from fivebar_host.server.store import JobRecord

#: Longest parameter name echoed back in an error message, characters.
MAX_ECHO = 64
#: What a job id in a path may look like: decimal digits, optionally negative (a number no
#: job has is "not found"; anything else — `5_0`, `+5`, ` 5`, `0x5` — is not an id).
_ID_TEXT = re.compile(r"-?[0-9]+")


def _id_digits(value: Any) -> Any:
    """Refuse a path job id that is not plain decimal digits before pydantic's lax int
    parsing would read `1_0` as job 10."""
    if isinstance(value, str) and not _ID_TEXT.fullmatch(value):
        raise ValueError("a job id is a whole number in decimal digits")
    return value


#: A job id in a path (out-of-range numbers are answered 404 by `Context.get_rec`).
JobId = Annotated[int, BeforeValidator(_id_digits),
                  Path(description="The job's id (a positive integer).")]


class ApiError(FivebarError):
    """An error answer: HTTP status, stable key, message, optional details and headers."""

    def __init__(self, status: int, error: str, message: str,
                 detail: dict[str, Any] | None = None,
                 headers: dict[str, str] | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.error = error
        self.message = message
        self.detail = detail or {}
        self.headers = headers


def busy(message: str, retry_after_s: float = RETRY_AFTER_S) -> ApiError:
    """The 503 answer of a daemon that cannot take more work now (with Retry-After)."""
    return ApiError(503, "busy", message,
                    headers={"Retry-After": str(max(1, math.ceil(retry_after_s)))})


def shown(key: str) -> str:
    """A client's parameter name or value as echoed in a message (long ones shortened:
    first and last characters and the length)."""
    return shorten(key, MAX_ECHO)


# ---------------------------------------------------------------------------- models
class ErrorOut(BaseModel):
    """Every error response."""

    error: str = Field(description="Stable key: input_error, job_error, bad_option, "
                       "not_found, conflict, unauthorized, too_large, ...")
    message: str = Field(description="What went wrong, where, and what to do.")
    reason: str | None = Field(None, description="job_error only: reach, joint_limit, "
                               "type1_margin, type2_margin, mode_change, does_not_fit, ...")
    where: dict[str, Any] | None = Field(None, description="job_error only: path and point.")


def _option_out(o: Option) -> tuple[Any, Any]:
    """A job option as a field of `OptionsOut`: its stored JSON type, its default and help."""
    kinds: dict[str, Any] = {"bool": bool, "float": float, "int": int, "choice": str,
                             "xy": list[float], "text": str}
    kind = list[str] if o.repeat else kinds[o.kind]
    default = [] if o.repeat else o.default
    return (kind if default is not None else kind | None,
            Field(default, description=o.describe()))


#: The plot options a job was submitted with: every job option, generated from its one
#: definition (`fivebar_host.options`), as the submission stored it.
_OPTION_FIELDS: dict[str, Any] = {o.name: _option_out(o) for o in JOB_OPTIONS}
OptionsOut = create_model("OptionsOut", __doc__="The plot options a job was submitted with.",
                          **_OPTION_FIELDS)


class ResumeOut(BaseModel):
    """Where an interrupted job continues."""

    next_segment: int = Field(description="First job segment not known to be finished.")
    position: list[int] | None = Field(description="Firmware steps [A, B] where the machine "
                                       "stopped; null when unknown (home before resuming).")
    reason: str
    copy_number: int = Field(1, description="The copy (`copies` option, 1-based) it "
                             "continues in.")


class OverridesOut(BaseModel):
    """The running job's live overrides (POST /api/jobs/{id}/overrides)."""

    feed_pct: int = Field(description="Feed, % of the planned speed (10..100, slower only).")
    power_pct: int = Field(description="Laser power, % of the planned power (0..100).")


class JobOut(BaseModel):
    """A job in the queue or in the history."""

    id: int
    name: str
    state: Literal["queued", "running", "paused", "held", "done", "failed", "cancelled"]
    message: str = Field(description="What happened last (fault, interruption, result).")
    question: str | None = Field(description="held: what the daemon needs a person to "
                                 "confirm (resume with confirm=true once it is so).")
    submitted_at: float = Field(description="Unix time.")
    started_at: float | None
    finished_at: float | None
    options: OptionsOut  # type: ignore[valid-type]  # a model made from the options
    mode: str = Field(description="Working mode the job was compiled in.")
    max_dev_mm: float | None = Field(description="Largest deviation from the drawing, mm.")
    segments_total: int
    segments_done: int = Field(description="Segments finished of the copy being drawn.")
    copy_number: int = Field(1, description="The copy being drawn (or last drawn), "
                             "1-based; options.copies is how many the job draws.")
    progress: float = Field(description="segments_done / segments_total.")
    estimated_s: float = Field(description="Planned duration of the whole job, s.")
    remaining_s: float | None = Field(description="Planned time left, s.")
    elapsed_s: float = Field(description="Time spent running (all runs of it), s.")
    underruns: int | None = Field(description="done: times the firmware queue ran empty "
                                  "mid-job (0 is the goal); null if unknown.")
    resume: ResumeOut | None
    overrides: OverridesOut | None = Field(None, description="Running or paused: the live "
                                           "feed and laser-power overrides; else null.")


class MachineOut(BaseModel):
    """The machine as last reported (no request reaches the serial port)."""

    connected: bool
    port: str
    error: str | None
    firmware: dict[str, Any] | None = Field(description="version, protocol, rx_bytes, "
                                            "queue_blocks, line_bytes from the banner.")
    state: str | None = Field(description="Idle, Run, Hold, Home or Alarm.")
    detail: int | None = Field(description="Hold reason or alarm code.")
    position: dict[str, int] | None = Field(description="Firmware steps {a, b}.")
    position_mm: dict[str, float] | None = Field(None, description="The pen {x, y} in machine "
                                                 "mm (forward kinematics), when pose_known.")
    laser: int | None = Field(description="Laser output now (0 = off).")
    queued_blocks: int | None = Field(description="Blocks waiting in the firmware queue.")
    done_line: int | None
    accepted_line: int | None
    underruns: int | None = Field(description="Times the queue ran empty since reset (U:).")
    pose_known: bool = Field(description="The daemon trusts the firmware's position.")
    motors_off: bool = Field(False, description="The motors were switched off (M18); the "
                             "next motion switches them on (M17).")
    alarm: str | None = Field(None, description="Alarm: its code and reason in words.")
    status_age_s: float | None = Field(description="Age of the last status report, s.")


class CompilingOut(BaseModel):
    """A drawing being compiled (a submission or a dry run), before any job exists."""

    name: str = Field(description="The drawing's name as submitted.")
    stage: str = Field(description="reading, placing, ordering paths, solving, travel, "
                       "segments, timing, validating.")
    progress: float | None = Field(description="How far the stage is, 0..1 (null: not "
                                   "known).")
    elapsed_s: float
    note: str | None = Field(None, description="The size of the work and its estimated "
                             "time, once known.")


class StatusOut(BaseModel):
    """Daemon, machine and queue at a glance."""

    version: str
    uptime_s: float
    stopping: bool
    machine: MachineOut
    jobs: dict[str, int] = Field(description="Number of jobs per state.")
    current_job: int | None
    blocked_by: int | None = Field(description="A paused or held job that keeps the queue "
                                   "from moving (resume or cancel it).")
    compiling: list[CompilingOut] = Field(default_factory=list, description="Drawings "
                                          "being compiled now (state `compiling`).")


# ---------------------------------------------------------------------------- the job view
def job_out(rec: JobRecord, live: LiveView | None) -> JobOut:
    """The API view of a job, with live progress for the running one (`live`: the
    machine thread's last published progress)."""
    done, remaining, elapsed = rec.segments_done, rec.remaining_s, rec.run_s
    copy = rec.resume.copy if rec.resume is not None else rec.copy
    ov = None
    if live is not None and live.job_id == rec.id:
        done, remaining, elapsed = live.segments_done, live.remaining_s, live.elapsed_s
        copy = live.copy
        if rec.state in (st_.RUNNING, st_.PAUSED):
            ov = OverridesOut(feed_pct=live.feed_pct, power_pct=live.power_pct)
    if rec.state == st_.QUEUED and rec.resume is None:
        remaining = rec.estimated_s
    o = JobOptions.from_json(rec.options).to_json()
    return JobOut(
        id=rec.id, name=rec.name, state=rec.state,  # type: ignore[arg-type]
        message=rec.message, question=rec.question, submitted_at=rec.submitted_at,
        started_at=rec.started_at, finished_at=rec.finished_at, options=OptionsOut(**o),
        mode=rec.mode, max_dev_mm=rec.max_dev_mm, segments_total=rec.segments_total,
        segments_done=done, copy_number=copy,
        progress=round(done / rec.segments_total, 6) if rec.segments_total else 1.0,
        estimated_s=rec.estimated_s, remaining_s=remaining, elapsed_s=round(elapsed, 3),
        underruns=rec.underruns, overrides=ov,
        resume=None if rec.resume is None else ResumeOut(
            next_segment=rec.resume.next_segment,
            position=list(rec.resume.position) if rec.resume.position else None,
            reason=rec.resume.reason, copy_number=rec.resume.copy))
