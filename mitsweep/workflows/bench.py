"""Reproducible benchmarks, every target in one process (``mitsweep bench``).

Each target is a module ``mitsweep.<pkg>.bench`` exposing ``run_bench(options) -> dict``
(``options.quick``: smaller problem sizes), or a study module without one whose runner
is here (:data:`RUNNERS`: ``weights``, the weight choice against the oracle,
:func:`weight_bench`). Baselines run in the same process as what they are compared
with, so that ratios survive a noisy machine.
"""

from __future__ import annotations

import importlib
import logging
import os
import resource
import time
from collections.abc import Callable, Iterable
from types import ModuleType, SimpleNamespace
from typing import Any

from .. import __version__
from ._base import WorkflowResult

__all__ = ["run_benchmarks", "BENCH_TARGETS", "RUNNERS", "TargetMissing", "reset_peak_rss",
           "peak_rss_mib", "weight_bench"]

logger = logging.getLogger(__name__)

#: Target name → its benchmark module.
BENCH_TARGETS = {
    "tracer": "mitsweep.tracer.bench",
    "render": "mitsweep.render.bench",
    "deconv": "mitsweep.deconv.bench",
    "dataset": "mitsweep.pipeline.bench",
    "calibrate": "mitsweep.photo.bench",
    "weights": "mitsweep.deconv.weight_bench",
}
# Each module imported by its literal name (the layering check reads every import).
_IMPORTERS: dict[str, Callable[[], ModuleType]] = {
    "tracer": lambda: importlib.import_module("mitsweep.tracer.bench"),
    "render": lambda: importlib.import_module("mitsweep.render.bench"),
    "deconv": lambda: importlib.import_module("mitsweep.deconv.bench"),
    "dataset": lambda: importlib.import_module("mitsweep.pipeline.bench"),
    "calibrate": lambda: importlib.import_module("mitsweep.photo.bench"),
    "weights": lambda: importlib.import_module("mitsweep.deconv.weight_bench"),
}

#: The sizes (px) and noise levels σ of ``bench weights``: quick, and full (the
#: independent blur of docs/guide/weights.md at 512 px).
WEIGHT_BENCH_QUICK: dict[str, tuple] = {"sizes": (256,), "sigmas": (0.005, 0.001)}
WEIGHT_BENCH_FULL: dict[str, tuple] = {"sizes": (512,), "sigmas": (0.005, 0.001)}


def weight_bench(options: SimpleNamespace) -> dict:
    """The ``weights`` target: Wiener's chosen NSR against the oracle NSR (the best, by
    search against the truth) on the independent spatially varying blur
    (:func:`mitsweep.deconv.weight_bench.synthetic_weight_bench`), one process.

    Parameters
    ----------
    options : namespace
        ``options.quick``: 256 px instead of 512 px (both at σ = 0.005 and 0.001,
        :data:`WEIGHT_BENCH_QUICK`, :data:`WEIGHT_BENCH_FULL`).

    Returns
    -------
    dict
        ``sizes_px``, ``sigmas`` and ``rules`` (what each chosen NSR is), and ``cases``:
        per case (``"256px_sigma_0.005"``) the ``oracle``'s ``nsr`` and ``psnr_db``, and
        for each rule (``before``: the former blind estimate, the baseline; ``model``:
        :func:`~mitsweep.deconv.weights.model_nsr` with the known σ; ``blind``:
        :func:`~mitsweep.deconv.weights.blind_nsr`; ``mirror``: ``model_nsr`` with the
        spectrum read over the disk) its ``nsr``, ``psnr_db`` and
        ``loss_db`` (oracle − chosen), and ``model_seconds``, ``blind_seconds``.
    """
    from ..deconv.weight_bench import synthetic_weight_bench

    sizes = WEIGHT_BENCH_QUICK if getattr(options, "quick", False) else WEIGHT_BENCH_FULL
    rows = synthetic_weight_bench(sizes["sizes"], sizes["sigmas"])
    cases = {}
    for (size, sigma), row in zip([(n, g) for n in sizes["sizes"] for g in sizes["sigmas"]],
                                  rows, strict=True):
        case: dict = {"oracle": {"nsr": row["oracle"]["weight"],
                                 "psnr_db": row["oracle"]["psnr_db"]}}
        for rule in ("before", "model", "blind", "mirror"):
            case[rule] = {"nsr": row[rule]["weight"], "psnr_db": row[rule]["psnr_db"],
                          "loss_db": row[rule]["loss_db"]}
        case["model_seconds"] = row["model_seconds"]
        case["blind_seconds"] = row["blind_seconds"]
        cases[f"{size}px_sigma_{sigma:g}"] = case
    return {"sizes_px": list(sizes["sizes"]), "sigmas": list(sizes["sigmas"]),
            "rules": {"before": "polar Wiener's nsr=None: sigma^2 over the image variance "
                                "(the former rule, the baseline)",
                      "model": "deconv.weights.model_nsr with the known sigma",
                      "blind": "deconv.weights.blind_nsr (nothing known)",
                      "mirror": "deconv.weights.model_nsr with the known sigma and the "
                                "spectrum read over the disk (spectrum='mirror')"},
            "cases": cases}


#: Targets whose module has no ``run_bench``: the runner that benchmarks it.
RUNNERS: dict[str, Callable[[SimpleNamespace], dict]] = {"weights": weight_bench}


def _runner(name: str, module: ModuleType) -> Callable[[SimpleNamespace], dict]:
    """The function that runs target ``name`` whose module is ``module``."""
    runner = RUNNERS.get(name)
    if runner is not None and not hasattr(module, "run_bench"):
        return runner
    return module.run_bench


class TargetMissing(Exception):
    """The benchmark module of a target is not part of this installation."""


def missing_module(exc: ModuleNotFoundError, modname: str) -> bool:
    """Whether ``exc`` says that ``modname`` itself (or a package holding it) does not
    exist, rather than a dependency it imports."""
    return exc.name is not None and (modname == exc.name or modname.startswith(exc.name + "."))


def _import_target(name: str) -> ModuleType:
    try:
        return _IMPORTERS[name]()
    except ModuleNotFoundError as exc:
        if missing_module(exc, BENCH_TARGETS[name]):
            raise TargetMissing(f"{BENCH_TARGETS[name]} is not available ({exc})") from exc
        raise


def _read_status_kib(field: str) -> float | None:
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return float(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def reset_peak_rss() -> bool:
    """Reset this process's peak resident set (Linux: ``/proc/self/clear_refs``, 5) to
    its current size, so the next peak read belongs to what runs next; False where the
    kernel does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_rss_mib() -> float:
    """Peak resident memory of this process, MiB: ``VmHWM`` (which
    :func:`reset_peak_rss` resets), else ``getrusage``'s ``ru_maxrss`` (process life)."""
    hwm = _read_status_kib("VmHWM")
    if hwm is not None:
        return hwm / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_benchmarks(target: str = "all", *, quick: bool = False,
                   load: Callable[[str], ModuleType] | None = None,
                   names: Iterable[str] | None = None) -> WorkflowResult:
    """Run one benchmark target, or every one in turn in this process (``mitsweep bench``).

    Parameters
    ----------
    target : str
        A name of :data:`BENCH_TARGETS`, or ``"all"``.
    quick : bool
        Smaller problem sizes (a smoke run).
    load : callable, optional
        Target name → its benchmark module (default: the modules of :data:`BENCH_TARGETS`);
        raises :class:`TargetMissing` for a module this installation lacks.
    names : iterable of str, optional
        The targets ``"all"`` runs (default: those of :data:`BENCH_TARGETS`).

    Returns
    -------
    WorkflowResult
        ``value`` and ``summary``: one target's result dict; for ``"all"``, ``machine``
        (:func:`mitsweep.backend.describe_machine`), ``quick``, ``seconds``,
        ``peak_rss_mib`` and ``targets``: per target its ``result`` (or ``error``, or
        ``skipped`` with the reason), ``seconds`` and peak resident memory.
        ``provenance``: ``target``, ``quick``, ``status`` (1 if a target failed, else 0),
        ``version``.

    Raises
    ------
    TargetMissing
        A single target whose module is not installed.

    Examples
    --------
    >>> from mitsweep.workflows import run_benchmarks
    >>> r = run_benchmarks("deconv", quick=True)                  # doctest: +SKIP
    >>> r.value["polar"]["time_ratio_vs_skimage"] > 0             # doctest: +SKIP
    True
    """
    load = load or _import_target
    options = SimpleNamespace(quick=bool(quick))
    if target != "all":
        result = _runner(target, load(target))(options)
        return WorkflowResult(result, {"workflow": "run_benchmarks", "version": __version__,
                                       "target": target, "quick": bool(quick), "status": 0},
                              result)
    from ..backend import describe_machine

    targets: dict[str, dict] = {}
    report: dict[str, Any] = {"machine": describe_machine(), "quick": bool(quick),
                              "targets": targets}
    status = 0
    t_all = time.perf_counter()
    for name in (list(BENCH_TARGETS) if names is None else names):
        entry: dict = {}
        try:
            mod = load(name)
        except TargetMissing as exc:
            entry["skipped"] = str(exc)
            logger.warning("bench %s skipped: %s", name, exc)
            report["targets"][name] = entry
            continue
        resettable = reset_peak_rss()
        rss0 = peak_rss_mib()
        t0 = time.perf_counter()
        logger.info("bench %s ...", name)
        try:
            entry["result"] = _runner(name, mod)(options)
        except Exception as exc:  # one broken target must not hide the others' figures
            logger.debug("bench %s failed", name, exc_info=True)
            entry["error"] = f"{type(exc).__name__}: {exc}"
            status = 1
        entry["seconds"] = time.perf_counter() - t0
        entry["peak_rss_mib"] = peak_rss_mib()
        entry["peak_rss_growth_mib"] = entry["peak_rss_mib"] - rss0
        entry["peak_rss_scope"] = "this target" if resettable else "process so far"
        report["targets"][name] = entry
    report["seconds"] = time.perf_counter() - t_all
    # the resets also reset ru_maxrss: the process's peak is the largest target's
    report["peak_rss_mib"] = max([peak_rss_mib()] + [e["peak_rss_mib"] for e in
                                                     report["targets"].values()
                                                     if "peak_rss_mib" in e])
    report["machine"]["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    return WorkflowResult(report, {"workflow": "run_benchmarks", "version": __version__,
                                   "target": target, "quick": bool(quick), "status": status},
                          report)
