"""Dask for dataset runs: an embedded ``LocalCluster`` or a running scheduler.

Imported only for ``executor="dask"`` (``dask.distributed`` is a dependency). The
embedded cluster runs ``jobs`` worker processes of one thread each (Dr.Jit and the FFTs
use the cores of a process; one task per process keeps them from competing), on the
loopback interface, with no dashboard, and downloads nothing. Every worker runs
:func:`~mitsweep.pipeline.worker_setup.init_worker` when it starts (also when its nanny
restarts it after it died), through :class:`MitsweepWorkerPlugin`.

A scheduler given by address is checked first by :func:`check_scheduler`: the TCP
connection, Dask's handshake and one ``identity`` request and its answer, all within
:data:`~mitsweep.pipeline.worker_setup.CONNECT_TIMEOUT_S` in all. Dask bounds only the
connection (its handshake read has no timeout: a server that accepts and never speaks
holds the client for ever), and it reads an HTTP server's answer as the length of a
frame (an allocation of exabytes); both become one :class:`DatasetError` naming the
address.
"""

from __future__ import annotations

import asyncio
import concurrent.futures as cf
import contextlib
import logging
from collections.abc import Iterator

from distributed import Client, LocalCluster, Worker, WorkerPlugin

from .runner import DatasetError
from .worker_setup import CONNECT_TIMEOUT_S, init_worker

__all__ = ["MitsweepWorkerPlugin", "check_scheduler", "dask_executor", "local_cluster"]

logger = logging.getLogger(__name__)


class MitsweepWorkerPlugin(WorkerPlugin):
    """Selects the backend, sets the Mitsuba variant and registers the ``focalsweep``
    sensor on each worker as it starts."""

    name = "mitsweep"

    def setup(self, worker: Worker) -> None:
        """Initialise the worker (:func:`~mitsweep.pipeline.worker_setup.init_worker`).

        Parameters
        ----------
        worker : distributed.Worker
            The worker starting (Dask's argument; the set-up is per process and does
            not use it).
        """
        init_worker()


def local_cluster(jobs: int) -> LocalCluster:
    """``jobs`` single-threaded worker processes on 127.0.0.1, no dashboard.

    Parameters
    ----------
    jobs : int
        Worker processes (one thread each).

    Returns
    -------
    distributed.LocalCluster
        Started; the caller closes it.
    """
    return LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address=None,
                        silence_logs=logging.ERROR)


async def _reach(host: str, port: int) -> None:
    """Open and close a TCP connection (OSError when nothing listens)."""
    _, writer = await asyncio.open_connection(host, port)
    writer.close()


async def _identity(address: str, timeout: float) -> dict:
    """The scheduler's answer to ``identity`` (a dict with ``type``)."""
    from distributed.comm import connect

    comm = await connect(address, timeout=timeout)
    try:
        await comm.write({"op": "identity", "reply": True})
        return await comm.read()
    finally:
        comm.abort()


async def _probe(address: str, timeout: float) -> dict:
    from distributed.comm.addressing import get_address_host_port

    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    host, port = get_address_host_port(address)
    try:
        await asyncio.wait_for(_reach(host, port), timeout)
    except asyncio.TimeoutError:
        raise OSError(f"no connection within {timeout:g} s") from None
    return await asyncio.wait_for(_identity(address, timeout),
                                  max(deadline - loop.time(), 0.0))


def check_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Raise :class:`DatasetError` unless a Dask scheduler answers at ``address``
    within ``timeout`` seconds in all: the TCP connection, Dask's handshake and an
    ``identity`` request.

    The check runs on an event loop of its own in a helper thread, so that it also
    works where the caller runs one (a notebook).

    Parameters
    ----------
    address : str
        The scheduler's address, ``tcp://HOST:PORT`` or ``tls://HOST:PORT``.
    timeout : float
        Seconds for the whole check (default
        :data:`~mitsweep.pipeline.worker_setup.CONNECT_TIMEOUT_S`).

    Raises
    ------
    DatasetError
        One line naming the address: nothing reachable, or not a Dask scheduler.
    """
    with cf.ThreadPoolExecutor(max_workers=1, thread_name_prefix="mitsweep-probe") as pool:
        try:
            reply = pool.submit(asyncio.run, _probe(address, timeout)).result()
        except asyncio.TimeoutError:  # connected, then no (complete) Dask answer
            raise DatasetError(f"scheduler: {address} is not a Dask scheduler (no Dask "
                               f"answer within {timeout:g} s)") from None
        except OSError as exc:  # refused, unreachable, closed at once
            raise DatasetError(f"scheduler: cannot reach a Dask scheduler at {address} "
                               f"within {timeout:g} s ({exc})") from None
        except Exception as exc:  # garbled frames: MemoryError, ValueError, msgpack's
            raise DatasetError(f"scheduler: {address} is not a Dask scheduler (its answer "
                               f"is not Dask's protocol: {type(exc).__name__})") from None
    if not (isinstance(reply, dict) and reply.get("type") == "Scheduler"):
        kind = reply.get("type") if isinstance(reply, dict) else type(reply).__name__
        raise DatasetError(f"scheduler: {address} is not a Dask scheduler (it is a "
                           f"{kind})")


@contextlib.contextmanager
def dask_executor(*, jobs: int, scheduler: str | None = None) -> Iterator:
    """A ``concurrent.futures`` view of a Dask client (``pure=False``: a task submitted
    again after its worker was lost is a new task, not the failed one).

    Every worker is initialised by :class:`MitsweepWorkerPlugin`; the client, and the
    cluster when one was started here, are closed on exit.

    Parameters
    ----------
    jobs : int
        Worker processes of the embedded :func:`local_cluster` (unused with
        ``scheduler``).
    scheduler : str, optional
        The address of a running scheduler (checked by :func:`check_scheduler`); None
        starts an embedded local cluster.

    Yields
    ------
    concurrent.futures.Executor
        The client's executor.

    Raises
    ------
    DatasetError
        The scheduler cannot be reached or is not a Dask scheduler.
    """
    cluster = None
    try:
        if scheduler is None:
            cluster = local_cluster(jobs)
            client = Client(cluster)
        else:
            check_scheduler(scheduler)
            try:
                client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
            except OSError as exc:  # TimeoutError included
                raise DatasetError(f"scheduler: cannot reach a Dask scheduler at "
                                   f"{scheduler} within {CONNECT_TIMEOUT_S} s ({exc})"
                                   ) from None
    except BaseException:
        if cluster is not None:
            cluster.close()
        raise
    try:
        client.register_plugin(MitsweepWorkerPlugin(), name=MitsweepWorkerPlugin.name)
        n = len(client.scheduler_info().get("workers", {}))
        logger.info("dask: %s, %d workers", scheduler or "local cluster", n)
        executor = client.get_executor(pure=False)
        yield executor
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
