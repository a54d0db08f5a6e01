"""The machine thread's state: one record it alone writes, and the snapshot others read.

`MachineRecord` is everything the daemon's machine thread (server.worker) knows and decides
about the machine and the running job: the connection, whether the arms' pose is trusted,
the motors, the job it runs and that job's live progress, the request (pause, resume,
cancel) in force for it, the question waiting for a person, the one-off confirmations given
with resume requests, and whether the daemon is stopping. Only the machine thread writes it
(the worker loop and the collaborators it calls: `control`, `jobrun`, `manual`, `pose`,
`recovery`); other threads never see it. They send requests (server.requests) and read a
`Snapshot`: an immutable copy the machine thread publishes after every change, so a status
request never waits for the machine thread nor reaches the serial port.

`machine_view` turns a snapshot into the machine fields of `GET /api/status` (and the web
page's `status` event).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from fivebar_host import protocol
from fivebar_host.compile.steps import pen_position_mm
from fivebar_host.config import Profile
from fivebar_host.controllers.fivebar.controller import FivebarController
from fivebar_host.errors import FivebarError
from fivebar_host.protocol import Banner, StatusReport
from fivebar_host.run.overrides import Overrides
from fivebar_host.server.journal import JournalLink


class ActionError(FivebarError, RuntimeError):
    """A machine action (home, jog …) that cannot be done now; the message says why."""


class JobStateError(FivebarError, RuntimeError):
    """A job request that does not fit the job's state (e.g. pausing a finished job)."""


@dataclass(frozen=True)
class WorkerConfig:
    """What the worker needs to reach and drive the machine."""

    port_url: str
    profile: Profile
    baud: int
    banner_timeout_s: float
    reply_timeout_s: float
    reconnect_s: float = 2.0
    idle_poll_s: float = 0.25
    auto_resume: bool = False
    drain_timeout_s: float = 120.0
    #: What a command refused the port is told (the lock file's hint): where the API is.
    port_hint: str | None = None


@dataclass(frozen=True)
class Connection:
    """The open machine: the journalled link, and fivebar's controller over it (home, pen,
    motors off, the host's moves); the link itself for what only fivebar's firmware has
    (the `Ln` counters, holds with `!` / `~`, alarm pushes)."""

    link: JournalLink
    controller: FivebarController


@dataclass
class Live:
    """Progress of the running job, updated on every reply and status report."""

    job_id: int
    segments_done: int
    segments_total: int
    elapsed_s: float
    remaining_s: float
    paused: bool = False
    copy: int = 1  # the copy (`copies` option) being drawn, 1-based
    #: The run's live feed and laser-power overrides (`run.overrides`), which `run_job`
    #: reads for every line it writes; set by a `SetOverrides` request.
    overrides: Overrides = field(default_factory=Overrides)


@dataclass
class MachineRecord:
    """The machine thread's state (module docstring); written by the machine thread only."""

    conn: Connection | None = None
    error: str | None = "not connected yet"  # why there is no connection
    recovered: bool = False  # interrupted jobs were settled since this connection opened
    pose_known: bool = False  # the firmware's position is trusted
    #: The motors were switched off (M18): the arms move freely, the pose is unknown, and
    #: the next motion switches them on again (M17) first.
    motors_off: bool = False
    current: int | None = None  # the job being run
    live: Live | None = None
    request: str | None = None  # for the running job: pause, resume, cancel
    question: str | None = None  # what the running job waits for a person to confirm
    #: Resume requests' confirmations, taken by the job's next run.
    confirm_once: dict[int, bool] = field(default_factory=dict)
    terminate: bool = False  # the daemon stops: the running job stops at a segment's end
    hurry: bool = False  # ... or at once (a second signal)


@dataclass(frozen=True)
class LiveView:
    """The running job's live progress as published (a copy of `Live`)."""

    job_id: int
    segments_done: int
    segments_total: int
    elapsed_s: float
    remaining_s: float
    paused: bool
    copy: int
    feed_pct: int
    power_pct: int


@dataclass(frozen=True)
class Snapshot:
    """What other threads know of the machine thread: a copy of the record as published."""

    port: str
    connected: bool = False
    error: str | None = "not connected yet"
    banner: Banner | None = None
    status: StatusReport | None = None  # the last status report
    status_at: float = 0.0  # when it came (monotonic s)
    pose_known: bool = False
    motors_off: bool = False
    current: int | None = None
    live: LiveView | None = None

    @classmethod
    def of(cls, record: MachineRecord, port: str) -> Snapshot:
        """A copy of `record` (machine thread)."""
        link = record.conn.link if record.conn is not None else None
        live = record.live
        view = None
        if live is not None:
            feed, power = live.overrides.values()
            view = LiveView(live.job_id, live.segments_done, live.segments_total,
                            live.elapsed_s, live.remaining_s, live.paused, live.copy, feed,
                            power)
        return cls(port, link is not None, record.error,
                   None if link is None else link.banner,
                   None if link is None else link.last_status,
                   0.0 if link is None else link.status_at, record.pose_known,
                   record.motors_off, record.current, view)


def _code_text(code: int | None) -> str:
    """An alarm's reason in words, from the protocol's code table."""
    info = protocol.CODES.get(code if code is not None else -1)
    return f"alarm {code}: {info.description}" if info else f"alarm {code}"


def _position_mm(profile: Profile, snap: Snapshot) -> dict[str, float] | None:
    """The pen in machine mm (forward kinematics), when the position is trusted."""
    st = snap.status
    if st is None or not snap.pose_known:
        return None
    xy = pen_position_mm(profile.geometry, profile.kinematics.assembly,
                         profile.motors.home_rad, profile.motors.steps_per_rev, st.a, st.b)
    return None if xy is None else {"x": round(xy[0], 3), "y": round(xy[1], 3)}


def machine_view(snap: Snapshot, profile: Profile) -> dict[str, Any]:
    """What is known about the machine (the API's `MachineOut` fields)."""
    st, banner = snap.status, snap.banner
    return {
        "connected": snap.connected,
        "port": snap.port,
        "error": snap.error,
        "firmware": None if banner is None else {
            "version": banner.version, "protocol": banner.proto, "rx_bytes": banner.rx,
            "queue_blocks": banner.queue, "line_bytes": banner.line_max},
        "state": None if st is None else st.state,
        "detail": None if st is None else st.detail,
        "position": None if st is None else {"a": st.a, "b": st.b},
        "position_mm": _position_mm(profile, snap),
        "laser": None if st is None else st.laser,
        "queued_blocks": None if st is None else st.queued,
        "done_line": None if st is None else st.done_line,
        "accepted_line": None if st is None else st.accepted_line,
        "underruns": None if st is None else st.underruns,
        "pose_known": snap.pose_known,
        "motors_off": snap.motors_off,
        "alarm": None if st is None or st.state != "Alarm" else _code_text(st.detail),
        "status_age_s": None if not snap.connected or st is None
        else round(time.monotonic() - snap.status_at, 3),
    }
