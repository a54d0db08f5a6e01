"""Fixtures shared by the test modules of tests/."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from fivebar_host.devices import register, sim

register()  # the test suite is an entry point: the emulator's and the mocks' URL schemes
# Every `fivebar-sim://` machine is new (the tests that keep one between runs say where).
os.environ["FIVEBAR_SIM_STATE"] = "off"


@pytest.fixture
def quick_profile(tmp_path: Path) -> Path:
    """The default profile with 1 s reply and banner timeouts, so a silent device is found
    quickly."""
    text = (Path(__file__).resolve().parent.parent / "configs" / "default.toml").read_text()
    p = tmp_path / "quick.toml"
    p.write_text(text.replace("reply_timeout_s = 10.0", "reply_timeout_s = 1.0")
                 .replace("banner_timeout_s = 5.0", "banner_timeout_s = 1.0"))
    return p


@pytest.fixture(scope="session")
def sim_build() -> sim.BuildPaths:
    """Firmware and harness, built once per session; skip only without the toolchain."""
    reason = sim.toolchain_missing()
    if reason is not None:
        pytest.skip(f"emulator unavailable: {reason}")
    return sim.ensure_built()


@pytest.fixture
def clean_mock() -> Iterator[None]:
    """No named `fivebar-mock://?machine=NAME` machine before or after the test."""
    from fivebar_host.devices import mock

    mock.forget_machines()
    yield
    mock.forget_machines()
