"""Submissions compile in child processes (`server.compiler`): the same job as in the
daemon's own process, errors with every field, a dead child refused cleanly, and a daemon
whose uploads and dry runs really compile elsewhere."""

from __future__ import annotations

import asyncio
import json
import os
from pathlib import Path

import pytest

from fivebar_host.config import load_profile
from fivebar_host.server.compiler import Compiler
from fivebar_host.server.jobs import JobOptions, SubmitError, compile_upload, fingerprint
from tests.serve_support import running_daemon, send

ROOT = Path(__file__).resolve().parents[1]
SIMPLE = (ROOT / "examples" / "simple.svg").read_bytes()
FAR = b"G21\nG90\nG0 X0 Y0\nG1 X500 Y500\n"


def run(compiler: Compiler, fn: object, *args: object) -> object:
    return asyncio.run(compiler.run(fn, *args))  # type: ignore[arg-type]


def test_a_child_compiles_the_same_job_in_another_process() -> None:
    prof = load_profile()
    c = Compiler()
    try:
        assert run(c, os.getpid) != os.getpid()
        child = run(c, compile_upload, SIMPLE, "simple.svg", JobOptions(), prof)
    finally:
        c.close()
    here = compile_upload(SIMPLE, "simple.svg", JobOptions(), prof)
    assert child.fingerprint == here.fingerprint  # type: ignore[attr-defined]
    assert child.job.n_segments == here.job.n_segments  # type: ignore[attr-defined]


def test_a_refusal_crosses_with_its_code_status_and_detail() -> None:
    c = Compiler()
    try:
        with pytest.raises(SubmitError) as e:
            run(c, compile_upload, FAR, "far.gcode", JobOptions(), load_profile())
    finally:
        c.close()
    with pytest.raises(SubmitError) as h:
        compile_upload(FAR, "far.gcode", JobOptions(), load_profile())
    here = h.value
    assert (e.value.code, e.value.status, str(e.value)) == (here.code, here.status, str(here))
    assert e.value.detail == here.detail and e.value.code == "job_error"


def test_a_child_that_dies_is_a_refusal_and_the_next_compiles() -> None:
    c = Compiler()
    try:
        with pytest.raises(SubmitError) as e:
            run(c, os._exit, 3)
        assert e.value.code == "compile_failed" and e.value.status == 500
        assert run(c, os.getpid) != os.getpid()
    finally:
        c.close()


def test_the_daemon_compiles_submissions_and_dry_runs_in_children(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiler replaced in the daemon's process is not the one that runs: the dry run
    and the submission are compiled by a child (forked from a server that never saw the
    replacement)."""
    import fivebar_host.server.jobs as jobs_module

    def in_daemon(*args: object) -> object:
        raise AssertionError("compiled in the daemon's process")

    monkeypatch.setattr(jobs_module, "compile_drawing", in_daemon)
    with running_daemon(tmp_path, "children") as d:
        r = send(d.url, "POST", "/api/dryrun?name=simple.svg", SIMPLE,
                 {"Content-Type": "image/svg+xml"})
        assert r.status == 200, r.body
        assert json.loads(r.body)["segments"] > 0
        r = send(d.url, "POST", "/api/jobs?name=far.gcode", FAR,
                 {"Content-Type": "text/x-gcode"})
        assert r.status == 422 and json.loads(r.body)["error"] == "job_error"
        assert json.loads(r.body)["reason"]  # the detail crossed from the child


def test_fingerprint_is_what_identifies_a_job() -> None:
    prof = load_profile()
    a = compile_upload(SIMPLE, "simple.svg", JobOptions(), prof)
    assert fingerprint(a.job) == a.fingerprint
