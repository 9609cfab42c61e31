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
