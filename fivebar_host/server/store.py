"""SQLite persistence of the daemon: the job queue, resume points and the machine's pose.

One small database file in the daemon's state directory (stdlib `sqlite3`, WAL journal).
Everything the daemon needs to carry on after a crash, a power loss or SIGKILL lives here:

- each job's upload (the drawing bytes, dropped once the job is over), its options, state,
  progress and time estimates;
- its resume point: the first segment not known to be finished and the firmware position
  where the machine stopped (None when unknown) — the same fields as `run.resume.ResumePoint`;
- its *stream record*, written before the first line of a stream leaves the host: the
  firmware line number of the stream's first line, the segment it started at and the start
  position. The program streamed is a pure function of the job and those three values
  (`run.moves.build_program`), so after a crash the firmware's own `Ln` counter (the line of
  the last block it executed) maps back to the exact segment the machine reached;
- what the daemon knows about the machine: whether its position is trusted ("pose known")
  and the firmware's line counter when that was last recorded;
- the order of the queue: a job's `queue_key` (its id until someone reorders the queue). A
  job that already started (resumed after a hold) runs before the others.

Every committed write bumps `JobStore.version` and calls the `listeners` (the web page's
event stream wakes on them instead of polling the database).

All access goes through one connection guarded by a lock: the HTTP threads read, the worker
writes, and SQLite's own locking would add nothing but "database is locked" retries.
"""

from __future__ import annotations

import builtins
import json
import os
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fivebar_host.errors import FivebarError

#: Job states. `held` jobs wait for a person (a fault, an interrupted job, or a question such
#: as "are the arms at the home pose?"); they block the queue until resumed or cancelled.
QUEUED, RUNNING, PAUSED, HELD, DONE, FAILED, CANCELLED = (
    "queued", "running", "paused", "held", "done", "failed", "cancelled")
STATES = (QUEUED, RUNNING, PAUSED, HELD, DONE, FAILED, CANCELLED)
FINAL_STATES = frozenset({DONE, FAILED, CANCELLED})
#: States that keep later jobs from starting (the paper holds a half-drawn job).
BLOCKING_STATES = frozenset({RUNNING, PAUSED, HELD})

SCHEMA_VERSION = 4
#: Job ids SQLite can hold (a signed 64-bit INTEGER PRIMARY KEY; AUTOINCREMENT starts at 1).
#: A number outside is no job: looked up it is "not found", never an OverflowError.
MIN_JOB_ID, MAX_JOB_ID = 1, 2**63 - 1


def valid_job_id(job_id: int) -> bool:
    """Whether `job_id` can name a row at all (SQLite refuses to bind larger integers)."""
    return MIN_JOB_ID <= job_id <= MAX_JOB_ID

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL,
    options TEXT NOT NULL,
    upload BLOB,
    upload_sha256 TEXT NOT NULL,
    state TEXT NOT NULL,
    message TEXT NOT NULL DEFAULT '',
    question TEXT,
    submitted_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL,
    fingerprint TEXT NOT NULL,
    mode TEXT NOT NULL,
    max_dev_mm REAL,
    segments_total INTEGER NOT NULL,
    estimated_s REAL NOT NULL,
    segments_done INTEGER NOT NULL DEFAULT 0,
    remaining_s REAL,
    run_s REAL NOT NULL DEFAULT 0,
    underruns INTEGER,
    resume_next INTEGER,
    resume_a INTEGER,
    resume_b INTEGER,
    resume_reason TEXT,
    stream_first_line INTEGER,
    stream_start_segment INTEGER,
    stream_start_a INTEGER,
    stream_start_b INTEGER,
    stream_lines INTEGER,
    queue_key REAL,
    resume_copy INTEGER,
    stream_copy INTEGER
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state);
CREATE TABLE IF NOT EXISTS machine (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""


class StoreError(FivebarError, RuntimeError):
    """The database cannot be opened or is of an unknown (newer) schema."""


@dataclass(frozen=True)
class ResumeRecord:
    """A job's resume point (mirrors `run.resume.ResumePoint` without the file name)."""

    next_segment: int
    position: tuple[int, int] | None
    reason: str
    copy: int = 1  # the copy (`copies` option) it stopped in


@dataclass(frozen=True)
class StreamRecord:
    """Where a stream of a job began: enough to rebuild the exact program sent."""

    first_line: int
    start_segment: int
    start_position: tuple[int, int]
    lines: int
    copy: int = 1  # the copy (`copies` option) the stream drew


@dataclass
class JobRecord:
    """One row of the queue (the upload bytes are loaded separately, on demand)."""

    id: int
    name: str
    options: dict[str, Any]
    upload_sha256: str
    state: str
    message: str
    question: str | None
    submitted_at: float
    started_at: float | None
    finished_at: float | None
    fingerprint: str
    mode: str
    max_dev_mm: float | None
    segments_total: int
    estimated_s: float
    segments_done: int
    remaining_s: float | None
    run_s: float
    underruns: int | None
    resume: ResumeRecord | None
    stream: StreamRecord | None
    #: The copy of the last stream begun (1 before any); kept when its record is cleared,
    #: so `segments_done` is known to count segments of this copy.
    copy: int = 1


#: The order queued jobs run in: those that started before (resumed) first, then by key.
_QUEUE_ORDER = "(started_at IS NULL), COALESCE(queue_key, id), id"

_COLUMNS = ("id, name, options, upload_sha256, state, message, question, submitted_at, "
            "started_at, finished_at, fingerprint, mode, max_dev_mm, segments_total, "
            "estimated_s, segments_done, remaining_s, run_s, underruns, resume_next, resume_a, "
            "resume_b, resume_reason, stream_first_line, stream_start_segment, stream_start_a, "
            "stream_start_b, stream_lines, resume_copy, stream_copy")


def _record(row: sqlite3.Row) -> JobRecord:
    resume = None
    if row["resume_next"] is not None:
        pos = None if row["resume_a"] is None else (int(row["resume_a"]), int(row["resume_b"]))
        resume = ResumeRecord(int(row["resume_next"]), pos, str(row["resume_reason"] or ""),
                              int(row["resume_copy"] or 1))
    stream = None
    copy = int(row["stream_copy"] or 1)
    if row["stream_first_line"] is not None:
        stream = StreamRecord(int(row["stream_first_line"]), int(row["stream_start_segment"]),
                              (int(row["stream_start_a"]), int(row["stream_start_b"])),
                              int(row["stream_lines"]), copy)
    return JobRecord(
        id=int(row["id"]), name=str(row["name"]), options=json.loads(row["options"]),
        upload_sha256=str(row["upload_sha256"]), state=str(row["state"]),
        message=str(row["message"]), question=row["question"],
        submitted_at=float(row["submitted_at"]), started_at=row["started_at"],
        finished_at=row["finished_at"], fingerprint=str(row["fingerprint"]),
        mode=str(row["mode"]), max_dev_mm=row["max_dev_mm"],
        segments_total=int(row["segments_total"]), estimated_s=float(row["estimated_s"]),
        segments_done=int(row["segments_done"]), remaining_s=row["remaining_s"],
        run_s=float(row["run_s"]), underruns=row["underruns"], resume=resume, stream=stream,
        copy=copy)


class JobStore:
    """The daemon's database (see the module docstring). Thread-safe."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            # Uploads are the user's drawings: the file (and SQLite's -wal/-shm files, which
            # take its mode) is private to the daemon's user.
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT, 0o600))
            self._db = sqlite3.connect(str(path), check_same_thread=False,
                                       isolation_level=None, timeout=5.0)
        except (OSError, sqlite3.Error) as e:
            raise StoreError(f"{path}: cannot open the database: {e}") from e
        self._db.row_factory = sqlite3.Row
        self._lock = threading.RLock()
        #: Bumped by every committed write; `listeners` are called after it (any thread).
        self.version = 0
        self.listeners: list[Callable[[], None]] = []
        try:
            with self._lock:
                self._db.execute("PRAGMA journal_mode=WAL")
                # NORMAL: a commit survives a crash or SIGKILL of the daemon (the WAL is in
                # the OS's hands); after a power loss the last few commits may be lost, and
                # recovery then starts from an older, still conservative resume point.
                self._db.execute("PRAGMA synchronous=NORMAL")
                version = int(self._db.execute("PRAGMA user_version").fetchone()[0])
                if version > SCHEMA_VERSION:
                    raise StoreError(f"{path}: database schema {version} is newer than this "
                                     f"program's ({SCHEMA_VERSION}); upgrade fivebar")
                self._db.executescript(_SCHEMA)
                cols = {str(r[1]) for r in self._db.execute("PRAGMA table_info(jobs)")}
                if "queue_key" not in cols:  # schema 1: the queue ran in id order
                    self._db.execute("ALTER TABLE jobs ADD COLUMN queue_key REAL")
                if "resume_copy" not in cols:  # schema 2: one copy a job
                    self._db.execute("ALTER TABLE jobs ADD COLUMN resume_copy INTEGER")
                if "stream_copy" not in cols:  # schema 3: a stream's copy not recorded
                    self._db.execute("ALTER TABLE jobs ADD COLUMN stream_copy INTEGER")
                self._db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
        except sqlite3.Error as e:
            raise StoreError(f"{path}: not a usable fivebar database: {e}") from e

    def close(self) -> None:
        """Close the connection (idempotent)."""
        with self._lock:
            self._db.close()

    @contextmanager
    def _tx(self) -> Iterator[sqlite3.Connection]:
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")
            self.version += 1
        for fn in list(self.listeners):
            fn()

    # ------------------------------------------------------------------ jobs
    def add_job(self, *, name: str, options: dict[str, Any], upload: bytes, upload_sha256: str,
                fingerprint: str, mode: str, max_dev_mm: float | None, segments_total: int,
                estimated_s: float) -> JobRecord:
        """Queue a compiled, checked job; returns its record."""
        with self._tx() as db:
            cur = db.execute(
                "INSERT INTO jobs (name, options, upload, upload_sha256, state, submitted_at, "
                "fingerprint, mode, max_dev_mm, segments_total, estimated_s, remaining_s) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (name, json.dumps(options, sort_keys=True), upload, upload_sha256, QUEUED,
                 time.time(), fingerprint, mode, max_dev_mm, segments_total, estimated_s,
                 estimated_s))
            job_id = int(cur.lastrowid or 0)
        rec = self.get(job_id)
        assert rec is not None
        return rec

    def get(self, job_id: int) -> JobRecord | None:
        """One job, or None (also for a number no job can have)."""
        if not valid_job_id(job_id):
            return None
        with self._lock:
            row = self._db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE id = ?",
                                   (job_id,)).fetchone()
        return None if row is None else _record(row)

    def upload(self, job_id: int) -> bytes | None:
        """The drawing bytes of a job (None once the job is over)."""
        if not valid_job_id(job_id):
            return None
        with self._lock:
            row = self._db.execute("SELECT upload FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None or row[0] is None else bytes(row[0])

    def list(self, states: tuple[str, ...] | None = None, limit: int = 200) -> list[JobRecord]:
        """Jobs, oldest first (the most recent `limit`), optionally only in `states`."""
        q = f"SELECT {_COLUMNS} FROM jobs"
        args: list[Any] = []
        if states:
            q += f" WHERE state IN ({', '.join('?' * len(states))})"
            args += list(states)
        q += " ORDER BY id DESC LIMIT ?"
        args.append(limit)
        with self._lock:
            rows = self._db.execute(q, args).fetchall()
        return [_record(r) for r in reversed(rows)]

    def next_queued(self) -> JobRecord | None:
        """The job to run next: a resumed one (it started before), else the first queued
        one in queue order (`queue_key`, the id until the queue is reordered)."""
        with self._lock:
            row = self._db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE state = ? "
                                   f"ORDER BY {_QUEUE_ORDER} LIMIT 1", (QUEUED,)).fetchone()
        return None if row is None else _record(row)

    def queue_order(self) -> builtins.list[int]:
        """The ids of the queued jobs in the order they will run."""
        with self._lock:
            rows = self._db.execute(f"SELECT id FROM jobs WHERE state = ? "
                                    f"ORDER BY {_QUEUE_ORDER}", (QUEUED,)).fetchall()
        return [int(r[0]) for r in rows]

    def move(self, job_id: int, index: int) -> builtins.list[int] | None:
        """Move a queued job that has not started to place `index` (0 = next to run, clamped)
        among the queued jobs that have not started; the new queue order, or None when the
        job is not such a job (it runs, ran, or is unknown)."""
        if not valid_job_id(job_id):
            return None
        with self._tx() as db:
            rows = db.execute("SELECT id, COALESCE(queue_key, id) FROM jobs WHERE state = ? "
                              f"AND started_at IS NULL ORDER BY {_QUEUE_ORDER}",
                              (QUEUED,)).fetchall()
            ids = [int(r[0]) for r in rows]
            if job_id not in ids:
                return None
            keys = sorted(float(r[1]) for r in rows)
            ids.remove(job_id)
            ids.insert(max(0, min(index, len(ids))), job_id)
            db.executemany("UPDATE jobs SET queue_key = ? WHERE id = ?", zip(keys, ids,
                                                                             strict=True))
        return self.queue_order()

    def blocking(self) -> JobRecord | None:
        """A job that keeps the queue from moving (running, paused or held), if any."""
        with self._lock:
            row = self._db.execute(
                f"SELECT {_COLUMNS} FROM jobs WHERE state IN "
                f"({', '.join('?' * len(BLOCKING_STATES))}) ORDER BY id LIMIT 1",
                tuple(sorted(BLOCKING_STATES))).fetchone()
        return None if row is None else _record(row)

    def counts(self) -> dict[str, int]:
        """Number of jobs per state."""
        with self._lock:
            rows = self._db.execute("SELECT state, COUNT(*) FROM jobs GROUP BY state").fetchall()
        out = dict.fromkeys(STATES, 0)
        out.update({str(s): int(n) for s, n in rows})
        return out

    def update(self, job_id: int, **fields: Any) -> None:
        """Set columns of a job (names checked against the schema)."""
        if not fields:
            return
        allowed = {"state", "message", "question", "started_at", "finished_at",
                   "segments_done", "remaining_s", "run_s", "underruns"}
        bad = set(fields) - allowed
        if bad:
            raise ValueError(f"not updatable: {sorted(bad)}")
        sets = ", ".join(f"{k} = ?" for k in fields)
        with self._tx() as db:
            db.execute(f"UPDATE jobs SET {sets} WHERE id = ?", (*fields.values(), job_id))

    def set_state(self, job_id: int, state: str, message: str | None = None,
                  question: str | None = None) -> None:
        """Move a job to `state`; a final state also drops its upload and stream record."""
        if state not in STATES:
            raise ValueError(f"unknown job state {state!r}")
        with self._tx() as db:
            db.execute("UPDATE jobs SET state = ?, question = ? WHERE id = ?",
                       (state, question, job_id))
            if message is not None:
                db.execute("UPDATE jobs SET message = ? WHERE id = ?", (message, job_id))
            if state in FINAL_STATES:
                db.execute("UPDATE jobs SET finished_at = ?, upload = NULL, resume_next = NULL, "
                           "resume_a = NULL, resume_b = NULL, stream_first_line = NULL "
                           "WHERE id = ?", (time.time(), job_id))

    def set_resume(self, job_id: int, resume: ResumeRecord | None) -> None:
        """Record (or clear) a job's resume point."""
        with self._tx() as db:
            if resume is None:
                db.execute("UPDATE jobs SET resume_next = NULL, resume_a = NULL, "
                           "resume_b = NULL, resume_reason = NULL, resume_copy = NULL "
                           "WHERE id = ?", (job_id,))
            else:
                a, b = resume.position if resume.position is not None else (None, None)
                db.execute("UPDATE jobs SET resume_next = ?, resume_a = ?, resume_b = ?, "
                           "resume_reason = ?, segments_done = ?, resume_copy = ? "
                           "WHERE id = ?",
                           (resume.next_segment, a, b, resume.reason, resume.next_segment,
                            resume.copy, job_id))

    def set_stream(self, job_id: int, stream: StreamRecord | None) -> None:
        """Record where a stream began (before its first line is written), or clear it."""
        with self._tx() as db:
            if stream is None:
                db.execute("UPDATE jobs SET stream_first_line = NULL WHERE id = ?", (job_id,))
            else:
                db.execute("UPDATE jobs SET stream_first_line = ?, stream_start_segment = ?, "
                           "stream_start_a = ?, stream_start_b = ?, stream_lines = ?, "
                           "stream_copy = ? WHERE id = ?",
                           (stream.first_line, stream.start_segment, stream.start_position[0],
                            stream.start_position[1], stream.lines, stream.copy, job_id))

    def delete(self, job_id: int) -> bool:
        """Remove a finished job from the history; False if it is not over (or unknown)."""
        if not valid_job_id(job_id):
            return False
        with self._tx() as db:
            cur = db.execute(f"DELETE FROM jobs WHERE id = ? AND state IN "
                             f"({', '.join('?' * len(FINAL_STATES))})",
                             (job_id, *sorted(FINAL_STATES)))
            return cur.rowcount > 0

    def prune(self, keep: int = 500) -> int:
        """Forget all but the `keep` most recent finished jobs; returns how many went."""
        with self._tx() as db:
            cur = db.execute(
                f"DELETE FROM jobs WHERE state IN ({', '.join('?' * len(FINAL_STATES))}) "
                "AND id NOT IN (SELECT id FROM jobs ORDER BY id DESC LIMIT ?)",
                (*sorted(FINAL_STATES), keep))
            return cur.rowcount

    # ------------------------------------------------------------------ machine facts
    def machine(self) -> dict[str, Any]:
        """What the daemon recorded about the machine (JSON values by key)."""
        with self._lock:
            rows = self._db.execute("SELECT key, value FROM machine").fetchall()
        return {str(k): json.loads(v) for k, v in rows}

    def set_machine(self, **values: Any) -> None:
        """Record machine facts (pose_known, position, accepted_line, ...)."""
        with self._tx() as db:
            for k, v in values.items():
                db.execute("INSERT INTO machine (key, value) VALUES (?, ?) "
                           "ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                           (k, json.dumps(v)))
