"""What the SVG reader does not draw, counted for ONE note (`Undrawn.note`) and named when a
file has nothing else (`Undrawn.only`): one table entry per kind, so a kind that becomes
drawn (markers and raster images did: `<image>` goes to `raster.svgimage`) leaves the
table and nothing else changes.

Elements (`ELEMENTS`) are counted where the walk meets them; properties (`PROPERTIES`: a
filter on an element that is drawn without it) where the element's own style sets them.
Markers are drawn (`markers`). Text keeps its own note with its hint (`reader.TEXT_HINT`)
until it is drawn.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fivebar_host.toolpath.svg.xmltree import Node

#: Elements not drawn, and why.
ELEMENTS: dict[str, str] = {
    "foreignObject": "foreign content (HTML)",
    "video": "video",
    "audio": "audio",
    "canvas": "canvas",
    "iframe": "embedded document",
}
#: Properties whose rendering is not drawn (the element itself is), and why.
PROPERTIES: dict[str, str] = {
    "filter": "filter effects (drawn without the filter)",
}


@dataclass
class Undrawn:
    """Per kind ("<image>", "markers …"): how many and the first element."""

    kinds: dict[str, tuple[int, Node]] = field(default_factory=dict)

    def element(self, node: Node) -> bool:
        """Count an element of `ELEMENTS`; True when it is one (the walk then skips it)."""
        why = ELEMENTS.get(node.tag)
        if why is None:
            return False
        self._add(f"<{node.tag}> ({why})", node)
        return True

    def properties(self, node: Node, spec: dict[str, str]) -> None:
        """Count the `PROPERTIES` an element's own style sets (each kind once per element)."""
        seen = set()
        for prop, why in PROPERTIES.items():
            value = spec.get(prop)
            if value is not None and value.strip().lower() not in ("none", "") \
                    and why not in seen:
                seen.add(why)
                self._add(why, node)

    def _add(self, kind: str, node: Node) -> None:
        n, first = self.kinds.get(kind, (0, node))
        self.kinds[kind] = (n + 1, first)

    def note(self) -> str | None:
        """One warning naming each kind, its count and its first element."""
        if not self.kinds:
            return None
        parts = [f"{n} × {kind} (first: {first.describe()} at line {first.line})"
                 for kind, (n, first) in self.kinds.items()]
        return "not drawn: " + "; ".join(parts)

    def only(self) -> str:
        """For a file with nothing to draw: what it holds instead ("" when nothing)."""
        elements = [f"{n} <{k.split('>')[0][1:]}> element{'s' if n > 1 else ''} "
                    f"({k.split('(', 1)[1]} at line {first.line}"
                    for k, (n, first) in self.kinds.items() if k.startswith("<")]
        return ("; it holds " + ", ".join(elements)) if elements else ""
