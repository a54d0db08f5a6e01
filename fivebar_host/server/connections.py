"""The daemon's HTTP connections: a deadline for the request headers and a cap per client.

uvicorn closes a connection that stays idle after a response (`timeout_keep_alive`), but it
waits for the headers of a request for ever: 600 connections sending a header byte now and
then (slowloris) stayed open as long as they liked. `protocol_class` makes uvicorn's h11
protocol with

* **a header deadline.** The request line and headers must be complete within
  `HEADER_TIMEOUT_S` of the connection opening, or of the previous response on a kept-alive
  connection; otherwise the answer is 408 `{"error": "timeout", ...}` and the connection is
  closed. (The body has its own deadline, in `security.Guard`.)
* **a cap per client address.** At most `MAX_CONNECTIONS_PER_CLIENT` connections from one
  address at once; the next is answered 503 `busy` (with Retry-After) and closed before its
  request is read. Loopback counts as one client like any other address.

Idle connections are bounded by uvicorn's keep-alive timeout (5 s) and these two limits.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol

from fivebar_host.server.security import RETRY_AFTER_S

#: Longest a client may take to send a request's line and headers, s.
HEADER_TIMEOUT_S = 10.0
#: Connections one client address may hold open at once.
MAX_CONNECTIONS_PER_CLIENT = 512


def raw_answer(status: int, reason: str, error: str, message: str,
               extra: str = "") -> bytes:
    """A complete HTTP/1.1 JSON error answer that closes the connection, written before
    any request was parsed (so without h11's help)."""
    body = json.dumps({"error": error, "message": message}).encode()
    head = (f"HTTP/1.1 {status} {reason}\r\ncontent-type: application/json\r\n"
            f"content-length: {len(body)}\r\nx-content-type-options: nosniff\r\n"
            f"connection: close\r\n{extra}\r\n")
    return head.encode("latin-1") + body


def protocol_class(header_timeout_s: float = HEADER_TIMEOUT_S,
                   max_per_client: int = MAX_CONNECTIONS_PER_CLIENT) -> type[H11Protocol]:
    """uvicorn's h11 protocol with the header deadline and the per-client cap (module doc);
    a class per daemon, so that each counts its own connections."""
    open_by_client: dict[str, int] = {}

    class GuardedH11(H11Protocol):
        """H11Protocol with a header deadline and a connection cap per client address."""

        _deadline: asyncio.TimerHandle | None = None
        _seen_cycle: Any = None
        _counted: str | None = None

        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            who = self.client[0] if self.client else "?"
            if open_by_client.get(who, 0) >= max_per_client:
                transport.write(raw_answer(
                    503, "Service Unavailable", "busy",
                    f"{max_per_client} connections from {who} are open, the limit for one "
                    "client; close some and retry", f"retry-after: {RETRY_AFTER_S}\r\n"))
                transport.close()
                return
            open_by_client[who] = open_by_client.get(who, 0) + 1
            self._counted = who
            self._arm()

        def connection_lost(self, exc: Exception | None) -> None:
            self._disarm()
            if self._counted is not None:
                left = open_by_client.get(self._counted, 1) - 1
                if left > 0:
                    open_by_client[self._counted] = left
                else:
                    open_by_client.pop(self._counted, None)
                self._counted = None
            super().connection_lost(exc)

        def data_received(self, data: bytes) -> None:
            super().data_received(data)
            self._check_headers()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            if not self.transport.is_closing():
                self._arm()  # the next request's headers: a deadline of their own
                self._check_headers()  # unless a pipelined one was parsed already

        def _check_headers(self) -> None:
            if self.cycle is not None and self.cycle is not self._seen_cycle:
                self._seen_cycle = self.cycle  # a request's headers are in
                self._disarm()

        def _arm(self) -> None:
            self._disarm()
            self._deadline = self.loop.call_later(header_timeout_s, self._too_slow)

        def _disarm(self) -> None:
            if self._deadline is not None:
                self._deadline.cancel()
                self._deadline = None

        def _too_slow(self) -> None:
            self._deadline = None
            if self.transport.is_closing():
                return
            if self.cycle is not None and not self.cycle.response_complete:
                return  # a request is being answered: not ours to cut
            self.transport.write(raw_answer(
                408, "Request Timeout", "timeout",
                f"no complete request line and headers within {header_timeout_s:g} s; the "
                "connection is closed"))
            self.transport.close()

    return GuardedH11
