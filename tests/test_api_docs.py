"""docs/api.md's examples run: every ```python block, in order, in one namespace, from the
repository root; the ```python emulator blocks too when the emulator can be built. A block
that raises (an assert in it, or an API that changed) fails the test, naming the block."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from fivebar_host.devices.sim import toolchain_missing

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "api.md"
_BLOCK = re.compile(r"^```python( emulator)?\n(.*?)^```$", re.S | re.M)


def blocks() -> list[tuple[bool, str]]:
    """(needs the emulator, code) of every python block of docs/api.md, in order."""
    return [(bool(m.group(1)), m.group(2)) for m in _BLOCK.finditer(DOC.read_text())]


def run_blocks(which: list[tuple[bool, str]], ns: dict[str, Any]) -> None:
    for k, (_, code) in enumerate(which):
        first = code.strip().splitlines()[0]
        try:
            exec(compile(code, f"{DOC}:block{k}", "exec"), ns)
        except Exception as e:
            raise AssertionError(f"docs/api.md block {k} ({first!r}) failed: {e!r}") from e


@pytest.fixture(scope="module")
def namespace() -> dict[str, Any]:
    """The namespace after every plain block ran (from the repository root)."""
    import os

    plain = [b for b in blocks() if not b[0]]
    assert len(plain) >= 5  # compile, in memory, inspect, stream, simulate
    ns: dict[str, Any] = {"__name__": "api_docs"}
    old = Path.cwd()
    os.chdir(ROOT)
    try:
        run_blocks(plain, ns)
    finally:
        os.chdir(old)
    return ns


def test_plain_blocks_run(namespace: dict[str, Any]) -> None:
    job = namespace["job"]
    assert job.n_segments > 0 and namespace["report"].segments == job.n_segments
    assert (namespace["work"] / "preview.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.skipif(toolchain_missing() is not None,
                    reason=f"emulator unavailable: {toolchain_missing()}")
def test_emulator_blocks_run(namespace: dict[str, Any]) -> None:
    emu = [b for b in blocks() if b[0]]
    assert emu
    run_blocks(emu, namespace)
    assert namespace["ex"].max_deviation_mm <= namespace["job2"].tolerance_mm + \
        namespace["job2"].step_quantum_mm
