"""CSS for the SVG reader: `<style>` sheets, `class`, the `style` attribute and presentation
attributes, cascaded per element as CSS Cascade 4 orders them for one author origin.

Supported, as far as it changes what is drawn (the properties in `PROPS`): selectors made of
type, universal, `#id`, `.class`, `[attr]`, `[attr=v]`, `[attr~=v]`, `[attr^=v]`, `[attr$=v]`,
`[attr*=v]`, `:root`, `:first-child`, descendant (` `) and child (`>`) combinators, comma
groups; specificity and source order; `!important`. Precedence per property:
important (style attribute > sheet) > style attribute > sheet > presentation attribute.

Not supported, said once per kind as a warning (`StyleSheet.warnings`): sibling combinators
(`+`, `~`) and other structural pseudo-classes (the rule is ignored), `@media`/`@supports`
blocks and `@import` (never fetched: no network). Dynamic pseudo-classes (`:hover`, ...)
never match a still picture and are dropped silently, as are rules that set nothing in `PROPS`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

from fivebar_host.toolpath.svg.xmltree import Node

#: Properties the reader uses (others do not change which outlines a pen draws).
PROPS = frozenset({"display", "visibility", "stroke", "fill", "stroke-width", "opacity",
                   "fill-opacity", "stroke-opacity", "clip-path", "mask", "clip-rule",
                   "fill-rule", "font-size", "stroke-dasharray", "overflow",
                   # text (svg.text): fonts, spacing, anchoring, baselines, decoration
                   "font-family", "font-weight", "font-style", "text-anchor",
                   "dominant-baseline", "alignment-baseline", "baseline-shift",
                   "letter-spacing", "word-spacing", "white-space", "font-kerning",
                   "text-decoration", "text-decoration-line", "text-transform", "direction",
                   "writing-mode", "font-variant", "unicode-bidi", "font-stretch"}
                  # counted when not drawn (`undrawn.PROPERTIES`)
                  | {"marker-start", "marker-mid", "marker-end", "marker", "filter"})
#: The `font` shorthand's parts (CSS Fonts 4 §2.8): style, variant, weight and stretch
#: keywords, then size[/line-height] and the family list.
_FONT_STYLE = {"italic", "oblique"}
_FONT_WEIGHT = {"bold", "bolder", "lighter"}
_FONT_KEYWORD = {"normal", "small-caps", "condensed", "expanded", "semi-condensed",
                 "semi-expanded", "ultra-condensed", "extra-condensed", "extra-expanded",
                 "ultra-expanded"}
_DYNAMIC = frozenset({"hover", "active", "focus", "visited", "link", "focus-within",
                      "focus-visible", "target"})
_COMMENT = re.compile(r"/\*.*?\*/", re.S)
_IDENT = r"-?[_a-zA-Z\u00a0-\uffff][_a-zA-Z0-9\u00a0-\uffff-]*"
_TOKEN = re.compile(
    rf"(?P<tag>\*|{_IDENT}(?:\|{_IDENT})?)|#(?P<id>[_a-zA-Z0-9\u00a0-\uffff-]+)|\.(?P<cls>{_IDENT})"
    rf"|\[\s*(?P<an>{_IDENT})\s*(?:(?P<op>[~^$*|]?=)\s*(?P<av>\"[^\"]*\"|'[^']*'|[^\]\s]+)\s*)?\]"
    rf"|::?(?P<ps>{_IDENT})(?:\((?P<pa>[^)]*)\))?|(?P<comb>\s*[>+~]\s*|\s+)")

Decl = tuple[str, str, bool]  # property, value, !important


class UnsupportedSelectorError(Exception):
    """A selector this reader cannot match; the message says which part."""


@dataclass(frozen=True)
class Compound:
    tag: str | None
    ids: tuple[str, ...] = ()
    classes: tuple[str, ...] = ()
    attrs: tuple[tuple[str, str, str], ...] = ()
    pseudos: tuple[str, ...] = ()

    def matches(self, n: Node) -> bool:
        if self.tag is not None and n.tag != self.tag:
            return False
        if any(n.get("id") != i for i in self.ids):
            return False
        cls = (n.get("class") or "").split()
        if any(c not in cls for c in self.classes):
            return False
        if not all(_attr_match(n.get(a), op, v) for a, op, v in self.attrs):
            return False
        for p in self.pseudos:
            if p == "root" and n.parent is not None:
                return False
            if p == "first-child" and n.parent is not None and n.parent.children[0] is not n:
                return False
        return True


def _attr_match(have: str | None, op: str, want: str) -> bool:
    if have is None:
        return False
    return {"": True, "=": have == want, "~=": want in have.split(),
            "^=": bool(want) and have.startswith(want), "$=": bool(want) and have.endswith(want),
            "*=": bool(want) and want in have,
            "|=": have == want or have.startswith(want + "-")}[op]


@dataclass(frozen=True)
class Selector:
    """Compounds left to right and the combinators between them (' ' or '>')."""

    parts: tuple[Compound, ...]
    combs: tuple[str, ...]
    specificity: tuple[int, int, int]

    def matches(self, n: Node) -> bool:
        return self._match(n, len(self.parts) - 1)

    def _match(self, n: Node, k: int) -> bool:
        if not self.parts[k].matches(n):
            return False
        if k == 0:
            return True
        p = n.parent
        if self.combs[k - 1] == ">":
            return p is not None and self._match(p, k - 1)
        while p is not None:
            if self._match(p, k - 1):
                return True
            p = p.parent
        return False


def parse_selector(text: str) -> Selector | None:
    """A selector, or None if it can never match a still picture (`UnsupportedSelectorError`
    if this reader cannot match it)."""
    parts: list[Compound] = []
    combs: list[str] = []
    cur: dict[str, list[str]] = {"tag": [], "id": [], "cls": [], "ps": []}
    attrs: list[tuple[str, str, str]] = []
    pos, s = 0, text.strip()
    spec = [0, 0, 0]

    def close() -> None:
        if not (cur["tag"] or cur["id"] or cur["cls"] or cur["ps"] or attrs):
            raise UnsupportedSelectorError(f"selector {text!r} is malformed")
        tag = cur["tag"][0] if cur["tag"] and cur["tag"][0] != "*" else None
        parts.append(Compound(tag, tuple(cur["id"]), tuple(cur["cls"]), tuple(attrs),
                              tuple(cur["ps"])))
        for v in cur.values():
            v.clear()
        attrs.clear()

    while pos < len(s):
        m = _TOKEN.match(s, pos)
        if not m or m.end() == pos:
            raise UnsupportedSelectorError(f"selector {text!r} is malformed at {s[pos:pos + 10]!r}")
        pos = m.end()
        g = m.lastgroup
        if g == "comb":
            close()
            c = m.group("comb").strip() or " "
            if c in "+~":
                raise UnsupportedSelectorError(f"sibling combinator {c!r} in {text!r}")
            combs.append(c)
        elif g == "tag":
            if cur["tag"] or cur["id"] or cur["cls"] or cur["ps"] or attrs:
                raise UnsupportedSelectorError(f"selector {text!r} is malformed")
            cur["tag"].append(m.group("tag").split("|")[-1])
            spec[2] += m.group("tag") != "*"
        elif g == "id":
            cur["id"].append(m.group("id"))
            spec[0] += 1
        elif g == "cls":
            cur["cls"].append(m.group("cls"))
            spec[1] += 1
        elif g == "av" or g == "an":
            av = m.group("av") or ""
            attrs.append((m.group("an"), m.group("op") or "", av.strip("\"'")))
            spec[1] += 1
        else:
            ps = m.group("ps").lower()
            if ps in _DYNAMIC:
                return None
            if ps not in ("root", "first-child"):
                raise UnsupportedSelectorError(f"pseudo-class :{ps} in {text!r}")
            cur["ps"].append(ps)
            spec[1] += 1
    close()
    return Selector(tuple(parts), tuple(combs), (spec[0], spec[1], spec[2]))


def declarations(text: str) -> list[Decl]:
    """`a: b; c: d !important` → [(a, b, False), (c, d, True)] (properties lower-cased;
    semicolons inside quotes or parentheses, as in data URLs, do not split)."""
    out: list[Decl] = []
    for part in _split_outside(text, ";"):
        if ":" not in part:
            continue
        k, v = part.split(":", 1)
        v = v.strip()
        imp = bool(re.search(r"!\s*important\s*$", v, re.I))
        if imp:
            v = re.sub(r"!\s*important\s*$", "", v, flags=re.I).strip()
        k = k.strip().lower()
        if k == "font":
            out.extend((name, val, imp) for name, val in font_shorthand(v))
        elif k and v:
            out.append((k, v, imp))
    return out


def font_shorthand(value: str) -> list[tuple[str, str]]:
    """The longhands the `font` shorthand sets (CSS Fonts 4 §2.8): style, weight, size and
    family (variant and stretch keywords are accepted and left at normal); [] when the
    value is not a font shorthand (a system font keyword such as `caption`)."""
    words = value.replace("/", " / ").split()
    style, weight = "normal", "normal"
    for i, w in enumerate(words):
        lw = w.lower()
        if lw in _FONT_STYLE:
            style = lw
        elif lw in _FONT_WEIGHT or (lw.isdigit() and 1 <= int(lw) <= 1000):
            weight = lw
        elif lw not in _FONT_KEYWORD:
            size = w
            rest = words[i + 1:]
            if rest[:1] == ["/"]:
                rest = rest[2:]  # line-height: no lines to space in SVG text
            family = " ".join(rest)
            if not family:
                return []
            return [("font-style", style), ("font-weight", weight), ("font-size", size),
                    ("font-family", family)]
    return []


def _split_outside(text: str, sep: str) -> Iterator[str]:
    depth, quote, start = 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch == "(":
            depth += 1
        elif ch == ")":
            depth = max(0, depth - 1)
        elif ch == sep and depth == 0:
            yield text[start:i]
            start = i + 1
    yield text[start:]


@dataclass(frozen=True)
class Rule:
    selector: Selector
    decls: tuple[Decl, ...]
    order: int


class StyleSheet:
    """All `<style>` rules of a document, indexed by the key of their rightmost compound."""

    def __init__(self) -> None:
        self.by_key: dict[str, list[Rule]] = {}
        self.warnings: list[str] = []
        self._n = 0

    def _warn(self, text: str) -> None:
        if text not in self.warnings:
            self.warnings.append(text)

    def add_sheet(self, text: str, where: str) -> None:
        """Parse a style sheet's text; `where` names it in warnings (e.g. '<style> line 3')."""
        text = _COMMENT.sub(" ", text.replace("<![CDATA[", " ").replace("]]>", " "))
        for prelude, body in _blocks(text):
            if prelude.startswith("@"):
                self._at_rule(prelude, where)
                continue
            decls = tuple(d for d in declarations(body) if d[0] in PROPS)
            if not decls:
                continue
            for sel_text in _split_outside(prelude, ","):
                try:
                    sel = parse_selector(sel_text)
                except UnsupportedSelectorError as e:
                    self._warn(f"{where}: ignored a CSS rule ({e}); the elements it styles "
                               "may be drawn differently than a browser shows them")
                    continue
                if sel is not None:
                    self._add(Rule(sel, decls, self._n))
                    self._n += 1

    def _at_rule(self, prelude: str, where: str) -> None:
        word = prelude.split(None, 1)[0].lower().rstrip(";")
        if word in ("@import", "@media", "@supports", "@layer", "@container"):
            self._warn(f"{where}: ignored CSS {word} (only plain rules in the file's own "
                       "<style> are applied; nothing is fetched)")

    def _add(self, r: Rule) -> None:
        last = r.selector.parts[-1]
        key = (f"#{last.ids[0]}" if last.ids else f".{last.classes[0]}" if last.classes
               else last.tag or "*")
        self.by_key.setdefault(key, []).append(r)

    def matching(self, n: Node) -> list[Rule]:
        keys = [n.tag, "*"]
        if n.get("id"):
            keys.append(f"#{n.get('id')}")
        keys += [f".{c}" for c in (n.get("class") or "").split()]
        seen: dict[int, Rule] = {}
        for k in keys:
            for r in self.by_key.get(k, ()):
                if r.order not in seen and r.selector.matches(n):
                    seen[r.order] = r
        return list(seen.values())

    def cascade(self, n: Node) -> dict[str, str]:
        """The specified value of every property in `PROPS` set on this element."""
        ranked: dict[str, tuple[tuple[int, int, tuple[int, int, int], int], str]] = {}

        def offer(prop: str, value: str, key: tuple[int, int, tuple[int, int, int], int]) -> None:
            if prop in PROPS and (prop not in ranked or key >= ranked[prop][0]):
                ranked[prop] = (key, value.strip())

        for prop, v in n.attrs.items():  # an element has few attributes; PROPS has many
            if prop in PROPS and v.strip():
                offer(prop, v, (0, 0, (0, 0, 0), 0))
        if self.by_key:
            for r in self.matching(n):
                for prop, value, imp in r.decls:
                    offer(prop, value, (int(imp), 1, r.selector.specificity, r.order))
        for prop, value, imp in declarations(n.get("style") or ""):
            offer(prop, value, (int(imp), 2, (0, 0, 0), 0))
        return {k: v for k, (_, v) in ranked.items()}


def _blocks(text: str) -> Iterable[tuple[str, str]]:
    """Top-level (prelude, body) pairs; an at-rule without a block has body ''."""
    i, n = 0, len(text)
    while i < n:
        j = i
        while j < n and text[j] not in "{;":
            j += 1
        prelude = text[i:j].strip()
        if j >= n:
            if prelude:
                yield prelude, ""
            return
        if text[j] == ";":
            if prelude:
                yield prelude, ""
            i = j + 1
            continue
        depth, k = 1, j + 1
        while k < n and depth:
            depth += {"{": 1, "}": -1}.get(text[k], 0)
            k += 1
        yield prelude, text[j + 1:k - 1]
        i = k
