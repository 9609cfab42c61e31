"""Dask for dataset runs: an embedded ``LocalCluster`` or a running scheduler.

Imported only for ``executor="dask"`` (``dask.distributed`` is a dependency). The
embedded cluster runs ``jobs`` worker processes of one thread each (Dr.Jit and the FFTs
use the cores of a process; one task per process keeps them from competing), on the
loopback interface, with no dashboard, and downloads nothing. Every worker runs
:func:`~mitsweep.pipeline.executors.init_worker` when it starts (also when its nanny
restarts it after it died), through :class:`MitsweepWorkerPlugin`.
"""

from __future__ import annotations

import contextlib
import logging
from typing import Iterator

from distributed import Client, LocalCluster, Worker, WorkerPlugin

from .executors import CONNECT_TIMEOUT_S, init_worker
from .runner import DatasetError

__all__ = ["MitsweepWorkerPlugin", "dask_executor", "local_cluster"]

logger = logging.getLogger(__name__)


class MitsweepWorkerPlugin(WorkerPlugin):
    """Selects the backend, sets the Mitsuba variant and registers the ``focalsweep``
    sensor on each worker as it starts."""

    name = "mitsweep"

    def setup(self, worker: Worker) -> None:
        init_worker()


def local_cluster(jobs: int) -> LocalCluster:
    """``jobs`` single-threaded worker processes on 127.0.0.1, no dashboard."""
    return LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address=None,
                        silence_logs=logging.ERROR)


@contextlib.contextmanager
def dask_executor(*, jobs: int, scheduler: str | None = None) -> Iterator:
    """A ``concurrent.futures`` view of a Dask client (``pure=False``: a task submitted
    again after its worker was lost is a new task, not the failed one)."""
    cluster = None
    try:
        if scheduler is None:
            cluster = local_cluster(jobs)
            client = Client(cluster)
        else:
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
