"""What the SVG reader does not draw is counted in one note (`toolpath/svg/undrawn.py`):
foreign objects and filters; `<image>` is drawn now (as a raster, tests/test_svg_image.py):
a file holding only images reads, one mixing them with paths is refused naming both."""

from __future__ import annotations

import pytest

from fivebar_host.errors import InputError
from fivebar_host.toolpath.svg import read_svg

HEAD = '<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" ' \
       'viewBox="0 0 100 100">'


def test_every_undrawn_kind_is_in_one_note() -> None:
    svg = (HEAD + '<defs><marker id="a"><path d="M0 0 L4 2 L0 4z"/></marker></defs>\n'
           '<video width="5" height="5"/><video/>\n'
           '<foreignObject width="9" height="9"/>\n'
           '<path d="M10 10 L90 90" stroke="black" marker-end="url(#a)"/>\n'
           '<path d="M10 90 L90 10" stroke="black" style="filter:url(#f)"/></svg>')
    d = read_svg(svg.encode(), file="u.svg")
    (note,) = [w for w in d.warnings if w.startswith("not drawn:")]
    assert "2 × <video> (video) (first: <video> at line 2)" in note
    assert "1 × <foreignObject>" in note
    assert "marker" not in note  # markers are drawn (tests/test_svg_markers.py)
    assert d.n_strokes > 2  # two paths and the marker's arrowhead (clipped to its 3 × 3)
    assert "1 × filter effects (drawn without the filter)" in note


def test_an_image_only_file_is_read_with_its_images() -> None:
    svg = HEAD + '\n<image href="photo.png" width="50" height="50"/></svg>'
    d = read_svg(svg.encode(), file="i.svg")
    assert d.n_strokes == 0 and [(i.line, i.href) for i in d.images] == [(2, "photo.png")]
    assert not any("not drawn" in w for w in d.warnings)


def test_an_image_beside_paths_is_refused_naming_both() -> None:
    svg = (HEAD + '\n<image id="pic" href="photo.png" width="50" height="50"/>\n'
           '<path id="outline" d="M0 0 L9 9" stroke="black"/></svg>')
    with pytest.raises(InputError, match=r"mixes raster images \(<image id='pic'> at line 2\) "
                                         r"with drawn vector elements \(<path id='outline'> at "
                                         r"line 3\).*split it into two files"):
        read_svg(svg.encode(), file="m.svg")
