"""Which single-stroke font draws a CSS `font-family`: the bundled fonts, their names, the
generic families and the profile's `[text]` table (`TextConfig`), as one `FontLibrary`.

Names are compared case-insensitively without spaces, hyphens and underscores ("Hershey
Sans", "hershey-sans" and "HersheySans" are one name), and a trailing "Regular" is ignored
(CSS Fonts 4 §5.1 matches family names case-insensitively; the rest forgives how tools write
PostScript names). A family name resolves, first match wins, through:

1. the profile's `aliases` (name → family, face or SVG font file);
2. the generic families `serif`, `sans-serif`, `cursive`, `fantasy`, `monospace` (and
   `system-ui`, `ui-serif` …) → the profile's choice for each (`TextConfig.generic`);
3. common system font names (Arial, Helvetica, Times New Roman, Courier …) → their generic;
4. the bundled families ("Hershey Sans", "Hershey Serif", "Hershey Script", …, "Relief
   SingleLine"), the EMS Hershey Text names (HersheySans1, HersheySerifMed, HersheyScript1 …)
   and vpype's names (futural, timesr, scripts …), so drawings made for those tools draw
   with the same glyphs;
5. SVG font files in the profile's `font_dirs`, by file stem or by their `font-family`.

A family with several faces picks one by weight and style (CSS Fonts 4 §5.2, simplified to
the faces these fonts have): weight ≥ 600 takes the bold face if there is one; italic or
oblique takes the italic face, else the regular face slanted by 14° (the oblique angle CSS
Fonts 4 gives `oblique` and a synthesized italic). A pen has one width, so there is no
synthetic bold.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from fivebar_host.errors import InputError
from fivebar_host.toolpath.fonts.svgfont import Font, load_svg_font

DATA = Path(__file__).resolve().parent / "data"
#: Bundled faces: key → (file under data/, the name the dry run shows).
FACES: dict[str, tuple[str, str]] = {
    "futural": ("hershey/futural.svg", "HersheySans1 (futural)"),
    "futuram": ("hershey/futuram.svg", "HersheySansMed (futuram)"),
    "rowmans": ("hershey/rowmans.svg", "Hershey Roman simplex (rowmans)"),
    "rowmand": ("hershey/rowmand.svg", "Hershey Roman duplex (rowmand)"),
    "rowmant": ("hershey/rowmant.svg", "Hershey Roman triplex (rowmant)"),
    "timesr": ("hershey/timesr.svg", "HersheySerifMed (timesr)"),
    "timesrb": ("hershey/timesrb.svg", "HersheySerifBold (timesrb)"),
    "timesi": ("hershey/timesi.svg", "HersheySerifMedItalic (timesi)"),
    "timesib": ("hershey/timesib.svg", "HersheySerifBoldItalic (timesib)"),
    "scripts": ("hershey/scripts.svg", "HersheyScript1 (scripts)"),
    "scriptc": ("hershey/scriptc.svg", "HersheyScriptMed (scriptc)"),
    "cursive": ("hershey/cursive.svg", "Hershey Cursive (cursive)"),
    "gothiceng": ("hershey/gothiceng.svg", "HersheyGothEnglish (gothiceng)"),
    "gothicger": ("hershey/gothicger.svg", "Hershey Gothic German (gothicger)"),
    "gothicita": ("hershey/gothicita.svg", "Hershey Gothic Italian (gothicita)"),
    "gothgbt": ("hershey/gothgbt.svg", "Hershey Gothic English triplex (gothgbt)"),
    "gothgrt": ("hershey/gothgrt.svg", "Hershey Gothic German triplex (gothgrt)"),
    "gothitt": ("hershey/gothitt.svg", "Hershey Gothic Italian triplex (gothitt)"),
    "hersheysansmono": ("hershey/HersheySansMono.svg", "HersheySansMono"),
    "relief": ("relief/ReliefSingleLineSVG-Regular.svg", "Relief SingleLine"),
}
#: Bundled families: name → faces by (bold, italic); a missing face falls back (module doc).
FAMILIES: dict[str, dict[tuple[bool, bool], str]] = {
    "Hershey Sans": {(False, False): "futural", (True, False): "futuram"},
    "Hershey Serif": {(False, False): "timesr", (True, False): "timesrb",
                      (False, True): "timesi", (True, True): "timesib"},
    "Hershey Script": {(False, False): "scripts", (True, False): "scriptc"},
    "Hershey Roman": {(False, False): "rowmans", (True, False): "rowmand"},
    "Hershey Cursive": {(False, False): "cursive"},
    "Hershey Gothic English": {(False, False): "gothiceng", (True, False): "gothgbt"},
    "Hershey Gothic German": {(False, False): "gothicger", (True, False): "gothgrt"},
    "Hershey Gothic Italian": {(False, False): "gothicita", (True, False): "gothitt"},
    "Hershey Sans Mono": {(False, False): "hersheysansmono"},
    "Relief SingleLine": {(False, False): "relief"},
}
#: Other names of single faces: the EMS Hershey Text names and Relief's own names.
FACE_NAMES: dict[str, str] = {
    "HersheySans1": "futural", "HersheySansMed": "futuram", "HersheySerif": "timesr",
    "HersheySerifMed": "timesr", "HersheySerifMedItalic": "timesi",
    "HersheySerifBold": "timesrb", "HersheySerifBoldItalic": "timesib",
    "HersheyScript1": "scripts", "HersheyScriptMed": "scriptc",
    "HersheyGothEnglish": "gothiceng", "Relief SingleLine SVG": "relief",
    "ReliefSingleLineSVG": "relief", "Relief SingleLine Outline": "relief",
    "ReliefSingleLineCAD": "relief", "ReliefSingleLineOTF-SVG": "relief",
}
GENERICS = ("serif", "sans-serif", "cursive", "fantasy", "monospace")
#: Other generic keywords (CSS Fonts 4 §2.1.1) → the generic they are drawn as.
GENERIC_ALIASES = {"system-ui": "sans-serif", "ui-sans-serif": "sans-serif",
                   "ui-serif": "serif", "ui-monospace": "monospace", "ui-rounded": "sans-serif",
                   "math": "serif", "emoji": "sans-serif", "fangsong": "serif"}
#: Common system fonts → the generic family that stands in for them.
COMMON: dict[str, str] = {
    **dict.fromkeys(("Arial", "Helvetica", "Helvetica Neue", "Verdana", "Tahoma",
                     "Segoe UI", "Roboto", "Open Sans", "Lato", "Calibri", "Futura",
                     "Gill Sans", "DejaVu Sans", "Liberation Sans", "Noto Sans", "Ubuntu",
                     "Trebuchet MS", "Century Gothic", "Avenir", "Frutiger", "Vectora",
                     "Bitstream Vera Sans", "Cantarell", "Source Sans Pro", "Inter"),
                    "sans-serif"),
    **dict.fromkeys(("Times", "Times New Roman", "Georgia", "Garamond", "Cambria",
                     "Palatino", "Palatino Linotype", "Book Antiqua", "Baskerville",
                     "DejaVu Serif", "Liberation Serif", "Noto Serif", "Bitstream Vera Serif",
                     "Century Schoolbook", "Bookman", "Source Serif Pro"), "serif"),
    **dict.fromkeys(("Courier", "Courier New", "Consolas", "Menlo", "Monaco",
                     "Lucida Console", "DejaVu Sans Mono", "Liberation Mono", "Noto Sans Mono",
                     "Source Code Pro", "Ubuntu Mono", "Fira Mono", "Fira Code"),
                    "monospace"),
    **dict.fromkeys(("Comic Sans MS", "Brush Script MT", "Lucida Handwriting",
                     "Segoe Script", "Apple Chancery", "URW Chancery L", "Zapf Chancery",
                     "Dancing Script", "Pacifico"), "cursive"),
    **dict.fromkeys(("Impact", "Papyrus", "Old English Text MT", "Blackletter"), "fantasy"),
}
#: Shear of the synthesized oblique: CSS Fonts 4's default oblique angle, 14°.
OBLIQUE_DEG = 14.0


def norm(name: str) -> str:
    """A family name as compared (module doc)."""
    n = re.sub(r"[\s_-]+", "", name.strip().strip("'\"")).lower()
    return n[:-7] if n.endswith("regular") and len(n) > 7 else n


_COMMON = {norm(k): v for k, v in COMMON.items()}
#: Fonts read in this process, by bundled key or (resolved path, modification time).
_LOADED: dict[tuple[str, int], Font] = {}


def forget_fonts() -> None:
    """Forget the fonts read so far (the next read loads them again: a cold read)."""
    _LOADED.clear()


@dataclass(frozen=True)
class TextConfig:
    """The profile's `[text]` table: the font each generic family draws with (a family,
    face or SVG font file), the one used for characters no chosen font has (`fallback`; ""
    for none: such a character is an error), the family of text without `font-family`
    (`default`, CSS's initial value: browsers use serif), more names (`aliases`) and
    directories of SVG font files (`font_dirs`)."""

    generic: Mapping[str, str] = field(default_factory=lambda: {
        "serif": "Hershey Serif", "sans-serif": "Hershey Sans", "cursive": "Hershey Script",
        "fantasy": "Hershey Gothic English", "monospace": "Hershey Sans Mono"})
    fallback: str = "Relief SingleLine"
    default: str = "serif"
    aliases: Mapping[str, str] = field(default_factory=dict)
    font_dirs: tuple[str, ...] = ()
    source: str = "<built-in>"


@dataclass(frozen=True)
class Face:
    """A chosen face: the font, the name the dry run shows, and whether it is slanted to
    stand in for an italic (`oblique`, CSS Fonts 4 font-synthesis)."""

    font: Font
    label: str
    oblique: bool = False


class FontLibrary:
    """Resolves family names to faces (module doc) and loads each font file once."""

    def __init__(self, config: TextConfig | None = None) -> None:
        self.config = config or TextConfig()
        self._dir_index: dict[str, Path] | None = None
        self._aliases = {norm(k): v for k, v in self.config.aliases.items()}
        self._families = {norm(k): k for k in FAMILIES}
        self._faces = {norm(k): v for k, v in FACE_NAMES.items()} | {k: k for k in FACES}

    # ------------------------------------------------------------------ loading
    def load(self, key: str) -> Font:
        """A bundled face by key, or an SVG font file by path, read once per process (a
        file again when it changed)."""
        if key in FACES:
            cache_key: tuple[str, int] = (key, 0)
            path = DATA / FACES[key][0]
        else:
            path = Path(key).expanduser()
            try:
                cache_key = (str(path.resolve()), path.stat().st_mtime_ns)
            except OSError as e:
                raise InputError(f"cannot read font file: {e.strerror or e}", str(path)) from e
        font = _LOADED.get(cache_key)
        if font is None:
            font = load_svg_font(path, name=key if key in FACES else None)
            _LOADED[cache_key] = font
        return font

    # ------------------------------------------------------------------ resolving
    def face(self, family: str, bold: bool = False, italic: bool = False,
             trusted: bool = False, quoted: bool = False) -> Face | None:
        """The face for one family name (None: unknown here). `trusted` names may be file
        paths (the profile's); a drawing's names never read files outside `font_dirs`.
        A `quoted` name is never a generic family (CSS Fonts 4 §2.1.1: "cursive" quoted is
        the family of that name, vpype's Hershey font, not the generic)."""
        found = self._locate(family, bold, italic, trusted, 0, quoted)
        if found is None:
            return None
        key, label, oblique = found
        font = self.load(key)
        return Face(font, label or f"{font.family} ({Path(key).name})", oblique)

    def known(self, family: str) -> bool:
        """Whether a (trusted) name resolves, without reading any font."""
        return self._locate(family, False, False, True, 0) is not None

    def _locate(self, family: str, bold: bool, italic: bool, trusted: bool,
                depth: int, quoted: bool = False) -> tuple[str, str, bool] | None:
        """(what `load` takes, the label, synthesized oblique) for a family name."""
        if depth > 8:
            raise InputError(f"[text] names refer to each other in a cycle ({family!r})",
                             self.config.source)
        key = norm(family)
        again = self._aliases.get(key)
        if again is None:
            generic = GENERIC_ALIASES.get(family.strip().lower(), family.strip().lower())
            again = (self.config.generic.get(generic) if generic in GENERICS and not quoted
                     else _COMMON.get(key))
        if again is not None:
            return self._locate(again, bold, italic, True, depth + 1)
        if key in self._families:
            faces = FAMILIES[self._families[key]]
            choice = faces.get((bold, italic)) or faces.get((False, italic))
            oblique = choice is None and italic
            choice = choice or faces.get((bold, False)) or faces[(False, False)]
            return choice, FACES[choice][1], oblique
        if key in self._faces:
            face_key = self._faces[key]
            return face_key, FACES[face_key][1], italic
        path = self._dir_font(key) or (self._file(family) if trusted else None)
        return None if path is None else (str(path), "", italic)

    def _file(self, text: str) -> Path | None:
        if not text.lower().endswith(".svg"):
            return None
        p = Path(text).expanduser()
        if not p.is_file():
            raise InputError(f"[text]: SVG font file {text!r} does not exist",
                             self.config.source)
        return p

    def _dir_font(self, key: str) -> Path | None:
        """An SVG font in `font_dirs` by file stem or `font-family` (indexed once)."""
        if not self.config.font_dirs:
            return None
        if self._dir_index is None:
            self._dir_index = {}
            for d in self.config.font_dirs:
                for p in sorted(Path(d).expanduser().glob("*.svg")):
                    self._dir_index.setdefault(norm(p.stem), p)
                    try:
                        self._dir_index.setdefault(norm(self.load(str(p)).family), p)
                    except InputError:
                        continue  # not an SVG font: found by stem only, refused when used
        return self._dir_index.get(key)

    def fallback(self) -> Face | None:
        """The face for characters no chosen font has (None: none configured)."""
        fb = self.config.fallback
        return self.face(fb, trusted=True) if fb else None

    def default_family(self) -> str:
        return self.config.default
