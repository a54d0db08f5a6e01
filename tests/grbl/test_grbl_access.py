"""The bridge's network face: loopback by default; any other address only with an allow-list
of senders (GRBL senders cannot send a token) or an explicit `--insecure-listen`; SIGINT and
SIGTERM stop it with the machine held and reset (laser off)."""

from __future__ import annotations

import ipaddress
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from grbl_support import start_bridge, stop_bridge

from fivebar_host.bridge.serve import REFUSED_MSG, Access, parse_allow, parse_listen
from fivebar_host.errors import UsageError

ROOT = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-c", "from fivebar_host.cli import main; main()"]


def test_who_may_connect() -> None:
    lan = Access([parse_allow("192.168.1.0/24"), parse_allow("10.0.0.7")])
    assert lan.permits("127.0.0.1") and lan.permits("::1") and lan.permits("127.0.0.9")
    assert lan.permits("192.168.1.20") and lan.permits("::ffff:192.168.1.20")
    assert lan.permits("10.0.0.7") and not lan.permits("10.0.0.8")
    assert not lan.permits("192.168.2.1") and not lan.permits("garbage")
    assert Access([]).permits("127.0.0.1") and not Access([]).permits("192.168.1.20")
    assert Access(None).permits("203.0.113.5")  # --insecure-listen
    assert parse_listen("[::]:23") == ("::", 23) and parse_listen("23") == ("127.0.0.1", 23)
    with pytest.raises(UsageError, match=r"--allow takes an IP address.*\(300 characters\)"):
        parse_allow("x" * 300)


@pytest.mark.parametrize("listen", ["0.0.0.0:0", "[::]:0", "192.0.2.1:2323"])
def test_a_network_address_without_an_allow_list_is_refused_before_the_port(
        listen: str) -> None:
    # a port that does not exist: had the bridge tried to open it, it would say so instead
    run = subprocess.run([*CLI, "bridge", "--port", "/nonexistent/tty", "--listen", listen],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert run.returncode == 2, run.stderr
    assert "is not a loopback address" in run.stderr and "--allow" in run.stderr
    assert "--insecure-listen" in run.stderr and "cannot open" not in run.stderr


def bridge_process(*args: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([*CLI, "bridge", "--port", "fivebar-mock://?speed=10", *args],
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)
    assert proc.stderr is not None
    line = proc.stderr.readline()
    assert "GRBL 1.1h on tcp" in line, line
    return proc


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_the_bridge_with_the_machine_held_and_the_laser_off(
        sig: signal.Signals) -> None:
    proc = bridge_process("--listen", "127.0.0.1:0")
    time.sleep(0.3)
    t0 = time.monotonic()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert time.monotonic() - t0 < 15
    assert "machine held and reset" in err and "laser off" in err


@pytest.mark.parametrize("args, loud", [
    (["--allow", "192.0.2.0/24"], "NOTE: fivebar bridge listens on 0.0.0.0; only loopback "
     "and 192.0.2.0/24 may connect"),
    (["--insecure-listen"], "WARNING: fivebar bridge listens on 0.0.0.0 for EVERY address")])
def test_an_allow_list_or_insecure_listen_is_said_loudly(args: list[str], loud: str) -> None:
    proc = bridge_process("--listen", "0.0.0.0:0", *args)
    assert proc.stderr is not None
    assert loud in proc.stderr.readline()
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=30)
    assert proc.returncode == 0


def test_a_client_off_the_list_is_told_and_closed(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    r = start_bridge("mock", tmp_path)
    try:
        # loopback always may connect: make this test's own address count as a stranger's
        r.server.access = Access([ipaddress.ip_network("192.0.2.0/24")])
        monkeypatch.setattr(ipaddress.IPv4Address, "is_loopback", property(lambda s: False))
        assert r.server.address is not None
        with socket.create_connection(r.server.address, timeout=5) as s:
            got = b""
            while chunk := s.recv(256):
                got += chunk
        assert got == REFUSED_MSG and r.server.refused == 1
    finally:
        monkeypatch.undo()
        stop_bridge(r)
