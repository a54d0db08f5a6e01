"""Pause, resume, cancel, stop and actions: the requests other threads make of the machine thread.

HTTP handlers and the daemon call the public methods (any thread): they only set a request
under the worker's condition variable, or queue an action for the machine thread to run
between jobs; `set_overrides` changes the running job's live `Overrides`, which its stream
reads for every line it writes. The machine thread reads the requests through the stop-kind
methods, which the job's operator (`server.operator`) passes on while a job streams:
`should_stop` makes it hold the
machine (`!`, laser off at once); `on_interrupt` then waits while paused (polling `?`),
resumes (`~`), or gives up. Cancel gives up at once; a stop (SIGTERM) first lets the
firmware run out of queued lines, so the machine stops at the end of a segment
(server.worker has the story).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

from fivebar_host import protocol
from fivebar_host.controllers.fivebar.controller import FivebarController
from fivebar_host.protocol import StatusReport
from fivebar_host.run.operator import Answering
from fivebar_host.server import store as st_
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.machine import ActionError, JobStateError, MachineState

log = logging.getLogger("fivebar.serve")


class Control(MachineState):
    """The worker's requests (any thread) and stop kind (machine thread)."""

    # ================================================================== requests (any thread)
    def notify(self) -> None:
        """Something was queued: look at the queue now."""
        with self._cv:
            self._cv.notify_all()

    def terminate(self, hurry: bool = False) -> None:
        """Stop: the running job stops at a segment boundary (or at once with `hurry`)."""
        with self._cv:
            self._terminate = True
            self._hurry = self._hurry or hurry
            self._cv.notify_all()

    def pause(self, job_id: int) -> None:
        """Hold the running job (laser off at once)."""
        with self._cv:
            if self.current != job_id:
                raise JobStateError(f"job {job_id} is not running")
            if self._request not in ("cancel",):
                self._request = "pause"
            self._cv.notify_all()

    def resume(self, job_id: int, confirm: bool = False) -> None:
        """Continue a paused job, or requeue a held one (at the head of the queue)."""
        with self._cv:
            if self.current == job_id:
                if self._request == "pause" or (self.live is not None and self.live.paused):
                    self._request = "resume"
                    self._cv.notify_all()
                    return
                raise JobStateError(f"job {job_id} is running, not paused")
            rec = self.store.get(job_id)
            if rec is None:
                raise KeyError(job_id)
            if rec.state != st_.HELD:
                raise JobStateError(f"job {job_id} is {rec.state}: only a paused or held job "
                                    "can be resumed")
            self._confirm_once[job_id] = confirm
            self.store.set_state(job_id, st_.QUEUED, message="resume requested")
            self._cv.notify_all()

    def set_overrides(self, job_id: int, feed_pct: int | None = None,
                      power_pct: int | None = None) -> tuple[int, int]:
        """Set the running (or paused) job's live feed and laser-power overrides; the
        factors now in force, (feed %, power %). They change the lines not yet written
        (`run.overrides`): a power change at the next line, a feed change at the next rest."""
        with self._cv:
            live = self.live
            if self.current != job_id or live is None or live.job_id != job_id:
                raise JobStateError(f"job {job_id} is not running: overrides apply to the "
                                    "running job only")
            live.overrides.set(feed_pct, power_pct)
            values = live.overrides.values()
        log.info("job %d: overrides %s", job_id, live.overrides.text())
        self.on_change()
        return values

    def cancel(self, job_id: int) -> None:
        """Cancel a job: the running one stops at once (laser off); others leave the queue."""
        with self._cv:
            if self.current == job_id:
                self._request = "cancel"
                self._cv.notify_all()
                return
            rec = self.store.get(job_id)
            if rec is None:
                raise KeyError(job_id)
            if rec.state in st_.FINAL_STATES:
                raise JobStateError(f"job {job_id} is already {rec.state}")
            self.store.set_state(job_id, st_.CANCELLED, message="cancelled before it ran"
                                 if rec.state == st_.QUEUED and rec.resume is None
                                 else "cancelled while held")
            self.cache.drop(job_id)
            self._cv.notify_all()

    def run_action(self, fn: Callable[[JournalLink], Any], timeout_s: float) -> Any:
        """Run `fn(link)` on the machine thread between jobs; its result or its exception."""
        fut: Future[Any] = Future()
        with self._cv:
            if self._terminate:
                raise ActionError("the daemon is stopping")
            self._actions.append((fn, fut))
            self._cv.notify_all()
        return fut.result(timeout=timeout_s)

    def home(self, at_home: bool, timeout_s: float = 180.0) -> StatusReport:
        """Home the machine: `$H` with endstops, else `G92 A0 B0` once the person confirms."""
        def act(link: JournalLink) -> StatusReport:
            if self.current is not None:
                raise ActionError(f"job {self.current} is running: cancel it before homing")
            if not self.cfg.profile.motors.endstops and not at_home:
                raise ActionError("the machine has no endstops: place the arms at the home pose "
                                  "and confirm with at_home=true")
            self._motors_on(link)
            FivebarController(link, self.cfg.profile).home(Answering(at_home))
            st = link.wait_idle(120.0)
            self._set_pose(True, st)
            return st

        if self.link is None:
            raise ActionError(f"the machine is not connected ({self.error})")
        result: StatusReport = self.run_action(act, timeout_s)
        return result

    # ------------------------------------------------------------------ stop kind (machine thread)
    def _stop_kind(self) -> str | None:
        with self._cv:
            if self._terminate:
                return "terminate"
            return self._request

    def _why(self) -> str:
        kind = self._stop_kind()
        return {"cancel": "job cancelled", "terminate": "the daemon is stopping",
                "pause": "paused"}.get(kind or "", "interrupted")

    def should_stop(self) -> bool:
        return self._stop_kind() in ("pause", "cancel", "terminate")

    def on_interrupt(self) -> bool:
        """Called by `Link.stream` with the machine held: True resumes, False gives up."""
        link = self.link
        assert link is not None
        kind = self._stop_kind()
        if kind == "terminate":
            self._drain(link)
            return False
        if kind == "cancel":
            return False
        current = self.current
        assert current is not None
        return self._wait_paused(link, current)

    def _wait_paused(self, link: JournalLink, job_id: int,
                     message: str = "paused: held, laser off") -> bool:
        """Stay held (or idle at a pen change) until resume (True), cancel or stop (False);
        keeps polling `?`. `message` is the paused job's reason."""
        if self.live is not None:
            self.live.paused = True
        self.store.set_state(job_id, st_.PAUSED, message=message)
        log.info("job %d %s", job_id, message)
        try:
            while True:
                kind = self._stop_kind()
                if kind in ("cancel", "terminate"):
                    return False
                if kind == "resume":
                    with self._cv:
                        self._request = None
                    self.store.set_state(job_id, st_.RUNNING, message="")
                    log.info("job %d resumed", job_id)
                    return True
                link.status()
                with self._cv:
                    self._cv.wait(0.2)
        finally:
            if self.live is not None:
                self.live.paused = False

    def _drain(self, link: JournalLink) -> None:
        """Let the held machine run out of queued lines: it stops at a segment's end."""
        link.realtime(protocol.RT_RESUME)
        deadline = time.monotonic() + self.cfg.drain_timeout_s
        while time.monotonic() < deadline:
            with self._cv:
                if self._hurry:
                    log.warning("stopping at once (second signal): the machine holds "
                                "inside a segment")
                    return
            st = link.status()
            if st.state != "Run" and st.queued == 0:
                return
            time.sleep(0.05)
        log.warning("the machine did not run out of queued lines within %g s; holding it",
                    self.cfg.drain_timeout_s)
