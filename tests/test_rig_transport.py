"""Line transport on a real pty: deadlines, strict framing, the log, a vanishing port."""

from __future__ import annotations

import os
import time
import tty

import pytest

from mitsweep.rig.errors import PortLost, PortUnavailable, ProtocolError, ReplyTimeout
from mitsweep.rig.transport import LineTransport, XorChecksum, open_port


@pytest.fixture
def pty_link():
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    transport = LineTransport(open_port(path), name="dut", timeout_s=0.2)
    state = {"master": master, "slave": slave}
    yield transport, state
    transport.close()
    for fd in state.values():
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass


def test_line_round_trip_and_log(pty_link):
    t, fds = pty_link
    t.write_line("PING")
    assert os.read(fds["master"], 100) == b"PING\n"
    os.write(fds["master"], b"PONG 1\r\nPONG 2\n")
    assert [t.read_line(), t.read_line()] == ["PONG 1", "PONG 2"]
    entries = t.log.entries
    assert [(e.direction, e.text) for e in entries] == [("tx", "PING"), ("rx", "PONG 1"),
                                                         ("rx", "PONG 2")]
    assert all(b.t_s >= a.t_s for a, b in zip(entries, entries[1:]))


def test_nothing_before_deadline_is_timeout(pty_link):
    t, _ = pty_link
    start = time.monotonic()
    with pytest.raises(ReplyTimeout):
        t.read_line(timeout_s=0.1)
    # the deadline is honoured: not early, and not much later (0.05 s read granularity)
    assert 0.1 <= time.monotonic() - start < 0.3


def test_partial_line_at_deadline_is_protocol_error(pty_link):
    t, fds = pty_link
    os.write(fds["master"], b"OK STA")
    with pytest.raises(ProtocolError, match="partial line"):
        t.read_line(timeout_s=0.1)


@pytest.mark.parametrize("junk", [b"\xff\xfe\x01\n", b"OK\x07BELL\n"])
def test_non_printable_line_is_protocol_error(pty_link, junk):
    t, fds = pty_link
    os.write(fds["master"], junk)
    with pytest.raises(ProtocolError, match="garbage"):
        t.read_line()


def test_checksum_applied_both_ways(pty_link):
    t, fds = pty_link
    t.checksum = XorChecksum()
    t.write_line("STOP")
    assert os.read(fds["master"], 100) == b"STOP*18\n"
    os.write(fds["master"], b"OK CLOSE*00\n")
    with pytest.raises(ProtocolError, match="bad checksum"):
        t.read_line()


def test_closed_far_end_is_port_lost(pty_link):
    t, fds = pty_link
    os.close(fds["master"])
    os.close(fds["slave"])
    fds["master"] = fds["slave"] = None
    with pytest.raises(PortLost):
        t.read_line(timeout_s=0.2)
    with pytest.raises(PortLost):   # and stays lost
        t.write_line("STOP")


def test_missing_port_is_port_unavailable(tmp_path):
    with pytest.raises(PortUnavailable, match="cannot open"):
        open_port(str(tmp_path / "ttyACM9"))


def test_busy_cores_fixture_keeps_the_cpus_busy(busy_cores):
    """The load the rig tests run under in CI: one spinning process per CPU."""
    assert len(busy_cores) == (os.cpu_count() or 2)
    for pid in busy_cores:
        os.kill(pid, 0)   # alive (raises if not)
    time.sleep(0.5)
    ticks = [int(open(f"/proc/{pid}/stat").read().split()[13]) for pid in busy_cores]
    assert all(t > 0 for t in ticks), ticks   # each got CPU time (user ticks)


def _answer_stop(fds, reply: bytes, *, after_s: float = 0.0):
    """Device thread: wait for ``STOP``, then answer ``reply``."""
    import threading

    def run():
        got = b""
        while b"STOP\n" not in got:
            got += os.read(fds["master"], 100)
        time.sleep(after_s)
        os.write(fds["master"], reply)
    th = threading.Thread(target=run, daemon=True)
    th.start()
    return th


def test_safety_path_discards_a_partial_line_left_by_an_interruption(pty_link):
    """A signal can land between a read and its use, leaving the head of a line ("E" of
    "EV OPEN ...") in the buffer; the stop's reply must not be glued to it (seen under
    load: 'EOK STOP 366770 5139', the stop then reported unconfirmed)."""
    from mitsweep.rig.arduino import ArduinoSweepController

    t, fds = pty_link
    os.write(fds["master"], b"EV POS 1 2\nE")
    time.sleep(0.05)
    assert t.read_line() == "EV POS 1 2"
    t.fill(0.05)                       # the partial "E" is now buffered
    assert t.unread == b"E"
    th = _answer_stop(fds, b"OK STOP 1234 5139\n")
    a = ArduinoSweepController(t, steps_per_mm=400.0)
    assert a.safe_stop(timeout_s=1.0) == 5139
    th.join(1.0)
    assert any(e.text == "E <partial, discarded>" for e in t.log.entries)


def test_safety_path_sends_the_stop_again_when_unanswered(pty_link):
    """A lost reply (or a garbled one) is not the end: the stop is idempotent and is sent
    again, ``attempts`` times in all, before it counts as unconfirmed."""
    t, fds = pty_link
    sent = []

    def device():
        got = b""
        while got.count(b"STOP\n") < 2:   # ignore the first STOP, answer the second
            got += os.read(fds["master"], 100)
        sent.append(got)
        os.write(fds["master"], b"OK STOP 1 7\n")
    import threading

    th = threading.Thread(target=device, daemon=True)
    th.start()
    got = t.send_on_safety_path("STOP", lambda ln: ln if ln.startswith("OK STOP") else None,
                                timeout_s=0.3, attempts=3)
    th.join(1.0)
    assert got == "OK STOP 1 7" and sent[0].count(b"STOP\n") == 2
    with pytest.raises(ReplyTimeout, match="in 2 attempts"):
        t.send_on_safety_path("STOP", lambda ln: None, timeout_s=0.1, attempts=2)
