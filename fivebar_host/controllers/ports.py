"""One owner per port: the advisory lock every fivebar command takes before it opens a port,
and the exclusive open behind it.

Opening the serial port of an Arduino resets it through DTR, and a second program that opens
a port in use writes into the first one's stream. So every opener — `plot`, `jog`, `home`,
`frame`, `status`, `pen`, `motors`, `bridge`, `serve`, and `flash` through `hold_port` — goes
through this module, *before* the device is opened:

* **Lock file.** `LCK..<device>` in `/run/lock` or `/var/lock` when writable (the place and
  name uucp, minicom and lockdev use; the first line is the PID, right-aligned in 10
  characters, as they write it), else in a per-user runtime directory. It holds the owner's
  PID, command, start time and a hint for the refused (the daemon's: "use `fivebar plot
  --server URL`"). Held with `flock`, so it is released when its process dies however it
  dies; a file left behind by a dead owner (its lock free, or a foreign lock file whose PID
  is gone) is taken over with a note. A device reached through a symlink (a pty's link) is
  locked under the device it points at.
* **Exclusive open.** The device is then opened with pyserial's `exclusive=True` (its own
  `flock` on the device) and put in `TIOCEXCL` mode, so other programs that do not know the
  lock file are refused by the kernel too (except root's: the lock file is what stops a
  second fivebar command run as root).
* **URLs without a device node.** `fivebar-mock://?machine=NAME`, `fivebar-sim://?machine=NAME`
  and `fivebar-grbl://?machine=NAME` name a machine that lives in this process: the same name
  is the same port, held in this process only. Without `machine=` each open makes a machine
  of its own, so there is nothing to share and nothing is locked.

A second opener is refused with `PortBusyError` naming the owner, before it writes a byte or
opens the device (so a board is never reset by the refused command).

Public API (also for commands that run another program on the port, such as a firmware
upload): `hold_port(url, command)` is a context manager that holds the lock; `owner_of(url)`
reads who holds it; `open_port` and `close_port` are what the links use.
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import os
import sys
import threading
import urllib.parse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fivebar_host.run.errors import LinkError

try:  # POSIX only: on Windows a COM port is exclusive by itself
    import fcntl
    import termios
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]
    termios = None  # type: ignore[assignment]

#: Where lock files go, first writable one wins (after `$FIVEBAR_LOCK_DIR`).
SYSTEM_LOCK_DIRS = (Path("/run/lock"), Path("/var/lock"))
#: What this process calls itself in the lock files it writes (`set_command`).
_command: str | None = None
#: Ports held by this process: key → owner (a second open in the same process is refused
#: here, before the lock file is even tried).
_HELD: dict[str, Owner] = {}
_HELD_LOCK = threading.Lock()


@dataclass(frozen=True)
class Owner:
    """Who holds a port: process, command, since when, and what the refused should do."""

    pid: int
    command: str
    since: str
    hint: str | None = None
    fivebar: bool = True  # written by fivebar (else another program's lock file)

    def describe(self) -> str:
        """"`fivebar serve` (pid 1234) since 2025-05-01 10:41:52; use …"."""
        who = f"`{self.command}` (pid {self.pid})" if self.command else f"pid {self.pid}"
        since = f" since {self.since}" if self.since else ""
        return f"{who}{since}" + (f"; {self.hint}" if self.hint else "")


class PortBusyError(LinkError):
    """Another process (or another part of this one) holds the port; nothing was sent."""

    def __init__(self, url: str, owner: Owner | None, why: str = "") -> None:
        held = f"held by {owner.describe()}" if owner else (why or "in use")
        super().__init__(f"{url}: the port is {held}; nothing was sent to it")
        self.url = url
        self.owner = owner


def set_command(command: str) -> None:
    """Name this process in the lock files it writes ("fivebar plot"); the CLI sets it."""
    global _command
    _command = command


def current_command() -> str:
    """This process's name for lock files: `set_command`'s, else from its arguments."""
    if _command:
        return _command
    argv = [a for a in sys.argv if a and not a.startswith("-")]
    return " ".join(Path(a).name if i == 0 else a for i, a in enumerate(argv[:2]))[:80]


# ------------------------------------------------------------------ what a port is
@dataclass(frozen=True)
class PortKey:
    """What makes two URLs the same port: `key`; `device` the device node (lock file and
    exclusive open) or None for a machine that lives in this process."""

    key: str
    device: Path | None


def port_key(url: str) -> PortKey | None:
    """The port `url` opens, or None when each open is a port of its own (module doc)."""
    if "://" in url:
        scheme, _, rest = url.partition("://")
        query = urllib.parse.parse_qs(rest.partition("?")[2])
        names = query.get("machine")
        return PortKey(f"{scheme}://?machine={names[-1]}", None) if names else None
    path = Path(url)
    try:
        real = path.resolve(strict=True)
    except (OSError, RuntimeError):
        return None  # not there: the open fails and says so
    return PortKey(str(real), real)


def lock_dir() -> Path:
    """Where lock files go: `$FIVEBAR_LOCK_DIR`, `/run/lock` or `/var/lock` when writable,
    else `$XDG_RUNTIME_DIR/fivebar` or a per-user folder in the temporary directory."""
    env = os.environ.get("FIVEBAR_LOCK_DIR")
    if env:
        return Path(env)
    for d in SYSTEM_LOCK_DIRS:
        if d.is_dir() and os.access(d, os.W_OK | os.X_OK):
            return d
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    base = Path(runtime) / "fivebar" if runtime else Path(
        os.environ.get("TMPDIR", "/tmp")) / f"fivebar-locks-{os.getuid()}"
    base.mkdir(mode=0o700, parents=True, exist_ok=True)
    return base


def lock_path(device: Path) -> Path:
    """`LCK..ttyUSB0` for /dev/ttyUSB0, `LCK..pts_3` for /dev/pts/3 (uucp's naming)."""
    try:
        name = str(device.relative_to("/dev"))
    except ValueError:
        name = str(device).lstrip("/")
    return lock_dir() / ("LCK.." + name.replace("/", "_"))


# ------------------------------------------------------------------ the lock file
def _format(owner: Owner) -> str:
    lines = [f"{owner.pid:>10d}", f"command={owner.command}", f"since={owner.since}"]
    if owner.hint:
        lines.append(f"hint={owner.hint}")
    return "\n".join(lines) + "\n"


def parse_lock(text: str) -> Owner | None:
    """The owner a lock file names (ours, or another program's bare PID), or None."""
    lines = text.splitlines()
    if not lines:
        return None
    try:
        pid = int(lines[0].split()[0]) if lines[0].strip() else 0
    except ValueError:
        return None
    fields = dict(line.split("=", 1) for line in lines[1:] if "=" in line)
    if "command" not in fields:
        return Owner(pid, "", "", fivebar=False) if pid > 0 else None
    return Owner(pid, fields["command"][:200], fields.get("since", "")[:40],
                 fields.get("hint", "")[:200] or None)


def _alive(pid: int) -> bool:
    """Whether process `pid` exists and is no zombie."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    with contextlib.suppress(OSError):
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat.rpartition(")")[2].split()[0] != "Z"
    return True


def _read(fd: int) -> str:
    os.lseek(fd, 0, os.SEEK_SET)
    return os.read(fd, 4096).decode("utf-8", "replace")


def _take_file(path: Path, url: str, me: Owner) -> tuple[int, str | None]:
    """flock `path` (made if missing) and write `me` into it: (fd, note on a stale lock);
    `PortBusyError` when a live process holds it."""
    assert fcntl is not None
    for _ in range(5):
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = parse_lock(_read(fd))
            os.close(fd)
            raise PortBusyError(url, owner, f"locked ({path})") from None
        try:
            same = os.stat(path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if not same:  # its owner removed it between our open and our lock: again
            os.close(fd)
            continue
        old = parse_lock(_read(fd))
        note = None
        if old is not None and old.pid != me.pid:
            if not old.fivebar and _alive(old.pid):
                os.close(fd)
                raise PortBusyError(url, old, f"locked by pid {old.pid} ({path})")
            what = f"`{old.command}` " if old.command else ""
            note = (f"{url}: took over a stale lock ({path}) of {what}pid {old.pid}"
                    + (f" since {old.since}" if old.since else "") + ", which is gone")
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, _format(me).encode())
        return fd, note
    raise PortBusyError(url, None, f"its lock file {path} keeps changing")


class PortLock:
    """A held port (`hold_port`): released by `release()` or at the end of a `with`."""

    def __init__(self, url: str, key: PortKey | None, owner: Owner) -> None:
        self.url = url
        self.key = key
        self.owner = owner
        self.path: Path | None = None
        self.note: str | None = None  # a stale lock was taken over: what it was
        self._fd: int | None = None
        self._held = False

    def acquire(self) -> PortLock:
        """Take the port (module doc); `PortBusyError` naming the owner if it is held."""
        if self.key is None:
            return self
        with _HELD_LOCK:
            if self.key.key in _HELD:
                raise PortBusyError(self.url, _HELD[self.key.key])
            _HELD[self.key.key] = self.owner
        self._held = True
        try:
            if self.key.device is not None and fcntl is not None:
                self.path = lock_path(self.key.device)
                self._fd, self.note = _take_file(self.path, self.url, self.owner)
        except BaseException:
            self.release()
            raise
        return self

    def release(self) -> None:
        """Give the port up (idempotent): the lock file goes, then its lock."""
        if self._fd is not None:
            assert fcntl is not None and self.path is not None
            with contextlib.suppress(OSError):
                if os.stat(self.path, follow_symlinks=False).st_ino == os.fstat(self._fd).st_ino:
                    os.unlink(self.path)
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None
        if self._held and self.key is not None:
            with _HELD_LOCK:
                _HELD.pop(self.key.key, None)
            self._held = False

    def __enter__(self) -> PortLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def hold_port(url: str, command: str | None = None, hint: str | None = None) -> PortLock:
    """Hold the port `url` names for this process, before opening it: a `PortLock`, also a
    context manager (`with hold_port(url, "fivebar flash"): run avrdude`). `command` names
    the holder in the lock file (default: `current_command()`), `hint` tells a refused
    opener what to do instead. `PortBusyError` when another holds it."""
    now = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M:%S")
    owner = Owner(os.getpid(), command or current_command(), now, hint)
    return PortLock(url, port_key(url), owner).acquire()


def owner_of(url: str) -> Owner | None:
    """Who holds the port `url` names now (None: nobody, or nothing to hold); reads only."""
    key = port_key(url)
    if key is None:
        return None
    with _HELD_LOCK:
        if key.key in _HELD:
            return _HELD[key.key]
    if key.device is None or fcntl is None:
        return None
    try:
        fd = os.open(lock_path(key.device), os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return parse_lock(_read(fd))
        old = parse_lock(_read(fd))
        return old if old is not None and not old.fivebar and _alive(old.pid) else None
    finally:
        os.close(fd)


def refuse_if_held(url: str) -> None:
    """`PortBusyError` now if another holds the port (a command checks before long work,
    such as compiling a drawing; the open checks again)."""
    owner = owner_of(url)
    if owner is not None:
        raise PortBusyError(url, owner)


# ------------------------------------------------------------------ opening
def open_port(url: str, *, command: str | None = None, hint: str | None = None,
              **serial_kwargs: Any) -> tuple[Any, PortLock]:
    """Hold the port, then open it (exclusive for a device node): (pyserial port, lock).
    `PortBusyError` if it is held; pyserial's errors if it cannot be opened (the lock is
    then released). Close with `close_port`."""
    import serial

    lock = hold_port(url, command, hint)
    try:
        if lock.key is not None and lock.key.device is not None and fcntl is not None:
            serial_kwargs.setdefault("exclusive", True)
        try:
            port = serial.serial_for_url(url, **serial_kwargs)
        except serial.SerialException as e:
            if "exclusively lock" in str(e):
                raise PortBusyError(url, None, "locked by another program (flock on the "
                                    "device)") from e
            raise
        _exclusive(port, True)
    except BaseException:
        lock.release()
        raise
    return port, lock


def open_trouble(url: str, exc: BaseException) -> tuple[str, str]:
    """Why a port would not open, for people: (kind, message) — `permission` (the user may
    not open serial ports: the group to join), `busy` (another program has it), `no_port`
    (no such device: `fivebar doctor` lists them), else `open` with the OS's words. One
    diagnosis for every command that opens a port (the links, `fivebar flash`)."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.EACCES or "Permission denied" in text or "[Errno 13]" in text:
        return "permission", (f"{url}: permission denied: your user may not open serial "
                              "ports. Fix: sudo usermod -aG dialout $USER (Arch, Fedora: the "
                              "uucp group), then log out and back in")
    if code in (errno.EBUSY, errno.EAGAIN) or "[Errno 16]" in text or "[Errno 11]" in text \
            or "busy" in text.lower():
        return "busy", (f"{url}: the port is in use by another program (the Arduino IDE's "
                        "serial monitor, `fivebar serve`, a printer host, ModemManager): "
                        "close it, then try again")
    if code == errno.ENOENT or "No such file" in text or "[Errno 2]" in text:
        return "no_port", (f"{url}: no such port: is the board plugged in? `fivebar doctor` "
                           "lists the serial ports this computer has")
    return "open", f"{url}: cannot open the port: {text}"


def _exclusive(port: Any, on: bool) -> None:
    """TIOCEXCL (no further opens) or TIOCNXCL on a real tty; nothing for URL ports."""
    fd = getattr(port, "fd", None)
    if fd is None or termios is None or fcntl is None:
        return
    with contextlib.suppress(OSError, AttributeError):
        fcntl.ioctl(fd, termios.TIOCEXCL if on else termios.TIOCNXCL)


def close_port(port: Any, lock: PortLock | None) -> None:
    """Close a port `open_port` opened and give it up (idempotent)."""
    import serial

    with contextlib.suppress(serial.SerialException, OSError):
        if getattr(port, "is_open", False):
            _exclusive(port, False)
        port.close()
    if lock is not None:
        lock.release()
