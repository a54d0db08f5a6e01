"""Every value an error echoes is shortened (first and last characters and the length), so
what a user sent never makes an unbounded line on a terminal, in a log or in an answer."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from fivebar_host.cli import main
from fivebar_host.errors import InputError, bounded, shorten


def test_shorten_keeps_both_ends_and_says_the_length() -> None:
    assert shorten("short") == "short"
    s = shorten("1" * 10**6)
    assert s.startswith("1" * 40 + "…") and s.endswith(" (1000000 characters)")
    assert len(s) < 100


def test_bounded_shortens_long_words_only() -> None:
    msg = "drawing.svg:3: X" + "9" * 5000 + ": not a finite number"
    out = bounded(msg)
    assert out.startswith("drawing.svg:3: X999") and out.endswith(
        " (5001 characters): not a finite number")
    assert bounded("a normal message, kept as it is") == "a normal message, kept as it is"
    assert len(str(InputError("bad " + "y" * 10**5, "f.svg", 2))) < 200


def test_a_million_digit_number_is_not_echoed_whole(tmp_path: Path) -> None:
    src = tmp_path / "big.gcode"
    src.write_text("G1 X" + "1" * 10**6 + " Y10 F100\n")
    res = CliRunner().invoke(main, ["convert", str(src), "-o", str(tmp_path / "out.txt")])
    assert res.exit_code == 2
    assert "(1000001 characters): not a finite number" in res.output
    assert len(res.output) < 300
