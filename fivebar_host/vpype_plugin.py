"""vpype plugin: plot or preview vpype's document on a five-bar machine.

Installed with the optional extra (`pip install fivebar[vpype]`) and registered through
vpype's plugin entry point (`[project.entry-points."vpype.plugins"]` in pyproject.toml), so
that the pipeline a vpype user already writes ends in the plotter:

    vpype read x.svg linemerge linesort fivebar plot --port /dev/ttyUSB0
    vpype read x.svg fivebar preview --preview x.png

`fivebar plot` / `fivebar preview` take the options of `fivebar plot` (generated from
`fivebar_host.options`: --tolerance, --origin, --fit, --mode, --laser, --layer, …, and
--config). `preview` is `fivebar plot --dry-run`: the report and the picture. The document
is handed on unchanged, so more vpype commands may follow.

vpype keeps its lines in CSS pixels (1/96 in), y down from the page's top-left corner;
`document_to_drawing` turns them into a fivebar `Drawing` in millimetres, y up from the
page's bottom-left corner (the frame an SVG is read into), one stroke of straight lines per
vpype line, so the placement (centred in the safe area unless --origin/--fit) and every
check are those of an SVG plot. vpype's lines are dense polylines (curves are linearised by
`read`), which the job compiler's line simplification (`fivebar_host.toolpath.simplify`)
turns back into few long chords within the tolerance.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import click
import numpy as np
import vpype as vp
import vpype_cli

from fivebar_host.cli.common import job_options, load, port_option, yes_option
from fivebar_host.errors import FivebarError, InputError
from fivebar_host.options import compile_values
from fivebar_host.toolpath.geometry import LINE, Drawing, SourceInfo
from kinematics.arrays import FloatArray, IntArray

#: CSS pixels per millimetre (vpype's unit: 96 px per inch).
PX_PER_MM = 96.0 / 25.4
#: What the document is called in messages and in the resume file's name.
DEFAULT_NAME = "vpype-document"


def _layer_ids(document: vp.Document, layers: tuple[str, ...], name: str) -> list[int]:
    """The document's layer ids selected by `--layer` values (id or vpype name); all
    without any."""
    ids = sorted(document.layers)
    if not layers:
        return ids
    names = {lid: str(document.layers[lid].property(vp.METADATA_FIELD_NAME) or "")
             for lid in ids}
    chosen = [lid for lid in ids if str(lid) in layers or names[lid] in layers]
    unknown = [w for w in layers if w not in {str(i) for i in ids} | set(names.values())]
    if unknown:
        raise InputError(f"no layer {', '.join(unknown)} in the vpype document (layers: "
                         + ", ".join(f"{i} {names[i]!r}" if names[i] else str(i)
                                     for i in ids) + ")", name)
    return chosen


def document_to_drawing(document: vp.Document, layers: tuple[str, ...] = (),
                        name: str = DEFAULT_NAME) -> Drawing:
    """vpype's document (CSS px, y down) as a fivebar `Drawing` (mm, y up, the page's
    bottom-left corner at the origin): one stroke of LINE primitives per vpype line of at
    least two points, in layer order. Raises `InputError` when nothing is left to draw."""
    page = document.page_size
    if page is None:
        bounds = document.bounds()
        height_px = float(bounds[3]) if bounds is not None else 0.0
        size_mm = None
    else:
        height_px = float(page[1])
        size_mm = (float(page[0]) / PX_PER_MM, float(page[1]) / PX_PER_MM)
    height_mm = height_px / PX_PER_MM
    params: list[FloatArray] = []
    stroke: list[IntArray] = []
    sources: list[SourceInfo] = []
    for lid in _layer_ids(document, layers, name):
        for k, line in enumerate(document.layers[lid]):
            z = np.asarray(line, dtype=np.complex128)
            if z.shape[0] < 2:
                continue
            xy = np.column_stack((z.real, height_px - z.imag)) / PX_PER_MM
            p = np.zeros((xy.shape[0] - 1, 8))
            p[:, 0:2], p[:, 2:4] = xy[:-1], xy[1:]
            params.append(p)
            stroke.append(np.full(p.shape[0], len(sources), dtype=np.int64))
            sources.append(SourceInfo(len(sources), f"layer {lid} line {k}", None, "vpype",
                                      str(lid)))
    if not sources:
        raise InputError("the vpype document has no lines to draw", name)
    all_params = np.concatenate(params)
    n, s = all_params.shape[0], len(sources)
    if not np.isfinite(all_params).all():
        raise InputError("the vpype document has a coordinate that is not a finite number",
                         name)
    return Drawing(file=name, kind=np.full(n, LINE, dtype=np.int8), params=all_params,
                   stroke=np.concatenate(stroke), line=np.zeros(n, dtype=np.int64),
                   stroke_source=np.arange(s, dtype=np.int64), stroke_power=np.ones(s),
                   stroke_feed_mm_s=np.full(s, math.nan), sources=sources,
                   page_height_mm=height_mm, page_size_mm=size_mm)


def _run(document: vp.Document, action: str, port: str | None, preview_path: Path,
         yes: bool, name: str, config_path: Path | None, job_values: dict[str, Any]) -> None:
    """Compile the document and preview it, or plot it on `port` (raises FivebarError)."""
    from fivebar_host.compile import CompileOptions, compile_drawing, nbar_opinion

    laser = bool(job_values.get("laser"))
    prof = load(config_path)
    drawing = document_to_drawing(document, tuple(job_values.get("layers") or ()), name)
    job = compile_drawing(drawing, prof, CompileOptions(**compile_values(job_values)))
    if action == "preview":
        from fivebar_host.report.preview import draw_preview
        from fivebar_host.report.text.dryrun import report_lines

        for line in report_lines(job, nbar_opinion(job, prof), laser=laser):
            click.echo(line)
        draw_preview(job, prof, preview_path)
        click.echo(f"preview       {preview_path}")
        return
    if port is None:
        raise click.UsageError("fivebar plot needs --port PORT (e.g. /dev/ttyUSB0, or "
                               "fivebar-sim:// for the emulator); fivebar preview draws "
                               "the picture and the report without a machine")
    from fivebar_host.cli.session import Plot, plot_on_machine
    from fivebar_host.cli.stops import check_stops
    from fivebar_host.controllers import DEFAULT
    from fivebar_host.run.stops import Copies

    copies = Copies(int(job_values.get("copies") or 1),
                    float(job_values.get("page_delay_s") or 0.0))
    check_stops(job)
    plot_on_machine(Plot(Path(name), port, DEFAULT, laser, False, yes, copies, preview_path),
                    prof, job)


class _ActionFirst(click.Command):
    """`fivebar ACTION [OPTIONS]`: vpype chains commands with options *before* positional
    arguments (the next positional word starts the next command), so the action is taken
    from the front here and the options after it are parsed as usual."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0] in ACTIONS:
            rest = super().parse_args(ctx, args[1:])
            ctx.params["action"] = args[0]
            return rest
        if any(a in ("--help", "-h") for a in args[:1]):
            return super().parse_args(ctx, args)
        raise click.UsageError(f"fivebar needs an action first: {' or '.join(ACTIONS)} "
                               f"(got {args[0]!r})" if args else
                               f"fivebar needs an action: {' or '.join(ACTIONS)}", ctx)

    def collect_usage_pieces(self, ctx: click.Context) -> list[str]:
        return ["{" + "|".join(ACTIONS) + "}", *super().collect_usage_pieces(ctx)]


#: What `fivebar` does with the document: stream it to --port, or the dry run.
ACTIONS = ("plot", "preview")


@click.command("fivebar", cls=_ActionFirst)
@port_option
@click.option("--preview", "preview_path", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("preview.png"), show_default=True,
              help="Where `preview` writes the picture (PNG); after an emulator plot, the "
              "executed path's CSV goes next to it.")
@click.option("--name", default=DEFAULT_NAME, show_default=True,
              help="The document's name in messages and in the resume file's name.")
@yes_option
@job_options()
@vpype_cli.global_processor  # type: ignore[untyped-decorator]  # vpype has no type hints
def fivebar(document: vp.Document, port: str | None, preview_path: Path, name: str,
            yes: bool, config_path: Path | None, action: str = "preview",
            **job_values: Any) -> vp.Document:
    """Plot the document on a five-bar machine (`fivebar plot --port PORT`), or write its
    dry-run report and preview picture (`fivebar preview`). Options as in `fivebar plot`.
    The document is passed on unchanged."""
    from fivebar_host.devices import register

    register()  # the emulator's and the mocks' URL schemes (fivebar-sim:// …)
    try:
        _run(document, action, port, preview_path, yes, name, config_path, job_values)
    except FivebarError as e:
        raise click.ClickException(str(e)) from e
    return document
