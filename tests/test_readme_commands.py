"""The README's commands, pasted as written, succeed (issue 36): every `fivebar …` line of
its code blocks runs, in order, on a terminal (a pseudo-terminal that answers "y" where a
person is asked, as the README's reader would), against the emulated Uno.

What the reader would change, and only that: the port `/dev/ttyUSB0` is the emulated Uno
with Optiboot (`fivebar-sim://?bootloader=optiboot`, kept between commands like a real board:
`fivebar flash` writes the firmware into it first, later commands find it there); the
drawing placeholders (`drawing.svg`, `art.svg`) are the reader's own drawing, a small one
here (`MINE_SVG`, 24x12 mm: a rectangle, a circle and a path — the emulator draws at the
machine's real speed, and the suite's time matters), `mine.toml` the default profile and
`my.toml` a machine made for the 200x150 page the README asks of it (`fivebar design --page
200x150 -o my.toml`, as the README's next command makes one); `--hold 30` holds 1 s; the
real-time photo demo (`?realtime=1`, 20 s of the full photo, measured by
`benchmarks/raster.py`) burns the photo 8 mm wide at 0.1 mm (its `raster:` line still
printed from the pin trace). Commands with `…` (elisions), the long-running services
(`serve`, `bridge`, `plot --server`) and `calibrate fit` (it needs a ruler's measurements)
are not run; the test lists them so none is dropped silently."""

from __future__ import annotations

import os
import pty
import re
import select
import shlex
import shutil
import sys
import time
from pathlib import Path

import pytest

from fivebar_host.devices.sim import ARDUINO_BOOTLOADERS

ROOT = Path(__file__).resolve().parents[1]
PORT = "'fivebar-sim://?bootloader=optiboot'"
#: Commands not run, by a piece of their text, and why.
NOT_RUN = {"…": "an elision, not a command", "fivebar serve": "a service that runs until "
           "stopped", "--server": "needs a running daemon", "fivebar bridge": "a service",
           "calibrate fit": "needs measurements taken with a ruler"}


def readme_commands() -> list[str]:
    """The `fivebar` lines of the README's indented code blocks, continuations joined and
    trailing comments cut."""
    out, pending = [], ""
    for raw in (ROOT / "README.md").read_text().splitlines():
        if not raw.startswith("    ") and not pending:
            continue
        line = pending + raw.strip()
        pending = ""
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        line = re.sub(r"\s{2,}#.*$", "", line).strip()
        if line.startswith("fivebar "):
            out.append(line)
    return out


def pasted(cmd: str) -> str:
    """What the reader runs (module doc)."""
    cmd = cmd.replace("/dev/ttyUSB0", PORT).replace("--hold 30", "--hold 1")
    for name in ("drawing.svg", "art.svg"):
        cmd = cmd.replace(name, "mine.svg")
    if "realtime=1" in cmd and "photo.png" in cmd:
        cmd += " --width 8mm --line-interval 0.1mm"
    return cmd


#: The reader's drawing (module doc).
MINE_SVG = """<svg xmlns="http://www.w3.org/2000/svg" width="24mm" height="12mm"
viewBox="0 0 24 12"><g fill="none" stroke="black"><rect x="1" y="1" width="22" height="10" rx="1"/>
<circle cx="7" cy="6" r="3"/><path d="M 13 9 L 16 3 L 19 9 Z"/></g></svg>
"""


def on_terminal(argv: list[str], cwd: Path, env: dict[str, str], timeout_s: float = 240
                ) -> tuple[int, str]:
    """Run `argv` on a pseudo-terminal, answering "y" to yes/no questions; (status, text)."""
    pid, fd = pty.fork()
    if pid == 0:  # the child: the command
        os.chdir(cwd)
        os.execvpe(argv[0], argv, env)
    out = b""
    answered = 0
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            try:
                chunk = os.read(fd, 4096)
            except OSError:
                break
            if not chunk:
                break
            out += chunk
            if out.count(b"[y/N]") > answered:
                answered += 1
                os.write(fd, b"y\n")
    else:
        os.kill(pid, 9)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), out.decode(errors="replace")


@pytest.mark.skipif(not (ARDUINO_BOOTLOADERS / "optiboot").exists(),
                    reason="arduino-core-avr (the bootloaders) not installed")
def test_the_readme_commands_pasted_as_written_succeed(sim_build: object, tmp_path: Path
                                                       ) -> None:
    for d in ("examples", "configs"):
        (tmp_path / d).symlink_to(ROOT / d)
    (tmp_path / "mine.svg").write_text(MINE_SVG)
    shutil.copy(ROOT / "configs" / "default.toml", tmp_path / "mine.toml")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIVEBAR_SIM_STATE": str(tmp_path / "sim"),
           "TERM": "dumb", "COLUMNS": "100"}
    ran, skipped = [], []
    code, text = on_terminal([sys.executable, "-c", "from fivebar_host.cli import main; main()",
                              "design", "--page", "200x150", "--margin-deg", "15", "-o",
                              "my.toml"], tmp_path, env)
    assert code == 0, text
    for cmd in readme_commands():
        why = next((w for k, w in NOT_RUN.items() if k in cmd), None)
        if why is not None:
            skipped.append(f"{cmd}  ({why})")
            continue
        args = shlex.split(pasted(cmd))
        argv = [sys.executable, "-c", "from fivebar_host.cli import main; main()", *args[1:]]
        code, text = on_terminal(argv, tmp_path, env)
        print(f"$ {pasted(cmd)}\n{text[-600:]}")
        assert code == 0, f"{cmd}\n{text[-3000:]}"
        ran.append(cmd)
    print("not run:\n" + "\n".join(skipped))
    assert any(c.startswith("fivebar flash") for c in ran)
    assert any(c.startswith("fivebar doctor") for c in ran)
    assert any("pen down" in c for c in ran) and len(ran) >= 25
