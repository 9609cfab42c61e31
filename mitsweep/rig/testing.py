"""Protocol testing in the style of pymeasure's ``expected_protocol``.

A test lists the exact bytes exchanged; the driver runs against a scripted byte stream
that fails on any write that is not the next expected one, and :func:`expected_protocol`
fails at exit if any expected exchange was not used or any reply was left unread::

    with expected_protocol(lambda t: ZaberStage(t, steps_per_mm=1000),
                           [(b"/1 1 get pos\\n", b"@01 1 OK IDLE -- 1500\\r\\n")]) as stage:
        assert stage.state().position == 1.5

An exchange ``(None, reply)`` is unsolicited output (a READY line, an event): it is
delivered right after the previous exchange's reply (or at once, if it comes first).
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from collections.abc import Callable, Iterable, Iterator

from .transport import LineTransport

__all__ = ["ScriptedSerial", "expected_protocol"]


class ScriptedSerial:
    """A pyserial-like object that plays a script of ``(write, reply)`` byte pairs.

    Parameters
    ----------
    exchanges : iterable of (bytes or None, bytes or None)
        In order, each write expected and the bytes it is answered with; a write of
        None is unsolicited output, delivered after the previous reply (or at once).
    """

    def __init__(self, exchanges: Iterable[tuple[bytes | None, bytes | None]]) -> None:
        self.exchanges = list(exchanges)
        self.index = 0
        self.timeout: float | None = 0
        self._rx = bytearray()
        self.closed = False
        self._deliver_unsolicited()

    def _deliver_unsolicited(self) -> None:
        while self.index < len(self.exchanges) and self.exchanges[self.index][0] is None:
            self._rx += self.exchanges[self.index][1] or b""
            self.index += 1

    # -- pyserial surface ---------------------------------------------------------------
    def write(self, data: bytes) -> int:
        """Take a write, which must be the next expected one, and queue its reply.

        Parameters
        ----------
        data : bytes
            What the driver sends.

        Raises
        ------
        AssertionError
            ``data`` is not the next exchange's write, or none is left.
        """
        if self.index >= len(self.exchanges):
            raise AssertionError(f"unexpected write {bytes(data)!r}: no exchange left")
        expected, reply = self.exchanges[self.index]
        if bytes(data) != expected:
            raise AssertionError(f"unexpected write {bytes(data)!r}, expected {expected!r} "
                                 f"(exchange {self.index})")
        self.index += 1
        self._rx += reply or b""
        self._deliver_unsolicited()
        return len(data)

    @property
    def in_waiting(self) -> int:
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes of the queued replies (waiting up to :attr:`timeout`,
        at most 10 ms, when none is queued).

        Parameters
        ----------
        size : int
            Most bytes to return.
        """
        if not self._rx and self.timeout:
            time.sleep(min(self.timeout, 0.01))   # nothing will ever come: honour the wait
        out = bytes(self._rx[:size])
        del self._rx[:size]
        return out

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.closed = True

    # -- checks -------------------------------------------------------------------------
    def assert_all_used(self) -> None:
        unused = self.exchanges[self.index:]
        if unused:
            raise AssertionError(f"{len(unused)} expected exchange(s) not used: {unused!r}")
        if self._rx:
            raise AssertionError(f"reply bytes never read: {bytes(self._rx)!r}")


@contextmanager
def expected_protocol(factory: Callable[[LineTransport], object],
                      exchanges: Iterable[tuple[bytes | None, bytes | None]], *,
                      timeout_s: float = 0.05, name: str = "device") -> Iterator[object]:
    """Yield ``factory(transport)`` on a scripted stream; fail on unused exchanges.

    Parameters
    ----------
    factory : callable
        Builds the driver under test from a :class:`~mitsweep.rig.transport.LineTransport`.
    exchanges : iterable of (bytes or None, bytes or None)
        The script (:class:`ScriptedSerial`): exact bytes written and replied.
    timeout_s : float
        The transport's read deadline, s.
    name : str
        The transport's device name.
    """
    ser = ScriptedSerial(exchanges)
    transport = LineTransport(ser, name=name, timeout_s=timeout_s)
    driver = factory(transport)
    yield driver
    ser.assert_all_used()
    if transport.unread:
        raise AssertionError(f"reply bytes never read: {transport.unread!r}")


def fast_rig_setup(setup, *, steps_per_mm: float = 400.0):
    """``setup`` with a rig that positions quickly (10 mm/s, 100 mm/s²), for tests and
    demos against the simulator; the sweep itself keeps the setup's velocity.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup to adapt.
    steps_per_mm : float
        The rig's steps (or microsteps) per mm.
    """
    import dataclasses

    rig = dataclasses.replace(setup.rig, max_velocity=10.0, acceleration=100.0,
                              steps_per_mm=steps_per_mm)
    return dataclasses.replace(setup, rig=rig)
