"""Setting up a worker process for dataset tasks (shared by the executors and Dask).

Mitsuba has no distributed rendering of its own, and a worker process inherits nothing
from the submitting one: it must select the Dr.Jit backend, set the Mitsuba variant and
register mitsweep's plugins itself. :func:`init_worker` does that when a pool process
(:mod:`~mitsweep.pipeline.executors`) or a Dask worker (:mod:`~mitsweep.pipeline.cluster`)
starts.
"""

from __future__ import annotations

import logging

__all__ = ["CONNECT_TIMEOUT_S", "init_worker"]

logger = logging.getLogger(__name__)

#: Seconds to reach a Dask scheduler given by address before giving up.
CONNECT_TIMEOUT_S = 10


def init_worker() -> None:
    """Prepare a fresh worker process for renders: backend, variant, sensor plugin.

    The backend is chosen on the worker (``MITSWEEP_BACKEND`` as the worker sees it),
    never copied from the submitting process. A failure is logged, not raised: the
    task that needs the backend raises it with its own message.
    """
    logging.getLogger("mitsweep").setLevel(logging.INFO)  # for the per-task logs
    try:
        from ..render.sensor import register

        variant = register()  # selects the backend and the variant first
        logger.info("worker ready: mitsuba variant %s, focalsweep sensor registered",
                    variant)
    except Exception as exc:  # BackendError, a missing library: the tasks will say
        logger.warning("worker set-up failed (%s); its render tasks will fail", exc)
