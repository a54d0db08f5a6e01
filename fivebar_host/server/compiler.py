"""Compiling submissions away from the process that streams to the machine.

The daemon streams a running job from its machine thread; a submission compiled in a thread
of the same process holds the interpreter lock for most of a compile (parsing, ordering,
segmenting are Python), and the streaming thread then answers the firmware too late: 5
uploads of 3 MB compiled during a 330 segments/s job made its queue run empty 20 times
(every time the arms stop dead mid-path), none without them. So each compilation runs in a
child process of its own (`multiprocessing` forkserver: the children fork from a clean
server process that imported the compiler once, never from the threaded daemon), which
sends the result back through a pipe and exits, so a big drawing's memory goes back to the
system when it is done. The daemon's compilation slots bound how many run at once; a thread
waits for each child's answer, holding no lock while it waits.

`processes=False` compiles in a thread of the daemon, as before (tests that replace the
compile function in-process use it).
"""

from __future__ import annotations

import multiprocessing
import threading
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any, TypeVar, cast

from starlette.concurrency import run_in_threadpool

from fivebar_host import progress
from fivebar_host.server.jobs import SubmitError

T = TypeVar("T")

#: Modules the forkserver imports once, so each compilation's process starts with them.
PRELOAD = ["fivebar_host.server.jobs", "fivebar_host.server.dryrun"]
_START_LOCK = threading.Lock()


def _context() -> Any:
    """The forkserver context, its preload set before the server first starts."""
    with _START_LOCK:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        return ctx


#: What a compiling process sends before its answer: a progress report.
PROGRESS = "progress"


def _child(out: Connection, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
    """A compilation's process: send its progress reports (`PROGRESS`, event) as they come,
    then (True, result) or (False, the exception)."""
    try:
        with progress.listening_with(lambda ev: out.send((PROGRESS, ev))):
            value = fn(*args)
        result: tuple[bool, Any] = (True, value)
    except BaseException as e:  # every failure goes back to the daemon
        try:
            out.send((False, e))
        except Exception:  # an exception that does not pickle
            out.send((False, SubmitError("invalid", "".join(
                traceback.format_exception_only(type(e), e)).strip(), status=500)))
        return
    out.send(result)


class Compiler:
    """Runs compile functions in child processes (or threads); see the module doc."""

    def __init__(self, processes: bool = True) -> None:
        self.processes = processes
        self._running: set[BaseProcess] = set()
        self._lock = threading.Lock()
        self._closed = False

    async def run(self, fn: Callable[..., T], *args: Any,
                  on_progress: progress.Listener | None = None) -> T:
        """`fn(*args)` in a child process (a module-level function: it is sent by name),
        or in a thread; its exception is raised here. A child that died (killed for its
        memory, say) is a `SubmitError`. Its progress reports go to `on_progress` (called
        in a worker thread)."""
        hear = on_progress or (lambda ev: None)
        if not self.processes:
            return await run_in_threadpool(_listening, hear, fn, args)
        return await run_in_threadpool(self._in_child, fn, args, hear)

    def _in_child(self, fn: Callable[..., T], args: tuple[Any, ...],
                  hear: progress.Listener) -> T:
        """Start the child, wait for its answer (in a thread: the wait holds no lock)."""
        ctx = _context()
        recv, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_child, args=(send, fn, args), daemon=True,
                           name="fivebar-compile")
        with self._lock:
            if self._closed:
                raise SubmitError("stopping", "the daemon is stopping; nothing was queued",
                                  status=503)
            proc.start()
            self._running.add(proc)
        send.close()
        try:
            while True:
                ok, value = recv.recv()
                if ok != PROGRESS:
                    break
                hear(value)
        except EOFError:
            proc.join(5.0)
            raise SubmitError("compile_failed", "the compiling process died (exit "
                              f"{proc.exitcode}; out of memory?); nothing was queued",
                              status=500) from None
        finally:
            recv.close()
            with self._lock:
                self._running.discard(proc)
        proc.join(5.0)
        if not ok:
            raise value
        return cast(T, value)

    def close(self) -> None:
        """Stop the compilations still running (their submissions are refused)."""
        with self._lock:
            self._closed = True
            running = list(self._running)
        for proc in running:
            proc.terminate()


def _listening(hear: progress.Listener, fn: Callable[..., T], args: tuple[Any, ...]) -> T:
    """`fn(*args)` with its progress reports going to `hear` (the thread mode)."""
    with progress.listening_with(hear):
        return fn(*args)
