"""Reading a large SVG without holding its whole element tree: two expat passes.

A drawing of a million paths held as a tree costs far more than its primitives (a `Node`, an
attribute dict and its strings per element, and the freed objects fragment the heap), so the
reader walks what it can while parsing:

1. `scan`: every style sheet (a `<style>` anywhere applies to the whole document), the ids
   that something references (`<use>` href, `url(#id)` in any attribute) and whether every
   reference points back to an element already closed. It also finds every XML error, so
   nothing is drawn from a file that turns out to be malformed.
2. `StreamTree`: the tree is built again, but a child of a *streaming container* (the root,
   or a plain `<g>`/`<a>` without its own clip-path or mask, itself in a streaming
   container) is walked as soon as it ends — with the context its container got when it
   started, exactly as the recursive walk would — and then dropped unless an id in it is
   referenced. Everything else (defs, switch, nested svg, clipped groups, hidden groups) is
   built and walked whole, as before.

Semantics are those of the tree walk: style sheets and ids are known before anything is
walked, the cascade sees the same ancestors and `:first-child` (a dropped child leaves a
placeholder), side effects happen in document order. A reference to an element that is not
closed yet (a forward `<use>`, a clip path defined further down, a `url()` in a style sheet)
makes `scan` answer "not streamable", and the reader builds the whole tree as before.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

from fivebar_host.errors import InputError
from fivebar_host.toolpath.svg.walk import Ctx, Walker
from fivebar_host.toolpath.svg.xmltree import (
    MAX_DEPTH,
    SVG_NS,
    XLINK_NS,
    Node,
    add_chars,
    clean_attrs,
    keeps_text,
    new_parser,
    run_parser,
    too_deep,
)

_URL_REF = re.compile(r"url\(\s*['\"]?#([^'\")\s]+)")
_HREFS = ("href", f"{XLINK_NS} href")
#: What a dropped child leaves in its container's `children` (keeps `:first-child` exact).
GONE = Node("", "#gone", {}, 0)


@dataclass
class Scan:
    """What pass 1 found: the style sheets (text, line) in document order, the referenced
    ids, and whether the drawing can be walked while it is parsed."""

    sheets: list[tuple[str, int]] = field(default_factory=list)
    referenced: set[str] = field(default_factory=set)
    streamable: bool = True


def _is_style(ns: str, local: str, attrs: dict[str, str]) -> bool:
    return local == "style" and ns in ("", SVG_NS) and (
        attrs.get("type") or "text/css") in ("text/css", "")


def scan(data: bytes, file: str) -> Scan:
    """Pass 1 (module doc); raises the XML errors `parse_xml` raises."""
    parser = new_parser()
    out = Scan()
    events = 0
    closed: dict[str, int] = {}  # first element with an id → event count at its end
    refs: list[tuple[str, int]] = []
    stack: list[tuple[str | None, int, list[str]]] = []  # (first id, sheet index, text)

    def start(name: str, attrs: dict[str, str]) -> None:
        nonlocal events
        events += 1
        ns, _, local = name.rpartition(" ")
        a = clean_attrs(attrs)
        if len(stack) >= MAX_DEPTH:
            raise too_deep(file, parser.CurrentLineNumber)
        ident = a.get("id")
        first = ident if ident and ident not in closed else None
        if first is not None:
            closed[first] = 1 << 62  # open: any reference now is a forward one
        for k, v in a.items():
            if k in _HREFS and v.startswith("#"):
                refs.append((v[1:], events))
            elif "url(" in v:
                refs.extend((m, events) for m in _URL_REF.findall(v))
        sheet = -1
        if _is_style(ns, local, a):
            sheet = len(out.sheets)
            out.sheets.append(("", parser.CurrentLineNumber))
        stack.append((first, sheet, []))

    def end(name: str) -> None:
        nonlocal events
        events += 1
        first, sheet, text = stack.pop()
        if first is not None:
            closed[first] = events
        if sheet >= 0:
            out.sheets[sheet] = ("".join(text), out.sheets[sheet][1])

    def chars(t: str) -> None:
        if stack and stack[-1][1] >= 0 and sum(map(len, stack[-1][2])) < 1_000_000:
            stack[-1][2].append(t)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    run_parser(parser, data, file)
    if events == 0:
        raise InputError("no XML root element", file)
    out.referenced = {r for r, _ in refs}
    out.streamable = all(closed.get(r, 0) < at for r, at in refs) and not any(
        "url(" in t for t, _ in out.sheets)
    return out


@dataclass
class _Frame:
    node: Node
    ctx: Ctx | None  # a streaming container's context; None: built whole
    pinned: bool  # holds a referenced id: kept in the tree
    hidden: bool = False  # a container entered here whose opacity is 0: never walked
    text: bool = False  # in <text>: its character data is kept (xmltree)


class StreamTree:
    """Pass 2 (module doc). `on_root(root)` does the reader's root work (checks, page,
    entering the root) and returns the root's context, or None when nothing in it is drawn."""

    def __init__(self, walker: Walker, referenced: set[str],
                 on_root: Callable[[Node], Ctx | None]) -> None:
        self.w = walker
        self.referenced = referenced
        self.on_root = on_root
        self.stack: list[_Frame] = []
        self.root: Node | None = None

    def parse(self, data: bytes, file: str) -> Node:
        """Parse and walk; returns the root (with what was kept of the tree)."""
        parser = new_parser()
        self.parser = parser
        parser.StartElementHandler = self._start
        parser.EndElementHandler = self._end
        parser.CharacterDataHandler = self._chars
        run_parser(parser, data, file, stage="reading")
        assert self.root is not None  # scan refused a file without one
        return self.root

    def _start(self, name: str, attrs: dict[str, str]) -> None:
        ns, _, local = name.rpartition(" ")
        node = Node(local, ns, clean_attrs(attrs), self.parser.CurrentLineNumber)
        ident = node.get("id")
        if ident and ident not in self.w.ids:
            self.w.ids[ident] = node
        pinned = bool(ident) and ident in self.referenced
        if not self.stack:
            self.root = node
            ctx = self.on_root(node)
            self.stack.append(_Frame(node, ctx if ctx is not None and ctx.opacity > 0 else
                                     None, pinned))
            return
        parent = self.stack[-1]
        node.parent = parent.node
        parent.node.children.append(node)
        fr = _Frame(node, None, pinned, text=parent.text or keeps_text(node))
        if parent.ctx is not None and not pinned:
            self._enter_container(fr, parent.ctx)
        self.stack.append(fr)

    def _enter_container(self, fr: _Frame, pctx: Ctx) -> None:
        """Make `fr` a streaming container if it is one, entered as `Walker.walk` enters it;
        any other element keeps ctx None and is walked whole at its end."""
        node = fr.node
        if not (node.is_svg and node.tag in ("g", "a")):
            return
        spec = self.w.sheet.cascade(node)
        if "clip-path" in spec or "mask" in spec or \
                spec.get("display", "").strip().lower() == "none":
            return
        c = self.w.enter(node, spec, pctx, True)
        if c.opacity <= 0.0:
            self.w.skipped_hidden += 1  # as `Walker.walk` counts it; never walked
            fr.hidden = True
            return
        fr.ctx = c

    def _end(self, name: str) -> None:
        fr = self.stack.pop()
        if not self.stack:
            return
        parent = self.stack[-1]
        parent.pinned |= fr.pinned
        if parent.ctx is None:
            return
        if fr.ctx is None and not fr.hidden:
            self.w.walk(fr.node, parent.ctx)
        if not fr.pinned:
            parent.node.children[-1] = GONE

    def _chars(self, text: str) -> None:
        if self.stack and self.stack[-1].text:
            add_chars(self.stack[-1].node, text)
