"""How an IPSF is sampled: one parameter object for every tracing entry point.

The same sampling keywords travelled together through :func:`~mitsweep.tracer.integrated_psf`,
:func:`~mitsweep.tracer.ipsf.integrated_psfs`, :func:`~mitsweep.tracer.ipsf_bank` and
:func:`~mitsweep.tracer.cache.cached_bank`; :class:`TraceSettings` carries them, and the
bank cache keys on it. The *physics* of the sweep (``motion``, ``sweep``) stays a
separate argument: it is part of the optics (the cache keys it by the optics'
fingerprint), not of how the optics are sampled.

The separate keywords (``rays=``, ``kernel_size=``, ...) still work for one release, with
a :class:`DeprecationWarning` (:func:`settings_from_keywords`).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from .deposit import DepositStrategy

__all__ = ["TraceSettings", "settings_from_keywords", "METHODS", "DEFAULT_RAYS",
           "DEFAULT_KERNEL_SIZE", "DEFAULT_TIME_SAMPLES", "DEFAULT_PLANES"]

#: Sweep integration methods (:class:`TraceSettings` ``method``).
METHODS = ("exact", "continuous", "planes")
DEFAULT_RAYS = 1_000_000
DEFAULT_KERNEL_SIZE = 31
#: Stratified sweep times per ray. Measured (docs/reference/tracer.md, convergence): 1 and 4 reach
#: the same L1 error per second; 4 halves the error at a given ray count.
DEFAULT_TIME_SAMPLES = 4
#: Focal planes of ``method="planes"`` unless given.
DEFAULT_PLANES = 16


def _is_int(value: Any) -> bool:
    """An integer, or an integral float (``1e6`` rays), not a bool."""
    if isinstance(value, bool):
        return False
    try:
        return int(value) == value
    except (TypeError, ValueError, OverflowError):
        return False


@dataclass(frozen=True, kw_only=True)
class TraceSettings:
    """How the rays of an IPSF are sampled and binned.

    Attributes
    ----------
    rays : int
        Rays traced per IPSF (after the pilot passes that fit the sampling box), >= 1.
    kernel_size : int
        K, odd, >= 3: each kernel is (K, K) pixels of the sensor's pitch.
    seed : int
        Seed of the low-discrepancy sample stream (a bank's point ``j`` uses
        ``seed + j``).
    method : {"exact", "continuous", "planes"}
        ``"exact"``: each ray's whole sweep deposited analytically; ``"continuous"``:
        ``time_samples`` stratified times per ray; ``"planes"``: the paper's sum over
        ``n_planes`` focal planes equally spaced in time.
    time_samples : int
        Times per ray of ``"continuous"``, 1 to 64.
    n_planes : int
        Planes of ``"planes"``, 1 to 64.
    deposit : DepositStrategy, optional
        How the deposit adds the weights (speed only: results agree to the float64
        summation order); not part of a bank's cache key. None (default): the default
        strategy, or that of an enclosing deprecated
        :func:`~mitsweep.tracer.kernel.deposit_strategy_scope`.

    Raises
    ------
    ValueError
        A value out of its range, naming the key and the allowed values.
    """

    rays: int = DEFAULT_RAYS
    kernel_size: int = DEFAULT_KERNEL_SIZE
    seed: int = 0
    method: str = "exact"
    time_samples: int = DEFAULT_TIME_SAMPLES
    n_planes: int = DEFAULT_PLANES
    deposit: DepositStrategy | None = None

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method: must be one of {', '.join(METHODS)}, "
                             f"got {self.method!r}")
        K = self.kernel_size
        if not _is_int(K) or K < 3 or K % 2 == 0:
            raise ValueError(f"kernel_size: must be an odd integer >= 3, got {K!r}")
        if not _is_int(self.rays) or self.rays < 1:
            raise ValueError(f"rays: must be >= 1, got {self.rays!r}")
        if not _is_int(self.seed):
            raise ValueError(f"seed: must be an integer, got {self.seed!r}")
        # As before this class: the method's own count is checked, the other ignored.
        if self.method == "continuous" and (not _is_int(self.time_samples)
                                            or not 1 <= self.time_samples <= 64):
            raise ValueError(f"time_samples: must be in [1, 64], got {self.time_samples!r}")
        if self.method == "planes" and (not _is_int(self.n_planes)
                                        or not 1 <= self.n_planes <= 64):
            raise ValueError(f"n_planes: must be in [1, 64], got {self.n_planes!r}")
        if self.deposit is not None and not isinstance(self.deposit, DepositStrategy):
            raise ValueError(f"deposit: must be a DepositStrategy, got {self.deposit!r}")
        for name in ("rays", "kernel_size", "seed", "time_samples", "n_planes"):
            if _is_int(getattr(self, name)):
                object.__setattr__(self, name, int(getattr(self, name)))

    def cache_fields(self) -> dict[str, Any]:
        """The settings a bank's cache key holds (not ``deposit``: it changes the speed,
        not the bank), in the key's historical form: ``n_planes`` only where it is not
        the default, so keys of banks cached before this class existed still match."""
        out = {"rays": self.rays, "kernel_size": self.kernel_size, "seed": self.seed,
               "method": self.method, "time_samples": self.time_samples}
        if self.n_planes != DEFAULT_PLANES:
            out["n_planes"] = self.n_planes
        return out


#: The keyword names :func:`settings_from_keywords` accepts in place of a TraceSettings.
SETTINGS_KEYWORDS = frozenset(f.name for f in dataclasses.fields(TraceSettings)) - {"deposit"}


def settings_from_keywords(settings: TraceSettings | None, keywords: Mapping[str, Any], *,
                           caller: str, allowed: frozenset[str] = SETTINGS_KEYWORDS,
                           stacklevel: int = 3) -> TraceSettings:
    """``settings`` (default ``TraceSettings()``) with the deprecated separate keywords
    applied.

    Parameters
    ----------
    settings : TraceSettings, optional
    keywords : mapping
        The caller's leftover keyword arguments (``**kw``).
    caller : str
        The public function's name, for the messages.
    allowed : frozenset of str
        The deprecated keywords the caller used to take.
    stacklevel : int
        Of the warning: 3 points at the caller's caller.

    Raises
    ------
    TypeError
        A keyword the caller never took (as Python's own message).
    ValueError
        A value out of range (:class:`TraceSettings`).

    Warns
    -----
    DeprecationWarning
        When any keyword is given: they go in the next release.
    """
    unknown = sorted(set(keywords) - allowed)
    if unknown:
        raise TypeError(f"{caller}() got an unexpected keyword argument {unknown[0]!r}")
    base = TraceSettings() if settings is None else settings
    if not keywords:
        return base
    names = ", ".join(f"{k}=" for k in sorted(keywords))
    warnings.warn(f"{caller}({names}...) is deprecated: pass "
                  f"settings=TraceSettings({names}...) instead", DeprecationWarning,
                  stacklevel=stacklevel)
    return dataclasses.replace(base, **keywords)
