"""The web page in plain words and units (issue 36), in a real headless Chromium.

Unit-bearing fields are text the daemon reads with the CLI's parser (`50%` is half size,
`1in` is 25.4 mm); why a job waits (the home question, a pen change) is at the top of the
first screen of a phone (390×844) without scrolling, asked once; no option's API name is in
the page's visible text. Screenshots go to build/screenshots (web_support.shot)."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from layers_support import PEN, layers_text
from web_support import (
    EXAMPLES,
    PHONE,
    browser_missing,
    chromium,
    daemon,
    drop_file,
    errors_shown,
    shot,
    wait,
)

from fivebar_host.options import JOB_OPTIONS
from fivebar_host.server.client import ServerClient, plot_options

pytestmark = pytest.mark.browser
SIMPLE = EXAMPLES / "simple.svg"
SQUARE = EXAMPLES / "square.gcode"
#: What must not be read on the page: the options' API and field names (those that are not
#: plain words), and the API's way of answering a question.
API_NAMES = sorted({o.query for o in JOB_OPTIONS if "_" in o.query}
                   | {o.name for o in JOB_OPTIONS if "_" in o.name} | {"confirm=true"})


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    why = browser_missing()
    if why is not None:
        pytest.skip(why)
    with chromium(tmp_path_factory.mktemp("chromium-profile")) as driver:
        yield driver


def visible_text(d: Any) -> str:
    return str(d.execute_script("return document.body.innerText"))


def open_page(d: Any, url: str, size: tuple[int, int] | None = None) -> None:
    if size is not None:
        d.set_window_size(*size)
    d.get(url + "/")
    wait(d, lambda d: d.find_element("css selector", "#link").text == "live",
         what="the event stream")
    wait(d, lambda d: d.find_elements("css selector", "#opt-scale"), what="the option form")


def placement(d: Any, **fields: str) -> str:
    """The dry run's placement line with these option fields typed as text."""
    for query, value in fields.items():
        box = d.find_element("css selector", f"#opt-{query}")
        box.clear()
        box.send_keys(value)
    d.find_element("css selector", "#check").click()
    report = wait(d, lambda d: d.find_element("css selector", "#dryrun").is_displayed()
                  and d.execute_script("return document.querySelector('#report').textContent"),
                  what="the dry run")
    line = next(ln for ln in str(report).splitlines() if ln.startswith("placement"))
    for query in fields:
        d.find_element("css selector", f"#opt-{query}").clear()
    return line


def size_mm(line: str) -> tuple[float, float]:
    m = re.search(r"([\d.]+) × ([\d.]+) mm", line)
    assert m is not None, line
    return float(m.group(1)), float(m.group(2))


def test_units_in_the_form_are_read_as_the_cli_reads_them(browser: Any, tmp_path: Path) -> None:
    d = browser
    with daemon(tmp_path / "state", "fivebar-mock://?speed=0&machine=words1") as dm:
        open_page(d, dm.url, PHONE)
        for query in ("scale", "tolerance", "origin", "draw_speed", "accel"):
            assert d.find_element("css selector", f"#opt-{query}").get_attribute("type") \
                == "text"
        drop_file(d, SIMPLE.read_bytes(), SIMPLE.name)
        full = placement(d)
        half = placement(d, scale="50%")
        assert "scale 0.5" in half, half
        (w1, h1), (w2, h2) = size_mm(full), size_mm(half)
        assert abs(w2 - w1 / 2) < 0.2 and abs(h2 - h1 / 2) < 0.2  # 50 % is half, not 50×
        inches = placement(d, scale="50%", origin="1in,4in")
        assert inches == placement(d, scale="50%", origin="25.4,101.6")  # 1 in = 25.4 mm
        shot(d, "words-01-phone-form")
        bad = placement_error(d, scale="50 %%")
        assert "scale" in bad.lower() or "percentage" in bad.lower()


def placement_error(d: Any, **fields: str) -> str:
    for query, value in fields.items():
        box = d.find_element("css selector", f"#opt-{query}")
        box.clear()
        box.send_keys(value)
    d.find_element("css selector", "#check").click()
    return str(wait(d, lambda d: errors_shown(d), what="the refusal")[0])


def in_first_screen(d: Any, sel: str) -> bool:
    return bool(d.execute_script(
        "const r = document.querySelector(arguments[0]).getBoundingClientRect();"
        "return window.scrollY === 0 && r.height > 0 && r.top >= 0 && "
        "r.bottom <= window.innerHeight", sel))


def test_why_a_job_waits_is_on_the_first_phone_screen(browser: Any, tmp_path: Path) -> None:
    d = browser
    with daemon(tmp_path / "state", "fivebar-mock://?speed=0&machine=words2") as dm:
        open_page(d, dm.url, PHONE)
        job = ServerClient(dm.url).submit(SQUARE.read_bytes(), "square.gcode",
                                          plot_options())["id"]  # no answer: it asks
        top = wait(d, lambda d: d.find_element("css selector", "#waiting").text,
                   what="the waiting reason")
        assert f"Job #{job}" in top and "home pose" in top and "Yes, they are" in top
        assert in_first_screen(d, "#waiting")
        page = visible_text(d)
        assert page.count("home pose θ1") == 1  # the question is asked once
        assert not d.find_element("css selector", "#at-home-row").is_displayed()
        shot(d, "words-02-phone-home-question")
        for name in API_NAMES:
            assert name not in page, name
        d.find_element("xpath", "//div[@id='waiting']//button[text()='Yes, they are']").click()
        wait(d, lambda d: not d.find_element("css selector", "#waiting").is_displayed(),
             what="the answer taken")


def test_a_pen_change_says_so_at_the_top(browser: Any, tmp_path: Path) -> None:
    d = browser
    with daemon(tmp_path / "state", "fivebar-mock://?speed=0&machine=words3",
                profile_path=PEN) as dm:
        open_page(d, dm.url, PHONE)
        ServerClient(dm.url).submit(layers_text().encode(), "layers.svg",
                                    plot_options(layer_pause=True, confirm=True))
        top = wait(d, lambda d: "pen change" in (t := d.find_element(
            "css selector", "#waiting").text) and t, what="the pen change")
        assert "layer 2/2 'red'" in top and "Continue" in top
        assert in_first_screen(d, "#waiting")
        shot(d, "words-03-phone-pen-change")
        for name in API_NAMES:
            assert name not in visible_text(d), name
