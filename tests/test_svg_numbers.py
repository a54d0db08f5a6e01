"""SVG number lists: the one-match reading of a valid list gives exactly what the scanner
(number by number, the reference) gives, on lists valid and not."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from fivebar_host.toolpath.svg.units import _scan_numbers, number_prefix

# the characters that matter to the grammar, and some that end it
ALPHABET = "0123456789.+-eE, \t\n\r\fx\u00a0"


@settings(max_examples=3000, deadline=None)
@given(st.text(alphabet=ALPHABET, max_size=24))
def test_fast_path_equals_the_scanner(text: str) -> None:
    assert number_prefix(text) == _scan_numbers(text)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=32), max_size=40),
       st.sampled_from([" ", ",", ", ", " ,", "\n"]))
def test_written_lists_read_back(values: list[float], sep: str) -> None:
    text = sep.join(repr(v) for v in values)
    assert number_prefix(text) == (values, None) == _scan_numbers(text)


def test_examples() -> None:
    assert number_prefix("1-2.5.5e1,3 4") == ([1.0, -2.5, 5.0, 3.0, 4.0], None)
    assert number_prefix(" 1, 2 ,") == ([1.0, 2.0], 5)  # a comma must be followed
    assert number_prefix("1 x 2") == ([1.0], 2)
    assert number_prefix("") == ([], None)
