"""The `fivebar` command line: thin click wrappers over the pipeline modules.

Only this module imports click. Each command parses units at the edge, calls pure functions and
turns their errors into a one-line message and a non-zero exit.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Any, TypeVar

import click
import numpy as np

from fivebar_host import __version__
from fivebar_host.config import ConfigError, Profile, describe, load_profile
from kinematics.fivebar import KinematicsError

F = TypeVar("F", bound=Callable[..., Any])

config_option = click.option(
    "--config", "config_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
    help="Machine profile (TOML). Default: the bundled configs/default.toml.")


def _fail(message: str, code: int = 2) -> None:
    """Print an error in one line on stderr and exit non-zero."""
    click.echo(f"error: {message}", err=True)
    sys.exit(code)


def handle_errors(fn: F) -> F:
    """Turn the project's documented errors into clean messages with exit status 2."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (ConfigError, KinematicsError) as e:
            _fail(str(e))
        return None

    return wrapper  # type: ignore[return-value]


def _profile(config_path: Path | None) -> Profile:
    return load_profile(config_path)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="fivebar")
def main() -> None:
    """Drive a five-bar-linkage pen plotter or laser engraver from SVG or G-code."""


@main.group()
def config() -> None:
    """Machine profiles."""


@config.command("check")
@click.argument("path", type=click.Path(dir_okay=False, path_type=Path))
@handle_errors
def config_check(path: Path) -> None:
    """Parse and validate the profile PATH; print it, or the error naming the key."""
    click.echo(describe(load_profile(path)))


@main.command("ik")
@click.argument("x_mm", type=float)
@click.argument("y_mm", type=float)
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--"]), default=None,
              help="Working mode (default: the profile's).")
@config_option
@handle_errors
def ik(x_mm: float, y_mm: float, mode: str | None, config_path: Path | None) -> None:
    """Motor angles (and steps from home) that put the pen at X_MM, Y_MM."""
    prof = _profile(config_path)
    fb = prof.geometry
    m = mode or (prof.kinematics.working_mode if prof.kinematics.working_mode != "auto"
                 else "+-")
    th = np.asarray(fb.inverse((x_mm, y_mm), m))
    margins = fb.singularity_margins(th, (x_mm, y_mm))[0]
    mu = fb.transmission_angles(th, (x_mm, y_mm))[0]
    steps = [round((th[i] - prof.motors.home_rad[i]) / prof.motors.rad_per_step)
             for i in range(2)]
    click.echo(f"mode {m}: θ1 = {math.degrees(th[0]):.6f}°, θ2 = {math.degrees(th[1]):.6f}°")
    click.echo(f"steps from home: A = {steps[0]}, B = {steps[1]}")
    click.echo(f"transmission angles: μ1 = {math.degrees(mu[0]):.3f}°, "
               f"μ2 = {math.degrees(mu[1]):.3f}°")
    click.echo("singularity margins: type 1 arm 1 = {:.3f}°, arm 2 = {:.3f}°, type 2 = {:.3f}°"
               .format(*np.degrees(margins)))


@main.command("fk")
@click.argument("theta1_deg", type=float)
@click.argument("theta2_deg", type=float)
@click.option("--assembly", type=click.Choice(["+", "-"]), default=None,
              help="Assembly mode: '+' puts P left of R1→R2 (default: the profile's).")
@config_option
@handle_errors
def fk(theta1_deg: float, theta2_deg: float, assembly: str | None,
       config_path: Path | None) -> None:
    """Pen position for motor angles THETA1_DEG, THETA2_DEG (from +x, counter-clockwise)."""
    prof = _profile(config_path)
    fb = prof.geometry
    assembly = assembly or prof.kinematics.assembly
    th = np.radians([theta1_deg, theta2_deg])
    p = np.asarray(fb.forward(th, assembly))
    modes = fb.mode_of(p, th)[0]
    mode = "".join("+" if s > 0 else "-" if s < 0 else "0" for s in modes)
    click.echo(f"P = ({p[0]:.6f}, {p[1]:.6f}) mm  (assembly {assembly}, working mode {mode})")


# --------------------------------------------------------------------- jobs: convert, plot
def _xy(text: str | None) -> tuple[float, float] | None:
    """Parse "X,Y" (mm) for --origin."""
    if text is None:
        return None
    parts = text.replace(" ", "").split(",")
    try:
        x, y = (float(v) for v in parts)
    except ValueError:
        raise click.BadParameter(f"must look like X,Y in mm (e.g. 10,95); got {text!r}",
                                 param_hint="--origin") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise click.BadParameter(f"must be finite; got {text!r}", param_hint="--origin")
    return x, y


laser_option = click.option(
    "--laser", is_flag=True,
    help="Laser job: drawing segments carry the profile's power (S > 0). Without it every "
    "line says S0 (pen plotter: pen down/up = M3/M5 around drawing strokes).")


def job_options(fn: F) -> F:
    """The options that choose how a drawing becomes a job (shared by convert and plot)."""
    opts = [
        config_option,
        click.option("--mode", type=click.Choice(["++", "+-", "-+", "--", "auto"]),
                     default=None, help="Working mode; auto tries all four and picks one "
                     "that clears every check (default: the profile's)."),
        click.option("--tolerance", type=click.FloatRange(min=1e-4, max=10.0), default=None,
                     help="Largest deviation of the drawn path, mm (default: the profile's)."),
        click.option("--origin", "origin_text", default=None, metavar="X,Y",
                     help="Put the drawing's origin (SVG: page bottom-left) at machine X,Y mm "
                     "(default: centred in the largest safe rectangle)."),
        click.option("--scale", type=float, default=None, help="Scale factor (default 1)."),
        click.option("--rotate", "rotate_deg", type=float, default=0.0,
                     help="Rotate the drawing, degrees counter-clockwise."),
        click.option("--fit", is_flag=True, help="Scale the drawing to fill the largest "
                     "singularity-safe rectangle of the working mode."),
        click.option("--layer", "layers", multiple=True, metavar="NAME",
                     help="Only this Inkscape layer (label or id); repeatable."),
        click.option("--keep-order", is_flag=True,
                     help="Draw paths in file order (no reordering to cut travel)."),
    ]
    for o in reversed(opts):
        fn = o(fn)
    return fn


def compile_from_cli(drawing: Path, config_path: Path | None, mode: str | None,
                     tolerance: float | None, origin_text: str | None, scale: float | None,
                     rotate_deg: float, fit: bool, layers: tuple[str, ...],
                     keep_order: bool) -> tuple[Profile, Any]:
    """Compile and check a drawing from `job_options` values: (profile, Job). Raises the
    pipeline's errors (`InputError`, `JobError`, `ConfigError`, `ValueError`)."""
    from fivebar_host.compile import CompileOptions, compile_job

    prof = _profile(config_path)
    opts = CompileOptions(mode=mode, tolerance_mm=tolerance, origin_mm=_xy(origin_text),
                          scale=scale, rotate_deg=rotate_deg, fit=fit, layers=tuple(layers),
                          keep_order=keep_order)
    return prof, compile_job(drawing, prof, opts)


def handle_job_errors(fn: F) -> F:
    """Like `handle_errors`, also for drawing and job errors (exit status 2, one message)."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (ConfigError, KinematicsError, ValueError) as e:
            _fail(str(e))
        except OSError as e:
            _fail(f"{getattr(e, 'filename', '') or ''}: {e.strerror or e}".lstrip(": "))
        return None

    return wrapper  # type: ignore[return-value]


# --------------------------------------------------------------------- issue 9: --server
def server_option(fn: F) -> F:
    """Add `--server URL` and `--token` to `plot`: the drawing goes to a running `fivebar
    serve`, which compiles, checks, queues and runs it; the command follows it with the same
    progress bar. The plot function itself is untouched: without --server the wrapper calls
    it unchanged; with it, `_plot_via_server` gets the same option values."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        server = kwargs.pop("server", None)
        token = kwargs.pop("token", None)
        if server is None:
            return fn(*args, **kwargs)
        return _plot_via_server(server, token, kwargs)

    wrapper = click.option(
        "--token", default=None, metavar="TOKEN", envvar="FIVEBAR_TOKEN",
        help="The daemon's token (needed when it listens on a non-loopback address). "
        "Default: $FIVEBAR_TOKEN, else the local daemon's token file.")(wrapper)
    wrapper = click.option(
        "--server", default=None, metavar="URL",
        help="Send the drawing to a running `fivebar serve` at URL (http://HOST:PORT) and "
        "follow it there, instead of opening --port.")(wrapper)
    return wrapper  # type: ignore[return-value]


def _plot_via_server(server: str, token: str | None, kw: dict[str, Any]) -> None:
    """`plot --server`: submit, then follow the job's progress until it is over.

    Ctrl-C pauses the job on the daemon (held, laser off) and asks to resume or abort (no
    terminal: abort cancels it). A question of the daemon (are the arms at the home pose?)
    is asked here; --yes answers it in advance."""
    import signal

    from fivebar_host.server.client import (
        ServerClient,
        ServerError,
        default_token,
        follow,
        plot_options,
    )

    given = [flag for flag, key in (("--port", "port"), ("--dry-run", "dry_run"),
                                    ("--resume", "resume"), ("--config", "config_path"))
             if kw.get(key)]
    if given:
        _fail(f"--server hands the drawing to the daemon, which has its own port and profile "
              f"(fivebar serve --port/--config) and resumes its own jobs; drop "
              f"{', '.join(given)}")
    drawing = Path(kw["drawing"])
    try:
        data = drawing.read_bytes()
    except OSError as e:
        _fail(f"{drawing}: {e.strerror or e}")
        return
    yes = bool(kw.get("yes", False))
    try:
        client = ServerClient(server, token or default_token())
        job = client.submit(data, drawing.name, plot_options(
            laser=bool(kw.get("laser", False)), mode=kw.get("mode"),
            tolerance=kw.get("tolerance"), origin=_xy(kw.get("origin_text")),
            scale=kw.get("scale"), rotate_deg=float(kw.get("rotate_deg", 0.0)),
            fit=bool(kw.get("fit", False)), layers=tuple(kw.get("layers", ())),
            keep_order=bool(kw.get("keep_order", False)), confirm=yes))
    except ServerError as e:
        _fail(str(e), code=2 if e.status in (400, 413, 415, 422) else 3)
        return
    jid = int(job["id"])
    click.echo(f"job {jid} queued on {client.base}: {job['segments_total']} segments, mode "
               f"{job['mode']}, ≈ {job['estimated_s']:.1f} s"
               + (f", max deviation {job['max_dev_mm']:.4f} mm" if job["max_dev_mm"] else ""))
    interrupted = {"flag": False}

    def on_sigint(signum: int, frame: Any) -> None:
        interrupted["flag"] = True

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        with click.progressbar(length=int(job["segments_total"]), label="plotting",
                               show_eta=False, show_percent=True,
                               item_show_func=lambda s: s) as bar:
            state = {"done": 0}

            def on_update(j: dict[str, Any]) -> None:
                done = int(j["segments_done"])
                if done > state["done"] or j["state"] != "running":
                    bar.update(max(0, done - state["done"]),
                               f"segment {done}/{j['segments_total']}, "
                               f"{j['elapsed_s']:.0f} s elapsed, "
                               f"≈ {j['remaining_s'] or 0:.0f} s left"
                               + ("" if j["state"] == "running" else f" ({j['state']})"))
                    state["done"] = max(state["done"], done)

            while True:
                job = follow(client, jid, on_update, should_stop=lambda: interrupted["flag"])
                if interrupted["flag"]:
                    interrupted["flag"] = False
                    if job["state"] in ("queued", "running"):
                        job = client.pause(jid) if job["state"] == "running" else job
                        click.echo("\npaused on the daemon: held, laser off.", err=True)
                    choice = click.prompt("resume or abort?",
                                          type=click.Choice(["resume", "abort"]),
                                          default="abort", err=True) \
                        if sys.stdin.isatty() else "abort"
                    if choice == "abort":
                        client.cancel(jid)
                    elif client.job(jid)["state"] in ("paused", "held"):
                        client.resume(jid)
                    continue
                if job["state"] == "held" and sys.stdin.isatty():
                    if job.get("question"):
                        if click.confirm(f"\n{job['question']}", default=False, err=True):
                            client.resume(jid, confirm=True)
                            continue
                    else:
                        click.echo(f"\nheld: {job['message']}", err=True)
                        choice = click.prompt("resume, abort or leave it held?",
                                              type=click.Choice(["resume", "abort", "leave"]),
                                              default="leave", err=True)
                        if choice == "resume":
                            client.resume(jid)
                            continue
                        if choice == "abort":
                            client.cancel(jid)
                            continue
                break
    except ServerError as e:
        _fail(str(e), code=3)
        return
    finally:
        signal.signal(signal.SIGINT, previous)
    if job["state"] != "done":
        _fail(f"job {jid} {job['state']}: {job['message']}", code=3)
    click.echo(str(job["message"]))


@main.command("convert")
@click.argument("drawing", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="Where to write the firmware lines.")
@click.option("--relative", is_flag=True,
              help="Relative step moves (G91) instead of absolute targets (G90).")
@laser_option
@job_options
@handle_job_errors
def convert(drawing: Path, output: Path, relative: bool, laser: bool,
            config_path: Path | None, mode: str | None, tolerance: float | None,
            origin_text: str | None, scale: float | None, rotate_deg: float, fit: bool,
            layers: tuple[str, ...], keep_order: bool) -> None:
    """Compile DRAWING (SVG or G-code) into firmware-ready step lines (G1 A B P S).

    Without --laser the job is a pen plot: S0 on every line."""
    from fivebar_host.compile import encode_lines, write_atomic

    prof, job = compile_from_cli(drawing, config_path, mode, tolerance, origin_text, scale,
                                 rotate_deg, fit, layers, keep_order)
    lines = encode_lines(job, prof, relative=relative, laser=laser)
    write_atomic(output, "\n".join(lines) + "\n")
    tool = (f"laser (power up to S{int(job.power.max(initial=0))})" if laser
            else "pen (S0, no laser power)")
    from fivebar_host.compile import mode_sequence

    changes = f" ({len(job.mode_changes)} pen-up mode changes)" if job.mode_changes else ""
    click.echo(f"wrote {output}: {job.n_segments} segments, mode {mode_sequence(job)}{changes}, "
               f"{tool}, "
               f"≈ {job.total_time_s:.1f} s, max deviation {job.max_dev_mm:.4f} mm")


port_option = click.option(
    "--port", default=None, metavar="PORT",
    help="Serial port or URL: /dev/ttyUSB0, COM3, fivebar-mock://, fivebar-sim:// (emulator).")
yes_option = click.option(
    "--yes", "-y", is_flag=True,
    help="Answer yes to 'are the arms at the home pose?' (no endstops) without asking.")


def handle_link_errors(fn: F) -> F:
    """Machine-side failures (link, firmware, faults): one message, exit status 3."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from fivebar_host.link import LinkError

        try:
            return fn(*args, **kwargs)
        except LinkError as e:
            _fail(str(e), code=3)
        return None

    return wrapper  # type: ignore[return-value]


def _confirm(yes: bool) -> Callable[[str], bool]:
    """A yes/no question for the sender: --yes answers it; otherwise ask on the terminal."""

    def ask(question: str) -> bool:
        if yes:
            click.echo(f"{question} yes (--yes)")
            return True
        if not sys.stdin.isatty():
            click.echo(f"{question} (no terminal to ask: pass --yes)", err=True)
            return False
        return click.confirm(question, default=False)

    return ask


def _open_link(port: str, prof: Profile) -> Any:
    from fivebar_host.link import Link

    return Link.open(port, baud=prof.serial.baud,
                     banner_timeout_s=prof.serial.banner_timeout_s,
                     reply_timeout_s=prof.serial.reply_timeout_s)


@main.command("plot")
@click.argument("drawing", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--dry-run", is_flag=True,
              help="Run everything except the serial link: preview picture and report.")
@click.option("--preview", "preview_path", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("preview.png"), show_default=True, help="Dry-run picture (PNG).")
@server_option
@port_option
@click.option("--resume", is_flag=True,
              help="Continue an interrupted plot from its resume file (same drawing and options).")
@yes_option
@laser_option
@job_options
@handle_link_errors
@handle_job_errors
def plot(drawing: Path, dry_run: bool, preview_path: Path, port: str | None, resume: bool,
         yes: bool, laser: bool, config_path: Path | None, mode: str | None,
         tolerance: float | None, origin_text: str | None, scale: float | None,
         rotate_deg: float, fit: bool, layers: tuple[str, ...], keep_order: bool) -> None:
    """Compile and check DRAWING, then plot it on the machine at --port (or --dry-run).

    Everything is checked before anything moves. Ctrl-C holds the machine at once (laser
    off) and asks whether to resume or abort; a fault or an abort leaves a resume file, and
    the same command with --resume continues exactly where the machine stopped.
    """
    if not dry_run and port is None:
        _fail("give --port PORT to plot on a machine (e.g. /dev/ttyUSB0 or fivebar-sim:// "
              "for the emulator), or --dry-run for the preview and report")
    from fivebar_host.compile import nbar_opinion
    from fivebar_host.preview import draw_preview, report_lines

    prof, job = compile_from_cli(drawing, config_path, mode, tolerance, origin_text, scale,
                                 rotate_deg, fit, layers, keep_order)
    if dry_run:
        for line in report_lines(job, nbar_opinion(job, prof), laser=laser):
            click.echo(line)
        draw_preview(job, prof, preview_path)
        click.echo(f"preview       {preview_path}")
        return
    assert port is not None
    _stream_plot(drawing, port, prof, job, laser=laser, resume=resume, yes=yes,
                 preview_path=preview_path)


def _stream_plot(drawing: Path, port: str, prof: Profile, job: Any, *, laser: bool,
                 resume: bool, yes: bool, preview_path: Path) -> None:
    """Stream a compiled job with a progress bar, Ctrl-C hold/resume/abort, final report."""
    import signal

    from fivebar_host.sender import Progress, run_job

    click.echo(f"job: {job.n_segments} segments, {job.n_paths} paths, mode {job.mode}, "
               f"≈ {job.total_time_s:.1f} s, max deviation {job.max_dev_mm:.4f} mm")
    if not laser:
        click.echo("laser/pen power output stays at 0 (pen plot: M3/M5 lift the pen); "
                   "pass --laser to burn")
    interrupted = {"flag": False}

    def on_sigint(signum: int, frame: Any) -> None:
        interrupted["flag"] = True

    def on_interrupt() -> bool:
        interrupted["flag"] = False
        click.echo("\nheld: motion stopped, laser off.", err=True)
        choice = click.prompt("resume or abort?", type=click.Choice(["resume", "abort"]),
                              default="abort", err=True) if sys.stdin.isatty() else "abort"
        return bool(choice == "resume")

    link = _open_link(port, prof)
    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        with click.progressbar(length=job.n_segments, label="plotting",
                               show_eta=False, show_percent=True,
                               item_show_func=lambda s: s) as bar:
            state = {"done": 0}

            def on_progress(p: Progress) -> None:
                if p.segments_done > state["done"]:
                    bar.update(p.segments_done - state["done"],
                               f"segment {p.segments_done}/{p.segments_total}, "
                               f"{p.elapsed_s:.0f} s elapsed, ≈ {p.remaining_s:.0f} s left")
                    state["done"] = p.segments_done

            report = run_job(link, job, prof, drawing=drawing, laser=laser,
                             confirm=_confirm(yes), resume=resume, on_progress=on_progress,
                             should_stop=lambda: interrupted["flag"],
                             on_interrupt=on_interrupt, on_note=click.echo)
    finally:
        signal.signal(signal.SIGINT, previous)
        link.close()
    click.echo(f"done: {report.segments} segments in {report.elapsed_s:.1f} s "
               f"(planned {job.total_time_s:.1f} s), {report.bytes_sent} bytes sent, "
               f"{report.resends} resends; machine at A = {report.final.a}, "
               f"B = {report.final.b}")
    trace = getattr(link.port, "trace_path", None)
    if trace is not None and Path(trace).exists():
        _write_executed(job, prof, Path(trace), preview_path, report.start_segment)


def _write_executed(job: Any, prof: Profile, trace: Path, preview_path: Path,
                    first_segment: int) -> None:
    """After an emulator run: the executed path from the recorded pulses, next to the
    preview (CSV of pen points and their deviation), and its largest deviation."""
    from fivebar_host.compile import write_atomic
    from fivebar_host.devices.simtrace import read_trace
    from fivebar_host.executed import executed_path, merge_axes

    tr = read_trace(trace)
    t, track = merge_axes(tr.positions("A"), tr.positions("B"))
    ex = executed_path(job, prof, t / tr.freq, track, first_segment)
    out = preview_path.with_name(preview_path.stem + ".executed.csv")
    rows = ["t_s,a_steps,b_steps,x_mm,y_mm,segment,deviation_mm"]
    rows += [f"{ti:.6f},{a},{b},{x:.4f},{y:.4f},{sg},{'' if d != d else f'{d:.5f}'}"
             for ti, (a, b), (x, y), sg, d in zip(t / tr.freq, track.tolist(),
                                                  ex.points.tolist(), ex.segment.tolist(),
                                                  ex.deviation_mm.tolist(), strict=True)]
    write_atomic(out, "\n".join(rows) + "\n")
    click.echo(f"executed path (from the emulator's step pulses): {out}; max deviation "
               f"{ex.max_deviation_mm:.4f} mm (bound {job.tolerance_mm:g} + step quantum "
               f"{job.step_quantum_mm:.4f} mm)")


@main.command("home")
@port_option
@yes_option
@config_option
@handle_link_errors
@handle_errors
def home_cmd(port: str | None, yes: bool, config_path: Path | None) -> None:
    """Give the firmware a known position: $H with endstops, else confirm the home pose."""
    from fivebar_host.sender import home

    if port is None:
        _fail("give --port PORT")
    prof = _profile(config_path)
    link = _open_link(str(port), prof)
    try:
        st = home(link, prof, _confirm(yes))
    finally:
        link.close()
    click.echo(f"homed: A = {st.a}, B = {st.b} steps")


@main.command("jog")
@port_option
@click.option("--motor", type=click.Choice(["A", "B"]), default=None,
              help="Move one motor (with --steps).")
@click.option("--steps", type=int, default=0, help="Steps for --motor (signed).")
@click.option("--dx", type=float, default=0.0, help="Move the pen by this much in x, mm.")
@click.option("--dy", type=float, default=0.0, help="Move the pen by this much in y, mm.")
@yes_option
@config_option
@handle_link_errors
@handle_errors
def jog(port: str | None, motor: str | None, steps: int, dx: float, dy: float, yes: bool,
        config_path: Path | None) -> None:
    """Move one motor by --steps, or the pen by --dx/--dy mm (laser off).

    A pen move needs a known position (homed) and is checked; a motor move before homing
    (to bring the arms to the home pose) is not checked, and says so."""
    from fivebar_host.sender import ensure_known_pose, jog_lines

    if port is None:
        _fail("give --port PORT")
    if (motor is None) == (dx == 0.0 and dy == 0.0):
        _fail("give either --motor with --steps, or --dx/--dy")
    prof = _profile(config_path)
    kin = prof.kinematics
    mode = kin.working_mode if kin.working_mode != "auto" else "+-"
    link = _open_link(str(port), prof)
    try:
        st = link.status()
        checked = st.homed or motor is None
        if checked:
            st = ensure_known_pose(link, prof, _confirm(yes))
        else:
            click.echo("position unknown (not homed): the motor move is not checked against "
                       "limits or singularities", err=True)
        lines = jog_lines(prof, 1 if kin.assembly == "+" else -1, mode, (st.a, st.b),
                          motor=motor, steps=steps, dxy_mm=None if motor else (dx, dy),
                          checked=checked)
        link.stream(lines)
        st = link.wait_idle(60.0)
    finally:
        link.close()
    click.echo(f"at A = {st.a}, B = {st.b} steps")


@main.command("frame")
@click.argument("drawing", type=click.Path(dir_okay=False, path_type=Path))
@port_option
@yes_option
@job_options
@handle_link_errors
@handle_job_errors
def frame(drawing: Path, port: str | None, yes: bool, config_path: Path | None,
          mode: str | None, tolerance: float | None, origin_text: str | None,
          scale: float | None, rotate_deg: float, fit: bool, layers: tuple[str, ...],
          keep_order: bool) -> None:
    """Trace the outline (bounding box) of DRAWING's job with the laser off, then go home."""
    from fivebar_host.sender import ensure_known_pose, frame_program

    if port is None:
        _fail("give --port PORT")
    prof, job = compile_from_cli(drawing, config_path, mode, tolerance, origin_text, scale,
                                 rotate_deg, fit, layers, keep_order)
    link = _open_link(str(port), prof)
    try:
        st = ensure_known_pose(link, prof, _confirm(yes))
        prog = frame_program(job, prof, (st.a, st.b))
        link.stream(prog.bodies)
        st = link.wait_idle(120.0)
    finally:
        link.close()
    x0, y0, x1, y1 = job.placement.machine_bbox
    click.echo(f"framed ({x0:.1f}, {y0:.1f})–({x1:.1f}, {y1:.1f}) mm; back at A = {st.a}, "
               f"B = {st.b}")


# --------------------------------------------------------------------- workspace and design
def _page_size(text: str) -> tuple[float, float]:
    """Parse a page size "WxH" in mm (also "W×H"), e.g. "200x150"."""
    parts = text.lower().replace("×", "x").split("x")
    try:
        w, h = (float(v) for v in parts)
    except ValueError:
        raise click.BadParameter(f"page size must look like 200x150 (mm); got {text!r}") from None
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        raise click.BadParameter(f"page size must be positive; got {text!r}")
    return w, h


@main.command("workspace")
@config_option
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("workspace.png"), show_default=True, help="Picture (PNG).")
@click.option("--no-plot", is_flag=True, help="Print the figures only, draw nothing.")
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--", "auto"]), default=None,
              help="Working mode to analyse in detail (default: the profile's).")
@click.option("--page", "page_text", default=None, metavar="WxH",
              help="Also check that a page of W x H mm fits (exit status 1 if not).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Per-grid-point numbers (CSV).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="The printed figures as JSON.")
@click.option("--resolution", type=click.FloatRange(min=0.01), default=None,
              help="Grid pitch in mm (default: ~400 cells across the workspace).")
@click.option("--delta-deg", type=click.FloatRange(min=0.0, min_open=True, max=45.0),
              default=5.0, show_default=True,
              help="Motor error for the ±δ sensitivity traces (thesis Sec. 4.1).")
@handle_errors
def workspace(config_path: Path | None, output: Path, no_plot: bool, mode: str | None,
              page_text: str | None, csv_path: Path | None, json_path: Path | None,
              resolution: float | None, delta_deg: float) -> None:
    """Workspace per working mode, singularity curves, safe region, largest page rectangle,
    transmission-angle and error-sensitivity maps for the machine profile."""
    from fivebar_host import workspace as ws
    from kinematics.analysis import NoSafeRegionError, workspace_report

    prof = _profile(config_path)
    page = _page_size(page_text) if page_text is not None else None
    kin = prof.kinematics
    try:
        rep = workspace_report(
            prof.geometry, mode or kin.working_mode, kin.min_type1_margin_rad,
            kin.min_type2_margin_rad, prof.motors.limits_rad, prof.motors.rad_per_step,
            delta_rad=math.radians(delta_deg), resolution_mm=resolution, page=page,
            assembly=kin.assembly)
    except NoSafeRegionError as e:
        _fail(str(e))
        return
    for line in ws.summary_lines(rep, prof.geometry):
        click.echo(line)
    if csv_path is not None:
        n = ws.write_csv(csv_path, rep)
        click.echo(f"wrote {csv_path} ({n} grid points)")
    if json_path is not None:
        ws.write_json(json_path, ws.summary_dict(rep, prof.geometry))
        click.echo(f"wrote {json_path}")
    if not no_plot:
        ws.plot_workspace(rep, prof.geometry, output, title=str(prof.source))
        click.echo(f"wrote {output}")
    if page is not None and rep.page is None:
        sys.exit(1)


@main.command("design")
@click.option("--page", "page_text", required=True, metavar="WxH",
              help="Page size in mm that must fit inside the safe workspace, e.g. 200x150.")
@click.option("--margin-deg", type=click.FloatRange(min=0.0, max=89.0), default=None,
              help="Minimum margin to both singularity types (default: the profile's).")
@click.option("--motor-spacing", default=None, metavar="W|LO:HI",
              help="Fix the motor spacing w (mm) or search it in LO:HI (default: searched).")
@click.option("--mode", type=click.Choice(["++", "+-", "-+", "--"]), default=None,
              help="Working mode (default: the profile's; '+-' if it says auto).")
@click.option("--candidates", type=click.IntRange(min=1, max=1_000_000), default=10_000,
              show_default=True, help="Random candidate designs to evaluate.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option("--top", type=click.IntRange(min=1, max=50), default=5, show_default=True,
              help="How many verified candidates to list.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("design.toml"), show_default=True,
              help="Profile (TOML) written for the best candidate.")
@config_option
@handle_errors
def design(page_text: str, margin_deg: float | None, motor_spacing: str | None,
           mode: str | None, candidates: int, seed: int, top: int, output: Path,
           config_path: Path | None) -> None:
    """Search link lengths (a1, b1, a2, b2, w) whose safe workspace holds the page, ranked by
    worst transmission angle and worst error sensitivity over it; write the best as a profile
    (motors, motion, laser and serial settings are copied from --config)."""
    import time

    from fivebar_host import workspace as ws
    from kinematics.analysis import design_search

    prof = _profile(config_path)
    pw, ph = _page_size(page_text)
    spacing: float | tuple[float, float] | None = None
    if motor_spacing is not None:
        try:
            vals = [float(v) for v in motor_spacing.split(":")]
        except ValueError:
            raise click.BadParameter(f"--motor-spacing must be W or LO:HI in mm; got "
                                     f"{motor_spacing!r}") from None
        if len(vals) not in (1, 2) or not all(math.isfinite(v) and v > 0 for v in vals) or (
                len(vals) == 2 and vals[0] >= vals[1]):
            raise click.BadParameter(f"--motor-spacing must be W or LO:HI (LO < HI, positive); "
                                     f"got {motor_spacing!r}")
        spacing = vals[0] if len(vals) == 1 else (vals[0], vals[1])
    kin = prof.kinematics
    m = mode or (kin.working_mode if kin.working_mode != "auto" else "+-")
    min1 = math.radians(margin_deg) if margin_deg is not None else kin.min_type1_margin_rad
    min2 = math.radians(margin_deg) if margin_deg is not None else kin.min_type2_margin_rad
    t0 = time.perf_counter()
    res = design_search(pw, ph, m, min1, min2, prof.motors.limits_rad, prof.motors.rad_per_step,
                        n_candidates=candidates, motor_spacing=spacing, seed=seed, top=top)
    seconds = time.perf_counter() - t0
    for line in ws.design_lines(res, seconds):
        click.echo(line)
    if not res.candidates:
        _fail(f"no design among {candidates} candidates fits a {pw:g} x {ph:g} mm page in mode "
              f"{m} with these margins and joint limits; try more --candidates, a smaller "
              "page, smaller --margin-deg or another --motor-spacing", code=1)
        return
    best = res.candidates[0]
    text = ws.design_profile_text(Path(prof.source).read_text(encoding="utf-8"), prof.source,
                                  best, min1, min2)
    output.write_text(text, encoding="utf-8")
    click.echo(f"wrote {output} (rank 1); check it with: fivebar workspace --config {output} "
               f"--page {pw:g}x{ph:g}")


@main.group()
def linkage() -> None:
    """General linkages through the n-bar solver (mechanism files: docs/mechanisms.md)."""


@linkage.command("simulate")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--steps", type=click.IntRange(min=1), default=None,
              help="Input steps to take (default: the file's [simulation] steps).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write every step (inputs, joints, residual, status) to a .csv or .json.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Draw the mechanism and the tracer curve (.png, .svg, .pdf).")
def linkage_simulate(file: Path, steps: int | None, output: Path | None,
                     plot_path: Path | None) -> None:
    """Simulate the mechanism FILE from its initial pose in equal input steps.

    Prints a summary; a motion limit is reported with its input value (exit 0), inconsistent
    constraints (nothing could move) exit with 1, an unusable file with 2.
    """
    from fivebar_host.linkage import load_mechanism, plot_simulation, summary, write_result
    from kinematics.nbar import MechanismError, sweep

    if output is not None and output.suffix.lower() not in (".csv", ".json"):
        _fail(f"{output}: -o must end in .csv or .json")
        return
    try:
        mech = load_mechanism(file)
    except MechanismError as e:
        _fail(str(e))
        return
    sim = sweep(mech, steps)
    click.echo(summary(sim))
    if output is not None:
        click.echo(f"wrote {write_result(sim, output)}")
    if plot_path is not None:
        click.echo(f"wrote {plot_simulation(sim, plot_path)}")
    if any(lim.kind == "inconsistent" for lim in sim.limits):
        sys.exit(1)


# --------------------------------------------------------------------- issue 9: the daemon
@main.command("serve")
@click.option("--port", "port_url", required=True, metavar="PORT",
              help="The machine's serial port or URL (as for plot --port).")
@config_option
@click.option("--listen", default="127.0.0.1:8765", show_default=True, metavar="HOST:PORT",
              help="Address of the HTTP API. Any non-loopback address requires the token on "
              "every request.")
@click.option("--state-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Database and token (default: $STATE_DIRECTORY, else "
              "~/.local/state/fivebar).")
@click.option("--require-token", is_flag=True,
              help="Require the token on loopback too (a computer shared by several users).")
@click.option("--max-upload-mb", type=click.FloatRange(min=0.001, max=1024.0), default=8.0,
              show_default=True, help="Largest accepted drawing upload.")
@click.option("--auto-resume", is_flag=True,
              help="On start, continue held jobs that have a resume point (after a stop, a "
              "crash or a fault) without waiting for a resume request.")
@click.option("--banner-timeout", type=click.FloatRange(min=0.1, max=60.0), default=None,
              help="Seconds to wait for the firmware's banner (default: the profile's).")
@click.option("--access-log", is_flag=True, help="Log every HTTP request.")
@click.option("--ready-file", type=click.Path(dir_okay=False, path_type=Path), default=None,
              hidden=True)
def serve(port_url: str, config_path: Path | None, listen: str, state_dir: Path | None,
          require_token: bool, max_upload_mb: float, auto_resume: bool,
          banner_timeout: float | None, access_log: bool, ready_file: Path | None) -> None:
    """Run the plotter daemon in the foreground: own the machine's port, queue and run jobs,
    serve the HTTP + JSON API (docs/serve.md). Logs go to stderr; SIGTERM stops the running
    job at a segment boundary with the laser off, then exits."""
    from fivebar_host.server.daemon import ServeConfig, ServeError, run_foreground
    from fivebar_host.server.security import SecurityError
    from fivebar_host.server.store import StoreError

    cfg = ServeConfig(port_url=port_url, profile_path=config_path, listen=listen,
                      state_dir=state_dir, require_token=require_token,
                      max_upload_bytes=int(max_upload_mb * 1024 * 1024),
                      auto_resume=auto_resume, banner_timeout_s=banner_timeout,
                      ready_file=ready_file, access_log=access_log)
    try:
        code = run_foreground(cfg)
    except (ServeError, SecurityError, StoreError, ConfigError) as e:
        _fail(str(e))
        return
    sys.exit(code)
