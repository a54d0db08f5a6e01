"""`fivebar text` and the profile's `[text]` table from the command line: the lettering file
reads back to the lettering's strokes (as `<text>` and as `--paths`), the dry run says which
font drew the text, a profile remaps generic families and points to a user's SVG font, and
bad input is a clear error with a non-zero exit."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.config import DEFAULT_PROFILE, ConfigError, parse_profile
from fivebar_host.toolpath.geometry import flatten
from fivebar_host.toolpath.svg import read_svg
from tests.test_text import TOY


def run(*args: str) -> tuple[int, str]:
    r = CliRunner().invoke(main, list(args))
    return r.exit_code, r.output + (r.stderr if r.stderr_bytes is not None else "")


def strokes(path: Path) -> list[np.ndarray]:
    d = read_svg(path)
    p = flatten(d, 1e-3)
    pts = d.to_file_frame(p.points)
    return [pts[a:b] for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True)]


def test_text_writes_a_text_element_and_its_strokes_as_paths(tmp_path: Path) -> None:
    a, b = tmp_path / "a.svg", tmp_path / "b.svg"
    args = ["text", "Hello,", "World & co", "--font", "Relief SingleLine", "--size", "7mm",
            "--anchor", "middle", "--letter-spacing", "0.2mm"]
    code, out = run(*args, "-o", str(a))
    assert code == 0, out
    assert "in Relief SingleLine at 7 mm" in out and "<text" in a.read_text()
    code, out = run(*args, "-o", str(b), "--paths")
    assert code == 0, out
    assert "<text" not in b.read_text() and "<path" in b.read_text()
    sa, sb = strokes(a), strokes(b)
    assert len(sa) == len(sb)
    assert all(np.allclose(x, y, atol=1e-3) for x, y in zip(sa, sb, strict=True))
    d = read_svg(a)
    assert d.texts[0].text == "Hello, / World & co"  # two lines: two chunks
    x0 = min(s[:, 0].min() for s in sa)
    assert x0 >= 5.0 - 1e-6  # the page has its 5 mm margin around the strokes


def test_text_dry_run_says_which_font_drew_it(tmp_path: Path) -> None:
    out_svg = tmp_path / "t.svg"
    code, out = run("text", "12:45", "--font", "monospace", "--size", "6mm", "-o",
                    str(out_svg), "--dry-run", "--preview", str(tmp_path / "p.png"))
    assert code == 0, out
    assert "text          <text> line 3 (source #0): '12:45' in HersheySansMono, 6.0 mm" in out
    assert (tmp_path / "p.png").stat().st_size > 0


def test_text_refuses_what_it_cannot_letter(tmp_path: Path) -> None:
    code, out = run("text", "-o", str(tmp_path / "x.svg"))
    assert code == 2 and "give the text to letter" in out
    code, out = run("text", "snow \u2603", "--font", "futural", "-o", str(tmp_path / "x.svg"))
    assert code == 2 and "U+2603" in out and not (tmp_path / "x.svg").exists()
    code, out = run("text", "a", "--size", "ten", "-o", str(tmp_path / "x.svg"))
    assert code == 2 and "must be a length" in out
    code, out = run("text", "--list-fonts")
    assert code == 0 and "HersheyScript1 (scripts)" in out and "Relief SingleLine" in out


def test_profile_text_table_remaps_generics_and_reads_user_fonts(tmp_path: Path) -> None:
    font = tmp_path / "toy.svg"
    font.write_bytes(TOY)
    prof = tmp_path / "p.toml"
    prof.write_text(f'[text]\nsans_serif = "Relief SingleLine"\naliases = {{ "Brand" = '
                    f'"{font}" }}\nfallback = ""\n')
    code, out = run("text", "ab", "--font", "Brand", "-o", str(tmp_path / "b.svg"),
                    "--config", str(prof))
    assert code == 0 and "Toy Font (toy.svg)" in out, out
    code, out = run("text", "Arial", "--font", "Arial", "-o", str(tmp_path / "c.svg"),
                    "--config", str(prof))
    assert code == 0 and "in Relief SingleLine" in out, out
    code, out = run("text", "é", "--font", "futural", "-o", str(tmp_path / "c.svg"),
                    "--config", str(prof))
    assert code == 2 and "(no [text] fallback)" in out
    code, out = run("config", "show", "--config", str(prof))
    assert code == 0 and 'sans_serif           = "Relief SingleLine"' in out


def _doc() -> dict[str, Any]:
    return tomllib.loads(DEFAULT_PROFILE.read_text())


@pytest.mark.parametrize(("key", "value", "msg"), [
    ("serif", "Comic Sans", r"\[text\] serif = 'Comic Sans' names no bundled font"),
    ("cursive", 3, r"\[text\] cursive: must be a string; got 3"),
    ("fallback", "missing.svg", r"\[text\] fallback: \[text\]: SVG font file 'missing.svg' "
                                r"does not exist"),
    ("aliases", {"A": 1}, r"\[text\] aliases: must be a table of names to fonts"),
    ("aliases", {"A": "B", "B": "A"}, r"\[text\] aliases.A: .*cycle"),
    ("font_dirs", "/tmp", r"\[text\] font_dirs: must be a list of directories"),
    ("fonts", [], r"\[text\] unknown key\(s\): fonts"),
])
def test_bad_text_table_names_the_key(key: str, value: Any, msg: str) -> None:
    doc = _doc()
    doc["text"][key] = value
    with pytest.raises(ConfigError, match=msg):
        parse_profile(doc, "p.toml")


def test_the_daemon_compiles_text_with_the_profiles_fonts(tmp_path: Path) -> None:
    """An upload with text compiles in the daemon with the profile's [text] table and its
    dry-run report (the web page's) says which font drew it; the page draws the job's
    paths, of which the glyph strokes are some, like any other."""
    from fivebar_host.config import load_profile
    from fivebar_host.report.text.dryrun import report_lines
    from fivebar_host.server.jobs import JobOptions, compile_upload

    prof = tmp_path / "p.toml"
    prof.write_text('[text]\ncursive = "Relief SingleLine"\n')
    data = (Path(__file__).resolve().parent.parent / "examples" / "birthday_card.svg"
            ).read_bytes()
    job = compile_upload(data, "card.svg", JobOptions(), load_profile(prof)).job
    lines = [ln for ln in report_lines(job) if ln.startswith("text")]
    assert len(lines) == 4 and "'Happy Birthday' in Relief SingleLine" in lines[0]
    assert job.n_paths <= sum(t.strokes for t in job.drawing.texts) + 2  # + border, heart
