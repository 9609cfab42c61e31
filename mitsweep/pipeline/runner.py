"""A resumable task runner: the items of a directory, a manifest, any executor.

A run makes the *items* of a directory (files, named by their path relative to it) from
:class:`Task`\\ s. A task is declared once: its function, its keyword parameters and its
inputs (other items). Those parameters and inputs are the item's manifest entry, with the
SHA-256 and size of the file as written; an item is complete when its entry has the
task's parameters and its file still has that checksum, so a rerun skips what is complete
and redoes the rest (also after a change of parameters).

The manifest holds nothing that differs between runs (no times, hosts or pids, items in
sorted order): one set of tasks gives the same bytes in every file and in the manifest,
whatever executed it. What does differ goes to the per-task logs, ``logs/ITEM.log``
(first line a JSON record: attempt, host, pid, start time, seconds; then the log records
of the task), written by the worker that ran it.

Tasks run in this process (``executor=None``, one at a time, in declaration order) or on
any :class:`concurrent.futures.Executor` (a process pool, Dask's
``Client.get_executor()``, ...), each as soon as its inputs are complete. A task whose
worker was lost (killed, or its pool broken) is submitted again, at most ``retries``
times; any other failure stops the run with the task's own exception. Either way the
items finished so far stay in the manifest, which is rewritten after every item, and a
rerun resumes.

Sharding (:class:`Shard`, ``K/N``) splits the tasks by their ``group`` (tasks of group
``g`` belong to shard ``g mod N + 1``); a shard also runs the shared tasks (group
``None``) its own tasks need, unless another run already made them. Shards run at the
same time into one directory: each holds its own lock and manifest
(``shards/K-of-N/``), and each, when done, merges every complete entry it finds into the
directory's manifest under the directory's lock; the merge that finds every item
complete writes the manifest a single run would have written and removes the shard
manifests. A run without a shard also adopts the entries of shard manifests, so it
finishes (or merges) what shards left.

Every write stays inside the directory: a folder below it that is a symbolic link (an
item's folder, ``logs/``, a shard's folder) is refused before anything is written
(:func:`refuse_symlinked_folders`), and an item that is itself a link is made again,
the link replaced by the file.
"""

from __future__ import annotations

import concurrent.futures as cf
import heapq
import json
import logging
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath
from typing import Any
from collections.abc import Callable, Iterable, Mapping, Sequence

from ..io import WriteError, write_text_atomic
from ..io.lock import DirectoryLock, DirectoryLocked
from ..io.scene_files import file_sha256 as sha256

__all__ = ["Task", "Shard", "DatasetError", "run_tasks", "sha256", "MANIFEST", "LOG_DIR",
           "SHARD_DIR", "DEFAULT_RETRIES", "MAX_SHARDS", "task_log_path", "read_task_log"]

logger = logging.getLogger(__name__)

MANIFEST = "manifest.json"
#: Per-task logs, under the directory: ``logs/ITEM.log``.
LOG_DIR = "logs"
#: Shards' own manifests and locks, under the directory: ``shards/K-of-N/``.
SHARD_DIR = "shards"
#: Times a task whose worker was lost is submitted again before the run stops.
DEFAULT_RETRIES = 2
MAX_SHARDS = 10_000
#: Seconds a finished shard waits for the directory's lock to merge (another shard's
#: merge takes about a second; a run without shards may hold it for hours).
MERGE_WAIT_S = 300.0
#: The package logger whose records a task's log holds.
_TOP_LOGGER = __name__.split(".")[0]


class DatasetError(ValueError):
    """A dataset directory is missing, inconsistent, or was made for another setup; or a
    run could not finish (the message says how to resume)."""


def _require(ok: bool, key: str, message: str) -> None:
    if not ok:
        raise DatasetError(f"{key}: {message}")


@dataclass(frozen=True)
class Shard:
    """Shard ``index`` of ``count`` (1-based: ``1/4`` … ``4/4``).

    Attributes
    ----------
    index : int
        K, in [1, ``count``].
    count : int
        N, the number of shards, in [1, :data:`MAX_SHARDS`].
    """

    index: int
    count: int

    def __post_init__(self) -> None:
        ok = (isinstance(self.index, int) and isinstance(self.count, int)
              and 1 <= self.index <= self.count <= MAX_SHARDS)
        _require(ok, "shard", f"must be K/N with 1 <= K <= N <= {MAX_SHARDS}, got "
                              f"{self.index!r}/{self.count!r}")

    @classmethod
    def parse(cls, text: str) -> Shard:
        """``"K/N"`` → ``Shard(K, N)``.

        Parameters
        ----------
        text : str
            ``K/N`` (blanks around the numbers allowed), e.g. ``"1/4"``.

        Returns
        -------
        Shard

        Raises
        ------
        DatasetError
            Naming the form, for any other text or a K or N out of range.
        """
        k, sep, n = str(text).strip().partition("/")
        if not (sep and k.strip().isdigit() and n.strip().isdigit()):
            raise DatasetError(f"shard: must be K/N with 1 <= K <= N <= {MAX_SHARDS} "
                               f"(e.g. 1/4), got {text!r}")
        return cls(int(k), int(n))

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"

    @property
    def dirname(self) -> str:
        """The shard's folder under :data:`SHARD_DIR`: ``K-of-N``."""
        return f"{self.index}-of-{self.count}"

    def owns(self, group: int) -> bool:
        """Whether the tasks of ``group`` are this shard's (``group mod N = K - 1``).

        Parameters
        ----------
        group : int
            A task's :attr:`Task.group` (not None).
        """
        return group % self.count == self.index - 1


@dataclass(frozen=True)
class Task:
    """One item of a directory and how to make it.

    ``fn(context, out, **inputs, **params)`` writes the file ``out``, atomically
    (:func:`mitsweep.io.atomic_path`, :func:`mitsweep.io.write_bytes_atomic`): an item
    that tasks of every group need (``group`` None) is made by every shard, at the same
    time where shards run at once, and each shard hashes what it wrote.

    Attributes
    ----------
    name : str
        The item: its file's path relative to the directory (``scene_000/sweep.exr``).
    fn : callable
        The task's function; it may return a dict of run information (timings) for the
        task's log.
    params : mapping
        Its other keyword arguments (JSON values): with the inputs' names, the item's
        manifest ``params``.
    inputs : mapping of str to str
        Keyword names to the items it reads (passed as paths; they are its
        dependencies).
    group : int or None
        The shard key (``None``: a task that tasks of every group may need).
    """

    name: str
    fn: Callable[..., Mapping[str, Any] | None]
    params: Mapping[str, Any] = field(default_factory=dict)
    inputs: Mapping[str, str] = field(default_factory=dict)
    group: int | None = None

    @property
    def deps(self) -> tuple[str, ...]:
        """The items this one is made from (the values of :attr:`inputs`)."""
        return tuple(self.inputs.values())

    def entry_params(self) -> dict:
        """The manifest's ``params`` of this item: its parameters and its inputs' names."""
        return _jsonable({**self.params, **self.inputs})


def _jsonable(obj):
    return json.loads(json.dumps(obj, default=str))


def task_log_path(root: Path, name: str) -> Path:
    """Where an item's task log is written.

    Parameters
    ----------
    root : Path
        The directory.
    name : str
        The item, relative to ``root``.

    Returns
    -------
    Path
        ``root/logs/NAME.log``.
    """
    return Path(root) / LOG_DIR / f"{name}.log"


def read_task_log(root: Path, name: str) -> dict | None:
    """The JSON record (first line) of an item's log.

    Parameters
    ----------
    root : Path
        The directory.
    name : str
        The item, relative to ``root``.

    Returns
    -------
    dict or None
        The record (``item``, ``attempt``, ``host``, ``pid``, ``started``, ``status``,
        ``seconds``...), or None if there is no log or its first line is not JSON.
    """
    try:
        with open(task_log_path(root, name), encoding="utf-8") as f:
            return json.loads(f.readline())
    except (OSError, ValueError):
        return None


# -- the worker side --------------------------------------------------------------------

class _Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


def run_task(task: Task, context: Any, root: str, attempt: int, coordinator_pid: int) -> dict:
    """Make one item (on whichever worker runs it) and checksum the file where it was
    written; write the task's log.

    Parameters
    ----------
    task : Task
        The item to make.
    context : object
        Passed to the task's function.
    root : str
        The directory (a string: it travels to other processes).
    attempt : int
        The submission's number, 1 for the first (recorded in the log).
    coordinator_pid : int
        The process id of the run's coordinator: a task run in that process leaves its
        warnings out of the result (they were shown already).

    Returns
    -------
    dict
        ``sha256`` and ``bytes`` of the file, ``seconds`` the task took and
        ``warnings`` (the messages the task logged at WARNING or above), for a
        coordinator in another process to show.

    Raises
    ------
    BaseException
        Whatever the task raised, after its log is written.
    """
    base = Path(root)
    out = base / task.name
    handler = _Records()
    top = logging.getLogger(_TOP_LOGGER)
    top.addHandler(handler)
    started = datetime.now(timezone.utc).isoformat(timespec="milliseconds")
    t0 = time.perf_counter()
    record = {"item": task.name, "attempt": attempt, "host": socket.gethostname(),
              "pid": os.getpid(), "started": started}
    try:
        info = task.fn(context, out, **{k: base / v for k, v in task.inputs.items()},
                       **task.params)
        digest, size = sha256(out), out.stat().st_size
    except BaseException as exc:
        top.removeHandler(handler)
        record.update(status="failed", seconds=round(time.perf_counter() - t0, 3),
                      error=f"{type(exc).__name__}: {exc}")
        _write_log(base, task.name, record, handler.records, traceback.format_exc())
        raise
    top.removeHandler(handler)
    seconds = time.perf_counter() - t0
    record.update(status="done", seconds=round(seconds, 3), sha256=digest, bytes=size,
                  **_jsonable(dict(info or {})))
    _write_log(base, task.name, record, handler.records)
    warnings = ([] if os.getpid() == coordinator_pid else  # else shown already
                [r.getMessage() for r in handler.records if r.levelno >= logging.WARNING])
    return {"sha256": digest, "bytes": size, "seconds": seconds, "warnings": warnings}


def _write_log(root: Path, name: str, record: dict, records: list, tail: str = "") -> None:
    """Best effort: a log that cannot be written (full disk) must not fail the item."""
    fmt = logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
    text = json.dumps(record, default=str) + "\n" + "".join(
        fmt.format(r) + "\n" for r in records) + tail
    path = task_log_path(root, name)
    link = symlinked_folder(Path(root), f"{LOG_DIR}/{name}.log")
    if link is not None:  # the coordinator refuses these; one made since is not followed
        logger.warning("%s: not written: %s is a symbolic link", path, link)
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, text)
    except OSError as exc:
        logger.warning("%s: cannot write the task's log (%s)", path, exc)


def _run_inline(task: Task, context: Any, root: str, attempt: int) -> cf.Future:
    """A finished future of ``task`` run here; KeyboardInterrupt and other
    BaseExceptions propagate at once."""
    fut: cf.Future = cf.Future()
    try:
        fut.set_result(run_task(task, context, root, attempt, os.getpid()))
    except Exception as exc:
        fut.set_exception(exc)
    return fut


# -- the coordinator side ---------------------------------------------------------------

def run_tasks(root: str | Path, tasks: Sequence[Task], context: Any, header: Mapping[str, Any],
              *, read_manifest: Callable[[Path], dict],
              check_header: Callable[[dict, Path], None],
              executor: cf.Executor | None = None,
              lost: tuple[type[BaseException], ...] = (),
              shard: Shard | None = None, wait: float | None = None, progress: bool = True,
              retries: int = DEFAULT_RETRIES, desc: str = "items") -> dict:
    """Make the items of ``root`` that are not complete; return the manifest.

    Parameters
    ----------
    root : path
        The directory (created if needed).
    tasks : sequence of Task
        Every item of the directory, in an order where inputs come first.
    context : object
        Passed to every task function (picklable for executors of other processes).
    header : mapping
        The manifest's other keys (what the items were made for), written before
        ``items``.
    read_manifest : callable
        ``read_manifest(path)``: a manifest file read and validated (raises
        :class:`DatasetError`).
    check_header : callable
        ``check_header(manifest, path)`` raises :class:`DatasetError` if a manifest
        found in the directory was made for something else.
    executor : concurrent.futures.Executor or None
        Where tasks run (``None``: here, one at a time).
    lost : tuple of exception types
        Failures meaning the task's worker was lost, besides
        :class:`concurrent.futures.BrokenExecutor`: the task is submitted again.
    shard : Shard, optional
        Run only this shard's tasks (see the module docstring).
    wait : float or None
        Seconds to wait for the lock of a run on the same directory (or shard);
        ``None`` refuses at once.
    progress : bool
        A tqdm bar of the items on stderr.
    retries : int
        Submissions of a task after its worker was lost, before the run stops.
    desc : str
        The progress bar's label.

    Returns
    -------
    dict
        The directory's manifest, with ``complete: true`` once every item verifies; a
        shard whose merge did not find every item complete returns its own manifest.
    """
    root = Path(root)
    if not (isinstance(retries, int) and retries >= 0):
        raise DatasetError(f"retries: must be an integer >= 0, got {retries!r}")
    home = root if shard is None else root / SHARD_DIR / shard.dirname
    if shard is not None:  # its lock and manifest go there
        refuse_symlinked_folders(root, [f"{SHARD_DIR}/{shard.dirname}/{MANIFEST}"])
    try:
        root.mkdir(parents=True, exist_ok=True)
        home.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DatasetError(f"{root}: cannot create the dataset directory "
                           f"({exc.strerror})") from None
    with DirectoryLock(home, wait=wait):  # before anything is written there
        mine = _select(tasks, shard)
        refuse_symlinked_folders(root, [n for t in mine
                                        for n in (t.name, f"{LOG_DIR}/{t.name}.log")])
        sources = _sources(root, read_manifest, check_header)
        manifest = {**header, "items": _complete_entries(root, mine, sources)}
        todo = [t for t in mine if t.name not in manifest["items"]]
        if len(mine) > len(todo):
            logger.info("resuming: %d of %d items already complete", len(mine) - len(todo),
                        len(mine))
        _write_manifest(home, manifest)  # entries that no longer verify are gone
        _prepare_directories(root, mine, todo, shard)
        _execute(root, home, manifest, todo, context, executor, lost=lost,
                 progress=progress, retries=retries, desc=desc)
        _verify(root, home, manifest, mine)
        if shard is None:
            manifest["complete"] = True
            _write_manifest(home, manifest)
            _remove_shard_manifests(root)
            return manifest
        _write_manifest(home, manifest)
    return _merge(root, tasks, header, read_manifest, check_header) or manifest


def symlinked_folder(root: Path, name: str) -> Path | None:
    """The first folder of ``name``'s path below ``root`` that is a symbolic link.

    Parameters
    ----------
    root : Path
        The directory (it may itself be a link: it is the user's choice of where the
        dataset is).
    name : str
        A POSIX path relative to ``root``.

    Returns
    -------
    Path or None
        That folder, or None when there is none.
    """
    parts = PurePosixPath(name).parts[:-1]
    for k in range(1, len(parts) + 1):
        p = root.joinpath(*parts[:k])
        if p.is_symlink():
            return p
    return None


def refuse_symlinked_folders(root: Path, names: Iterable[str]) -> None:
    """Refuse to write ``names`` (paths relative to ``root``) if a folder on the way is
    a symbolic link: written through, the dataset's files would land wherever it
    points, and a manifest whose items resolve outside the directory is refused when
    read. Each folder is examined once.

    Parameters
    ----------
    root : Path
        The directory.
    names : iterable of str
        POSIX paths relative to ``root`` about to be written.

    Raises
    ------
    DatasetError
        Naming the link and where it points.
    """
    seen: set[str] = set()
    for name in names:
        parent = PurePosixPath(name).parent.as_posix()
        if parent in seen:
            continue
        seen.add(parent)
        link = symlinked_folder(root, name)
        if link is not None:
            raise DatasetError(f"{link}: a symbolic link (to {os.readlink(link)}), not a "
                               f"folder of the dataset; mitsweep never writes through a "
                               f"link: remove it (and move what it holds back if needed), "
                               f"then rerun")


def _select(tasks: Sequence[Task], shard: Shard | None) -> list[Task]:
    """A shard's tasks and the tasks they need (in declaration order)."""
    if shard is None:
        return list(tasks)
    by_name = {t.name: t for t in tasks}
    wanted = {t.name for t in tasks if t.group is not None and shard.owns(t.group)}
    stack = list(wanted)
    while stack:
        for dep in by_name[stack.pop()].deps:
            if dep not in wanted:
                wanted.add(dep)
                stack.append(dep)
    return [t for t in tasks if t.name in wanted]


def _shard_manifests(root: Path) -> list[Path]:
    """The shards' manifests (none through a symlinked folder: they are not the
    directory's)."""
    if (root / SHARD_DIR).is_symlink():
        return []
    return sorted(p for p in (root / SHARD_DIR).glob(f"*/{MANIFEST}")
                  if not p.parent.is_symlink() and not p.is_symlink())


def _sources(root: Path, read_manifest, check_header) -> list[dict]:
    """Every manifest of the directory: its own, then the shards' (each validated and
    checked to be of the same dataset)."""
    out = []
    for path in [root / MANIFEST, *_shard_manifests(root)]:
        if path.is_file():
            manifest = read_manifest(path)
            check_header(manifest, path)
            out.append(manifest)
    return out


def _complete_entries(root: Path, tasks: Iterable[Task], sources: list[dict]) -> dict:
    """The entries of ``tasks`` (inputs first) some manifest records with the task's
    parameters, whose file still has the recorded SHA-256 (each file hashed once) and
    whose inputs are complete too (an item made from an input that is redone is
    redone), sorted."""
    found = {}
    for t in tasks:
        if not all(d in found for d in t.deps):
            continue
        params = t.entry_params()
        p = root / t.name
        digest = None
        for manifest in sources:
            item = manifest["items"].get(t.name)
            if item is None or item.get("params") != params:
                continue
            if digest is None:
                if p.is_symlink() or not p.is_file():  # a link is replaced, not trusted
                    break
                digest = sha256(p)
            if item.get("sha256") == digest:
                found[t.name] = {"params": params, "sha256": digest, "bytes": item["bytes"]}
                break
    return dict(sorted(found.items()))


def _prepare_directories(root: Path, mine: list[Task], todo: list[Task],
                         shard: Shard | None) -> None:
    """Parent folders of the items to make, and no temporaries left by a worker killed
    while writing an item or its log (only of items no other shard writes)."""
    for t in todo:
        p = root / t.name
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise WriteError(exc.errno, exc.strerror, str(p.parent)) from None
    ours = [t.name for t in mine if shard is None or t.group is not None]
    _sweep_temporaries(root, ours + [f"{LOG_DIR}/{n}.log" for n in ours])


def _sweep_temporaries(root: Path, names: Iterable[str]) -> None:
    """Remove the temporaries of these items (the atomic writers name them
    ``.NAME.*`` beside NAME), listing each folder once."""
    by_dir: dict[Path, set[str]] = {}
    for n in names:
        p = root / n
        by_dir.setdefault(p.parent, set()).add(p.name)
    for folder, basenames in by_dir.items():
        try:
            entries = [e.name for e in os.scandir(folder) if e.name.startswith(".")]
        except FileNotFoundError:
            continue
        for entry in entries:
            if any(entry.startswith(f".{b}.") for b in basenames):
                (folder / entry).unlink(missing_ok=True)
                logger.debug("removed %s, left by an interrupted write", folder / entry)


def _remove_temporaries(path: Path) -> None:
    _sweep_temporaries(path.parent, [path.name])


def _submit(executor: cf.Executor | None, task: Task, context: Any, root: Path,
            attempt: int, finished: int) -> cf.Future:
    if executor is None:
        return _run_inline(task, context, str(root), attempt)
    try:
        return executor.submit(run_task, task, context, str(root), attempt, os.getpid())
    except Exception as exc:  # a shut-down pool, a lost cluster
        raise DatasetError(f"cannot submit {task.name} to the executor ({exc}); the "
                           f"{finished} items finished are kept: rerun the same command "
                           f"to resume") from exc


#: Most tasks submitted to an executor and not yet finished (memory of huge runs).
MAX_IN_FLIGHT = 1024
#: The manifest is rewritten after every item up to this many entries; beyond, at most
#: every :data:`MANIFEST_INTERVAL_S` (rewriting a huge manifest after every item would
#: cost more than the items): a coordinator killed then loses the entries of that last
#: second, whose items a rerun makes again.
MANIFEST_EVERY_ITEM_UP_TO = 2000
MANIFEST_INTERVAL_S = 1.0


def _execute(root: Path, home: Path, manifest: dict, todo: list[Task], context: Any,
             executor: cf.Executor | None, *, lost: tuple[type[BaseException], ...],
             progress: bool, retries: int, desc: str) -> None:
    """Run ``todo``: each task once its inputs are done, in declaration order among
    those ready; record each finished item in the manifest at once."""
    lost_worker: tuple[type[BaseException], ...] = (cf.BrokenExecutor, cf.CancelledError, *lost)
    order = {t.name: k for k, t in enumerate(todo)}
    blocking = {t.name: {d for d in t.deps if d not in manifest["items"]} for t in todo}
    dependents: dict[str, list[Task]] = {}
    for t in todo:
        for d in blocking[t.name]:
            dependents.setdefault(d, []).append(t)
    ready = [order[t.name] for t in todo if not blocking[t.name]]
    heapq.heapify(ready)
    running: dict[cf.Future, Task] = {}
    attempts: dict[str, int] = {}
    limit = 1 if executor is None else MAX_IN_FLIGHT
    bar = _progress(len(todo), progress, desc)
    written = time.monotonic()
    try:
        while ready or running:
            while ready and len(running) < limit:
                t = todo[heapq.heappop(ready)]
                attempts[t.name] = attempts.get(t.name, 0) + 1
                running[_submit(executor, t, context, root, attempts[t.name],
                                len(manifest["items"]))] = t
            if not running:
                break
            finished, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for fut in sorted(finished, key=lambda f: order[running[f].name]):
                t = running.pop(fut)
                try:
                    result = fut.result()
                except lost_worker as exc:
                    _remove_temporaries(root / t.name)  # its worker died writing it
                    if attempts[t.name] > retries:
                        raise DatasetError(
                            f"{t.name}: its worker was lost {attempts[t.name]} times "
                            f"({type(exc).__name__}: {exc}); the {len(manifest['items'])} "
                            f"items finished are kept: rerun the same command to "
                            f"resume") from exc
                    logger.warning("%s: its worker was lost (%s); submitting it again "
                                   "(attempt %d of %d)", t.name, type(exc).__name__,
                                   attempts[t.name] + 1, retries + 1)
                    heapq.heappush(ready, order[t.name])
                    continue
                manifest["items"][t.name] = {"params": t.entry_params(),
                                             "sha256": result["sha256"],
                                             "bytes": result["bytes"]}
                if (len(manifest["items"]) <= MANIFEST_EVERY_ITEM_UP_TO
                        or time.monotonic() - written >= MANIFEST_INTERVAL_S):
                    _write_manifest(home, manifest)
                    written = time.monotonic()
                bar.update(1)
                for message in result["warnings"]:
                    logger.warning("%s: %s", t.name, message)
                for u in dependents.get(t.name, ()):
                    blocking[u.name].discard(t.name)
                    if not blocking[u.name]:
                        heapq.heappush(ready, order[u.name])
        left = [t.name for t in todo if t.name not in manifest["items"]]
        if left:
            raise DatasetError("tasks with unmet dependencies: " + ", ".join(left))
    except BaseException:
        for fut, t in running.items():
            if fut.cancel() or fut.done():  # nothing writes it any more
                _remove_temporaries(root / t.name)
        try:  # keep what finished; the failure itself is what the caller must see
            _write_manifest(home, manifest)
        except OSError as exc:
            logger.warning("%s: cannot record the finished items (%s)", home / MANIFEST, exc)
        raise
    finally:
        bar.close()
    _write_manifest(home, manifest)


def _verify(root: Path, home: Path, manifest: dict, tasks: list[Task]) -> None:
    """Every item's file still matches its recorded SHA-256, or the run is not
    complete: a mismatching item is dropped from the manifest (a rerun redoes it)."""
    bad = [t.name for t in tasks if not (root / t.name).is_file()
           or sha256(root / t.name) != manifest["items"][t.name]["sha256"]]
    if bad:
        for name in bad:
            manifest["items"].pop(name, None)
        _write_manifest(home, manifest)
        raise DatasetError(f"{root / bad[0]}: changed after it was written (its SHA-256 no "
                           f"longer matches the manifest"
                           + (f"; {len(bad) - 1} more items too" if len(bad) > 1 else "")
                           + "); rerun the same command to redo it")


def _merge(root: Path, tasks: Sequence[Task], header: Mapping[str, Any], read_manifest,
           check_header) -> dict | None:
    """Merge the shards' complete entries into the directory's manifest (under its
    lock); complete, it is the manifest of one run and the shard manifests go."""
    try:
        with DirectoryLock(root, wait=MERGE_WAIT_S):
            items = _complete_entries(root, tasks, _sources(root, read_manifest,
                                                            check_header))
            manifest = {**header, "items": items}
            if len(items) == len(tasks):
                manifest["complete"] = True
            _write_manifest(root, manifest)
            if manifest.get("complete"):
                _remove_shard_manifests(root)
                logger.info("%s: every shard is done; merged into %s", root, MANIFEST)
            else:
                logger.info("%s: %d of %d items done; the last shard to finish merges",
                            root, len(items), len(tasks))
            return manifest
    except DirectoryLocked as exc:
        logger.warning("%s; not merged: rerun without --shard to merge", exc)
        return None


def _remove_shard_manifests(root: Path) -> None:
    """Shard manifests of a complete directory (their entries are in its manifest);
    a shard whose run still holds its lock is left alone."""
    for path in _shard_manifests(root):
        try:
            with DirectoryLock(path.parent):
                path.unlink()
        except DirectoryLocked:
            continue
        try:
            path.parent.rmdir()
        except OSError:
            pass
    try:
        (root / SHARD_DIR).rmdir()
    except OSError:
        pass


def _write_manifest(home: Path, manifest: dict) -> None:
    manifest["items"] = dict(sorted(manifest["items"].items()))
    write_text_atomic(home / MANIFEST, json.dumps(manifest, indent=1, default=str) + "\n")


class _NoBar:
    def update(self, n=1):
        pass

    def close(self):
        pass


def _progress(total: int, enabled: bool, desc: str):
    if not enabled or total == 0:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="item", leave=False)
