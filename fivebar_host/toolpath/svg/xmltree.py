"""The XML layer of the SVG reader: a small element tree with source lines.

Parsed with expat (not ElementTree) because every error must name the line; external entities
are never fetched (expat does not load them unless asked) and libexpat ≥ 2.4 refuses billion-
laughs amplification, which surfaces here as a malformed-XML `InputError` like any other.
Text content is kept (for `<style>` sheets and to name `<text>` elements in the no-strokes hint).
"""

from __future__ import annotations

import xml.parsers.expat
from dataclasses import dataclass, field

from fivebar_host.errors import InputError

SVG_NS = "http://www.w3.org/2000/svg"
XLINK_NS = "http://www.w3.org/1999/xlink"
INKSCAPE_NS = "http://www.inkscape.org/namespaces/inkscape"
#: Deepest element nesting read (the tree is walked recursively).
MAX_DEPTH = 256


@dataclass(eq=False)
class Node:
    """A parsed XML element: local tag, namespace, attributes (local names; foreign
    namespaces as 'ns local'), children, parent, its text and its 1-based source line."""

    tag: str
    ns: str
    attrs: dict[str, str]
    line: int
    children: list[Node] = field(default_factory=list)
    parent: Node | None = None
    text: str = ""

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


def parse_xml(data: bytes, file: str) -> Node:
    """Parse with expat (keeps line numbers); external entities are never fetched."""
    parser = xml.parsers.expat.ParserCreate(namespace_separator=" ")
    root: list[Node] = []
    stack: list[Node] = []

    def start(name: str, attrs: dict[str, str]) -> None:
        ns, _, local = name.rpartition(" ")
        clean: dict[str, str] = {}
        for k, v in attrs.items():
            kns, _, kl = k.rpartition(" ")
            clean[kl if kns in ("", SVG_NS) else f"{kns} {kl}"] = v
        node = Node(local, ns, clean, parser.CurrentLineNumber)
        if len(stack) >= MAX_DEPTH:
            raise InputError(f"elements nest deeper than {MAX_DEPTH} levels", file, node.line)
        if stack:
            node.parent = stack[-1]
            stack[-1].children.append(node)
        else:
            root.append(node)
        stack.append(node)

    def end(name: str) -> None:
        stack.pop()

    def chars(text: str) -> None:
        if stack and len(stack[-1].text) < 1_000_000:
            stack[-1].text += text

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as e:
        raise InputError(f"malformed XML: {xml.parsers.expat.ErrorString(e.code)} "
                         f"(line {e.lineno}, column {e.offset + 1})", file, e.lineno) from e
    except (LookupError, UnicodeError) as e:  # an XML declaration naming an unknown encoding
        raise InputError(f"cannot decode the file: {e}", file) from e
    if not root:
        raise InputError("no XML root element", file)
    return root[0]
