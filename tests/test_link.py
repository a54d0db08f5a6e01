"""The link against the mock: a device that was not reset on open, a hung one rebooted,
another protocol version, a reset that cuts the line being transmitted."""

from __future__ import annotations

import pytest
import serial

from fivebar_host import protocol
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices import mock, urls
from fivebar_host.protocol import Banner
from fivebar_host.run.errors import FaultKind, FirmwareMismatchError, LinkFaultError

BANNER = Banner("1.1.0", protocol.PROTOCOL_VERSION, 255, 16, 128)


def test_handshake_with_a_device_left_in_numbered_mode() -> None:
    """A second session on a port that was not reset (no DTR) meets strict framing: its
    unnumbered ``$I`` is refused with ``error:10 resend:<n>``; it asks again as line n."""
    urls.register()
    port = serial.serial_for_url("fivebar-mock://?speed=0", timeout=0.02)
    try:
        first = Link(port, url="first")
        assert isinstance(first.handshake(1.5), Banner)  # the boot banner
        first.command("G90")
        first.command("G91")
        assert first.next_line == 3
        again = Link(port, url="again")
        assert again.handshake(1.5) == first.banner  # no banner until it asked as N3
        assert again.next_line == 4
        again.command("G90")
        assert again.status().accepted_line == 4
    finally:
        port.close()


def test_hardware_reset_revives_a_hung_controller_and_restarts_the_numbering() -> None:
    """DTR reboots a hung controller: a banner, laser off, the line counter back to 0 (the
    next line is 1) and the position, H and Ln done kept (docs/protocol.md 7)."""
    urls.register()
    port = serial.serial_for_url("fivebar-mock://?speed=0&stall_after=3&watchdog=0", timeout=0.02)
    try:
        link = Link(port, url="hung", reply_timeout_s=0.3)
        link.handshake(1.5)
        link.command("G92 A5 B6")
        link.command("G1 A25 B-4 P10000")
        link.wait_idle(1.0)
        link.command("G90")  # answered, then the controller hangs
        with pytest.raises(LinkFaultError, match="no status report"):
            link.status()
        assert link.next_line == 4
        assert link.hardware_reset()
        assert link.next_line == 1
        st = link.status()
        assert (st.a, st.b, st.homed, st.done_line, st.accepted_line) == (25, -4, True, 2, 0)
        link.command("G90")
        assert link.status().accepted_line == 1
    finally:
        port.close()


@pytest.mark.parametrize("proto", [3, 5])
def test_the_host_accepts_only_the_protocol_it_speaks(proto: int) -> None:
    urls.register()
    with pytest.raises(FirmwareMismatchError) as e:
        Link.open(f"fivebar-mock://?proto={proto}", banner_timeout_s=1.5)
    assert (f"speaks protocol {proto}; this host needs protocol {protocol.PROTOCOL_VERSION}"
            in str(e.value))


class ResetCutsTransmission(mock.MockSerial):
    """A mock whose resets strike while it transmits, as a real UART can be cut.

    The mock puts whole lines out at once; here, once, the line sent just before a reset's
    banner loses everything after its first byte, newline included, so the banner arrives
    glued to it (``ok`` + banner → ``ofivebar 1.1.0 proto:2 ...``).
    """

    cut: bytes | None = None  # the glued line as it was sent, once cut

    def _cut(self) -> None:
        fw = self.firmware
        if self.cut is not None or fw is None:
            return
        at = fw.out.rfind(b"fivebar ")
        if at < 2 or fw.out[at - 2:at] != b"\r\n":
            return
        start = fw.out.rfind(b"\n", 0, at - 2) + 1
        if start < at - 2:
            del fw.out[start + 1:at]
            self.cut = bytes(fw.out[start:fw.out.index(b"\n", start) + 1])

    def write(self, data: bytes | bytearray | memoryview) -> int:
        n = super().write(data)
        self._cut()
        return n

    def _update_dtr_state(self) -> None:
        super()._update_dtr_state()
        self._cut()


def test_a_banner_glued_to_a_cut_reply_is_a_restart_while_streaming() -> None:
    """reset_after=3: line 3's ``ok`` is being sent when the controller resets."""
    port = ResetCutsTransmission("fivebar-mock://?speed=0&reset_after=3", timeout=0.02)
    try:
        link = Link(port, url="cut")
        link.handshake(3.0)
        with pytest.raises(LinkFaultError) as e:
            link.stream([f"G1 A{10 * i} P10000" for i in range(1, 9)])
        assert port.cut is not None and port.cut.startswith(b"ofivebar 1.1.0 proto:")
        assert e.value.kind is FaultKind.RESET, e.value
        assert e.value.acked == 2  # line 3's ok was cut away
        assert link.banner == BANNER
    finally:
        port.close()


def test_a_banner_glued_to_a_cut_status_report_answers_a_reset() -> None:
    """Ctrl-X and DTR, each while a status report is still on its way."""
    port = ResetCutsTransmission("fivebar-mock://?speed=0", timeout=0.02)
    try:
        link = Link(port, url="cut")
        link.handshake(3.0)
        link.command("G92 A5 B6")
        link.wait_idle(1.0)
        port.write(protocol.RT_STATUS)
        assert link.reset() == BANNER
        assert port.cut is not None and port.cut.startswith(b"<fivebar 1.1.0 proto:")
        port.cut = None
        port.write(protocol.RT_STATUS)
        assert link.hardware_reset()
        assert port.cut is not None and port.cut.startswith(b"<fivebar 1.1.0 proto:")
        assert link.next_line == 1
        st = link.status()
        assert (st.a, st.b, st.homed, st.accepted_line) == (5, 6, True, 0)
    finally:
        port.close()


@pytest.mark.parametrize("url", ["fivebar-mock://?speed=0", "fivebar-sim://"])
def test_a_command_after_a_refused_one_runs(url: str) -> None:
    """A line refused with a plain error used its number (protocol 5.2, step 9): the next
    command goes out with the following number and runs — it is neither refused as a
    repeat nor skipped as a resend outside the stream."""
    if url.startswith("fivebar-sim"):
        from fivebar_host.devices.sim import toolchain_missing
        if toolchain_missing():
            pytest.skip("emulator unavailable")
    link = Link.open(url)
    try:
        with pytest.raises(LinkFaultError) as e:
            link.command("$99=1")
        assert e.value.kind is FaultKind.ERROR
        line = link.next_line
        assert link.status().accepted_line == line - 1
        link.command("G91")
        link.command("G1 A7 B-3 P2000")
        link.command("G1 A7 B-3 P2000")  # relative: two moves of 7 and −3
        st = link.wait_idle(10.0)
        assert (st.a, st.b) == (14, -6)
        assert st.accepted_line == line + 2
    finally:
        link.close()


def test_waiting_for_the_end_polls_soon_then_backs_off(monkeypatch: pytest.MonkeyPatch) -> None:
    """`wait_idle` asks for a status report 3 ms after the first, then doubles its pause up
    to the link's poll interval: a job that ends just after its last line is seen to end
    within milliseconds, not up to the interval later (the wall-clock segments/s of
    `benchmarks/link.py`), and a long wait still polls at the interval."""
    import sys
    import time
    pauses: list[float] = []
    real_sleep = time.sleep

    def sleep(s: float) -> None:
        if sys._getframe(1).f_globals["__name__"] == Link.__module__:  # the link's own pauses
            pauses.append(s)
        real_sleep(s)

    link = Link.open("fivebar-mock://?speed=1")
    try:
        link.command("G1 A50 B-50 P300000")  # 0.3 s of motion
        monkeypatch.setattr(time, "sleep", sleep)
        st = link.wait_idle(5.0)
    finally:
        monkeypatch.undo()
        link.close()
    assert (st.a, st.b) == (50, -50)
    assert pauses[:5] == pytest.approx([0.003, 0.006, 0.012, 0.024, 0.048])
    assert len(pauses) > 6 and set(pauses[5:]) == {link.poll_interval_s}
