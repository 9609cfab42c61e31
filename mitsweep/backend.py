"""The one place that chooses the Dr.Jit / Mitsuba backend, before any kernel runs.

Dr.Jit's LLVM (CPU) backend aborts the whole process on libLLVM < 19 ("LLVM ERROR:
Cannot select … fminimum"). :func:`select_backend` inspects the library without
compiling anything and picks, in order: CUDA when a GPU is usable (Dr.Jit initialised
its CUDA backend and found a device), LLVM when libLLVM >= 19 is loaded, otherwise it
raises :class:`BackendError` with a one-line instruction. ``MITSWEEP_BACKEND=cuda|llvm|
scalar`` forces a choice (``llvm`` keeps a GPU machine on the CPU); ``scalar`` is the
documented slow fallback for Mitsuba only (Python sensors run ~40× slower there, and the
tracer refuses it). The tracer then uses ``drjit.cuda`` or ``drjit.llvm``
(:func:`drjit_module`) and Mitsuba ``cuda_ad_rgb`` or ``llvm_ad_rgb``
(:func:`set_mitsuba_variant`); a CUDA variant that Mitsuba cannot set (no OptiX in the
driver) falls back to LLVM with a warning unless CUDA was asked for.

The LLVM backend's vector width (lanes per instruction; Dr.Jit picks the hardware
register width, 8 on AVX2, 16 on AVX-512) is set through drjit-core's exported C API
(``jit_llvm_set_target``, which the Python module does not wrap) by
:func:`set_llvm_vector_width`; ``MITSWEEP_LLVM_VECTOR_WIDTH`` (an integer, ``auto`` or
``native``) is applied by :func:`select_backend`, before any kernel is compiled. A
width that is a multiple of the register width unrolls each kernel's loop body.
Dr.Jit's kernel cache keys kernels by their IR, which spells the width, so the width
can change between kernels of one process (:func:`llvm_vector_width_scope`).

Mitsuba's and Dr.Jit's own log lines go through :mod:`logging` (loggers ``mitsuba`` and
``drjit``), so that stdout stays the command's: Mitsuba writes its warnings to stdout,
in colour, through its stream appender, which :func:`route_mitsuba_log` replaces;
drjit-core's stderr log is replaced by a callback (:func:`route_drjit_log`, its C API
``jit_set_log_level_callback``). Both keep their default level, warnings and errors.

:func:`describe_machine` says what a benchmark ran on (CPU, cores, memory, load, GPU,
the versions and the backend chosen), without compiling a kernel.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import functools
import logging
import os
import platform
import re
import shutil
import subprocess
import sys
import types
from collections.abc import Iterator
from typing import Any

__all__ = ["BackendError", "MIN_LLVM", "llvm_version", "select_backend", "mitsuba_variant",
           "set_mitsuba_variant", "drjit_module", "cuda_devices", "describe_machine",
           "llvm_vector_width", "native_llvm_vector_width", "set_llvm_vector_width",
           "llvm_vector_width_scope", "LLVM_WIDTH_ENV", "MAX_LLVM_VECTOR_WIDTH",
           "route_mitsuba_log", "route_drjit_log", "cuda_usable", "drjit_core",
           "llvm_target_api", "auto_llvm_vector_width", "apply_llvm_vector_width_setting"]

logger = logging.getLogger(__name__)

MIN_LLVM = (19, 0, 0)
_BACKENDS = ("cuda", "llvm", "scalar")


class BackendError(RuntimeError):
    """No usable Dr.Jit backend (the message says what to install or set)."""


def llvm_version() -> tuple[int, int, int] | None:
    """Version of the libLLVM Dr.Jit loaded, or None if none was found (no kernel runs)."""
    import drjit as dr

    if not dr.has_backend(dr.JitBackend.LLVM):
        return None
    return tuple(dr.detail.llvm_version())


def cuda_usable() -> bool:
    """Whether Dr.Jit's CUDA backend initialised and found a device (a driver problem
    reads as no device). :func:`select_backend` asks this first; it compiles nothing.

    Returns
    -------
    bool
        True when ``drjit.has_backend(JitBackend.CUDA)`` holds.
    """
    import drjit as dr

    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # pragma: no cover - driver problems
        return False


@functools.cache
def select_backend(prefer: str | None = None) -> str:
    """``"cuda"``, ``"llvm"`` or ``"scalar"``; checked before any kernel is compiled.

    Parameters
    ----------
    prefer : str, optional
        Force a backend (default: ``$MITSWEEP_BACKEND`` or automatic).

    Raises
    ------
    BackendError
        If the requested or any backend is unusable, e.g. libLLVM < 19.
    """
    route_drjit_log()  # before Dr.Jit initialises a backend (and logs about it)
    choice = prefer or os.environ.get("MITSWEEP_BACKEND") or None
    if choice is not None and choice not in _BACKENDS:
        raise BackendError(f"MITSWEEP_BACKEND: must be one of {', '.join(_BACKENDS)}, "
                           f"got {choice!r}")
    if choice in (None, "cuda") and cuda_usable():
        return "cuda"
    if choice == "cuda":
        raise BackendError("backend 'cuda' requested but no CUDA device is usable")
    if choice == "scalar":
        return "scalar"
    version = llvm_version()
    if version is None:
        raise BackendError("Dr.Jit found no libLLVM: install libLLVM >= 19 "
                           "(Debian/Ubuntu: apt-get install libllvm19) or set "
                           "DRJIT_LIBLLVM_PATH to it")
    if version < MIN_LLVM:
        raise BackendError(f"Dr.Jit loaded libLLVM {'.'.join(map(str, version))}, which aborts "
                           f"on its kernels; install libLLVM >= 19 (apt-get install libllvm19) "
                           f"or point DRJIT_LIBLLVM_PATH at it")
    apply_llvm_vector_width_setting()
    return "llvm"


# ---------------------------------------------------------------------------------------
# LLVM vector width

#: Environment setting: an integer (a power of two from the hardware width to
#: :data:`MAX_LLVM_VECTOR_WIDTH`), ``native`` (Dr.Jit's own choice) or ``auto``
#: (mitsweep's default, :func:`auto_llvm_vector_width`).
LLVM_WIDTH_ENV = "MITSWEEP_LLVM_VECTOR_WIDTH"
#: Widest width allowed: at 32 Dr.Jit 1.5 emits LLVM IR that does not parse (a mask
#: ``zext i32 … to i32``) and aborts the process on the first kernel.
MAX_LLVM_VECTOR_WIDTH = 16
#: ``auto``: twice the register width (each kernel's loop body unrolled once), at most
#: the maximum. Measured on AVX2 (8 lanes), widths interleaved in one process (load
#: 2-3 on 2 cores): 16 lanes cut the continuous tracer deposit's CPU time per ray by
#: 22-29 %; the exact deposit (-11 % to +4 %) and Mitsuba renders (pinhole and sweep
#: modes, -4 % to +3 % in three runs) stayed within the noise. ``mitsweep bench
#: tracer`` times both widths side by side (``llvm_widths``).
_AUTO_FACTOR = 2

# drjit-core's C API (include/drjit-core/jit.h), C++-mangled in libdrjit-core
_SYMBOLS = {
    "set_target": "_Z19jit_llvm_set_targetPKcS0_j",
    "target_cpu": "_Z19jit_llvm_target_cpuv",
    "target_features": "_Z24jit_llvm_target_featuresv",
    "vector_width": "_Z21jit_llvm_vector_widthv",
}
_LOG_SYMBOLS = {
    "set_callback": "_Z26jit_set_log_level_callback8LogLevelPFvS_PKcE",
    "set_stderr": "_Z24jit_set_log_level_stderr8LogLevel",
    "stderr_level": "_Z20jit_log_level_stderrv",
}
_native_width: int | None = None


@functools.cache
def drjit_core() -> ctypes.CDLL | str:
    """drjit-core, loaded from the very file the drjit package loaded (same path, so the
    same process-wide state), or why it cannot be.

    Returns
    -------
    ctypes.CDLL or str
        The library (its exported C API: the LLVM target and log callbacks mitsweep
        calls), or a one-line reason when no drjit-core file is beside the drjit package
        or it cannot be loaded. Cached: loaded once per process.
    """
    import drjit as dr

    folder = os.path.dirname(dr.__file__)
    names = ("libdrjit-core.so", "libdrjit-core.dylib", "drjit-core.dll")
    paths = [os.path.join(folder, n) for n in names if os.path.exists(os.path.join(folder, n))]
    if not paths:
        return f"drjit-core library not found in {folder}"
    try:
        return ctypes.CDLL(paths[0])
    except OSError as exc:
        return f"drjit-core cannot be loaded ({exc})"


@functools.cache
def llvm_target_api() -> dict | None:
    """ctypes functions of drjit-core's LLVM target API, or None (logged) when the
    library or one of its symbols is missing.

    Returns
    -------
    dict or None
        Key → ctypes function, argument and result types set: ``set_target(cpu,
        features, width)``, ``target_cpu()`` and ``target_features()`` (bytes),
        ``vector_width()`` (lanes), and the log-level functions :func:`route_drjit_log`
        uses. Cached; the first call also records Dr.Jit's own width for this CPU
        (:func:`native_llvm_vector_width`), before mitsweep changes it.
    """
    global _native_width
    lib = drjit_core()
    if isinstance(lib, str):
        logger.warning("%s: LLVM vector width unchanged", lib)
        return None
    try:
        api = {key: getattr(lib, sym) for key, sym in _SYMBOLS.items()}
    except AttributeError as exc:
        logger.warning("drjit-core's LLVM target API is not available (%s): LLVM vector "
                       "width unchanged", exc)
        return None
    api["set_target"].argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    api["set_target"].restype = None
    api["target_cpu"].restype = api["target_features"].restype = ctypes.c_char_p
    api["target_cpu"].argtypes = api["target_features"].argtypes = []
    api["vector_width"].restype = ctypes.c_uint32
    api["vector_width"].argtypes = []
    # Read before mitsweep changes anything: Dr.Jit's choice for this CPU.
    _native_width = int(api["vector_width"]())
    return api


def llvm_vector_width() -> int | None:
    """The LLVM backend's current vector width, or None where the API is missing."""
    api = llvm_target_api()
    return None if api is None else int(api["vector_width"]())


def native_llvm_vector_width() -> int | None:
    """The width Dr.Jit chose for this CPU (its register width), before any change."""
    return _native_width if llvm_target_api() is not None else None


def _check_width(width, source: str) -> int:
    # ASCII digits only: str.isdigit() accepts "²", which int() then refuses
    if isinstance(width, str) and re.fullmatch(r"[0-9]+", width.strip()):
        width = int(width)
    if isinstance(width, bool) or not isinstance(width, int):
        raise BackendError(f"{source}: must be an integer, 'auto' or 'native', got {width!r}")
    native = native_llvm_vector_width() or 1
    if not native <= width <= MAX_LLVM_VECTOR_WIDTH or width & (width - 1):
        raise BackendError(f"{source}: must be a power of two from {native} (this CPU's "
                           f"register width) to {MAX_LLVM_VECTOR_WIDTH}, got {width}")
    return width


def auto_llvm_vector_width() -> int | None:
    """mitsweep's default LLVM vector width (``auto``): twice the register width, at
    most :data:`MAX_LLVM_VECTOR_WIDTH`, never below the register width.

    Returns
    -------
    int or None
        Lanes per vector; None where drjit-core's target API is missing.
    """
    native = native_llvm_vector_width()
    return None if native is None else max(native, min(native * _AUTO_FACTOR,
                                                          MAX_LLVM_VECTOR_WIDTH))


def _set_width(api: dict, width: int) -> int:
    if int(api["vector_width"]()) != width:
        # keep Dr.Jit's target CPU and features, change only the width
        api["set_target"](api["target_cpu"](), api["target_features"](), width)
        logger.info("LLVM vector width %d (native %d)", width, _native_width)
    return int(api["vector_width"]())


def set_llvm_vector_width(width: int | str) -> int | None:
    """Set the LLVM backend's vector width for kernels compiled from now on.

    Parameters
    ----------
    width : int or {"auto", "native"}
        Lanes per vector: a power of two from the CPU's register width
        (:func:`native_llvm_vector_width`) to :data:`MAX_LLVM_VECTOR_WIDTH`;
        ``native`` is Dr.Jit's own choice, ``auto`` mitsweep's default (twice the
        register width, at most 16).

    Returns
    -------
    int or None
        The width now in effect; None (logged, nothing changed) when the selected
        backend is not LLVM or drjit-core's target API is missing.

    Raises
    ------
    BackendError
        If ``width`` is not such a power of two.
    """
    if select_backend() != "llvm":
        logger.info("backend is %s, not llvm: vector width unchanged", select_backend())
        return None
    return _set_llvm_vector_width(width, "vector width")


def _set_llvm_vector_width(width, source: str) -> int | None:
    api = llvm_target_api()
    if api is None:
        return None
    w: int | None
    if isinstance(width, str) and width.strip().lower() in ("auto", "native"):
        w = auto_llvm_vector_width() if width.strip().lower() == "auto" else native_llvm_vector_width()
    else:
        w = _check_width(width, source)
    # w is None only where the API is missing, which returned above
    return None if w is None else _set_width(api, w)


def apply_llvm_vector_width_setting() -> None:
    """Set the LLVM vector width from ``MITSWEEP_LLVM_VECTOR_WIDTH`` (:data:`LLVM_WIDTH_ENV`;
    unset or empty means ``auto``). :func:`select_backend` calls it once per process
    (it is cached), before any kernel is compiled.

    Raises
    ------
    BackendError
        If the variable holds neither ``auto``, ``native`` nor an allowed power of two;
        the message names the variable.
    """
    _set_llvm_vector_width(os.environ.get(LLVM_WIDTH_ENV, "").strip() or "auto",
                           LLVM_WIDTH_ENV)


@contextlib.contextmanager
def llvm_vector_width_scope(width: int | str) -> Iterator[int | None]:
    """Kernels compiled inside the ``with`` block use ``width``; the previous width is
    restored on exit. Safe between kernels: Dr.Jit caches kernels by their IR, which
    names the width, so no kernel compiled at one width is reused at another.

    Parameters
    ----------
    width : int or str
        Lanes per vector instruction, or ``"auto"`` / ``"native"``.
    """
    before = llvm_vector_width()
    now = set_llvm_vector_width(width)
    try:
        yield now
    finally:
        api = llvm_target_api()
        if now is not None and before is not None and api is not None:
            _set_width(api, before)


# ---------------------------------------------------------------------------------------
# Mitsuba's and Dr.Jit's log output, through logging

#: drjit-core's LogLevel (Disable = 0 ... Trace = 6) as logging levels.
_DRJIT_LEVELS = {1: logging.ERROR, 2: logging.WARNING, 3: logging.INFO, 4: logging.INFO,
                 5: logging.DEBUG, 6: logging.DEBUG}
_DRJIT_WARN = 2
_drjit_route: dict = {}


def _drjit_log(level: int, text: bytes) -> None:
    logging.getLogger("drjit").log(_DRJIT_LEVELS.get(level, logging.DEBUG),
                                   text.decode("utf-8", "replace").rstrip())


def route_drjit_log() -> bool:
    """Send drjit-core's warnings and errors to the ``drjit`` logger instead of stderr.

    Idempotent; undone at exit (:mod:`atexit`), before the interpreter that the
    callback needs is gone. Returns False (nothing changed, Dr.Jit keeps writing to
    stderr) where drjit-core's log API is not found.
    """
    if _drjit_route:
        return True
    lib = drjit_core()
    try:
        api = {key: getattr(lib, sym) for key, sym in _LOG_SYMBOLS.items()}
    except AttributeError:  # a string (no library) or a missing symbol
        logger.debug("drjit-core's log API is not available: Dr.Jit logs to stderr")
        return False
    callback_type = ctypes.CFUNCTYPE(None, ctypes.c_int, ctypes.c_char_p)
    api["set_callback"].argtypes = [ctypes.c_int, callback_type]
    api["set_callback"].restype = None
    api["set_stderr"].argtypes = [ctypes.c_int]
    api["set_stderr"].restype = None
    api["stderr_level"].restype = ctypes.c_int
    _drjit_route.update(api, callback=callback_type(_drjit_log),
                        stderr_before=int(api["stderr_level"]()), null=callback_type())
    api["set_callback"](_DRJIT_WARN, _drjit_route["callback"])
    api["set_stderr"](0)
    atexit.register(_unroute_drjit_log)
    return True


def _unroute_drjit_log() -> None:
    # Dr.Jit may still log while it shuts down, after Python could run the callback.
    if _drjit_route:
        _drjit_route["set_callback"](0, _drjit_route["null"])
        _drjit_route["set_stderr"](_drjit_route["stderr_before"])


@functools.cache
def _logging_appender_type() -> type[Any]:
    """An ``mi.Appender`` that forwards Mitsuba's lines to the ``mitsuba`` logger
    (defined once Mitsuba is imported: backend.py must not import it at load time)."""
    import mitsuba as mi

    levels = {mi.LogLevel.Trace: logging.DEBUG, mi.LogLevel.Debug: logging.DEBUG,
              mi.LogLevel.Info: logging.INFO, mi.LogLevel.Warn: logging.WARNING,
              mi.LogLevel.Error: logging.ERROR}

    class LoggingAppender(mi.Appender):
        def append(self, level, text: str) -> None:
            logging.getLogger("mitsuba").log(levels.get(level, logging.WARNING),
                                             text.rstrip())

        def log_progress(self, *args) -> None:  # mitsweep shows its own progress
            pass

    return LoggingAppender


_mitsuba_route: dict = {}


def route_mitsuba_log() -> None:
    """Replace Mitsuba's appenders (its stdout stream) by one that forwards each line
    to the ``mitsuba`` logger, as ``[Plugin] message`` (no date, thread or level: the
    logging format has its own). Idempotent; the appender is removed at exit."""
    if _mitsuba_route:
        return
    import mitsuba as mi

    # mi.logger() where this Mitsuba has it (its stubs do not declare it), else the thread's
    get_logger = getattr(mi, "logger", None)
    log = get_logger() if get_logger is not None else mi.Thread.thread().logger()
    formatter = mi.DefaultFormatter()
    formatter.set_has_date(False)
    formatter.set_has_thread(False)
    formatter.set_has_log_level(False)
    appender = _logging_appender_type()()
    log.clear_appenders()
    log.add_appender(appender)
    log.set_formatter(formatter)
    _mitsuba_route.update(log=log, appender=appender)
    atexit.register(_unroute_mitsuba_log)


def _unroute_mitsuba_log() -> None:
    # Mitsuba must not hold a Python object (nor call one) once the interpreter ends.
    if _mitsuba_route:
        _mitsuba_route["log"].remove_appender(_mitsuba_route.pop("appender"))


def mitsuba_variant(spectrum: str = "rgb", prefer: str | None = None) -> str:
    """The Mitsuba variant for the selected backend, e.g. ``llvm_ad_rgb``.

    Parameters
    ----------
    spectrum : str, optional
        ``"rgb"``, ``"mono"`` or ``"spectral"``.
    prefer : {"cuda", "llvm", "scalar"}, optional
        A backend to use (default: :func:`select_backend`'s choice).
    """
    backend = select_backend(prefer)
    return f"scalar_{spectrum}" if backend == "scalar" else f"{backend}_ad_{spectrum}"


def set_mitsuba_variant(spectrum: str = "rgb", prefer: str | None = None) -> str:
    """Select the Mitsuba variant (idempotent) and return its name.

    An automatic CUDA choice that Mitsuba refuses (its CUDA variants also need OptiX,
    which comes with the NVIDIA driver) falls back to the LLVM variant with a warning;
    a requested one (``prefer`` or ``$MITSWEEP_BACKEND``) raises :class:`BackendError`.
    Mitsuba's log goes to :mod:`logging` from here on (:func:`route_mitsuba_log`).

    Parameters
    ----------
    spectrum : str, optional
        ``"rgb"``, ``"mono"`` or ``"spectral"``.
    prefer : {"cuda", "llvm", "scalar"}, optional
        A backend to use (default: :func:`select_backend`'s choice).
    """
    import mitsuba as mi

    variant = mitsuba_variant(spectrum, prefer)
    route_mitsuba_log()
    if mi.variant() == variant:
        return variant
    try:
        mi.set_variant(variant)
    except Exception as exc:  # Mitsuba raises ImportError or RuntimeError here
        requested = prefer or os.environ.get("MITSWEEP_BACKEND")
        if not variant.startswith("cuda_") or requested == "cuda":
            raise BackendError(f"Mitsuba variant {variant} cannot be set: {exc}") from exc
        logger.warning("Mitsuba variant %s cannot be set (%s); using llvm_ad_%s",
                       variant, exc, spectrum)
        variant = mitsuba_variant(spectrum, "llvm")
        if mi.variant() != variant:
            mi.set_variant(variant)
    logger.info("mitsuba variant %s", variant)
    return variant


def drjit_module(prefer: str | None = None) -> types.ModuleType:
    """``drjit.cuda`` or ``drjit.llvm`` for the tracer (scalar is refused: too slow).

    Parameters
    ----------
    prefer : {"cuda", "llvm"}, optional
        A backend to use (default: :func:`select_backend`'s choice).
    """
    backend = select_backend(prefer)
    if backend == "scalar":
        raise BackendError("the tracer needs the 'llvm' or 'cuda' backend, not 'scalar'")
    import importlib

    return importlib.import_module(f"drjit.{backend}")


def cuda_devices() -> list[dict]:
    """NVIDIA GPUs as ``nvidia-smi`` lists them (name, memory in MiB, driver), or ``[]``
    when there is no ``nvidia-smi`` or it finds none. Independent of Dr.Jit's view."""
    exe = shutil.which("nvidia-smi")
    if exe is None:
        return []
    try:
        out = subprocess.run([exe, "--query-gpu=name,memory.total,driver_version",
                              "--format=csv,noheader,nounits"], capture_output=True,
                             text=True, timeout=10, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    devices = []
    for line in out.splitlines():
        parts = [p.strip() for p in line.split(",")]
        if len(parts) == 3:
            devices.append({"name": parts[0], "memory_mib": float(parts[1]),
                            "driver": parts[2]})
    return devices


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_total_bytes() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return None


def _version(dist: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def describe_machine() -> dict:
    """What a benchmark ran on, as a JSON-ready dict; compiles no kernel.

    Keys: ``cpu`` (model), ``cores_logical`` (``os.cpu_count``), ``cores_usable`` (this
    process's affinity), ``memory_gib``, ``load_average`` (1, 5, 15 min: a loaded
    machine makes wall times incomparable), ``os``, ``python``, the versions of
    ``numpy``, ``scipy``, ``drjit``, ``mitsuba`` and ``mitsweep``, ``llvm`` (the libLLVM
    Dr.Jit loaded), ``gpus`` (:func:`cuda_devices`), ``backend`` and ``variant`` (what
    :func:`select_backend` and :func:`mitsuba_variant` choose here, or the reason none
    can be chosen), ``llvm_vector_width`` and ``llvm_native_vector_width`` (LLVM
    backend: the width kernels are compiled at now, and Dr.Jit's own choice; None
    elsewhere).
    """
    from . import __version__

    usable: int | None
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        usable = os.cpu_count()
    mem = _memory_total_bytes()
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover
        load = None
    info: dict[str, Any] = {
        "cpu": _cpu_model(), "cores_logical": os.cpu_count(), "cores_usable": usable,
        "memory_gib": None if mem is None else round(mem / 2 ** 30, 1),
        "load_average": load, "os": platform.platform(),
        "python": sys.version.split()[0],
        **{name: _version(name) for name in ("numpy", "scipy", "drjit", "mitsuba")},
        "mitsweep": __version__,
    }
    try:
        v = llvm_version()
        info["llvm"] = None if v is None else ".".join(map(str, v))
    except ImportError as exc:
        info["llvm"] = f"unknown ({exc})"
    info["gpus"] = cuda_devices()
    try:
        info["backend"] = select_backend()
        info["variant"] = mitsuba_variant()
    except (BackendError, ImportError) as exc:
        info["backend"] = info["variant"] = f"none ({exc})"
    llvm = info["backend"] == "llvm"
    info["llvm_vector_width"] = llvm_vector_width() if llvm else None
    info["llvm_native_vector_width"] = native_llvm_vector_width() if llvm else None
    return info
