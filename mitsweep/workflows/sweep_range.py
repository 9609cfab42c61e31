"""The optimal focal-sweep range of a setup, optionally checked by tracing
(``mitsweep sweep-range``; paper Sec. 4, Eq. 4-9)."""

from __future__ import annotations

import logging
import math
import os

from .. import __version__
from ..config import Setup
from ._base import InputError, WorkflowResult, resolve_setup
from ._paths import check_outputs

__all__ = ["compute_sweep_range"]

logger = logging.getLogger(__name__)


def _traced_keys(traced) -> dict:
    return {"traced_field": traced.field,
            "traced_focus_min_mm": traced.focus_min,
            "traced_focus_max_mm": traced.focus_max,
            "traced_focus_min_at": traced.min_at,
            "traced_focus_max_at": traced.max_at,
            "traced_convergence": traced.convergence,
            "traced_points": traced.points}


def compute_sweep_range(setup: Setup | str | os.PathLike, *, fov_deg: float | None = None,
                        depth: tuple[float, float] | None = None, verify: bool = False,
                        field: str | None = None, plot: str | os.PathLike | None = None
                        ) -> WorkflowResult:
    """The optimal focal-sweep range, sensor travel and exposure of a setup
    (``mitsweep sweep-range``).

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup, its TOML file, or a bundled setup's name.
    fov_deg : float, optional
        Field of view, degrees, in (0, 360) (default: the setup's ``sweep.fov_deg``).
    depth : (float, float), optional
        Depth range (MIN, MAX), mm from the mirror, 0 < MIN <= MAX (MAX may be inf;
        default: the setup's).
    verify : bool
        Also trace the sweep range numerically (:func:`mitsweep.tracer.focus.traced_sweep_range`).
    field : {"plane", "mirror", "fov"}, optional
        With ``verify``, the field the traced range covers (default ``"plane"``, the
        paper's FOV zone; see ``mitsweep sweep-range --help``).
    plot : path-like, optional
        A PNG of the focal surfaces (paper Fig. 6).

    Returns
    -------
    WorkflowResult
        ``value``: the :class:`mitsweep.optics.SweepRange`. ``summary``: its dict with
        ``setup`` (and ``traced_*`` keys with ``verify``, ``plot``), what
        ``mitsweep sweep-range --json`` prints. ``provenance``: ``setup``, ``fov_deg``,
        ``depth``, ``verify``, ``field``, ``version``.

    Raises
    ------
    InputError
        A depth range or FOV out of range, ``field`` without ``verify``.
    mitsweep.config.SetupError
        An FOV beyond the mirror's reach (naming the largest it gives).

    Examples
    --------
    >>> from mitsweep.workflows import compute_sweep_range
    >>> r = compute_sweep_range("sphere").value
    >>> round(r.focus_min), round(r.focus_max)
    (339, 364)
    """
    from ..config import SetupError
    from ..optics import optimal_sweep_range

    if field is not None and not verify:
        raise InputError("--field: chooses the field of the traced range; give it with "
                         "--verify")
    if plot:
        check_outputs([None if isinstance(setup, Setup) else setup], {"--plot": plot})
        from ..plots import check_figure_path

        check_figure_path(os.fspath(plot), "--plot")  # before the traces, not after
    setup = resolve_setup(setup)
    dmin = dmax = None
    if depth is not None:
        dmin, dmax = depth
        if not (dmin > 0) or math.isnan(dmax) or not (dmax > 0):
            raise InputError(f"--depth: both must be > 0 mm, got {dmin:g} {dmax:g}")
        if dmin > dmax:
            raise InputError(f"--depth: MIN ({dmin:g}) must be <= MAX ({dmax:g})")
    if fov_deg is not None and not fov_deg < 360:
        raise InputError(f"--fov: must be in (0, 360) degrees, got {fov_deg:g}")
    result = optimal_sweep_range(setup, fov_deg=fov_deg, depth_min=dmin, depth_max=dmax)
    out = result.as_dict()
    out["setup"] = setup.name
    if verify:
        from ..tracer.focus import traced_sweep_range

        field = field or "plane"
        trace = lambda f: traced_sweep_range(
            setup, fov_deg=fov_deg, depth_min=result.depth_min,
            depth_max=result.depth_max, field=f)
        traced = trace(field)
        out.update(_traced_keys(traced))
        # traced_field_focus_*: the whole mirror (field "mirror"), as before for a tilted
        # mirror, whose tilt plane is not all of it; omitted where that field is undefined.
        whole = traced if field == "mirror" else None
        if whole is None and not setup.mirror.is_symmetric:
            try:
                whole = trace("mirror")
            except SetupError as exc:
                logger.info("no whole-mirror traced range: %s", exc)
        if whole is not None:
            out["traced_field_focus_min_mm"] = whole.focus_min
            out["traced_field_focus_max_mm"] = whole.focus_max
    if plot:
        from ..plots import plot_focal_surfaces

        plot_focal_surfaces(setup, result, os.fspath(plot))
        out["plot"] = os.fspath(plot)
    provenance = {"workflow": "compute_sweep_range", "version": __version__,
                  "setup": setup.name, "fov_deg": fov_deg, "depth": depth,
                  "verify": verify, "field": field}
    return WorkflowResult(result, provenance, out)
