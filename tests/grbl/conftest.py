"""Fixtures of the GRBL bridge tests (helpers in grbl_support.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from grbl_client import GrblClient
from grbl_support import Running, start_bridge, stop_bridge


@pytest.fixture(params=["mock", pytest.param("sim", marks=pytest.mark.sim)])
def bridge(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Running]:
    """The bridge in front of the mock and in front of the emulated firmware."""
    if request.param == "sim":
        request.getfixturevalue("sim_build")
    r = start_bridge(str(request.param), tmp_path)
    yield r
    stop_bridge(r)


@pytest.fixture
def grbl(bridge: Running) -> Iterator[GrblClient]:
    """A connected sender, unlocked ($X: the arms at the profile's homed pose)."""
    c = bridge.client()
    _, reply = c.command("$X")
    assert reply == "ok"
    yield c
    c.close()
