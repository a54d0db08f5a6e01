"""`fivebar text`: quick lettering without an SVG editor.

    fivebar text "Happy Birthday" "Ada" --font cursive --size 12mm -o card.svg
    fivebar text "Table 12" --size 10mm --dry-run          # write text.svg, then preview it
    fivebar text "Hello" --font HersheySans1 --port fivebar-sim://
    fivebar text --list-fonts

Each TEXT argument is a line. The file (`-o`, default text.svg) holds one SVG `<text>` in
the page it needs, so `fivebar plot` draws it like any drawing and an editor can change it;
`--paths` writes the single strokes as `<path>` elements instead (for vpype, Inkscape or the
AxiDraw software). With `--dry-run` or `--port` the file is then plotted as `fivebar plot`
would (the same job options; `fivebar plot FILE --resume` continues an interrupted plot).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from fivebar_host.cli.common import (
    LengthType,
    controller_option,
    handle_errors,
    job_options,
    load,
    main,
    port_option,
    yes_option,
)


@main.command("text")
@click.argument("lines", nargs=-1)
@click.option("--font", default="sans-serif", show_default=True, metavar="FAMILY",
              help="A CSS font-family: a generic family (sans-serif, serif, cursive, "
              "monospace, fantasy), a bundled font (Hershey Sans, HersheyScript1, futural, "
              "Relief SingleLine …; --list-fonts) or a name from the profile's [text].")
@click.option("--size", type=LengthType(), default="10mm", show_default=True,
              help="Font size (the em), mm or with a unit (0.5in, 24pt).")
@click.option("--bold", is_flag=True, help="The family's bold face, if it has one.")
@click.option("--italic", is_flag=True,
              help="The family's italic face, else its regular face slanted 14°.")
@click.option("--anchor", type=click.Choice(["start", "middle", "end"]), default="start",
              show_default=True, help="Align the lines at their start, middle or end.")
@click.option("--line-height", type=float, default=1.25, show_default=True,
              help="Distance between lines, a multiple of the size.")
@click.option("--letter-spacing", type=LengthType(), default="0mm", show_default=True,
              help="Extra space after every character.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("text.svg"), show_default=True, help="The SVG file to write.")
@click.option("--paths", is_flag=True,
              help="Write the single strokes as <path> elements instead of a <text>.")
@click.option("--list-fonts", is_flag=True, help="List the bundled fonts and their names.")
@click.option("--dry-run", is_flag=True, help="Then compile and check the file: report and "
              "preview picture, as `fivebar plot --dry-run`.")
@click.option("--preview", "preview_path", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("preview.png"), show_default=True, help="Dry-run picture (PNG).")
@port_option
@yes_option
@controller_option
@job_options()
@handle_errors
def text(lines: tuple[str, ...], font: str, size: float, bold: bool, italic: bool,
         anchor: str, line_height: float, letter_spacing: float, output: Path, paths: bool,
         list_fonts: bool, dry_run: bool, preview_path: Path, port: str | None, yes: bool,
         controller: str, config_path: Path | None, **job_values: Any) -> None:
    """Letter LINES (one line per argument) in a single-stroke font into an SVG file, and
    plot it with --dry-run or --port."""
    from fivebar_host.cli.common import fail

    if list_fonts:
        for line in font_table():
            click.echo(line)
        return
    if not lines:
        fail("give the text to letter, one argument per line (or --list-fonts)")
    if not (size > 0 and line_height > 0):
        fail("--size and --line-height must be positive")
    from fivebar_host.compile import write_atomic
    from fivebar_host.toolpath.svg import read_svg
    from fivebar_host.toolpath.svg.lettering import Lettering, lettering_svg, strokes_svg

    prof = load(config_path)
    split = tuple(part for line in lines for part in line.split("\n"))
    lt = Lettering(split, font, size, bold, italic, anchor, line_height, letter_spacing)
    svg = lettering_svg(lt, prof.text, str(output))
    drawing = read_svg(svg.encode(), file=str(output), text=prof.text)
    for info in drawing.texts:
        click.echo(f"lettered {len(split)} line(s), {info.glyphs} glyphs, {info.strokes} "
                   f"strokes in {', '.join(info.fonts)} at {size:g} mm")
    for note in drawing.warnings:
        click.echo(f"note: {note}")
    write_atomic(output, strokes_svg(drawing) if paths else svg)
    assert drawing.page_size_mm is not None
    w, h = drawing.page_size_mm
    click.echo(f"wrote {output} ({w:.1f} × {h:.1f} mm)")
    if dry_run or port is not None:
        from fivebar_host.cli.plot import plot_file

        plot_file(output, dry_run, preview_path, port, False, yes, controller, config_path,
                  job_values)


def font_table() -> list[str]:
    """The bundled families and faces with the names they answer to."""
    from fivebar_host.toolpath.fonts.library import FACE_NAMES, FACES, FAMILIES

    out = ["families (font-weight and font-style pick the face):"]
    for fam, faces in FAMILIES.items():
        parts = [f"{'bold ' if b else ''}{'italic ' if i else ''}".strip() or "regular"
                 for b, i in faces]
        out.append(f"  {fam:<24} " + ", ".join(f"{p}: {FACES[k][1]}" for p, k in
                                               zip(parts, faces.values(), strict=True)))
    out.append("faces (also by their file name, e.g. futural, timesr, scripts):")
    by_face: dict[str, list[str]] = {}
    for name, key in FACE_NAMES.items():
        by_face.setdefault(key, []).append(name)
    for key, (_, label) in FACES.items():
        names = [key, *by_face.get(key, [])]
        out.append(f"  {label:<40} {', '.join(dict.fromkeys(names))}")
    out.append("generic families map through the profile's [text] table; see docs/text.md")
    return out
