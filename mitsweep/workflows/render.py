"""Render a setup's scene, or a user's Mitsuba scene, through the mirror to an EXR with
its provenance (``mitsweep render``)."""

from __future__ import annotations

import os
from typing import Any
from collections.abc import Mapping, Sequence

from ..config import MAX_RESOLUTION, Setup
from ._base import InputError, WorkflowResult, read_motion_file, resolve_setup
from ._paths import check_outputs

__all__ = ["render_exr"]


def _check_out(path, suffix: str) -> None:
    from ..io.atomic import check_writable

    if not os.fspath(path).lower().endswith(suffix):
        raise InputError(f"{path}: the output must end in {suffix}")
    try:
        check_writable(path)
    except OSError as exc:
        raise InputError(str(exc)) from None


def render_exr(setup: Setup | str | os.PathLike, out: str | os.PathLike, *, mode: str,
               spp: int = 64, seed: int = 0, resolution: tuple[int, int] | None = None,
               aovs: Sequence[str] = (), f_number: float | None = None,
               sampler: str | None = None, full_frame: bool = False,
               preview: str | os.PathLike | None = None, preview_size: int | None = None,
               scene: str | os.PathLike | Mapping[str, Any] | None = None,
               scene_unit: str | None = None, motion: str | os.PathLike | None = None,
               progress: bool = False) -> WorkflowResult:
    """Render one image of a setup through the mirror with Mitsuba 3 and write it as an
    EXR with its provenance (``mitsweep render``).

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup, its TOML file, or a bundled setup's name.
    out : path-like
        The EXR to write (atomically).
    mode : {"pinhole", "focused", "sweep", "stopped"}
        pinhole: all-in-focus ground truth; focused: a normal camera focused at the
        mirror centre; sweep: the sensor moves over the optimal range; stopped: focused
        at a smaller aperture (``f_number``, default 11).
    spp, seed : int
        Samples per pixel; the random seed (>= 0).
    resolution : (int, int), optional
        Render W x H pixels over the setup's frame, the pitch scaled so the mirror's
        image stays in frame (each side at most ``MAX_RESOLUTION``).
    aovs : sequence of {"depth", "mask"}
        Extra layers.
    f_number : float, optional
        f-number of ``mode="stopped"`` only.
    sampler : {"multijitter", "independent"}, optional
        How a pixel's samples are drawn (default: the mode's).
    full_frame : bool
        Also render the pixels outside the mirror's image.
    preview, preview_size
        A tone-mapped PNG too, shrunk by an integer factor to at most ``preview_size``
        pixels wide.
    scene : path-like or dict, optional
        A Mitsuba scene (an XML file, or a scene dict) to render instead of the built-in
        room (default: the setup's ``[scene]`` file, if any); ``scene_unit`` its length
        unit (mm, cm, m).
    motion : path-like, optional
        A motion-profile file to run instead of the setup's sweep.
    progress : bool
        Mitsuba's progress bar.

    Returns
    -------
    WorkflowResult
        ``value``: the :class:`mitsweep.render.RenderResult` (``image``, ``aovs``,
        ``metadata``). ``provenance``: the render's metadata (what the EXR carries: setup,
        mode, spp, seed, sampler, timings, resolution, scene). ``summary``: what
        ``mitsweep render --json`` prints (``mean``: the image's mean, NaN if any pixel
        is not finite).

    Raises
    ------
    InputError
        An output of the wrong kind or unwritable, an option that does not apply to the
        mode or scene, a resolution or seed out of range.

    Examples
    --------
    >>> from mitsweep.workflows import render_exr
    >>> r = render_exr("sphere", "sweep.exr", mode="sweep", spp=16,
    ...                resolution=(128, 128))       # doctest: +SKIP
    >>> r.summary["resolution"]["resolution_px"]   # doctest: +SKIP
    [128, 128]
    """
    from ..render import render_image, render_to_exr

    scene_file = scene if isinstance(scene, (str, os.PathLike)) else None
    if scene_file is not None and not os.fspath(scene_file).strip():
        raise InputError("--scene: an empty path; give a Mitsuba XML scene file")
    setup_path = None if isinstance(setup, Setup) else setup
    setup = resolve_setup(setup)
    check_outputs([setup_path, scene_file or setup.scene.file, motion],
                  {"--out": out, "--preview": preview})
    _check_out(out, ".exr")
    if preview:
        _check_out(preview, ".png")
    if f_number is not None and mode != "stopped":
        raise InputError("--f-number applies to --mode stopped only (the other modes use "
                         "the setup's lens.f_number)")
    if seed < 0:
        raise InputError(f"--seed: must be >= 0, got {seed}")
    if scene_unit is not None and scene is None and setup.scene.file is None:
        raise InputError("--scene-unit applies to a scene file (--scene, or [scene] file in "
                         "the setup)")
    if resolution is not None and max(resolution) > MAX_RESOLUTION:
        raise InputError(f"--resolution: each side must be at most {MAX_RESOLUTION} px, "
                         f"got {resolution[0]} {resolution[1]}")
    profile = None if motion is None else read_motion_file(motion, setup).profile
    result = render_image(setup, mode, spp=spp, seed=seed, motion=profile,
                          aovs=tuple(dict.fromkeys(aovs)), f_number=f_number,
                          mirror_only=not full_frame, progress=progress, sampler=sampler,
                          scene=os.fspath(scene) if isinstance(scene, (str, os.PathLike)) else scene,
                          scene_unit=scene_unit, resolution=resolution)
    render_to_exr(os.fspath(out), result)
    if preview:
        from ..io.png import write_png

        write_png(os.fspath(preview), result.image, max_width=preview_size)
    m = result.metadata
    summary = {"out": os.fspath(out), "mode": mode, "spp": spp, "seed": seed,
               "sampler": m["sampler"],
               "render_s": m["render_s"], "aovs": sorted(result.aovs),
               "reference_sensor_distance_mm": m["reference_sensor_distance_mm"],
               "mean": float(result.image.mean())}
    if preview:
        summary["preview"] = os.fspath(preview)
    if "resolution" in m:
        summary["resolution"] = m["resolution"]
    if motion:
        summary["motion"] = os.fspath(motion)
    if "user_scene" in m:
        summary["scene"] = {k: m["user_scene"][k] for k in ("source", "sha256", "unit",
                                                            "replaced")}
    return WorkflowResult(result, dict(m, workflow="render_exr"), summary)
