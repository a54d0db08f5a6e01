"""The XML layer of the SVG reader: a small element tree with source lines.

Parsed with expat (not ElementTree) because every error must name the line; external entities
are never fetched (expat does not load them unless asked) and libexpat ≥ 2.4 refuses billion-
laughs amplification, which surfaces here as a malformed-XML `InputError` like any other.
Character data is kept inside `<text>` only (the style sheets come from the reader's first
pass): as ElementTree keeps it, an element's `text` is what comes before its first child and
a child's `tail` what follows it, so `<text>a<tspan>b</tspan>c</text>` keeps its order.
"""

from __future__ import annotations

import xml.parsers.expat
from dataclasses import dataclass, field

from fivebar_host import progress
from fivebar_host.errors import InputError

SVG_NS = "http://www.w3.org/2000/svg"
XLINK_NS = "http://www.w3.org/1999/xlink"
XML_NS = "http://www.w3.org/XML/1998/namespace"
INKSCAPE_NS = "http://www.inkscape.org/namespaces/inkscape"
#: Deepest element nesting read (the tree is walked recursively).
MAX_DEPTH = 256


@dataclass(eq=False)
class Node:
    """A parsed XML element: local tag, namespace, attributes (local names; foreign
    namespaces as 'ns local'), children, parent, its 1-based source line, and inside `<text>`
    its character data before the first child (`text`) and after its own end (`tail`)."""

    tag: str
    ns: str
    attrs: dict[str, str]
    line: int
    children: list[Node] = field(default_factory=list)
    parent: Node | None = None
    text: str = ""
    tail: str = ""

    def get(self, key: str, default: str | None = None) -> str | None:
        return self.attrs.get(key, default)

    @property
    def is_svg(self) -> bool:
        """An element of the SVG namespace (or of none, as in hand-written files)."""
        return self.ns in ("", SVG_NS)

    def describe(self) -> str:
        """`<path id="leaf">` or `<path>`: how messages name an element."""
        ident = self.get("id")
        return f'<{self.tag} id="{ident}">' if ident else f"<{self.tag}>"


def clean_attrs(attrs: dict[str, str]) -> dict[str, str]:
    """Attribute names as `Node.attrs` keeps them: local names for SVG (or no) namespace,
    'ns local' for foreign ones."""
    clean: dict[str, str] = {}
    for k, v in attrs.items():
        kns, _, kl = k.rpartition(" ")
        clean[kl if kns in ("", SVG_NS) else f"{kns} {kl}"] = v
    return clean


def new_parser() -> xml.parsers.expat.XMLParserType:
    """An expat parser reporting namespaced names as 'ns local'."""
    return xml.parsers.expat.ParserCreate(namespace_separator=" ")


#: Bytes parsed between two progress reports (`run_parser`'s `stage`).
PROGRESS_CHUNK = 1 << 20


def run_parser(parser: xml.parsers.expat.XMLParserType, data: bytes, file: str,
               stage: str | None = None) -> None:
    """Parse all of `data`; XML and decoding errors become `InputError`s naming the line.
    With `stage`, the bytes parsed are reported (`fivebar_host.progress`) as they go."""
    try:
        if stage is None or len(data) <= PROGRESS_CHUNK or not progress.listening():
            parser.Parse(data, True)
            return
        view = memoryview(data)
        for at in range(0, len(data), PROGRESS_CHUNK):
            parser.Parse(bytes(view[at:at + PROGRESS_CHUNK]), False)
            progress.report(stage, min(1.0, (at + PROGRESS_CHUNK) / len(data)))
        parser.Parse(b"", True)
    except xml.parsers.expat.ExpatError as e:
        raise InputError(f"malformed XML: {xml.parsers.expat.ErrorString(e.code)} "
                         f"(line {e.lineno}, column {e.offset + 1}){_not_xml(data)}", file,
                         e.lineno) from e
    except (LookupError, UnicodeError) as e:  # an XML declaration naming an unknown encoding
        raise InputError(f"cannot decode the file: {e}", file) from e


#: The first bytes of files people give as drawings that are no XML at all.
MAGIC = ((b"\x89PNG", "a PNG image", ".png"), (b"\xff\xd8\xff", "a JPEG image", ".jpg"),
         (b"GIF8", "a GIF image", ".gif"), (b"BM", "a BMP image", ".bmp"),
         (b"II*\x00", "a TIFF image", ".tif"), (b"MM\x00*", "a TIFF image", ".tif"),
         (b"%PDF", "a PDF document", ""))


def _not_xml(data: bytes) -> str:
    """What the file is instead, when its first bytes say (`MAGIC`), for the error."""
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "; the file is a WebP image: give it the extension .webp to engrave it"
    if data[:2] == b"BM" and data[6:10] != b"\x00\x00\x00\x00":  # BMP: reserved zeros
        return ""
    for magic, what, ext in MAGIC:
        if data.startswith(magic):
            if not ext:
                return f"; the file is {what}: export the drawing as SVG or G-code"
            return f"; the file is {what}: give it the extension {ext} to engrave it"
    return ""


#: Most characters kept per text piece (a text element's content is bounded anyway).
MAX_TEXT = 1_000_000


def keeps_text(node: Node) -> bool:
    """Whether character data in this element is kept: `<text>` and what it contains."""
    return node.is_svg and node.tag == "text"


def add_chars(node: Node, text: str) -> None:
    """Character data met while `node` is the innermost open element (see module doc)."""
    if node.children:
        last = node.children[-1]
        if len(last.tail) < MAX_TEXT:
            last.tail += text
    elif len(node.text) < MAX_TEXT:
        node.text += text


def too_deep(file: str, line: int) -> InputError:
    return InputError(f"elements nest deeper than {MAX_DEPTH} levels", file, line)


def parse_xml(data: bytes, file: str) -> Node:
    """Parse with expat (keeps line numbers); external entities are never fetched."""
    parser = new_parser()
    root: list[Node] = []
    stack: list[Node] = []
    keep: list[bool] = [False]  # per open element: inside <text>

    def start(name: str, attrs: dict[str, str]) -> None:
        ns, _, local = name.rpartition(" ")
        node = Node(local, ns, clean_attrs(attrs), parser.CurrentLineNumber)
        if len(stack) >= MAX_DEPTH:
            raise too_deep(file, node.line)
        if stack:
            node.parent = stack[-1]
            stack[-1].children.append(node)
        else:
            root.append(node)
        stack.append(node)
        keep.append(keep[-1] or keeps_text(node))

    def end(name: str) -> None:
        stack.pop()
        keep.pop()

    def chars(text: str) -> None:
        if stack and keep[-1]:
            add_chars(stack[-1], text)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    run_parser(parser, data, file)
    if not root:
        raise InputError("no XML root element", file)
    return root[0]
