"""The daemon's OpenAPI description and the daemon agree: schemathesis generates requests
from `GET /openapi.json` (schema-valid and invalid ones) and checks every answer against the
description — status codes, content types, headers (`Allow` on a 405), bodies — and that
schema-valid data is accepted. Bounded: a fixed number of examples per operation (about 20 s
on the 2-core machine); `st run URL/openapi.json --checks all` runs the same with the
repository's `schemathesis.toml`.

The one exception is in `schemathesis.toml` too: an upload's bytes are a drawing only once
they are read and compiled, so a schema-valid body that is no drawing (or a drawing out of
reach) is refused with 422 `input_error` / `job_error`: for those two operations 422 is an expected
answer to schema-valid data.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, settings

schemathesis = pytest.importorskip("schemathesis")
from serve_support import running_daemon  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def daemon_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with running_daemon(tmp_path_factory.mktemp("schema"), "schema", speed=50.0,
                        compile_processes=False) as d:
        yield d.url


@pytest.fixture(scope="module")
def api_schema(daemon_url: str) -> object:
    # the repository's schemathesis.toml: its one exception (module doc), as `st run` reads it
    config = schemathesis.config.SchemathesisConfig.from_path(ROOT / "schemathesis.toml")
    return schemathesis.openapi.from_url(f"{daemon_url}/openapi.json", config=config)


schema = schemathesis.pytest.from_fixture("api_schema")


# the event stream never ends: it is followed by tests/test_serve_web.py instead
@schema.exclude(path="/api/events").parametrize()
@settings(max_examples=12, deadline=None, phases=[Phase.explicit, Phase.generate],
          suppress_health_check=list(HealthCheck))
def test_the_api_answers_as_its_description_says(case: object, daemon_url: str) -> None:
    case.call_and_validate(base_url=daemon_url)  # type: ignore[attr-defined]


def test_the_repository_config_names_the_same_exception() -> None:
    text = (ROOT / "schemathesis.toml").read_text()
    assert 'include-path-regex = "^/api/(jobs|dryrun)$"' in text and '"422"' in text


@pytest.mark.parametrize("name", ["\u202egpj.svg", "a\u200bb.svg", "x\x85.svg", "a\u2066b.svg",
                                  ".hidden.svg", "..", "a\u2028b.svg"])
def test_names_with_control_or_bidi_characters_are_refused_visibly(
        daemon_url: str, name: str) -> None:
    from urllib.parse import quote

    from serve_support import send

    raw = send(daemon_url, "POST", f"/api/jobs?name={quote(name)}", b"G1 X10 Y100\n",
               {"Content-Type": "text/x-gcode"})
    doc = json.loads(raw.body)
    assert raw.status == 400 and doc["error"] == "bad_name", doc
    assert doc["message"].isascii()  # the name is shown escaped: \u202e, not the character
    assert ascii(name)[1:-1] in doc["message"]


def test_a_405_names_every_method_of_the_path(daemon_url: str) -> None:
    from serve_support import send

    raw = send(daemon_url, "OPTIONS", "/api/jobs/1")
    assert raw.status == 405 and raw.headers["allow"] == "DELETE, GET"
