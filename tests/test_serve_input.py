"""Every path and query value the daemon's API takes is validated: a malformed, out-of-range,
repeated or unknown one is answered 404 or 422 in the documented JSON error format, never 500,
and a refused request queues nothing. First a table of known bad requests (job ids beyond
SQLite's 64-bit integers among them), then hypothesis generating methods, paths, query strings
(with bad percent-encoding, huge values, repeats) and bodies against a daemon on loopback.

The fuzz is bounded (`FIVEBAR_FUZZ_EXAMPLES` requests, default 500, ~10 s); a longer run:
`FIVEBAR_FUZZ_EXAMPLES=5000 python -m pytest tests/test_serve_input.py -k fuzz -s`.
"""

from __future__ import annotations

import json
import os
import string
import urllib.parse
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from serve_support import Raw, running_daemon, send

from fivebar_host.devices import mock
from fivebar_host.options import JOB_OPTIONS
from fivebar_host.server.daemon import Daemon

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SMALL_GCODE = b"G21\nG90\nG0 X10 Y100\nG1 X15 Y100\nG1 X15 Y105\n"  # machine mm
FUZZ_EXAMPLES = int(os.environ.get("FIVEBAR_FUZZ_EXAMPLES", "500"))
HUGE = "9" * 26  # the id of the bug report: beyond SQLite's INTEGER


def error_of(ans: Raw) -> dict[str, object]:
    """The documented error body of an answer (asserted to be one)."""
    assert ans.headers.get("content-type", "").startswith("application/json"), ans
    doc = json.loads(ans.body)
    assert isinstance(doc, dict), ans
    assert isinstance(doc.get("error"), str) and doc["error"], ans
    assert isinstance(doc.get("message"), str) and doc["message"], ans
    return doc


def stored(d: Daemon) -> int:
    """Jobs in the daemon's store."""
    assert d.store is not None
    return sum(d.store.counts().values())


# (method, request target, status, error key)
BAD_REQUESTS = [
    ("GET", f"/api/jobs/{HUGE}", 404, "not_found"),
    ("GET", "/api/jobs/9223372036854775807", 404, "not_found"),  # the largest id: looked up
    ("GET", "/api/jobs/9223372036854775808", 404, "not_found"),  # one more: not an id
    ("GET", "/api/jobs/-1", 404, "not_found"),
    ("GET", "/api/jobs/0", 404, "not_found"),
    ("GET", "/api/jobs/" + "9" * 5000, 422, "bad_option"),
    ("POST", f"/api/jobs/{HUGE}/pause", 404, "not_found"),
    ("POST", f"/api/jobs/{HUGE}/resume?confirm=true", 404, "not_found"),
    ("POST", f"/api/jobs/{HUGE}/cancel", 404, "not_found"),
    ("DELETE", f"/api/jobs/{HUGE}", 404, "not_found"),
    ("DELETE", "/api/jobs/-9223372036854775809", 404, "not_found"),
    ("GET", "/api/jobs/abc", 422, "bad_option"),
    ("GET", "/api/jobs/1.5", 422, "bad_option"),
    ("GET", "/api/jobs/1_0", 422, "bad_option"),  # not job 10
    ("GET", "/api/jobs/+1", 422, "bad_option"),
    ("GET", "/api/jobs/%201", 422, "bad_option"),
    ("GET", "/api/jobs/%ff", 422, "bad_option"),
    ("GET", "/api/jobs/%", 422, "bad_option"),
    ("GET", "/api/jobs?limit=0", 422, "bad_option"),
    ("GET", "/api/jobs?limit=1001", 422, "bad_option"),
    ("GET", f"/api/jobs?limit={HUGE}", 422, "bad_option"),
    ("GET", "/api/jobs?limit=ten", 422, "bad_option"),
    ("GET", "/api/jobs?limit", 422, "bad_option"),
    ("GET", "/api/jobs?limit=1&limit=1000", 422, "bad_option"),
    ("GET", "/api/jobs?state=sleeping", 422, "bad_option"),
    ("GET", "/api/jobs?state=%ff", 422, "bad_query"),
    ("GET", "/api/jobs?state=queued%00", 422, "bad_query"),
    ("GET", "/api/jobs?limit=%", 422, "bad_query"),
    ("GET", "/api/jobs?limit=%1", 422, "bad_query"),
    ("GET", "/api/jobs?%zz=1", 422, "bad_query"),
    ("GET", "/api/jobs?" + "x" * 9000, 422, "bad_query"),
    ("GET", "/api/jobs?" + "y" * 5000, 422, "bad_option"),  # unknown; the echo is cut short
    ("GET", "/api/status?verbose=1", 422, "bad_option"),
    ("POST", "/api/jobs/1/resume?confirm=maybe", 422, "bad_option"),
    ("POST", "/api/jobs/1/resume?confirm=true&confirm=false", 422, "bad_option"),
    ("POST", "/api/machine/home?at_home=2", 422, "bad_option"),
    ("POST", "/api/machine/home?at_home=true&at_home=false", 422, "bad_option"),
    ("POST", "/api/jobs?name=a.gcode&name=b.gcode&confirm=true", 422, "bad_option"),
    ("POST", "/api/jobs?name=%ff.gcode&confirm=true", 422, "bad_query"),
    ("POST", "/api/jobs?name=a.gcode&layer=%c3&confirm=true", 422, "bad_query"),
    ("POST", "/api/jobs?name=a.gcode&confirm=true&confirm=true", 422, "bad_option"),
    ("POST", "/api/jobs?confirm=true", 422, "bad_option"),  # no name
    ("POST", "/api/jobs?name=a.gcode&scale=1e400&confirm=true", 422, "bad_option"),
    ("GET", "/api/nothing/here", 404, "not_found"),
    ("PUT", "/api/jobs/1", 405, "method_not_allowed"),
]


def test_every_path_and_query_value_is_validated(tmp_path: Path) -> None:
    with running_daemon(tmp_path, "validate") as d:
        for method, target, status, key in BAD_REQUESTS:
            body = SMALL_GCODE if method == "POST" else None
            ans = send(d.url, method, target, body, {"Content-Type": "text/x-gcode"})
            assert ans.status == status, (method, target[:80], ans)
            assert error_of(ans)["error"] == key, (method, target[:80], ans)
            assert len(ans.body) < 2048, (target[:80], ans.body[:200])  # no echo of a flood
        assert stored(d) == 0
        assert mock.machine("validate").ledger == []
        # the report's request, answered in full
        ans = send(d.url, "GET", f"/api/jobs/{HUGE}")
        assert json.loads(ans.body) == {
            "error": "not_found",
            "message": f"no job {HUGE}: job ids are 1..9223372036854775807"}
        # the same values well-formed are fine
        assert send(d.url, "GET", "/api/jobs?state=queued&state=held&limit=1000").status == 200


# ------------------------------------------------------------------------------ fuzzing
ROUTES = [("GET", "/api/status"), ("GET", "/api/jobs"), ("POST", "/api/jobs"),
          ("GET", "/api/jobs/{id}"), ("DELETE", "/api/jobs/{id}"),
          ("POST", "/api/jobs/{id}/pause"), ("POST", "/api/jobs/{id}/resume"),
          ("POST", "/api/jobs/{id}/cancel"), ("POST", "/api/machine/home"),
          ("GET", "/openapi.json")]
PARAM_NAMES = sorted({o.query for o in JOB_OPTIONS}
                     | {"name", "state", "limit", "confirm", "at_home"})
#: Raw fragments spliced into a target unencoded: bad or odd percent-encoding, separators.
JUNK = ["%", "%z", "%zz", "%ff", "%00", "%c3", "%e2%82", "%C3%A9", "%25", "+", "&", "=",
        ";", "%2F", "%3F"]
SAFE_ASCII = "".join(c for c in string.printable if c not in " \t\n\r\x0b\x0c/?#%")

values = st.one_of(
    st.sampled_from(["true", "false", "1", "0", "yes", "", "nan", "inf", "-1", "1e400",
                     "10,95", "0,0", "1,2,3", "auto", "queued", "held", "x.svg", "a.gcode",
                     "../x.svg", "9" * 30, "-9223372036854775809", "0.0001", "1000"]),
    st.integers(-2**80, 2**80).map(str),
    st.floats().map(repr),
    st.text(max_size=20),
    st.integers(1000, 10_000).map(lambda n: "v" * n),
)
keys = st.one_of(st.sampled_from(PARAM_NAMES), st.text(max_size=12))


@st.composite
def encoded(draw: st.DrawFn, text: st.SearchStrategy[str]) -> str:
    """A value percent-encoded, sometimes with a raw junk fragment spliced in."""
    out = urllib.parse.quote(draw(text), safe="")
    if draw(st.integers(0, 4)) == 0:
        at = draw(st.integers(0, len(out)))
        out = out[:at] + draw(st.sampled_from(JUNK)) + out[at:]
    return out


job_ids = st.one_of(
    st.integers(-2**80, 2**80).map(str),
    st.sampled_from(["0", "-0", "+1", "1_0", "1.0", "1e3", "0x1", "%31", "9" * 4400,
                     "9223372036854775807", "9223372036854775808"]),
    encoded(st.text(max_size=12)),
    st.text(alphabet=SAFE_ASCII, min_size=1, max_size=12),
)


@st.composite
def requests(draw: st.DrawFn) -> tuple[str, str, bytes | None, dict[str, str]]:
    """(method, target, body, headers): mostly a real route with fuzzed values."""
    method, template = draw(st.sampled_from(ROUTES))
    if draw(st.integers(0, 9)) == 0:
        method = draw(st.sampled_from(["GET", "POST", "DELETE", "PUT", "PATCH"]))
    path = template.replace("{id}", draw(job_ids))
    pairs = draw(st.lists(st.tuples(encoded(keys), encoded(values)), max_size=5))
    if method == "POST" and template == "/api/jobs" and draw(st.booleans()):
        pairs.insert(0, ("name", draw(st.sampled_from(["a.gcode", "b.svg", "c"]))))
    query = "&".join(f"{k}={v}" if draw(st.integers(0, 5)) else k for k, v in pairs)
    target = path + ("?" + query if query or draw(st.booleans()) else "")
    body = draw(st.one_of(st.none(), st.binary(max_size=256), st.just(SMALL_GCODE),
                          st.just((EXAMPLES / "simple.svg").read_bytes())))
    headers = {}
    ctype = draw(st.sampled_from([None, "text/x-gcode", "image/svg+xml", "text/plain",
                                  "application/octet-stream", "application/json", "x/y;q=1"]))
    if ctype is not None:
        headers["Content-Type"] = ctype
    return method, target, body, headers


def test_fuzz_paths_queries_and_bodies(tmp_path: Path) -> None:
    """No 5xx; every error is the JSON format; a refused submission queues nothing, and the
    store holds exactly the accepted ones (minus deleted); without an accepted request that
    may move the machine, the mock machine executed nothing."""
    seen = {"requests": 0, "accepted": 0, "deleted": 0, "moving": 0, "errors": 0}
    with running_daemon(tmp_path, "fuzz") as d:

        @settings(max_examples=FUZZ_EXAMPLES, deadline=None, database=None,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
        @given(requests())
        def one(req: tuple[str, str, bytes | None, dict[str, str]]) -> None:
            method, target, body, headers = req
            before = stored(d)
            ans = send(d.url, method, target, body, headers)
            seen["requests"] += 1
            assert ans.status < 500 or (ans.status == 503 and error_of(ans)["error"] == "busy"), \
                (method, target[:200], ans)
            submit = method == "POST" and target.split("?")[0] == "/api/jobs"
            if ans.status >= 400:
                seen["errors"] += 1
                error_of(ans)
                assert stored(d) == before, (method, target[:200], ans)  # nothing queued
            elif submit:
                assert ans.status == 201, ans
                seen["accepted"] += 1
            if method == "DELETE" and ans.status == 204:
                seen["deleted"] += 1
            if ans.status < 300 and (submit or "/resume" in target or "/home" in target):
                seen["moving"] += 1

        one()
        assert d.alive()
        assert stored(d) == seen["accepted"] - seen["deleted"], seen
        if seen["moving"] == 0:
            assert mock.machine("fuzz").ledger == []
    print(f"fuzz: {seen['requests']} requests, {seen['errors']} refused, "
          f"{seen['accepted']} accepted submissions, no 5xx")
    assert seen["requests"] >= FUZZ_EXAMPLES // 2


@pytest.mark.parametrize("target", ["/api/jobs/1", "/api/jobs?limit=5"])
def test_well_formed_values_still_work(tmp_path: Path, target: str) -> None:
    """The checks refuse only what is wrong: a real job is found by its plain id."""
    with running_daemon(tmp_path, "ok") as d:
        ans = send(d.url, "POST", "/api/jobs?name=a.gcode", SMALL_GCODE,
                   {"Content-Type": "text/x-gcode"})
        assert ans.status == 201, ans
        got = send(d.url, "GET", target)
        assert got.status == 200, got
        doc = json.loads(got.body)
        assert (doc if isinstance(doc, dict) else doc[0])["id"] == 1
