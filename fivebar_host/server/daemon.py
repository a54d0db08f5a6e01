"""Wiring and lifecycle of `fivebar serve`: state directory, token, worker, HTTP server.

`Daemon.start()` opens the database, makes or reads the token, starts the machine thread and
serves the API from uvicorn in a second thread on a socket bound here (so port 0 works and
the bound address is known). `run_foreground()` is the `fivebar serve` command: logs to
stderr, and on SIGTERM or SIGINT stops the running job at a segment boundary with the laser
off, waits for it, then exits 0. A second signal stops at once (the machine holds inside the
segment; the resume point records the exact position either way).
"""

from __future__ import annotations

import logging
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any

import uvicorn

from fivebar_host.config import Profile, load_profile
from fivebar_host.errors import FivebarError
from fivebar_host.server.app import create_app
from fivebar_host.server.compiler import Compiler
from fivebar_host.server.connections import HEADER_TIMEOUT_S, protocol_class
from fivebar_host.server.jobs import CompiledCache
from fivebar_host.server.security import (
    BODY_GRACE_S,
    BODY_IDLE_S,
    MAX_IN_FLIGHT,
    MAX_UPLOAD_BYTES_PENDING,
    MAX_UPLOADS,
    Guard,
    Policy,
    default_state_dir,
    is_loopback,
    load_or_create_token,
)
from fivebar_host.server.state import WorkerConfig
from fivebar_host.server.store import JobStore
from fivebar_host.server.stored import StoredJobs
from fivebar_host.server.worker import Worker

log = logging.getLogger("fivebar.serve")

DEFAULT_LISTEN = "127.0.0.1:8765"
DEFAULT_MAX_UPLOAD = 8 * 1024 * 1024
#: Connections the kernel holds for the daemon before it accepts them.
LISTEN_BACKLOG = 1024


class ServeError(FivebarError, RuntimeError):
    """The daemon cannot start: bad listen address, state directory, port in use ..."""


def parse_listen(text: str) -> tuple[str, int]:
    """"HOST:PORT" (IPv6 in brackets: "[::1]:8765") → (host, port)."""
    t = text.strip()
    if t.startswith("["):
        host, _, rest = t[1:].partition("]")
        port_text = rest[1:] if rest.startswith(":") else ""
    else:
        host, _, port_text = t.rpartition(":")
    try:
        port = int(port_text)
    except ValueError:
        raise ServeError(f"--listen must look like HOST:PORT (e.g. 127.0.0.1:8765); got "
                         f"{text!r}") from None
    if not host or not 0 <= port <= 65535:
        raise ServeError(f"--listen must look like HOST:PORT with a port 0..65535; got "
                         f"{text!r}")
    return host, port


@dataclass(frozen=True)
class ServeConfig:
    """Everything `fivebar serve` can be told."""

    port_url: str
    profile_path: Path | None = None
    listen: str = DEFAULT_LISTEN
    state_dir: Path | None = None
    require_token: bool = False
    max_upload_bytes: int = DEFAULT_MAX_UPLOAD
    auto_resume: bool = False
    banner_timeout_s: float | None = None
    ready_file: Path | None = None
    access_log: bool = False
    #: Load limits (docs/serve.md, Limits): uploads in progress and requests in flight
    #: before the answer is 503 busy, and compilations at once.
    max_uploads: int = MAX_UPLOADS
    max_in_flight: int = MAX_IN_FLIGHT
    compile_slots: int = 2
    #: Slow clients (docs/serve.md, Limits): the deadline of a request's headers and the
    #: pace a body must keep (`server.connections`, `security.Guard`).
    header_timeout_s: float = HEADER_TIMEOUT_S
    body_grace_s: float = BODY_GRACE_S
    body_idle_s: float = BODY_IDLE_S
    #: Compile submissions in child processes (`server.compiler`), never in a thread of
    #: the process that streams; False: in a thread (tests that replace the compiler).
    compile_processes: bool = True


def _bind(host: str, port: int) -> socket.socket:
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                   flags=socket.AI_PASSIVE)
    except socket.gaierror as e:
        raise ServeError(f"cannot resolve listen address {host!r}: {e}") from e
    family, kind, proto, _, addr = infos[0]
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(addr)
    except OSError as e:
        sock.close()
        raise ServeError(f"cannot listen on {host}:{port}: {e.strerror or e}") from e
    sock.set_inheritable(False)
    return sock


def _base_url(bound: tuple[Any, ...]) -> str:
    """The API's base URL from a bound socket address (host, port, …)."""
    shown = f"[{bound[0]}]" if ":" in bound[0] else bound[0]
    return f"http://{shown}:{bound[1]}"


class Daemon:
    """One running daemon (machine thread + HTTP thread); see the module docstring."""

    def __init__(self, cfg: ServeConfig, profile: Profile | None = None) -> None:
        self.cfg = cfg
        self.profile = profile or load_profile(cfg.profile_path)
        self.state_dir = cfg.state_dir or default_state_dir()
        self.stopping = threading.Event()
        self.url = ""
        self.token_path: Path | None = None
        self.token: str | None = None
        self._server: uvicorn.Server | None = None
        self._thread: threading.Thread | None = None
        self.compiler: Compiler | None = None
        self.store: JobStore | None = None
        self.cache: CompiledCache | None = None
        self.worker: Worker | None = None
        self.guard: Guard | None = None  # the HTTP guard (its counters: benchmarks, tests)

    def start(self, timeout_s: float = 15.0) -> str:
        """Start everything; returns the base URL (http://host:port)."""
        from fivebar_host.devices import register

        register()  # a daemon is an entry point: the emulator's and the mocks' URL schemes
        host, port = parse_listen(self.cfg.listen)
        loopback = is_loopback(host)
        self._open_state(need_token=self.cfg.require_token or not loopback)
        sock = _bind(host, port)
        worker, server = self._machine_and_http(loopback, _base_url(sock.getsockname()))
        worker.start()
        self._thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]},
                                        name="fivebar-http", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                self.stop(hurry=True)
                raise ServeError("the HTTP server did not start")
            time.sleep(0.01)
        self._announce(sock.getsockname(), loopback)
        return self.url

    def _open_state(self, need_token: bool) -> None:
        """The state directory and the API token (made on the first start)."""
        try:
            self.state_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
        except OSError as e:
            raise ServeError(f"{self.state_dir}: cannot create the state directory: "
                             f"{e.strerror or e}") from e
        token, self.token_path, created = load_or_create_token(self.state_dir)
        if created:
            log.info("created the API token: %s (mode 0600)", self.token_path)
        self.token = token if need_token else None

    def _machine_and_http(self, loopback: bool, url: str) -> tuple[Worker, uvicorn.Server]:
        """The database, the machine thread and the HTTP server over the guarded
        application (neither started); `url` is where the API will answer."""
        self.store = JobStore(self.state_dir / "fivebar.db")
        pruned = self.store.prune()
        if pruned:
            log.info("forgot %d old finished jobs", pruned)
        ser = self.profile.serial
        self.cache = CompiledCache()
        jobs = StoredJobs(self.store, self.cache, self.profile)
        self.worker = Worker(WorkerConfig(
            port_url=self.cfg.port_url, profile=self.profile, baud=ser.baud,
            banner_timeout_s=self.cfg.banner_timeout_s or ser.banner_timeout_s,
            reply_timeout_s=ser.reply_timeout_s, auto_resume=self.cfg.auto_resume,
            port_hint=f"use `fivebar plot --server {url}` (or the page there)"),
            self.store, jobs)
        self.compiler = Compiler(self.cfg.compile_processes)
        app = create_app(store=self.store, worker=self.worker.handle, jobs=jobs,
                         profile=self.profile, stopping=self.stopping,
                         compiler=self.compiler, compile_slots=self.cfg.compile_slots)
        guarded = Guard(app, Policy(token=self.token, loopback=loopback,
                                    upload_limit=self.cfg.max_upload_bytes,
                                    max_in_flight=self.cfg.max_in_flight,
                                    max_uploads=self.cfg.max_uploads,
                                    max_upload_bytes_pending=max(
                                        MAX_UPLOAD_BYTES_PENDING,
                                        2 * self.cfg.max_upload_bytes),
                                    body_grace_s=self.cfg.body_grace_s,
                                    body_idle_s=self.cfg.body_idle_s))
        self.guard = guarded
        # No limit_concurrency: uvicorn's cap counts open connections, idle ones included,
        # and refuses with a plain-text 503 — a burst of 200 connections was refused almost
        # whole. The Guard caps requests in flight and uploads instead, answering the
        # documented JSON `busy` with Retry-After; extra connections wait in the backlog.
        # The protocol class adds a deadline for request headers and a cap on connections
        # per client address (server.connections); the Guard one for bodies.
        config = uvicorn.Config(guarded, log_config=None, access_log=self.cfg.access_log,
                                lifespan="off", limit_concurrency=None, backlog=LISTEN_BACKLOG,
                                http=protocol_class(self.cfg.header_timeout_s),
                                timeout_keep_alive=5, server_header=False,
                                h11_max_incomplete_event_size=16 * 1024)
        self._server = uvicorn.Server(config)
        return self.worker, self._server

    def _announce(self, bound: tuple[Any, ...], loopback: bool) -> None:
        """The base URL from the bound socket address (host, port, …), the log lines that
        say where and how the daemon listens, and the ready file."""
        self.url = _base_url(bound)
        log.info("listening on %s (%s); machine port %s; state %s", self.url,
                 "token required" if self.token is not None else "loopback, no token",
                 self.cfg.port_url, self.state_dir)
        if not loopback:
            log.warning("listening on a non-loopback address: every request needs the token "
                        "from %s", self.token_path)
        if self.cfg.ready_file is not None:
            tmp = self.cfg.ready_file.with_name(self.cfg.ready_file.name + ".tmp")
            tmp.write_text(self.url + "\n", encoding="utf-8")
            tmp.replace(self.cfg.ready_file)

    def alive(self) -> bool:
        """Both threads still running."""
        return bool(self._thread and self._thread.is_alive() and self.worker
                    and self.worker.is_alive())

    def stop(self, hurry: bool = False, timeout_s: float = 180.0) -> None:
        """Stop the running job (segment boundary, laser off), then the HTTP server."""
        self.stopping.set()
        if self.worker is not None:
            self.worker.handle.terminate(hurry)
            if self.worker.ident is not None:  # started
                self.worker.join(timeout_s)
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(10.0)
        if self.compiler is not None:
            self.compiler.close()
        if self.store is not None:
            self.store.close()
            self.store = None


def setup_logging(level: int = logging.INFO) -> None:
    """Log lines to stderr (journald adds the time stamps under systemd)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)


def run_foreground(cfg: ServeConfig) -> int:
    """`fivebar serve`: run until SIGTERM/SIGINT, then stop cleanly; the exit status."""
    setup_logging()
    daemon = Daemon(cfg)
    signals: list[int] = []
    wake = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        signals.append(signum)
        wake.set()
        if len(signals) > 1 and daemon.worker is not None:
            daemon.worker.handle.terminate(hurry=True)

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        daemon.start()
        while not wake.wait(0.5):
            if not daemon.alive():
                log.error("a daemon thread stopped unexpectedly; exiting")
                daemon.stop(hurry=True)
                return 1
        log.info("%s: stopping (the running job stops at a segment boundary, laser off)",
                 signal.Signals(signals[0]).name)
        stopper = threading.Thread(target=daemon.stop, kwargs={"hurry": len(signals) > 1},
                                   daemon=True)
        stopper.start()
        while stopper.is_alive():
            stopper.join(0.2)
        log.info("stopped")
        return 0
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
