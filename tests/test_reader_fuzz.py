"""Fuzz the host's drawing readers (issue 16): every input ends in a `Drawing` or a named
`FivebarError`, never another exception or a hang.

Three generators: SVG element trees built from the reader's own vocabulary (shapes, groups,
`<use>`/`<symbol>`, `<switch>`, `<clipPath>`/`<mask>`, `<style>`; random attributes, path
data, transforms, lengths and styles), G-code programs of random lines and words, and
byte-level mutations (flip, insert, delete, duplicate) of the SVG corpus and the examples.
Each example runs under a wall-clock limit (SIGALRM). The default run is bounded (about 20 s);
`FIVEBAR_FUZZ_EXAMPLES=N` sets the examples per generator for a longer run. Each test prints
how many examples it ran (visible with `pytest -s`).
"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fivebar_host.errors import FivebarError
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.svg import read_svg

ROOT = Path(__file__).parent.parent
SEEDS = sorted((ROOT / "tests" / "svg_corpus").glob("*.svg")) + sorted(
    (ROOT / "examples").glob("*.svg")) + sorted((ROOT / "examples").glob("*.gcode"))
N = int(os.environ.get("FIVEBAR_FUZZ_EXAMPLES", "0"))
LIMIT_S = 5.0
SETTINGS = dict(deadline=None, derandomize=N == 0,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much])
COUNTS: dict[str, int] = {}


class HangError(Exception):
    """An example ran longer than the per-example limit."""


@contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    def fire(signum: int, frame: object) -> None:
        raise HangError(f"reader ran longer than {seconds} s")

    old = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def check(name: str, reader: Callable[[bytes], object], data: bytes) -> None:
    """The rule: a drawing or a FivebarError; anything else (or a hang) fails the test."""
    COUNTS[name] = COUNTS.get(name, 0) + 1
    with time_limit(LIMIT_S), suppress(FivebarError):
        reader(data)


def run_counted(name: str, test: Callable[[], None], at_least: int) -> None:
    """Run a hypothesis test and print how many examples it ran."""
    COUNTS[name] = 0
    test()
    print(f"\nfuzz {name}: {COUNTS[name]} examples")
    assert COUNTS[name] >= at_least


# --------------------------------------------------------------------------- SVG trees
NUM = st.one_of(st.integers(-300, 300).map(str),
                st.floats(-1e3, 1e3, allow_nan=False).map(lambda v: f"{v:.3g}"),
                st.sampled_from(["1e400", "-0", ".5", "1e-7", "NaN", "inf", "", "5e", "1.2.3"]))
LENGTH = st.builds(lambda n, u: n + u, NUM,
                   st.sampled_from(["", "", "px", "mm", "%", "em", "ex", "in", "pt", "vw", " "]))
IDS = ["a", "b", "c", "s", "m", "cp"]
PATH_TOKENS = st.sampled_from([*list("MmLlHhVvCcSsQqTtAaZz"), " ", ",", "-", ".", "e", "#"])
PATH_DATA = st.lists(st.one_of(PATH_TOKENS, NUM), max_size=30).map("".join)
TRANSFORM = st.lists(st.builds(
    lambda f, args: f"{f}({','.join(args)})",
    st.sampled_from(["translate", "scale", "rotate", "skewX", "skewY", "matrix", "bogus"]),
    st.lists(NUM, max_size=6)), max_size=3).map(" ".join)
STYLE_VALUES = {
    "display": ["none", "inline", "inherit"], "visibility": ["hidden", "visible", "collapse"],
    "stroke": ["black", "none", "#fff", "url(#a)", "rgba(0,0,0,0)", "currentColor"],
    "fill": ["none", "white", "black", "#888", "url(#g)", "transparent"],
    "opacity": ["0", "0.5", "1", "x"], "stroke-width": ["0", "1", "2mm", "-1", "10%"],
    "clip-path": ["url(#cp)", "url(#a)", "none", "circle(5px)"],
    "mask": ["url(#m)", "url(#zz)", "none"], "clip-rule": ["evenodd", "nonzero"],
    "font-size": ["10px", "2em", "150%", "large", "x"], "overflow": ["visible", "hidden"],
    "stroke-dasharray": ["none", "1 2"],
}
STYLE = st.dictionaries(st.sampled_from(sorted(STYLE_VALUES)), st.just(""), max_size=4).flatmap(
    lambda d: st.fixed_dictionaries({k: st.sampled_from(STYLE_VALUES[k]) for k in d}))
ATTRS: dict[str, st.SearchStrategy[str]] = {
    "x": LENGTH, "y": LENGTH, "width": LENGTH, "height": LENGTH, "r": LENGTH, "rx": LENGTH,
    "ry": LENGTH, "cx": LENGTH, "cy": LENGTH, "x1": LENGTH, "x2": LENGTH, "y1": LENGTH,
    "y2": LENGTH, "d": PATH_DATA, "transform": TRANSFORM,
    "points": st.lists(NUM, max_size=9).map(" ".join),
    "viewBox": st.lists(NUM, min_size=3, max_size=5).map(" ".join),
    "preserveAspectRatio": st.sampled_from(["none", "xMinYMax slice", "xMidYMid", "bad"]),
    "href": st.sampled_from([f"#{i}" for i in IDS] + ["#nope", "x.svg", ""]),
    "id": st.sampled_from(IDS), "class": st.sampled_from(["k", "guide", "k guide"]),
    "systemLanguage": st.sampled_from(["en", "fr", "", "en-US,de"]),
    "requiredExtensions": st.sampled_from(["", "http://x"]),
    "clipPathUnits": st.sampled_from(["objectBoundingBox", "userSpaceOnUse"]),
    "maskUnits": st.sampled_from(["objectBoundingBox", "userSpaceOnUse"]),
    "maskContentUnits": st.sampled_from(["objectBoundingBox", "userSpaceOnUse"]),
    **{k: st.sampled_from(v) for k, v in STYLE_VALUES.items()},
    "style": STYLE.map(lambda d: ";".join(f"{k}:{v}" for k, v in d.items())),
}
TAGS = ["path", "rect", "circle", "ellipse", "line", "polyline", "polygon", "text", "image"]
CONTAINERS = ["g", "svg", "switch", "symbol", "clipPath", "mask", "defs", "a", "use"]


def _attrs(draw: st.DrawFn) -> str:
    keys = draw(st.lists(st.sampled_from(sorted(ATTRS)), max_size=6, unique=True))
    out = []
    for k in keys:
        v = draw(ATTRS[k]).replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;")
        out.append(f'{k}="{v}"')
    return " ".join(out)


@st.composite
def element(draw: st.DrawFn, depth: int = 0) -> str:
    if depth >= 3 or draw(st.booleans()):
        tag = draw(st.sampled_from(TAGS))
        return f"<{tag} {_attrs(draw)}/>"
    tag = draw(st.sampled_from(CONTAINERS))
    kids = "".join(draw(st.lists(element(depth + 1), max_size=4)))
    return f"<{tag} {_attrs(draw)}>{kids}</{tag}>"


CSS = st.lists(st.builds(lambda sel, k, v: f"{sel} {{ {k}: {v} }}",
                         st.sampled_from(["rect", ".k", "#a", "g > path", "* ", "g path",
                                          "a + b", "p:hover", "@import x;", "[id=a]", "::x",
                                          "@media print", "}", "{"]),
                         st.sampled_from(sorted(STYLE_VALUES)),
                         st.sampled_from(["none", "black", "0", "hidden !important"])),
               max_size=4).map(" ".join)


@st.composite
def svg_document(draw: st.DrawFn) -> bytes:
    head = _attrs(draw)
    style = draw(CSS)
    body = "".join(draw(st.lists(element(), min_size=1, max_size=5)))
    sheet = f"<style>{style}</style>" if style else ""
    return (f'<svg xmlns="http://www.w3.org/2000/svg" {head}>{sheet}{body}</svg>').encode()


def test_fuzz_svg_trees() -> None:
    @settings(max_examples=N or 250, **SETTINGS)  # type: ignore[arg-type]
    @given(svg_document())
    def one(data: bytes) -> None:
        check("svg-trees", read_svg, data)

    run_counted("svg-trees", one, min(N or 250, 100))


# --------------------------------------------------------------------------- G-code
WORD = st.builds(lambda letter, n: f"{letter}{n}",
                 st.sampled_from([*list("GMXYZIJKRFSPTNE"), "g", "x"]),
                 st.one_of(st.sampled_from(["0", "1", "2", "3", "4", "17", "20", "21", "28",
                                            "90", "91", "92", "90.1", "5", "30", "1e3",
                                            "-", ".", "1e400", "nan"]), NUM))
GLINE = st.one_of(
    st.lists(WORD, max_size=6).map(" ".join),
    st.builds(lambda w, c: f"{w} ({c})", st.lists(WORD, max_size=3).map(" ".join),
              st.text(max_size=8)),
    st.builds(lambda w: f"{w} ; note", st.lists(WORD, max_size=3).map(" ".join)),
    st.sampled_from(["%", "", "M2", "N10 G1 X1*33", "(unclosed", "G1 X1 Y1 Z-1"]),
    st.text(max_size=12),
)


def test_fuzz_gcode_lines() -> None:
    @settings(max_examples=N or 400, **SETTINGS)  # type: ignore[arg-type]
    @given(st.lists(GLINE, max_size=25).map("\n".join))
    def one(text: str) -> None:
        check("gcode-lines", read_gcode, text.encode("utf-8", "surrogatepass"))

    run_counted("gcode-lines", one, min(N or 400, 100))


# --------------------------------------------------------------------------- byte mutations
@st.composite
def mutated(draw: st.DrawFn) -> tuple[Path, bytes]:
    path = draw(st.sampled_from(SEEDS))
    data = bytearray(path.read_bytes())
    for _ in range(draw(st.integers(1, 8))):
        op = draw(st.sampled_from(["flip", "insert", "delete", "dup"]))
        i = draw(st.integers(0, max(len(data) - 1, 0)))
        if op == "flip" and data:
            data[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "insert":
            data[i:i] = draw(st.sampled_from([b"<", b">", b"\"", b"-", b".", b"e", b"#", b"\x00",
                                              b"&", b"9" * 40, b"\xff\xfe", b"<g>", b"</g>"]))
        elif op == "delete":
            del data[i:i + draw(st.integers(1, 16))]
        else:
            j = draw(st.integers(i, min(len(data), i + 64)))
            data[j:j] = data[i:j]
    return path, bytes(data)


def test_fuzz_corpus_mutations() -> None:
    @settings(max_examples=N or 300, **SETTINGS)  # type: ignore[arg-type]
    @given(mutated())
    def one(case: tuple[Path, bytes]) -> None:
        path, data = case
        check("mutations", read_gcode if path.suffix == ".gcode" else read_svg, data)

    run_counted("mutations", one, min(N or 300, 100))


@pytest.mark.parametrize("path", SEEDS, ids=[p.name for p in SEEDS])
def test_seeds_read(path: Path) -> None:
    """The unmutated seeds are valid drawings (so mutations start from real input)."""
    (read_gcode if path.suffix == ".gcode" else read_svg)(path.read_bytes())
