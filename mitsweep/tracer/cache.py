"""IPSF banks traced on demand and kept on disk, keyed by the optics' fingerprint.

A real photograph needs the bank of *its* geometry: the camera's resolution and pixel
pitch and the motion the stage actually ran (a capture record's measured motion).
:func:`cached_bank` traces that bank once (:func:`mitsweep.tracer.ipsf_bank`) and keeps
it under ``cache_root()/banks`` (:func:`mitsweep.io.cache.cache_root`), so the next photo
of the same camera and sweep deconvolves at once.

The key is the optics' fingerprint (:func:`mitsweep.io.bank.optics_fingerprint` of the
setup's mirror, lens, sensor and sweep sections and the motion) and the trace settings
(kind, depths, rays, kernel size, points, seed, mitsweep's version). Each entry is a
directory ``{kind}-{optics16}-{trace12}`` holding ``bank.npz``. Two processes asking for
one bank do not both trace it: the entry's directory lock
(:class:`mitsweep.io.lock.DirectoryLock`) is held while tracing, the second waits and
then loads what the first wrote (atomically, :func:`mitsweep.io.bank.save_bank`). An
entry that does not load, or whose optics do not match its key, is traced again. With
the cache off (``MITSWEEP_CACHE=0``) or unusable (one warning,
:func:`mitsweep.io.cache.cache_dir`) the bank is traced in memory and not kept.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .. import __version__
from ..config import Setup, setup_to_dict
from ..io.bank import BankError, IPSFBank, load_bank, optics_fingerprint, optics_sections, \
    save_bank
from ..io.cache import cache_dir as _cache_dir
from ..io.cache import cache_root, warn_unusable
from ..io.lock import DirectoryLock
from ..optics.motion import MotionProfile
from ..optics.reference import reference_geometry
from .bank import EXTENTS, ipsf_bank
from .kernel import TRACE_REVISION
from .settings import TraceSettings, settings_from_keywords

__all__ = ["CachedBank", "cached_bank", "bank_cache_key", "bank_cache_dir"]

logger = logging.getLogger(__name__)

#: Bumped when the cache's layout or the meaning of its key changes. The tracer's own
#: revision (:data:`mitsweep.tracer.kernel.TRACE_REVISION`) is part of every key too, so a
#: bank traced by an older tracer under the same package version is not served.
CACHE_LAYOUT = 1
#: The tracing method of cached banks (that of :func:`mitsweep.tracer.ipsf_bank`).
DEFAULT_METHOD = TraceSettings().method


@dataclass(frozen=True)
class CachedBank:
    """A bank from the cache: the bank, its file (None: traced without the cache), and
    whether this call traced it.

    Attributes
    ----------
    bank : mitsweep.io.bank.IPSFBank
        The bank.
    path : pathlib.Path or None
        Its ``bank.npz`` in the cache; None where it was traced without the cache (off,
        unusable, or the file could not be written).
    traced : bool
        True when this call traced it, False when it was loaded from the cache.
    """

    bank: IPSFBank
    path: Path | None
    traced: bool


def bank_cache_dir(cache_dir: str | Path | None = None) -> Path:
    """``cache_dir`` or ``cache_root()/banks``.

    Parameters
    ----------
    cache_dir : str or path, optional
        The bank cache's directory; default ``banks`` under
        :func:`mitsweep.io.cache.cache_root`.

    Returns
    -------
    pathlib.Path
    """
    return Path(cache_dir) if cache_dir is not None else cache_root() / "banks"


def _trace_settings(kind, depths, settings: TraceSettings, n_radii, grid,
                    extent: str = "fov") -> dict:
    """The key's trace settings. Equal to the key of the keyword API this replaced for
    equal settings (``time_samples`` was always the default there, ``n_planes`` absent:
    :meth:`TraceSettings.cache_fields`), so banks cached before still hit; ``extent``
    enters the key only where it is not ``"fov"`` (the banks cached before)."""
    out = {"kind": kind, "depths_mm": ["inf" if math.isinf(d) else float(d) for d in depths],
           **settings.cache_fields(),
           "version": __version__, "layout": CACHE_LAYOUT, "trace_revision": TRACE_REVISION}
    if kind == "radial":
        out["n_radii"] = int(n_radii)
    else:
        out["grid"] = [int(g) for g in grid]
    if extent != "fov":
        out["extent"] = extent
    return out


def bank_cache_key(setup: Setup, *, motion: MotionProfile | None = None,
                   kind: str | None = None, depths: ArrayLike = (500.0,),
                   settings: TraceSettings | None = None, n_radii: int = 19,
                   grid: tuple[int, int] = (9, 9), extent: str = "fov", **deprecated: Any
                   ) -> tuple[str, dict, dict]:
    """``(entry name, optics, trace settings)`` of the bank :func:`cached_bank` returns.

    The key holds the optics' fingerprint and ``settings`` but its ``deposit`` strategy
    (which changes the speed, not the bank); ``**deprecated`` as :func:`cached_bank`.

    Parameters
    ----------
    setup, motion, kind, depths, settings, n_radii, grid, extent
        As :func:`cached_bank`.
    **deprecated
        As :func:`cached_bank`.

    Returns
    -------
    name : str
        The entry's directory name, ``{kind}-{optics16}-{trace12}``.
    optics : dict
        The optics sections the fingerprint is taken of
        (:func:`mitsweep.io.bank.optics_sections`).
    trace : dict
        The trace settings hashed into the name (file keys: ``depths_mm``, ``rays``, ...).
    """
    settings = settings_from_keywords(settings, deprecated, caller="bank_cache_key",
                                      allowed=_CACHE_KEYWORDS)
    kind = kind or ("radial" if setup.mirror.is_symmetric else "grid")
    if kind not in ("radial", "grid"):
        raise ValueError(f"kind: must be 'radial' or 'grid', got {kind!r}")
    if extent not in EXTENTS:
        raise ValueError(f"extent: must be one of {', '.join(map(repr, EXTENTS))}, got "
                         f"{extent!r}")
    geometry = reference_geometry(setup, motion=motion)
    optics = optics_sections(setup_to_dict(setup), geometry.motion.as_dict())
    depths = [float(d) for d in np.atleast_1d(np.asarray(depths, dtype=float))]
    trace = _trace_settings(kind, depths, settings, n_radii, grid, extent)
    digest = hashlib.sha256(json.dumps(trace, sort_keys=True).encode()).hexdigest()
    return f"{kind}-{optics_fingerprint(optics)[:16]}-{digest[:12]}", optics, trace


#: The deprecated keywords of :func:`cached_bank` (it never took ``time_samples`` or
#: ``n_planes``: its banks used the defaults).
_CACHE_KEYWORDS = frozenset({"rays", "kernel_size", "seed", "method"})


def cached_bank(setup: Setup, *, motion: MotionProfile | None = None,
                kind: str | None = None, depths: ArrayLike = (500.0,),
                settings: TraceSettings | None = None, n_radii: int = 19,
                grid: tuple[int, int] = (9, 9), cache_dir: str | Path | None = None,
                progress: Callable[[], object] | None = None, extent: str = "fov",
                **deprecated: Any) -> CachedBank:
    """The IPSF bank of ``setup`` and ``motion``, from the cache or traced into it.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The photo's geometry: its sensor section has the photo's resolution and pitch.
    motion : MotionProfile, optional
        The motion the stage ran (a capture record's measured, tabulated motion); default
        the setup's (:func:`mitsweep.optics.reference.reference_geometry`). It sets the
        bank's reference sensor distance (mid-travel).
    kind : {"radial", "grid"}, optional
        Default: radial for rotationally symmetric setups, grid for tilted ones.
    extent : {"fov", "rim"}
        As :func:`mitsweep.tracer.ipsf_bank`: ``"rim"`` keeps the bank that covers the
        whole mirror image under a key of its own (``"fov"`` keys are those of earlier
        releases: their banks still hit).
    depths, settings, n_radii, grid, progress
        As :func:`mitsweep.tracer.ipsf_bank`; ``settings`` (default ``TraceSettings()``)
        and the optics make the cache key (:func:`bank_cache_key`).
    cache_dir : path, optional
        Default :func:`bank_cache_dir` (none where the cache is off or unusable).
    **deprecated
        ``rays``, ``kernel_size``, ``seed``, ``method``: the fields of ``settings``, still
        accepted for one release (DeprecationWarning).

    Returns
    -------
    CachedBank
    """
    settings = settings_from_keywords(settings, deprecated, caller="cached_bank",
                                      allowed=_CACHE_KEYWORDS)
    name, optics, trace = bank_cache_key(setup, motion=motion, kind=kind, depths=depths,
                                         settings=settings, n_radii=n_radii, grid=grid,
                                         extent=extent)
    kw = {"n_radii": n_radii} if trace["kind"] == "radial" else {"grid": tuple(grid)}

    def trace_it() -> IPSFBank:
        geometry = reference_geometry(setup, motion=motion)
        bank = ipsf_bank(setup, kind=trace["kind"], depths=depths, settings=settings,
                         motion=geometry.motion, sweep=geometry.sweep, progress=progress,
                         extent=extent, **kw)
        bank.metadata["cache"] = {"entry": name, "trace": trace}
        return bank

    root = Path(cache_dir) if cache_dir is not None else _cache_dir("banks")
    entry = None if root is None else root / name
    if entry is not None:
        try:
            entry.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            warn_unusable(root, exc)
            entry = None
    if entry is None:
        logger.info("tracing the IPSF bank %s (%s, %d depths) without the cache", name,
                    trace["kind"], len(trace["depths_mm"]))
        return CachedBank(trace_it(), None, traced=True)
    path = entry / "bank.npz"
    fingerprint = optics_fingerprint(optics)
    with DirectoryLock(entry, wait=math.inf, command=f"tracing the IPSF bank {name}"):
        if path.is_file():
            try:
                bank = load_bank(path)
                if bank.optics is not None and optics_fingerprint(bank.optics) == fingerprint:
                    logger.info("IPSF bank from the cache: %s", path)
                    return CachedBank(bank, path, traced=False)
                logger.warning("%s: its optics do not match its cache key; tracing it again",
                               path)
            except BankError as exc:
                logger.warning("%s: unreadable cached bank (%s); tracing it again", path, exc)
        logger.info("tracing the IPSF bank %s (%s, %d depths) into %s", name,
                    trace["kind"], len(trace["depths_mm"]), entry)
        bank = trace_it()
        try:
            save_bank(path, bank)
        except OSError as exc:  # a full disk: the bank is traced, keep it in memory
            warn_unusable(entry, exc)
            return CachedBank(bank, None, traced=True)
    return CachedBank(bank, path, traced=True)
