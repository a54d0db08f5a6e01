"""`fivebar convert` and `fivebar plot --dry-run` from the command line: outputs, reports,
and bad input (clear error, non-zero exit, no output file written or half-written)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from fivebar_host.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run(*args: str) -> tuple[int, str]:
    r = CliRunner().invoke(main, list(args))
    return r.exit_code, r.output + (r.stderr if r.stderr_bytes is not None else "")


def test_convert_absolute_and_relative(tmp_path: Path) -> None:
    out = tmp_path / "job.gcode"
    code, text = run("convert", str(EXAMPLES / "simple.svg"), "-o", str(out))
    assert code == 0, text
    lines = out.read_text().splitlines()
    assert "G90" in lines and lines[-1] == "M5"
    assert sum(ln.startswith("G1 A") for ln in lines) > 100
    code, text = run("convert", str(EXAMPLES / "simple.svg"), "-o", str(out), "--relative",
                     "--tolerance", "0.2")
    assert code == 0 and "G91" in out.read_text()
    assert not list(tmp_path.glob(".*tmp"))  # no temporary files left behind


def test_convert_sends_power_only_with_laser(tmp_path: Path) -> None:
    """Issue 6: no S > 0 unless --laser is given."""
    out = tmp_path / "job.gcode"
    src = str(EXAMPLES / "square.gcode")
    code, text = run("convert", src, "-o", str(out))
    assert code == 0 and "pen (S0, no laser power)" in text, text
    g1 = [ln for ln in out.read_text().splitlines() if ln.startswith("G1 ")]
    assert g1 and all(ln.endswith(" S0") for ln in g1)
    assert "M3 S0" in out.read_text()  # pen down
    code, text = run("convert", src, "-o", str(out), "--laser")
    assert code == 0 and "laser (power up to S255)" in text, text
    g1 = [ln for ln in out.read_text().splitlines() if ln.startswith("G1 ")]
    assert {ln.rsplit(" ", 1)[1] for ln in g1} == {"S0", "S255"}
    code, text = run("plot", src, "--dry-run", "--preview", str(tmp_path / "p.png"))
    assert code == 0 and "tool          laser off: S0 on every line" in text
    code, text = run("plot", src, "--dry-run", "--laser", "--preview", str(tmp_path / "p.png"))
    assert code == 0 and "tool          laser: S up to 255" in text


def test_plot_dry_run_writes_preview_and_report(tmp_path: Path) -> None:
    png = tmp_path / "preview.png"
    code, text = run("plot", str(EXAMPLES / "fivebar_text.svg"), "--dry-run", "--preview",
                     str(png))
    assert code == 0, text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    for key in ("paths", "segments", "drawing", "travel", "time", "deviation", "margins",
                "working mode  +-"):
        assert key in text


def test_plot_mode_auto_says_which(tmp_path: Path) -> None:
    code, text = run("plot", str(EXAMPLES / "underside_machine_coords.gcode"), "--origin",
                     "0,0", "--mode", "auto", "--dry-run", "--preview", str(tmp_path / "p.png"),
                     "--config", str(EXAMPLES.parent / "configs" / "underside.toml"))
    assert code == 0, text
    assert "--mode auto chose ++" in text and "working mode  ++ (assembly -)" in text
    # the default machine is built in assembly "+": refused, naming the assembly
    code, text = run("plot", str(EXAMPLES / "underside_machine_coords.gcode"), "--origin",
                     "0,0", "--mode", "auto", "--dry-run", "--preview", str(tmp_path / "q.png"))
    assert code != 0 and "only reachable in assembly -" in text
    assert not (tmp_path / "q.png").exists()


def test_plot_without_port_or_dry_run_says_what_to_give() -> None:
    code, text = run("plot", str(EXAMPLES / "simple.svg"))
    assert code != 0 and "--port" in text and "--dry-run" in text


@pytest.mark.parametrize(("content", "suffix", "message"), [
    ("<svg xmlns='http://www.w3.org/2000/svg'><path d='M0 0 L1 1'></svg>", ".svg",
     "malformed XML"),
    ("<svg xmlns='http://www.w3.org/2000/svg' width='10mm' height='10mm'><text> </text></svg>",
     ".svg", "no strokes"),
    ("<svg xmlns='http://www.w3.org/2000/svg' width='10mm' height='10mm'>"
     "<path d='M0 0 L1e999 0'/></svg>", ".svg", "not finite or larger than"),
    ("<svg xmlns='http://www.w3.org/2000/svg' width='10mm' height='10mm'>"
     "<path d='M0 0 L 1e12 0'/></svg>", ".svg", "not finite or larger than"),
    ("G1 X1\nG1 X2 A-1\n", ".gcode", ":2: unsupported axis word A-1"),
    ("G1 X1 Z0\nG1 X2 Z-1\n", ".gcode", ":2: Z-1 changes Z during a cut"),  # laser profile
    ("G1 X1\nM98 P100\n", ".gcode", ":2: M98: a subroutine call"),  # M7 is skipped now
])
def test_bad_input_clear_error_and_no_output(tmp_path: Path, content: str, suffix: str,
                                             message: str) -> None:
    src = tmp_path / f"bad{suffix}"
    src.write_text(content)
    out = tmp_path / "out.gcode"
    code, text = run("convert", str(src), "-o", str(out))
    assert code != 0 and message in text and text.startswith("error: ")
    assert not out.exists()
    # an existing output stays as it was
    out.write_text("previous job\n")
    code, _ = run("convert", str(src), "-o", str(out))
    assert code != 0 and out.read_text() == "previous job\n"
    png = tmp_path / "p.png"
    code, text = run("plot", str(src), "--dry-run", "--preview", str(png))
    assert code != 0 and message in text and not png.exists()


@pytest.mark.parametrize(("fmt", "says"), [("PNG", "a PNG image: give it the extension .png"),
                                           ("JPEG", "a JPEG image: give it the extension .jpg"),
                                           ("BMP", "a BMP image: give it the extension .bmp"),
                                           ("WEBP", "a WebP image: give it the extension .webp")])
def test_an_image_named_svg_is_said_to_be_one(tmp_path: Path, fmt: str, says: str) -> None:
    from PIL import Image

    src = tmp_path / "photo.svg"
    Image.new("RGB", (8, 8)).save(src, format=fmt)
    code, text = run("plot", str(src), "--dry-run")
    assert code != 0 and "malformed XML" in text and says in text
    # two letters that start a BMP do not make one
    src.write_bytes(b"BMX is not an image\n")
    code, text = run("plot", str(src), "--dry-run")
    assert code != 0 and "malformed XML" in text and "the file is" not in text


def test_unreadable_file(tmp_path: Path) -> None:
    code, text = run("convert", str(tmp_path / "missing.svg"), "-o", str(tmp_path / "o"))
    assert code != 0 and "cannot read file" in text
    d = tmp_path / "dir.svg"
    d.mkdir()
    code, text = run("plot", str(d), "--dry-run")
    assert code != 0


def test_bad_options(tmp_path: Path) -> None:
    code, text = run("plot", str(EXAMPLES / "simple.svg"), "--dry-run", "--origin", "1;2")
    assert code != 0 and "--origin" in text
    code, text = run("plot", str(EXAMPLES / "simple.svg"), "--dry-run", "--fit", "--scale", "2",
                     "--preview", str(tmp_path / "p.png"))
    assert code != 0 and "--fit and --scale" in text


def test_convert_refuses_an_image_and_writes_nothing(tmp_path: Path) -> None:
    """A raster job's G7 lines are binary and numbered for one session (docs/protocol.md
    6.4): `convert` wrote them as "G7 segment …" messages, which the firmware answers with
    error:6. Now it refuses, naming the file, and writes no file."""
    import numpy as np
    from PIL import Image

    img = tmp_path / "grey.png"
    Image.fromarray(np.full((4, 20), 100, dtype=np.uint8)).save(img)
    out = tmp_path / "job.gcode"
    code, text = run("convert", str(img), "--laser", "--width", "4mm", "-o", str(out))
    assert code == 2 and f"{img}: an image (raster) job cannot be written" in text, text
    assert "fivebar plot" in text and not out.exists()


@pytest.mark.parametrize("command", [["status"], ["jog", "--dx", "5"], ["home"],
                                     ["frame", str(EXAMPLES / "simple.svg")]])
def test_machine_commands_without_a_port_say_where_to_find_one(command: list[str]) -> None:
    """A newcomer's first `fivebar status`: the refusal names the kind of port, where to find
    the machine's (`fivebar doctor`), and the emulator."""
    code, text = run(*command)
    assert code != 0 and "give --port PORT" in text, text
    assert "fivebar doctor" in text and "fivebar-sim://" in text, text


@pytest.mark.parametrize("controller", ["fivebar", "grbl"])
def test_a_port_that_is_not_there_is_named_with_where_to_look(tmp_path: Path,
                                                             controller: str) -> None:
    """The links say what `fivebar flash` says of a port that will not open (one diagnosis,
    `controllers.ports.open_trouble`): a missing device sends the user to `fivebar doctor`."""
    port = str(tmp_path / "ttyUSB9")
    code, text = run("status", "--port", port, "--controller", controller)
    assert code != 0 and f"{port}: no such port: is the board plugged in?" in text, text
    assert "`fivebar doctor` lists the serial ports" in text
