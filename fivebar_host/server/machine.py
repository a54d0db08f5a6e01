"""The machine thread's shared state: the link, what is known of the arms' pose, the snapshot.

`MachineState` is the base of the `Worker` thread (server.worker): it holds the state the
job run, the controls and the crash recovery share, and the few things all of them need —
(re)connecting the `JournalLink`, recording whether the pose is trusted (in SQLite, with the
controller's line counter), answering `run_job`'s pose questions, parking the arms, and
compiling a job record again. Only the machine thread calls its underscore methods;
`machine()` is the snapshot any thread may read (no serial traffic); `on_change` is called
(machine thread) after every status report and progress update, so the web page's event
stream can push the change at once.
"""

from __future__ import annotations

import contextlib
import logging
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.compile.steps import pen_position_mm
from fivebar_host.config import Profile
from fivebar_host.errors import FivebarError
from fivebar_host.program import Kind, Program
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import LinkError
from fivebar_host.run.moves import travel
from fivebar_host.run.overrides import Overrides
from fivebar_host.server.jobs import (
    Compiled,
    CompiledCache,
    JobOptions,
    SubmitError,
    compile_upload,
)
from fivebar_host.server.journal import JournalLink, ProgressWriter
from fivebar_host.server.store import JobRecord, JobStore

log = logging.getLogger("fivebar.serve")

_POSITION_Q = re.compile(r"A = (-?\d+), B = (-?\d+)")


def _nothing() -> None:
    """No one listens for changes."""


def _code_text(code: int | None) -> str:
    """An alarm's reason in words, from the protocol's code table."""
    info = protocol.CODES.get(code if code is not None else -1)
    return f"alarm {code}: {info.description}" if info else f"alarm {code}"


class ActionError(FivebarError, RuntimeError):
    """A machine action (home) that cannot be done now; the message says why."""


class JobStateError(FivebarError, RuntimeError):
    """A job request that does not fit the job's state (e.g. pausing a finished job)."""


@dataclass(frozen=True)
class WorkerConfig:
    """What the worker needs to reach and drive the machine."""

    port_url: str
    profile: Profile
    state_dir: Path
    baud: int
    banner_timeout_s: float
    reply_timeout_s: float
    reconnect_s: float = 2.0
    idle_poll_s: float = 0.25
    auto_resume: bool = False
    drain_timeout_s: float = 120.0


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
    #: reads for every line it writes; set through `Control.set_overrides`.
    overrides: Overrides = field(default_factory=Overrides)


class MachineState(threading.Thread):
    """The machine thread's state and its link and pose helpers (see the module docstring)."""

    def __init__(self, cfg: WorkerConfig, store: JobStore, cache: CompiledCache) -> None:
        super().__init__(name="fivebar-machine", daemon=True)
        self.cfg = cfg
        self.store = store
        self.cache = cache
        self._cv = threading.Condition()
        self._terminate = False
        self._hurry = False
        self._request: str | None = None  # for the running job: pause, resume, cancel
        self._confirm_once: dict[int, bool] = {}
        self._actions: deque[tuple[Callable[[JournalLink], Any], Future[Any]]] = deque()
        self.link: JournalLink | None = None
        self.error: str | None = "not connected yet"
        self.current: int | None = None
        self.live: Live | None = None
        self.pose_known = False
        self.finished = threading.Event()
        self._question: str | None = None
        self._recovered = False
        self.progress = ProgressWriter(store)
        #: The motors were switched off (M18): the arms move freely, the pose is unknown,
        #: and the next motion switches them on again (M17) first.
        self.motors_disabled = False
        #: Told of every status report and progress update (any quick callable).
        self.on_change: Callable[[], None] = _nothing

    # ================================================================== snapshot (any thread)
    def machine(self) -> dict[str, Any]:
        """What is known about the machine now (no serial traffic)."""
        link = self.link
        st = link.last_status if link is not None else None
        banner = link.banner if link is not None else None
        return {
            "connected": link is not None,
            "port": self.cfg.port_url,
            "error": self.error,
            "firmware": None if banner is None else {
                "version": banner.version, "protocol": banner.proto, "rx_bytes": banner.rx,
                "queue_blocks": banner.queue, "line_bytes": banner.line_max},
            "state": None if st is None else st.state,
            "detail": None if st is None else st.detail,
            "position": None if st is None else {"a": st.a, "b": st.b},
            "position_mm": self._position_mm(st),
            "laser": None if st is None else st.laser,
            "queued_blocks": None if st is None else st.queued,
            "done_line": None if st is None else st.done_line,
            "accepted_line": None if st is None else st.accepted_line,
            "underruns": None if st is None else st.underruns,
            "pose_known": self.pose_known,
            "motors_off": self.motors_disabled,
            "alarm": None if st is None or st.state != "Alarm" else _code_text(st.detail),
            "status_age_s": None if link is None or st is None
            else round(time.monotonic() - link.status_at, 3),
        }

    def _position_mm(self, st: StatusReport | None) -> dict[str, float] | None:
        """The pen in machine mm (forward kinematics), when the position is trusted."""
        if st is None or not self.pose_known:
            return None
        prof = self.cfg.profile
        xy = pen_position_mm(prof.geometry, prof.kinematics.assembly, prof.motors.home_rad,
                             prof.motors.steps_per_rev, st.a, st.b)
        return None if xy is None else {"x": round(xy[0], 3), "y": round(xy[1], 3)}

    # ------------------------------------------------------------------ link
    def _connect(self) -> bool:
        cfg = self.cfg
        try:
            opened = JournalLink.open(cfg.port_url, baud=cfg.baud,
                                      banner_timeout_s=cfg.banner_timeout_s,
                                      reply_timeout_s=cfg.reply_timeout_s,
                                      link_baud=cfg.profile.serial.link_baud)
        except (LinkError, OSError) as e:
            if self.error != str(e):
                log.warning("cannot open %s: %s (retrying every %g s)", cfg.port_url, e,
                            cfg.reconnect_s)
            self.error = str(e)
            return False
        assert isinstance(opened, JournalLink)
        link = opened
        if link.baud_warning:
            log.warning("%s", link.baud_warning)
        link.on_status = lambda: self.on_change()
        self.link = link
        self.error = None
        st = link.last_status
        assert link.banner is not None and st is not None
        log.info("connected to %s: firmware %s, protocol %d, rx %d bytes, queue %d blocks; "
                 "%s at A = %d, B = %d", cfg.port_url, link.banner.version, link.banner.proto,
                 link.banner.rx, link.banner.queue, st.state, st.a, st.b)
        # The pose the daemon recorded still holds if this is the same firmware session: its
        # line counter only grows until a reset or reboot (which also zero it). H:1 says the
        # firmware itself knows its position (kept across a reset; lost at power-on).
        facts = self.store.machine()
        rec_line = int(facts.get("accepted_line", 0) or 0)
        same_session = bool(facts.get("pose_known")) and 0 < rec_line <= st.accepted_line
        self.pose_known = (st.homed or same_session) and st.state != "Alarm"
        log.info("machine pose %s", "known (same controller session as before)"
                 if self.pose_known else "unknown until homed or confirmed")
        return True

    def _disconnected(self, why: str) -> None:
        log.error("link lost: %s", why)
        self.error = why
        if self.link is not None:
            self.link.close()
        self.link = None
        self._recovered = False  # a held job's stream record may be refined on reconnect

    def _emergency_stop(self) -> None:
        link = self.link
        if link is None:
            return
        with contextlib.suppress(Exception):
            link.realtime(protocol.RT_HOLD)
            link.reset()

    def _motors_on(self, link: JournalLink) -> None:
        """Switch the motors on again (`M17`) before a motion, after a motors-off."""
        if self.motors_disabled:
            link.command("M17")
            self.motors_disabled = False
            log.info("motors on (M17)")

    # ------------------------------------------------------------------ pose
    def _set_pose(self, known: bool, st: StatusReport | None) -> None:
        """Record whether the position is trusted, with the controller's line counter.

        A reset zeroes the counter, and so does a reboot; a restarted daemon trusts its record
        only when the counter is at least the recorded one and not zero. So after a reset
        one harmless numbered line (`G90`) marks the controller session as this one's."""
        self.pose_known = known
        link = self.link
        if known and link is not None and st is not None and st.accepted_line == 0:
            try:
                link.command("G90")
                st = link.status()
            except LinkError as e:
                log.warning("could not mark the controller session: %s", e)
        self._save_machine(st)

    def _save_machine(self, st: StatusReport | None = None) -> None:
        link = self.link
        st = st or (link.last_status if link is not None else None)
        try:
            if st is None:
                self.store.set_machine(pose_known=self.pose_known)
            else:
                self.store.set_machine(pose_known=self.pose_known,
                                       accepted_line=st.accepted_line, position=[st.a, st.b])
        except Exception:  # pragma: no cover - closing store at shutdown
            log.exception("could not record the machine state")

    def answer(self, link: JournalLink, question: str, job_confirm: bool,
                person_confirm: bool) -> bool:
        """Answer run_job's pose question (module docstring: Questions)."""
        st = link.last_status
        target: tuple[int, int] | None = None
        if "home pose" in question:
            target = (0, 0)
        else:
            m = _POSITION_Q.search(question)
            if m:
                target = (int(m.group(1)), int(m.group(2)))
        if (self.pose_known and target is not None and st is not None
                and (st.a, st.b) == target):
            log.info("%s yes (the daemon's record and the firmware's count agree)", question)
            self._question = None
            return True
        if person_confirm or (job_confirm and not self.pose_known):
            log.info("%s yes (confirmed by the person who %s the job)", question,
                     "resumed" if person_confirm else "submitted")
            self.pose_known = True
            self._question = None
            return True
        self._question = question
        return False

    def _park(self, link: JournalLink, job: Job) -> None:
        """Bring the arms to the homed pose (checked, laser off) when known to be elsewhere."""
        st = link.status()
        if not self.pose_known or (st.a, st.b) == (0, 0) or st.state != "Idle":
            return
        moves = travel(self.cfg.profile, job.assembly, (st.a, st.b), (0, 0),
                       "park the arms at the home pose before the next job")
        log.info("parking: travel from A = %d, B = %d to the home pose", st.a, st.b)
        res = link.stream(Program.join([Program.command(Kind.ABSOLUTE),
                                        Program.command(Kind.TOOL_OFF), moves]))
        link.wait_idle(max(30.0, 3.0 * res.elapsed_s), last_line=res.last_line)

    # ------------------------------------------------------------------ job records
    def _job(self, rec: JobRecord) -> Job:
        """The compiled job of a record (cached, or compiled again from its upload)."""
        job = self.cache.get(rec.id)
        if job is not None:
            return job
        return self.adopt(rec, compile_upload(self.upload(rec), rec.name,
                                              JobOptions.from_json(rec.options),
                                              self.cfg.profile))

    def upload(self, rec: JobRecord) -> bytes:
        """The stored drawing of a record, to compile it again."""
        data = self.store.upload(rec.id)
        if data is None:
            raise SubmitError("gone", f"job {rec.id}: its upload is no longer stored")
        return data

    def adopt(self, rec: JobRecord, compiled: Compiled) -> Job:
        """Cache a record's job compiled again (here or in a compiling process), once it
        is checked to be the job that was submitted."""
        if compiled.fingerprint != rec.fingerprint:
            raise SubmitError("changed", f"job {rec.id}: compiling it again gives a different "
                              "job (the daemon's profile or program changed since it was "
                              "submitted); submit it again")
        self.cache.put(rec.id, compiled.job)
        return compiled.job
