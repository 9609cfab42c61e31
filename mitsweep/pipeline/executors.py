"""Where dataset tasks run: here, a local process pool, Dask, or any Executor.

:func:`open_executor` turns ``"serial"``, ``"process"``, ``"dask"`` (or an
:class:`concurrent.futures.Executor` given by the caller) into what
:func:`~mitsweep.pipeline.runner.run_tasks` takes. Mitsuba has no distributed rendering
of its own, and a worker process inherits nothing from the submitting one: it must
select the Dr.Jit backend, set the Mitsuba variant and register the ``focalsweep``
sensor itself, or a render fails with "Plugin not found". :func:`init_worker`
(:mod:`~mitsweep.pipeline.worker_setup`, shared with :mod:`~mitsweep.pipeline.cluster`) does that
when a pool process or a Dask worker starts (a process-pool initializer, a Dask worker
plugin), and the render and tracing tasks do it again themselves
(:func:`mitsweep.render.sensor.register`, idempotent), so a task also runs on an
executor that was never initialised.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import logging
import multiprocessing
import re
from collections.abc import Iterator

from .runner import DatasetError
from .worker_setup import CONNECT_TIMEOUT_S, init_worker

__all__ = ["EXECUTORS", "open_executor", "init_worker", "check_scheduler_address",
           "CONNECT_TIMEOUT_S"]

logger = logging.getLogger(__name__)

EXECUTORS = ("serial", "process", "dask")
_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9][A-Za-z0-9.-]*):"
                      r"([0-9]{1,5})$")


def check_scheduler_address(address: str) -> str:
    """``address`` checked as a Dask scheduler address: ``tcp://HOST:PORT`` (or
    ``tls://``), port 1–65535.

    Parameters
    ----------
    address : str
        The address as given (surrounding blanks are ignored).

    Returns
    -------
    str
        The address, stripped.

    Raises
    ------
    DatasetError
        Any other form, or a port out of range.
    """
    m = _ADDRESS.match(str(address).strip())
    if m is None or not 1 <= int(m.group(3)) <= 65535:
        raise DatasetError(f"scheduler: must be a Dask scheduler address tcp://HOST:PORT "
                           f"(port 1-65535), got {address!r}")
    return str(address).strip()


class RestartingProcessPool(cf.Executor):
    """A spawn-context process pool that replaces itself once broken (a process was
    killed), so that the runner can submit the lost tasks again: the ``"process"``
    executor of :func:`open_executor`.

    Parameters
    ----------
    jobs : int
        Worker processes (>= 1).
    initializer : callable or None, optional
        Runs in each new process before its first task (default :func:`init_worker`,
        which sets the renderer up; None: nothing).
    """

    def __init__(self, jobs: int, initializer=init_worker) -> None:
        self._jobs = jobs
        self._initializer = initializer
        self._pool = self._new()

    def _new(self) -> cf.ProcessPoolExecutor:
        return cf.ProcessPoolExecutor(max_workers=self._jobs, initializer=self._initializer,
                                      mp_context=multiprocessing.get_context("spawn"))

    def submit(self, fn, /, *args, **kwargs):
        """Schedule ``fn(*args, **kwargs)``; a broken pool is first replaced by a new one
        (logged), the tasks it lost being the caller's to submit again.

        Parameters
        ----------
        fn : callable
            The task, picklable (it runs in another process).
        *args, **kwargs
            Its arguments, picklable.

        Returns
        -------
        concurrent.futures.Future
        """
        try:
            return self._pool.submit(fn, *args, **kwargs)
        except cf.BrokenExecutor:
            logger.warning("a worker process died; starting a new pool of %d", self._jobs)
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = self._new()
            return self._pool.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Shut the current pool down (:meth:`concurrent.futures.Executor.shutdown`).

        Parameters
        ----------
        wait : bool, optional
            Wait for the running tasks to finish (default True).
        cancel_futures : bool, optional
            Cancel the tasks not yet started (default False).
        """
        self._pool.shutdown(wait=wait, cancel_futures=cancel_futures)


@contextlib.contextmanager
def open_executor(executor: str | cf.Executor = "serial", *, jobs: int = 2,
                  scheduler: str | None = None
                  ) -> Iterator[tuple[cf.Executor | None, tuple[type[BaseException], ...]]]:
    """The executor for a run and the exceptions that mean a lost worker.

    A pool or cluster started here is shut down on exit; an Executor passed in is the
    caller's and stays up.

    Parameters
    ----------
    executor : {"serial", "process", "dask"} or concurrent.futures.Executor
        Where tasks run: here, a spawn-context pool of ``jobs`` processes, Dask (an
        embedded local cluster of ``jobs`` workers, or ``scheduler``), or the caller's
        executor.
    jobs : int
        Worker processes of ``"process"`` and of the embedded Dask cluster (>= 1).
    scheduler : str, optional
        A Dask scheduler's address (:func:`check_scheduler_address`); implies
        ``"dask"`` (``"serial"``, the default, is taken as ``"dask"`` then).

    Yields
    ------
    (concurrent.futures.Executor or None, tuple of type)
        The executor (None for ``"serial"``: the runner runs tasks itself) and the
        exception types that mean a lost worker (Dask's; empty otherwise).

    Raises
    ------
    DatasetError
        An unknown executor, a bad ``jobs``, a bad scheduler address or one with an
        executor other than Dask.
    """
    if scheduler is not None:
        scheduler = check_scheduler_address(scheduler)
        if executor not in ("dask", "serial") or isinstance(executor, cf.Executor):
            raise DatasetError(f"scheduler: needs the 'dask' executor, got {executor!r}")
        executor = "dask"
    if isinstance(executor, cf.Executor):
        yield executor, _dask_lost_errors()
        return
    if executor not in EXECUTORS:
        raise DatasetError(f"executor: must be one of {', '.join(EXECUTORS)} or a "
                           f"concurrent.futures.Executor, got {executor!r}")
    if not (isinstance(jobs, int) and not isinstance(jobs, bool) and jobs >= 1):
        raise DatasetError(f"jobs: must be a positive integer, got {jobs!r}")
    if executor == "serial":
        yield None, ()
    elif executor == "process":
        pool = RestartingProcessPool(jobs)
        try:
            yield pool, ()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    else:
        from .cluster import dask_executor

        with dask_executor(jobs=jobs, scheduler=scheduler) as pool:
            yield pool, _dask_lost_errors()


def _dask_lost_errors() -> tuple[type[BaseException], ...]:
    """Dask's exceptions for a task whose workers died (when Dask is loaded)."""
    import sys

    if "distributed" not in sys.modules:
        return ()
    from distributed import KilledWorker
    from distributed.comm import CommClosedError

    return (KilledWorker, CommClosedError)
