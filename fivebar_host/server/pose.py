"""What the daemon knows of the arms' pose, kept across its restarts (machine thread).

The firmware counts steps from wherever it was told the arms are; the daemon trusts that
count only when it homed the machine, a person confirmed the pose, or the count belongs to
the same controller session as its record in SQLite (the controller's line counter only
grows until a reset or a reboot, which zero it). `PoseKeeper` holds that judgement in the
machine thread's record (`pose_known`, `motors_off`), writes it to the database with the
line counter, answers `run_job`'s pose questions when the record makes a person's answer
unnecessary, switches the motors on again before a motion, and parks the arms at the home
pose before a job when they are known to be elsewhere.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.program import Kind, Program
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import LinkError
from fivebar_host.run.moves import slack_travel
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.state import Connection, MachineRecord
from fivebar_host.server.store import JobStore

log = logging.getLogger("fivebar.serve")

_POSITION_Q = re.compile(r"A = (-?\d+), B = (-?\d+)")


class PoseKeeper:
    """The arms' pose record and the motors (module docstring); machine thread only."""

    def __init__(self, record: MachineRecord, store: JobStore, profile: Profile,
                 changed: Callable[[], None]) -> None:
        self.record = record
        self.store = store
        self.profile = profile
        self.changed = changed  # publishes the record

    def connected(self, st: StatusReport) -> None:
        """A connection opened with status `st`: does the recorded pose still hold?"""
        # The pose the daemon recorded still holds if this is the same firmware session: its
        # line counter only grows until a reset or reboot (which also zero it). H:1 says the
        # firmware itself knows its position (kept across a reset; lost at power-on).
        facts = self.store.machine()
        rec_line = int(facts.get("accepted_line", 0) or 0)
        same_session = bool(facts.get("pose_known")) and 0 < rec_line <= st.accepted_line
        self.record.pose_known = (st.homed or same_session) and st.state != "Alarm"
        log.info("machine pose %s", "known (same controller session as before)"
                 if self.record.pose_known else "unknown until homed or confirmed")

    def set(self, known: bool, st: StatusReport | None) -> None:
        """Record whether the position is trusted, with the controller's line counter.

        A reset zeroes the counter, and so does a reboot; a restarted daemon trusts its record
        only when the counter is at least the recorded one and not zero. So after a reset
        one harmless numbered line (`G90`) marks the controller session as this one's."""
        self.record.pose_known = known
        conn = self.record.conn
        if known and conn is not None and st is not None and st.accepted_line == 0:
            try:
                conn.link.command("G90")
                st = conn.link.status()
            except LinkError as e:
                log.warning("could not mark the controller session: %s", e)
        self.save(st)
        self.changed()

    def forget(self) -> None:
        """The link broke mid-job: the arms may have moved on since the last report."""
        self.record.pose_known = False
        self.changed()

    def save(self, st: StatusReport | None = None) -> None:
        """Write the pose record (and the last status's line counter and position)."""
        conn = self.record.conn
        st = st or (conn.link.last_status if conn is not None else None)
        try:
            if st is None:
                self.store.set_machine(pose_known=self.record.pose_known)
            else:
                self.store.set_machine(pose_known=self.record.pose_known,
                                       accepted_line=st.accepted_line, position=[st.a, st.b])
        except Exception:  # pragma: no cover - closing store at shutdown
            log.exception("could not record the machine state")

    def answer(self, link: JournalLink, question: str, job_confirm: bool,
               person_confirm: bool) -> bool:
        """Answer run_job's pose question: yes when the record and the firmware's count
        agree, or a person confirmed (with the job, while the daemon did not know the pose,
        or with the resume request); otherwise the question waits for a person."""
        st = link.last_status
        target: tuple[int, int] | None = None
        if "home pose" in question:
            target = (0, 0)
        else:
            m = _POSITION_Q.search(question)
            if m:
                target = (int(m.group(1)), int(m.group(2)))
        rec = self.record
        if rec.pose_known and target is not None and st is not None and (st.a, st.b) == target:
            log.info("%s yes (the daemon's record and the firmware's count agree)", question)
            rec.question = None
            return True
        if person_confirm or (job_confirm and not rec.pose_known):
            log.info("%s yes (confirmed by the person who %s the job)", question,
                     "resumed" if person_confirm else "submitted")
            rec.pose_known = True
            rec.question = None
            self.changed()
            return True
        rec.question = question
        return False

    def motors_on(self, link: JournalLink) -> None:
        """Switch the motors on again (`M17`) before a motion, after a motors-off."""
        if self.record.motors_off:
            link.command("M17")
            self.record.motors_off = False
            self.changed()
            log.info("motors on (M17)")

    def park(self, conn: Connection, job: Job) -> None:
        """Bring the arms to the homed pose (checked, laser off) when known to be elsewhere."""
        st = conn.controller.status()
        if not self.record.pose_known or st.position == (0, 0) or st.state != "Idle":
            return
        # the slack taken up downward: the next job starts from that (compile/backlash.py)
        moves = slack_travel(self.profile, job.assembly, st.position, (0, 0), (0, 0),
                             "park the arms at the home pose before the next job")
        log.info("parking: travel from A = %d, B = %d to the home pose", *st.position)
        conn.controller.run_moves(Program.join([Program.command(Kind.ABSOLUTE),
                                                Program.command(Kind.TOOL_OFF), moves]),
                                  st.position)
