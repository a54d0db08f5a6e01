"""Where senders reach the bridge: a pseudo-terminal (for senders that open a serial device;
a symlink points at it) and a TCP port (network senders), served by one selector thread.

One sender at a time drives the machine: a second connection gets a `[MSG:…]` saying the
bridge is busy and is closed. GRBL senders cannot send a token, so who may connect over TCP
is an allow-list of client addresses (`Access`): loopback always, other addresses only when
listed (or every address with `--insecure-listen`); a refused client gets a `[MSG:…]` saying
so and is closed before the bridge reads a byte from it. A sender that connects gets GRBL's
banner; one that goes away (the pty's last opener closes it: the master reads EIO / hangs up;
a TCP peer closes) leaves the machine held with the laser off (`Bridge.detach`).
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import selectors
import socket
import termios
import threading
import tty
from collections.abc import Callable
from pathlib import Path

from fivebar_host.bridge.controller import Bridge
from fivebar_host.errors import UsageError, shorten

BUSY_MSG = b"[MSG:fivebar bridge busy: another sender is connected]\r\n"
REFUSED_MSG = b"[MSG:fivebar bridge: this address may not connect (--allow)]\r\n"

Network = ipaddress.IPv4Network | ipaddress.IPv6Network


def parse_listen(text: str) -> tuple[str, int]:
    """`HOST:PORT`, `[IPv6]:PORT` or `PORT` (loopback) → (host, port)."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        raise UsageError(f"--listen must be HOST:PORT or PORT; got {shorten(text)!r}") from None
    if not 0 <= number <= 65535:
        raise UsageError(f"--listen port out of range: {shorten(port)}")
    return (host.strip("[]") or "127.0.0.1"), number


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or `localhost`."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def parse_allow(text: str) -> Network:
    """One `--allow` value: an address or a network (`192.168.1.20`, `192.168.1.0/24`)."""
    try:
        return ipaddress.ip_network(text.strip(), strict=False)
    except ValueError:
        raise UsageError(f"--allow takes an IP address or network such as 192.168.1.0/24; "
                         f"got {shorten(text)!r}") from None


class Access:
    """Who may connect over TCP: loopback always; others when in `allow`, or anyone when
    `allow` is None (`--insecure-listen`)."""

    def __init__(self, allow: list[Network] | None) -> None:
        self.allow = allow

    def permits(self, address: str) -> bool:
        """Whether a client at `address` may drive the machine."""
        try:
            ip = ipaddress.ip_address(address.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        if ip.is_loopback or self.allow is None:
            return True
        return any(ip in net for net in self.allow)


#: Only local processes: the default.
LOOPBACK_ONLY = Access([])


class _Pty:
    """The pty end the bridge keeps (master) and its symlink; the slave is closed so that a
    sender's close shows as a hang-up."""

    def __init__(self, link: Path) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave, termios.TCSANOW)
        self.name = os.ttyname(slave)
        os.close(slave)
        os.set_blocking(self.master, False)
        self.link = link
        tmp = link.with_name(link.name + ".tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(self.name)
        tmp.replace(link)
        self.connected = False

    def write(self, data: bytes) -> None:
        with contextlib.suppress(BlockingIOError):  # nobody reading: lost, as on a wire
            os.write(self.master, data)

    def hung_up(self) -> bool:
        """True while no process has the slave open."""
        return select_poll(self.master)

    def close(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.link.unlink()
        with contextlib.suppress(OSError):
            os.close(self.master)


def select_poll(fd: int) -> bool:
    """Whether `fd` (a pty master) reports a hang-up."""
    import select

    poller = select.poll()
    poller.register(fd, select.POLLIN | select.POLLHUP)
    return any(ev & select.POLLHUP for _, ev in poller.poll(0))


class Server:
    """Serves `bridge` on a pty (`link`) and/or TCP (`listen`) until `stop`."""

    def __init__(self, bridge: Bridge, link: Path | None = None,
                 listen: tuple[str, int] | None = None, access: Access = LOOPBACK_ONLY,
                 log: Callable[[str], None] | None = None) -> None:
        self.bridge = bridge
        self.access = access
        self.log = log
        self.refused = 0  # TCP clients refused by the allow-list
        self.sel = selectors.DefaultSelector()
        self.pty = _Pty(link) if link is not None else None
        self.sock: socket.socket | None = None
        if listen is not None:
            family = socket.AF_INET6 if ":" in listen[0] else socket.AF_INET
            self.sock = socket.create_server(listen, family=family, reuse_port=False)
            self.sock.setblocking(False)
            self.sel.register(self.sock, selectors.EVENT_READ, "accept")
        self.client: socket.socket | None = None
        self.owner: Callable[[bytes], None] | None = None
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self.run, name="grbl-serve", daemon=True)

    @property
    def address(self) -> tuple[str, int] | None:
        if self.sock is None:
            return None
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def start(self) -> None:
        self.thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self.thread.is_alive():
            self.thread.join(5.0)
        if self.client is not None:
            self.client.close()
        if self.sock is not None:
            self.sock.close()
        if self.pty is not None:
            self.pty.close()

    # ------------------------------------------------------------------ the loop
    def run(self) -> None:
        while not self._stop.is_set():
            if self.pty is not None:
                self._pty_turn()
            for key, _ in self.sel.select(0.005):
                if key.data == "accept":
                    self._accept()
                else:
                    self._client_read()

    def _pty_turn(self) -> None:
        assert self.pty is not None
        pty = self.pty
        if pty.hung_up():
            if pty.connected:
                pty.connected = False
                self.bridge.detach(pty.write)
                self.owner = None
            return
        if not pty.connected and self.owner is None:
            pty.connected = True
            self.owner = pty.write
            self.bridge.attach(pty.write)
        try:
            data = os.read(pty.master, 4096)
        except BlockingIOError:
            return
        except OSError as e:
            if e.errno == errno.EIO:
                return
            raise
        if data and self.owner == pty.write:
            self.bridge.input.feed(data)

    def _accept(self) -> None:
        assert self.sock is not None
        conn, peer = self.sock.accept()
        if not self.access.permits(str(peer[0])):
            self.refused += 1
            if self.log is not None:
                self.log(f"refused a TCP client at {peer[0]}: not in --allow")
            with contextlib.suppress(OSError):
                conn.sendall(REFUSED_MSG)
            conn.close()
            return
        if self.owner is not None:
            with contextlib.suppress(OSError):
                conn.sendall(BUSY_MSG)
            conn.close()
            return
        conn.setblocking(True)
        conn.settimeout(2.0)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.client = conn
        self.owner = self._tcp_write
        self.sel.register(conn, selectors.EVENT_READ, "client")
        self.bridge.attach(self._tcp_write)

    def _tcp_write(self, data: bytes) -> None:
        if self.client is not None:
            self.client.sendall(data)

    def _client_read(self) -> None:
        assert self.client is not None
        try:
            data = self.client.recv(4096)
        except OSError:
            data = b""
        if data:
            self.bridge.input.feed(data)
            return
        self.sel.unregister(self.client)
        self.client.close()
        self.client = None
        self.bridge.detach(self._tcp_write)
        self.owner = None
