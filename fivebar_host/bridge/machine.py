"""The machine side of the bridge: one thread that owns the fivebar `Link` (numbered lines
with CRC, character counting, resends: `fivebar_host.run`) and streams the planned batches.

Everything that touches the port happens on this thread; the GRBL side asks through
`MachineDriver` methods (thread-safe flags and a queue) and reads `status`:

* a batch is streamed with `Link.stream`; its `should_stop` is the sender's feed hold or
  reset, and its `on_interrupt` waits until the sender resumes (`~`) or resets;
* between batches the driver polls a status report every `POLL_S`, which also keeps the
  firmware's host-silence laser watchdog fed;
* a reset stops the machine at once (firmware Ctrl-X: queue cleared, laser off, position
  kept) and drops every batch not yet sent;
* a fault of the link (error reply, alarm, silence, disconnect) is handed to `on_fault`;
* `moves_done` counts the accepted G-code moves that have run to their end (from the
  firmware's last finished line and the batch's move of each item, `moves_finished`), so the
  GRBL side can hold its `ok`s within GRBL's window (`controller.OK_WINDOW`).
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections.abc import Callable

from fivebar_host import protocol
from fivebar_host.compile.incremental import Batch, moves_finished
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.controllers.fivebar.stream import StreamProgress
from fivebar_host.errors import FivebarError
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import FaultKind, LinkError, LinkFaultError

POLL_S = 0.1


class MachineDriver:
    """Streams batches to the machine behind `link` on its own thread (module doc)."""

    def __init__(self, link: Link, on_fault: Callable[[str, int | None], None]) -> None:
        self.link = link
        self.on_fault = on_fault
        self.status: StatusReport = link.status()
        self.batches: queue.Queue[Batch] = queue.Queue()
        self.busy = False  # a batch is being streamed
        self.jogging = False
        self.hold_requested = False
        self.moves_done = 0  # accepted moves (not jogs) run to their end, all batches
        #: batches streamed and not yet run to their end: (batch, first line, moves before)
        self._running: list[tuple[Batch, int, int]] = []
        self._base = 0  # moves of every batch streamed before the newest
        self._resume = False
        self._reset = threading.Event()
        self._reset_done = threading.Event()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, name="fivebar-machine", daemon=True)

    # ------------------------------------------------------------------ requests
    def start(self) -> None:
        self.thread.start()

    def submit(self, batch: Batch) -> None:
        self.batches.put(batch)

    def hold(self) -> None:
        """Feed hold: the firmware freezes at once, laser off (docs/protocol.md 2)."""
        with self._lock:
            self.hold_requested = True
            self._resume = False

    def resume(self) -> None:
        with self._lock:
            if self.hold_requested:
                self._resume = True

    def reset(self, timeout_s: float = 10.0) -> StatusReport:
        """Stop everything now (firmware Ctrl-X); wait for it and return the status."""
        self._drop_batches()
        self._reset_done.clear()
        self._reset.set()
        if threading.current_thread() is not self.thread:
            self._reset_done.wait(timeout_s)
        return self.status

    def close(self) -> None:
        self._stop.set()
        if self.thread.is_alive():
            self.thread.join(5.0)

    @property
    def idle(self) -> bool:
        """Nothing queued on either side and the machine standing still."""
        st = self.status
        return (not self.busy and self.batches.empty() and st.state == "Idle"
                and st.queued == 0)

    # ------------------------------------------------------------------ the thread
    def _drop_batches(self) -> None:
        with contextlib.suppress(queue.Empty):
            while True:
                self.batches.get_nowait()

    def _run(self) -> None:
        last_poll = 0.0
        while not self._stop.is_set():
            try:
                if self._reset.is_set():
                    self._do_reset()
                    continue
                self._realtime()
                if not self.hold_requested and not self.batches.empty():
                    # busy before the batch leaves the queue, and until a status report
                    # read after its stream: the GRBL side never sees Idle in between
                    self.busy = True
                    try:
                        self._stream(self.batches.get_nowait())
                        self.status = self.link.status()
                        self._count_done(self.status)
                    finally:
                        self.busy = False
                    continue
                if time.monotonic() - last_poll >= POLL_S:
                    self.status = self.link.status()
                    self._count_done(self.status)
                    last_poll = time.monotonic()
                    if not self.busy and self.status.state == "Idle":
                        self.jogging = False
                time.sleep(0.005)
            except LinkFaultError as e:
                self._fault(e)
            except LinkError as e:
                self.on_fault(str(e), None)
                time.sleep(POLL_S)
            except FivebarError as e:  # a batch the wire cannot write: stop, say why
                self._halt()
                self.on_fault(f"batch refused by the host: {e}", None)

    def _realtime(self) -> None:
        """Hold / resume requests while no batch is streaming."""
        with self._lock:
            hold, resume = self.hold_requested, self._resume
            if resume:
                self.hold_requested = self._resume = False
        if hold and not resume and self.status.state != "Hold":
            self.link.realtime(protocol.RT_HOLD)
            self.status = self.link.status()
        elif resume:
            self.link.realtime(protocol.RT_RESUME)
            self.status = self.link.status()

    def _count_done(self, st: StatusReport | None) -> None:
        """`moves_done` from the firmware's last finished line: each batch still running
        maps its lines to its moves (`moves_finished`); one run to its end is dropped."""
        if st is None:
            return
        while self._running:
            batch, first, before = self._running[0]
            done = moves_finished(batch.program, st.done_line - first + 1, batch.moves)
            self.moves_done = max(self.moves_done, before + done)
            if done < batch.moves:
                break
            self._running.pop(0)

    def _settle(self) -> None:
        """After a stop: what ran is done, the rest of the batches never will be."""
        self._count_done(self.status)
        self._running.clear()
        self._base = self.moves_done

    def _do_reset(self) -> None:
        self._drop_batches()
        try:
            self.link.reset()
            self.status = self.link.status()
        finally:
            with self._lock:
                self.hold_requested = self._resume = False
            self.busy = self.jogging = False
            self._settle()
            self._reset.clear()
            self._reset_done.set()

    def _stream(self, batch: Batch) -> None:
        if not batch.jog and batch.moves:
            self._running.append((batch, self.link.next_line, self._base))
            self._base += batch.moves
            self._count_done(self.status)  # an empty program's moves are done at once
        if not len(batch.program):
            return
        self.busy = True
        self.jogging = batch.jog

        def progress(p: StreamProgress) -> None:
            if p.status is not None:
                self.status = p.status
                self._count_done(p.status)

        def interrupt() -> bool:
            """Held inside a stream: wait for the sender's resume or reset."""
            self.status = self.link.status()
            while not self._reset.is_set() and not self._stop.is_set():
                with self._lock:
                    if self._resume:
                        self.hold_requested = self._resume = False
                        return True
                time.sleep(0.01)
            return False

        try:
            self.link.stream(batch.program, on_progress=progress,
                             should_stop=lambda: self.hold_requested or self._reset.is_set(),
                             on_interrupt=interrupt)
        except LinkFaultError as e:
            if e.kind is not FaultKind.INTERRUPT:
                raise
        finally:
            self.busy = False

    def _fault(self, e: LinkFaultError) -> None:
        """A link fault: stop the machine (laser off) and tell the GRBL side."""
        self._halt()
        self.on_fault(e.message, e.code if e.kind is FaultKind.ALARM else None)

    def _halt(self) -> None:
        """Stop the machine: the batches dropped, a hold, then a reset (laser off)."""
        self._drop_batches()
        self.busy = self.jogging = False
        self._settle()
        with contextlib.suppress(LinkError):
            self.link.realtime(protocol.RT_HOLD)
        with contextlib.suppress(LinkError):
            self.link.reset()
            self.status = self.link.status()
