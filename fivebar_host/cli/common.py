"""What every `fivebar` command shares: the group, error handling, and the options.

The job options (tolerance, placement, working mode, laser …) are not declared here: they are
generated from their single definitions in `fivebar_host.options`, which the daemon's API and
its HTTP client use too. Commands receive them under their field names (`tolerance_mm`,
`origin_mm`, …) and hand them to `compile_from_cli` unchanged.

Errors: every error a user can see derives from `FivebarError`; `handle_errors` turns it into
one line on stderr and its exit status (2 bad input, 3 machine-side), and names the file of an
OS error. Nothing else is caught, so a bug still shows its traceback.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from fivebar_host import __version__
from fivebar_host.config import Profile, load_profile
from fivebar_host.controllers import DEFAULT as DEFAULT_CONTROLLER
from fivebar_host.controllers import names as controller_names
from fivebar_host.errors import FivebarError, OptionError, bounded
from fivebar_host.options import JOB_OPTIONS, Option, compile_values, parse_length, parse_page

if TYPE_CHECKING:
    from fivebar_host.run.controller import Controller

F = TypeVar("F", bound=Callable[..., Any])


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="fivebar")
@click.pass_context
def main(ctx: click.Context) -> None:
    """Drive a five-bar-linkage pen plotter or laser engraver from SVG, G-code or images."""
    from fivebar_host.controllers import ports
    from fivebar_host.devices import register

    register()  # the emulator's and the mocks' URL schemes for every command
    if not isinstance(sys.stdout, QuietPipe):
        sys.stdout = QuietPipe(sys.stdout)  # `fivebar … | head` ends quietly
    # how the lock file of a port this command opens names its holder ("fivebar plot")
    ports.set_command(f"fivebar {ctx.invoked_subcommand or ''}".strip())


class QuietPipe(io.TextIOBase):
    """Standard output that goes quiet when its reader leaves (`fivebar plot … | head`):
    the first write into a closed pipe points the descriptor at /dev/null and every later
    write is dropped, so the command finishes (a plot on a machine is not cut short by its
    output) without a traceback or an error line."""

    def __init__(self, inner: Any) -> None:
        super().__init__()
        self.inner = inner
        self.gone = False

    @property
    def encoding(self) -> str:  # type: ignore[override]
        return str(getattr(self.inner, "encoding", "utf-8"))

    def _quiet(self) -> None:
        self.gone = True
        with contextlib.suppress(OSError, ValueError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self.inner.fileno())
            os.close(devnull)

    def write(self, text: str) -> int:
        if not self.gone:
            try:
                self.inner.write(text)
            except BrokenPipeError:
                self._quiet()
        return len(text)

    def flush(self) -> None:
        if not self.gone:
            try:
                self.inner.flush()
            except BrokenPipeError:
                self._quiet()

    def isatty(self) -> bool:
        return bool(self.inner.isatty())

    def fileno(self) -> int:
        return int(self.inner.fileno())

    def writable(self) -> bool:
        return True


def fail(message: str, code: int = 2) -> None:
    """Print an error in one line on stderr and exit non-zero."""
    click.echo(f"error: {bounded(message)}", err=True)
    sys.exit(code)


def handle_errors(fn: F) -> F:
    """Turn fivebar's errors (and the OS errors of files the user named) into one message
    and the error's exit status."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except FivebarError as e:
            fail(str(e), code=e.exit_code)
        except OSError as e:
            fail(f"{getattr(e, 'filename', '') or ''}: {e.strerror or e}".lstrip(": "))
        return None

    return wrapper  # type: ignore[return-value]


def load(config_path: Path | None) -> Profile:
    """The machine profile (the bundled default without --config)."""
    return load_profile(config_path)


config_option = click.option(
    "--config", "config_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
    help="Machine profile (TOML). Default: the bundled configs/default.toml.")
port_option = click.option(
    "--port", default=None, metavar="PORT",
    help="Serial port or URL: /dev/ttyUSB0, COM3, fivebar-mock://, fivebar-sim:// (emulator).")
yes_option = click.option(
    "--yes", "-y", is_flag=True,
    help="Answer yes to 'are the arms at the home pose?' (no endstops) without asking.")


# ------------------------------------------------------------------ job options, generated
class OptionType(click.ParamType):  # type: ignore[type-arg]  # generic in click 8.2+ only
    """A click type that parses a value with its `Option` definition (same rules, same
    message as the daemon's API)."""

    def __init__(self, opt: Option) -> None:
        self.opt = opt
        self.name = opt.kind

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        if not isinstance(value, str):
            return value
        try:
            return self.opt.parse(value)
        except OptionError as e:
            self.fail(e.why, param, ctx)


class LengthType(click.ParamType):  # type: ignore[type-arg]  # generic in click 8.2+ only
    """A length in mm, read as every job option's (`options.parse_length`: 5, 5mm, 0.5in)."""

    name = "length"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> float:
        if isinstance(value, float):
            return value
        try:
            return parse_length(str(value))
        except ValueError as e:
            self.fail(str(e), param, ctx)


def click_option(opt: Option) -> Callable[[F], F]:
    """The click option generated from one job option definition."""
    if opt.kind == "bool":
        return click.option(opt.flag, opt.name, is_flag=True, help=opt.describe())
    if opt.word:  # `--hatch` alone means `--hatch pen`
        return click.option(opt.flag, opt.name, type=OptionType(opt), default=opt.default,
                            is_flag=False, flag_value=opt.word,
                            metavar=f"[{opt.metavar or 'VALUE'}]", help=opt.describe())
    return click.option(opt.flag, opt.name, type=OptionType(opt), default=opt.default,
                        multiple=opt.repeat, metavar=opt.metavar or None,
                        help=opt.describe())


def job_options(*, laser: bool = True) -> Callable[[F], F]:
    """The profile option and the job options of `fivebar_host.options` (without --laser
    for commands that never burn, such as frame)."""

    def deco(fn: F) -> F:
        for opt in reversed(JOB_OPTIONS):
            if opt.cli and (laser or opt.name != "laser"):
                fn = click_option(opt)(fn)
        return config_option(fn)

    return deco


def compile_from_cli(drawing: Path, config_path: Path | None,
                     values: dict[str, Any]) -> tuple[Profile, Any]:
    """Compile and check a drawing with the job option values a command received:
    (profile, Job). Raises the pipeline's errors."""
    from fivebar_host.cli.progress import compile_progress
    from fivebar_host.compile import CompileOptions, compile_job
    from fivebar_host.config import require_tool, with_pen_overrides
    from fivebar_host.raster.image import is_image_file

    prof = with_pen_overrides(load(config_path), values)
    require_tool(prof, bool(values.get("laser")))
    with compile_progress():  # a bar (TTY) or a line every few seconds for long compiles
        if is_image_file(drawing):
            from fivebar_host.raster.job import compile_raster, raster_options

            return prof, compile_raster(drawing, prof, raster_options(values, prof))
        if Path(drawing).suffix.lower() == ".svg":
            return prof, _compile_svg(drawing, prof, values)
        if values.get("fill") == "scan":
            from fivebar_host.raster.fill import compile_fill_scan

            return prof, compile_fill_scan(drawing, prof, values)
        return prof, compile_job(drawing, prof, CompileOptions(**compile_values(values)))


def _compile_svg(path: Path, prof: Profile, values: dict[str, Any]) -> Any:
    """An SVG's job: its `<image>` elements burned as a raster (`raster.svgimage`), its
    fills scanned (`--fill scan`), or its drawing compiled."""
    from fivebar_host.compile import CompileOptions
    from fivebar_host.compile.job import compile_drawing, read_drawing
    from fivebar_host.progress import report

    report("reading", 0.0)
    d = read_drawing(path, tuple(values.get("layers") or ()), values.get("max_segments"), prof)
    if d.images:
        from fivebar_host.raster.svgimage import compile_svg_images

        return compile_svg_images(d, prof, values, path.parent)
    if values.get("fill") == "scan":
        from fivebar_host.raster.fill import compile_fill_scan

        return compile_fill_scan(path, prof, values, d)
    return compile_drawing(d, prof, CompileOptions(**compile_values(values)), consume=True)


def pop_job_values(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Take the job option values out of a command's keyword arguments."""
    return {o.name: kwargs.pop(o.name) for o in JOB_OPTIONS if o.name in kwargs}


# ------------------------------------------------------------------ machine commands
controller_option = click.option(
    "--controller", type=click.Choice(list(controller_names())), default=DEFAULT_CONTROLLER,
    show_default=True,
    help="fivebar: fivebar's own firmware; grbl: a stock GRBL 1.1 board driven in joint "
    "space (G1 X<θA> Y<θB> in degrees; `fivebar grbl-settings` lists its $ settings).")


def machine(port: str | None, controller: str, prof: Profile) -> Controller:
    """Open the machine at --port (required for machine commands) with --controller."""
    if port is None:
        fail("give --port PORT: the machine's serial port (e.g. /dev/ttyUSB0 or COM3; "
             "`fivebar doctor` lists them), or fivebar-sim:// for the emulator")
    from fivebar_host.cli.session import open_machine

    return open_machine(controller, str(port), prof)


def page_size(text: str, landscape: bool = False) -> tuple[float, float]:
    """A page size (width, height) in mm from --page: a name (A4, letter …) or WxH with
    optional units ("200x150", "8.5inx11in"); `landscape` puts the longer side across."""
    try:
        return parse_page(text, landscape)
    except ValueError as e:
        raise click.BadParameter(str(e), param_hint="--page") from None


landscape_option = click.option(
    "--landscape", is_flag=True,
    help="Turn a --page size so that its longer side runs along x (A4 is 210x297 mm "
    "portrait, 297x210 mm landscape).")
