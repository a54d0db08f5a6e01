"""Queued jobs' compiled form: from the cache, or compiled again from the stored upload.

A submission's compiled job stays in the `CompiledCache` (a few jobs) until it has run; a job
the cache no longer holds (after a restart, or behind many others) is compiled again from
its upload in the database, and used only once it is checked to be the very job that was
submitted (same fingerprint). The machine thread compiles again in place (it runs the job
next); the web page's path view does it in a compiling process (server.compiler) and hands
the result to `adopt`.
"""

from __future__ import annotations

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.server.jobs import (
    Compiled,
    CompiledCache,
    JobOptions,
    SubmitError,
    compile_upload,
)
from fivebar_host.server.store import JobRecord, JobStore


class StoredJobs:
    """The compiled jobs of the database's records (module docstring); any thread."""

    def __init__(self, store: JobStore, cache: CompiledCache, profile: Profile) -> None:
        self.store = store
        self.cache = cache
        self.profile = profile

    def job(self, rec: JobRecord) -> Job:
        """The compiled job of a record (cached, or compiled again from its upload)."""
        job = self.cache.get(rec.id)
        if job is not None:
            return job
        return self.adopt(rec, compile_upload(self.upload(rec), rec.name,
                                              JobOptions.from_json(rec.options), self.profile))

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
