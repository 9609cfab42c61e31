"""Independent Dr.Jit point-source tracer: PSFs, focal-sweep IPSFs, banks, metrics, foci.

Deliberately independent of Mitsuba and of :mod:`mitsweep.render` (each checks the
other); it shares only the pure optics math of :mod:`mitsweep.optics` (placement, chief
ray, thin lens, sweep range). Dr.Jit types stay inside this package: the public API takes
and returns NumPy arrays.

Main entry points
-----------------
- :func:`integrated_psf` / :func:`psf`: one IPSF over the sweep / one PSF at a distance.
- :func:`ipsf_bank`: radial or grid banks over depths (:class:`mitsweep.io.bank.IPSFBank`).
- :class:`TraceSettings`: how an IPSF is sampled (rays, kernel size, seed, method, ...),
  one object for all of the above and the bank cache.
- :func:`numeric_focus`, :func:`traced_sweep_range`: traced foci and sweep range.
- :mod:`mitsweep.tracer.metrics`: cross-sections, kurtosis, V and V_avg.
"""

from .bank import ipsf_bank
from .focus import numeric_focus, traced_sweep_range
from .ipsf import integrated_psf, psf
from .settings import TraceSettings

__all__ = ["integrated_psf", "psf", "ipsf_bank", "numeric_focus", "traced_sweep_range",
           "TraceSettings"]
