"""The SVG reader's streaming walk (`toolpath.svg.stream`) against the whole-tree walk: the
same drawing, warnings and errors for every corpus file, example and hand-made case that
exercises what the streaming must get right (forward references, `:first-child`, referenced
elements inside streamed groups, hidden groups, layers); and the segment limit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import Drawing
from fivebar_host.toolpath.svg import read_svg, stream

HERE = Path(__file__).parent
FILES = sorted((HERE / "svg_corpus").glob("*.svg")) + sorted(
    (HERE.parent / "examples").glob("*.svg"))
HEAD = ('<svg xmlns="http://www.w3.org/2000/svg" '
        'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape" width="100mm" '
        'height="100mm" viewBox="0 0 100 100">')
CASES = {
    "first-child": '<style>path:first-child{display:none} g>path{stroke:red}</style>'
                   '<g><path d="M0 0L5 5"/><path d="M1 1L9 3" stroke="blue"/></g>'
                   '<path d="M2 2L4 9" stroke="black"/>',
    "forward-use": '<use href="#late" x="3"/><g><path id="late" d="M0 0L5 5" '
                   'stroke="black"/></g>',
    "backward-use": '<g transform="scale(2)"><path id="p" d="M0 0L5 5" stroke="black"/>'
                    '<g opacity="0"><path id="q" d="M1 0L5 5" stroke="black"/></g></g>'
                    '<use href="#p" x="3"/><use href="#q" y="2"/>',
    "use-own-group": '<g id="a"><path d="M0 0L5 5" stroke="black"/></g><use href="#a" x="9"/>',
    "clip-later": '<g clip-path="url(#c)"><path d="M0 0L50 50" stroke="black"/></g>'
                  '<clipPath id="c"><rect width="20" height="20"/></clipPath>',
    "clip-before": '<clipPath id="c"><rect width="20" height="20"/></clipPath>'
                   '<g><path clip-path="url(#c)" d="M0 0L50 50" stroke="black"/></g>',
    "hidden": '<g display="none"><path d="M0 0L5 5" stroke="black"/></g>'
              '<g style="opacity:0"><path d="M0 0L5 5" stroke="black"/></g>'
              '<a><text>x</text><path d="M0 0L5 5" stroke="black" stroke-dasharray="1"/></a>',
    "layers": '<g inkscape:groupmode="layer" inkscape:label="A"><path d="M0 0L5 5" '
              'stroke="black"/></g><g inkscape:groupmode="layer" id="B"><circle r="3" '
              'cx="9" cy="9" stroke="black"/></g>',
    "bad-later": '<path d="M0 0L5 5" stroke="black"/><rect width="-1" height="3"/>',
}


def _read(data: bytes, streaming: bool, monkeypatch: pytest.MonkeyPatch,
          **kw: object) -> Drawing | str:
    real = stream.scan

    def scan(data: bytes, file: str) -> stream.Scan:
        sc = real(data, file)
        sc.streamable = sc.streamable and streaming
        return sc

    monkeypatch.setattr("fivebar_host.toolpath.svg.reader.scan", scan)
    try:
        return read_svg(data, **kw)  # type: ignore[arg-type]
    except InputError as e:
        return str(e)


def _same(a: Drawing | str, b: Drawing | str) -> None:
    assert type(a) is type(b)
    if isinstance(a, str):
        assert a == b
        return
    assert isinstance(b, Drawing)
    for f in ("kind", "params", "stroke", "line", "stroke_source", "stroke_power"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert a.sources == b.sources
    assert a.warnings == b.warnings
    assert (a.page_size_mm, a.page_height_mm) == (b.page_size_mm, b.page_height_mm)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_streaming_reads_files_as_the_tree_walk(path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    data = path.read_bytes()
    _same(_read(data, True, monkeypatch), _read(data, False, monkeypatch))


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("layers", [None, ("A",)])
def test_streaming_reads_cases_as_the_tree_walk(name: str, layers: tuple[str, ...] | None,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    data = (HEAD + CASES[name] + "</svg>").encode()
    _same(_read(data, True, monkeypatch, layers=layers),
          _read(data, False, monkeypatch, layers=layers))


def test_scan_says_which_files_stream() -> None:
    def sc(body: str) -> stream.Scan:
        return stream.scan((HEAD + body + "</svg>").encode(), "x.svg")

    assert sc(CASES["backward-use"]).streamable
    assert sc(CASES["backward-use"]).referenced == {"p", "q"}
    assert sc(CASES["clip-before"]).streamable
    assert not sc(CASES["forward-use"]).streamable
    assert sc(CASES["use-own-group"]).streamable
    assert not sc(CASES["clip-later"]).streamable
    assert not sc('<style>g{clip-path:url(#c)}</style>').streamable


def test_streamed_groups_are_not_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    """Walked children of streaming containers leave only placeholders behind."""
    kept: list[int] = []
    real = stream.StreamTree.parse

    def parse(self: stream.StreamTree, data: bytes, file: str) -> object:
        root = real(self, data, file)
        kept.extend(1 for c in root.children if c is not stream.GONE)
        return root

    monkeypatch.setattr(stream.StreamTree, "parse", parse)
    body = "".join(f'<path d="M{i} 0L{i} 5" stroke="black"/>' for i in range(50))
    d = read_svg((HEAD + body + '<path id="k" d="M0 0L1 1"/><use href="#k"/></svg>').encode())
    assert d.kind.shape[0] == 52 and kept == [1]  # only the referenced path (filled) is kept


def test_segment_limit_names_the_file_the_count_and_the_option() -> None:
    body = "".join(f'<path d="M{i} 0L{i} 5L{i + 1} 5" stroke="black"/>' for i in range(10))
    data = (HEAD + body + "</svg>").encode()
    assert read_svg(data, max_segments=20).kind.shape[0] == 20
    with pytest.raises(InputError) as e:
        read_svg(data, file="big.svg", max_segments=19)
    msg = str(e.value)
    assert "big.svg" in msg and "19" in msg and "--max-segments" in msg


def test_flattened_point_limit_is_checked_before_flattening() -> None:
    from fivebar_host.toolpath.geometry import flatten

    d = read_svg((HEAD + '<circle cx="50" cy="50" r="40" stroke="black"/></svg>').encode(),
                 file="circle.svg")
    n = flatten(d, 0.01).points.shape[0]
    assert flatten(d, 0.01, max_points=n).points.shape[0] == n
    with pytest.raises(InputError, match=r"circle\.svg.*--max-segments"):
        flatten(d, 0.01, max_points=n - 1)
