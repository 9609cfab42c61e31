"""Every network wait is bounded: a ``--scheduler`` that is not a Dask scheduler is one
line naming its address, within the advertised timeout.

The peers are real sockets on the loopback interface, served by threads of the test:
a listener that accepts and never speaks (Dask's own handshake read has no timeout),
an ``http.server`` (it waits for a request line that Dask's binary handshake never
completes), and a server that answers HTTP at once (Dask reads the answer's first eight
bytes as a frame length, exabytes). A refused port stays the "cannot reach" message.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, HTTPServer

import pytest

from conftest import run_cli
from mitsweep.pipeline import DatasetError
from mitsweep.pipeline.cluster import check_scheduler
from mitsweep.pipeline.executors import CONNECT_TIMEOUT_S
from test_io_write_errors import tiny_setup_toml

#: The CLI's bound: the connection timeout plus the start of a Python process that imports
#: mitsweep, Dask and Mitsuba (about 3 s idle; 10 s leaves room for a loaded machine).
CLI_BOUND_S = CONNECT_TIMEOUT_S + 10
#: A hang is declared after this long (the subprocess is killed).
HANG_S = 3 * CONNECT_TIMEOUT_S + 30


@contextlib.contextmanager
def _listener(on_accept):
    """A TCP listener on 127.0.0.1 whose accepted connections go to ``on_accept``;
    yields its address."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held: list[socket.socket] = []

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:  # closed by the test
                return
            held.append(conn)
            on_accept(conn)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        server.close()
        for conn in held:
            conn.close()


@contextlib.contextmanager
def silent_peer():
    """Accepts every connection and never sends a byte."""
    with _listener(lambda conn: None) as address:
        yield address


@contextlib.contextmanager
def http_answering_peer():
    """Sends an HTTP response as soon as a connection is accepted."""
    with _listener(lambda conn: conn.sendall(b"HTTP/1.0 400 Bad Request\r\n"
                                             b"Content-Length: 0\r\n\r\n")) as address:
        yield address


class _Quiet(BaseHTTPRequestHandler):
    def do_GET(self):
        self.send_response(200)
        self.end_headers()

    def log_message(self, *args):  # keep the test's output clean
        pass


@contextlib.contextmanager
def http_server():
    """``http.server`` in a thread."""
    server = HTTPServer(("127.0.0.1", 0), _Quiet)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.server_port}"
    finally:
        server.shutdown()
        server.server_close()


PEERS = {"silent": silent_peer, "http.server": http_server,
         "answers HTTP at once": http_answering_peer}


@pytest.mark.parametrize("peer", PEERS)
def test_check_scheduler_refuses_a_peer_that_is_not_dask_within_its_timeout(peer):
    timeout = 1.0
    with PEERS[peer]() as address:
        t0 = time.monotonic()
        with pytest.raises(DatasetError) as info:
            check_scheduler(address, timeout=timeout)
        elapsed = time.monotonic() - t0
    assert str(info.value).startswith(f"scheduler: {address} is not a Dask scheduler")
    # 1 s of slack: the probe's thread and event loop start, and the sockets close
    assert elapsed <= timeout + 1.0, elapsed


def test_check_scheduler_says_cannot_reach_a_closed_port():
    # A port bound but never listened on, then released: nothing listens there. (Not a
    # closed _listener: its thread blocked in accept() keeps the listening socket alive,
    # so connections were still accepted into its backlog, the full suite's flake.)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    with pytest.raises(DatasetError, match=f"cannot reach a Dask scheduler at {address}"):
        check_scheduler(address, timeout=1.0)


@pytest.mark.parametrize("peer", [
    "answers HTTP at once",
    # the full CONNECT_TIMEOUT_S (10 s) of waiting: the bounded wait on a silent peer is
    # checked in process above (1 s timeout), the command's one line by the case above
    pytest.param("silent", marks=pytest.mark.slow),
    # the same path as "silent" (no answer: the full timeout), checked in process above
    pytest.param("http.server", marks=pytest.mark.slow),
])
def test_dataset_with_a_scheduler_that_is_not_dask_is_one_line_in_bounded_time(tmp_path, peer):
    setup = tiny_setup_toml(tmp_path)
    with PEERS[peer]() as address:
        t0 = time.monotonic()
        rc, out, err = run_cli("dataset", setup, "--out", tmp_path / "ds", "--scheduler",
                               address, timeout=HANG_S)
        elapsed = time.monotonic() - t0
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith(f"mitsweep: error: scheduler: {address} is not a Dask "
                               f"scheduler ("), err
    assert out == ""
    assert elapsed <= CLI_BOUND_S, elapsed
    assert not (tmp_path / "ds").exists()
