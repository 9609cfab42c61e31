"""The paper's Table 1 and figures for its setups (``mitsweep table1``,
``mitsweep figures``)."""

from __future__ import annotations

import os
from pathlib import Path
from collections.abc import Callable, Sequence

from .. import __version__
from ..config import Setup
from ._base import (InputError, Progress, WorkflowResult, progress_callback, resolve_setup)
from ._paths import check_outputs

__all__ = ["reproduce_table1", "make_paper_figures", "paper_setup_file"]


def reproduce_table1(setup: Setup | str | os.PathLike, *,
                     ranges: Sequence[tuple[float, float]] | None = None, radii: int = 19,
                     rays: int = 1_000_000, kernel_size: int = 63, seed: int = 0,
                     plot: str | os.PathLike | None = None,
                     progress: Progress = None) -> WorkflowResult:
    """The paper's Table 1: depth variance V_avg (Eq. 3) and IPSF kurtosis at the image
    centre and periphery for several sweep ranges, and a conventional camera
    (``mitsweep table1``).

    Parameters
    ----------
    setup : Setup, path-like or str
        An untilted mirror's setup, its TOML file or a bundled name.
    ranges : sequence of (float, float), optional
        Sweep ranges as focus distances (MIN, MAX), mm (default: the paper's three,
        scaled to the setup's optimal range, and the optimal range).
    radii, rays, kernel_size, seed
        Field points, rays per IPSF, kernel size (odd, >= 3), sample-stream seed.
    plot : path-like, optional
        Bar charts of the table (PNG).
    progress : None, True or callable
        Progress per traced IPSF.

    Returns
    -------
    WorkflowResult
        ``value`` and ``summary``: the table (:func:`mitsweep.tracer.table1.table1`'s
        dict: ``rows``, ``conventional``, ``epsilon``, ``depths_mm``...).
        ``provenance``: ``setup``, ``ranges``, ``radii``, ``rays``, ``kernel_size``,
        ``seed``, ``version``.

    Raises
    ------
    InputError
        A kernel size that is even or below 3.

    Examples
    --------
    >>> from mitsweep.workflows import reproduce_table1
    >>> t = reproduce_table1("sphere", radii=3, rays=20_000).value  # doctest: +SKIP
    >>> [round(r["v_avg"], 3) for r in t["rows"]]                    # doctest: +SKIP
    """
    from ..io.atomic import check_writable
    from ..tracer.table1 import PAPER_DEPTHS_MM, default_ranges, table1

    setup_path = None if isinstance(setup, Setup) else setup
    setup = resolve_setup(setup)
    check_outputs([setup_path], {"--plot": plot})
    if plot:  # before the traces, not after
        from ..plots import check_figure_path

        check_writable(os.fspath(plot))
        check_figure_path(os.fspath(plot), "--plot")
    if kernel_size % 2 == 0 or kernel_size < 3:
        raise InputError(f"--kernel-size: must be odd and >= 3, got {kernel_size}")
    ranges = ranges or default_ranges(setup)
    total = len(ranges) * radii * len(PAPER_DEPTHS_MM)
    with progress_callback(progress, total, "Table 1", "ipsf") as step:
        result = table1(setup, ranges=ranges, n_radii=radii, rays=rays,
                        kernel_size=kernel_size, seed=seed, progress=step)
    if plot:
        from ..plots import plot_table1

        plot_table1(result, os.fspath(plot))
        result["plot"] = os.fspath(plot)
    provenance = {"workflow": "reproduce_table1", "version": __version__,
                  "setup": setup.name, "ranges": [list(r) for r in ranges], "radii": radii,
                  "rays": rays, "kernel_size": kernel_size, "seed": seed}
    return WorkflowResult(result, provenance, result)


def paper_setup_file(text: str | os.PathLike) -> Path:
    """A paper setup's name (the bundled file, :func:`mitsweep.resources.bundled_setup`)
    or a path → its TOML file.

    Parameters
    ----------
    text : str or path-like
        ``sphere``, ``paraboloid``, ``paraboloid_tilted``, or an existing ``.toml``
        file.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Neither a paper setup nor an existing ``.toml`` file.
    """
    from ..pipeline.figures import PAPER_SETUPS
    from ..resources import bundled_setup

    if text in PAPER_SETUPS:
        return bundled_setup(text)
    p = Path(text)
    if p.suffix == ".toml" and p.is_file():
        return p
    raise InputError(f"--setup {os.fspath(text)!r}: not a paper setup "
                     f"({', '.join(PAPER_SETUPS)}) nor an existing .toml file")


def make_paper_figures(out: str | os.PathLike, *,
                       setups: Sequence[str | os.PathLike] | None = None,
                       quick: bool = False, force: bool = False, seed: int = 0,
                       step: Callable[[str], object] | None = None) -> WorkflowResult:
    """Regenerate the paper's figures (Figs. 3-6, 8-10 and Table 1) for its setups, as PNG
    and PDF, with their provenance in ``figures.json`` (``mitsweep figures``).

    Parameters
    ----------
    out : path-like
        Output directory (renders kept under ``out/data`` and reused).
    setups : sequence of str or path-like, optional
        Paper setups by name or setup TOML files (default: the paper's three).
    quick : bool
        Small renders and few rays (every file in minutes).
    force : bool
        Overwrite the figures of an earlier run in ``out``.
    seed : int
        Seed of traces and renders.
    step : callable, optional
        Called with one line per stage.

    Returns
    -------
    WorkflowResult
        ``value`` and ``summary``: the report (``figures.json``: per setup its files,
        ``total_s``...). ``provenance``: ``setups``, ``out``, ``quality``, ``seed``,
        ``version``.

    Raises
    ------
    InputError
        An unknown setup, a setup given twice, an existing run without ``force``, an
        output directory that cannot be made.

    Examples
    --------
    >>> from mitsweep.workflows import make_paper_figures
    >>> r = make_paper_figures("figs", setups=["sphere"], quick=True)  # doctest: +SKIP
    """
    from ..pipeline.figures import (
        FULL,
        PAPER_SETUPS,
        QUICK,
        data_dir,
        figure_files,
        make_figures,
    )

    if os.fspath(out).strip() == "":
        raise InputError("--out: must name a directory")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory")
    paths = [paper_setup_file(s) for s in (setups or PAPER_SETUPS)]
    loaded = [resolve_setup(str(p)) for p in paths]
    names = [s.name for s in loaded]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"--setup: {', '.join(dup)} given twice (each setup's name is its "
                         f"files' suffix)")
    quality = QUICK if quick else FULL
    files = [out / name for s in loaded for name in figure_files(s)] + [out / "figures.json"]
    check_outputs([str(p) for p in paths], {"--out": files})
    if not force:
        existing = [f for f in files if f.exists()]
        existing += [d for d in (data_dir(out, s, quality) for s in loaded) if d.exists()]
        if existing:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise InputError(f"{existing[0]} exists{more}: refusing to overwrite an earlier "
                             f"run's figures; pass --force, or choose another --out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot create {out} ({exc.strerror})") from None
    report = make_figures(loaded, out, quality=quality, seed=seed,
                          step=step or (lambda message: None))
    provenance = {"workflow": "make_paper_figures", "version": __version__, "setups": names,
                  "out": str(out), "quality": quality.name, "seed": seed}
    return WorkflowResult(report, provenance, report)
