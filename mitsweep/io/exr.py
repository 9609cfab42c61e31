"""EXR images with provenance metadata, through the OpenEXR package.

Images are NumPy arrays (H, W) or (H, W, C) float32 (float64 is stored as float32,
float16 as half). Metadata is a flat dict of str → JSON-serialisable values, stored as
string attributes prefixed ``mitsweep:`` so that other tools show them and leave them be.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import logging
import os
import sys
import tempfile
from pathlib import Path
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np

from ..resources import ResourceError, check_allocation
from .atomic import atomic_path

__all__ = ["ExrError", "write_exr", "read_exr", "read_exr_header", "channel_names_for",
           "stack_channels"]

_PREFIX = "mitsweep:"

logger = logging.getLogger(__name__)


class ExrError(ValueError):
    """An EXR file cannot be read or does not hold what was expected."""


def channel_names_for(n: int) -> list[str]:
    """The EXR channel names of an image with ``n`` channels.

    Parameters
    ----------
    n : int
        Number of channels (the last axis of an (H, W, C) image; 1 for (H, W)).

    Returns
    -------
    list of str
        ``Y`` for 1; ``R, G, B`` for 3; ``R, G, B, A`` for 4; ``C0`` … ``C{n-1}``
        otherwise.
    """
    return {1: ["Y"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}.get(
        n, [f"C{i}" for i in range(n)])


def write_exr(path: str | Path, image: np.ndarray | None = None,
              *, channels: Mapping[str, np.ndarray] | None = None,
              metadata: Mapping[str, Any] | None = None) -> Path:
    """Write ``image`` (H, W[, C]) and/or named ``channels`` (each (H, W)) atomically.

    Parameters
    ----------
    path : path
        Target file; written to a temporary file and renamed, so an interrupted write
        leaves no partial EXR and keeps any previous file.
    image : (H, W) or (H, W, C) ndarray, optional
        Channels Y; R, G, B[, A]; or C0… by count.
    channels : mapping of str to (H, W) ndarray, optional
        Extra named layers, e.g. ``{"depth.Z": ..., "mask.Y": ...}``.
    metadata : mapping, optional
        Provenance; each value is stored JSON-encoded under ``mitsweep:KEY``.
    """
    import OpenEXR

    chans: dict[str, np.ndarray] = {}
    if image is not None:
        img = np.asarray(image)
        if img.ndim == 2:
            img = img[..., None]
        if img.ndim != 3:
            raise ExrError(f"image must be (H, W) or (H, W, C), got shape {img.shape}")
        for i, name in enumerate(channel_names_for(img.shape[2])):
            chans[name] = img[..., i]
    for name, arr in (channels or {}).items():
        arr = np.asarray(arr)
        if arr.ndim != 2:
            raise ExrError(f"channel {name!r} must be (H, W), got shape {arr.shape}")
        chans[name] = arr
    if not chans:
        raise ExrError("nothing to write: give an image or channels")
    shapes = {a.shape for a in chans.values()}
    if len(shapes) != 1:
        raise ExrError(f"all channels must have one shape, got {sorted(shapes)}")
    out = {}
    for name, arr in chans.items():
        dt = np.float16 if arr.dtype == np.float16 else np.float32
        a = np.ascontiguousarray(arr, dtype=dt)
        if not np.all(np.isfinite(a)):
            raise ExrError(f"channel {name!r} holds NaN or inf values; refusing to write them")
        out[name] = a
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (metadata or {}).items():
        header[_PREFIX + str(key)] = json.dumps(value, default=_json_default)
    with atomic_path(path, suffix=".exr") as tmp:
        try:
            with OpenEXR.File(header, out) as f:
                f.write(str(tmp))
        except RuntimeError as exc:  # OpenEXR reports I/O failures as RuntimeError
            code = _errno_of(str(exc), tmp.parent)
            raise OSError(code, os.strerror(code)) from exc
    return Path(path)


#: Causes of a failed write that OpenEXR names in its message by their strerror text.
_WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES,
                 errno.EPERM, errno.ENOENT, errno.EIO)


def _errno_of(message: str, directory: Path) -> int:
    """The errno behind OpenEXR's RuntimeError: from the strerror text its message
    quotes (``... No space left on device.``), else a full file system, else EIO."""
    for code in _WRITE_ERRNOS:
        if os.strerror(code) in message:
            return code
    try:
        st = os.statvfs(directory)
    except OSError:
        return errno.EIO
    if st.f_bavail == 0 or (st.f_files > 0 and st.f_favail == 0):
        return errno.ENOSPC
    return errno.EIO


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


def _metadata(header: Mapping[str, Any]) -> dict[str, Any]:
    meta = {}
    for k, v in header.items():
        if isinstance(k, str) and k.startswith(_PREFIX):
            try:
                meta[k[len(_PREFIX):]] = json.loads(v)
            except (TypeError, ValueError):
                meta[k[len(_PREFIX):]] = v
    return meta



@contextlib.contextmanager
def _openexr_chatter():
    """Collect what OpenEXR prints while reading a damaged file instead of letting it
    reach the user's terminal: its Python binding prints warnings on ``sys.stdout`` and
    the C library writes errors to file descriptor 2. Yields the list of lines said."""
    said: list[str] = []
    buf = io.StringIO()
    try:
        fd_saved = os.dup(2)
    except OSError:  # no stderr descriptor (e.g. a daemon): nothing to divert
        fd_saved = None
    with tempfile.TemporaryFile(mode="w+b") as sink:
        if fd_saved is not None:
            sys.stderr.flush()
            os.dup2(sink.fileno(), 2)
        try:
            with contextlib.redirect_stdout(buf):
                yield said
        finally:
            if fd_saved is not None:
                os.dup2(fd_saved, 2)
                os.close(fd_saved)
            sink.seek(0)
            text = buf.getvalue() + sink.read().decode("utf-8", "replace")
            said.extend(line.strip() for line in text.splitlines() if line.strip())


def _first_cause(said: list[str], exc: BaseException) -> str:
    """The most telling message of a failed read: the library's own words first."""
    for line in said:
        if "EXR_ERR" in line or "corrupt" in line.lower():
            return line.split(": ", 1)[-1]
    return str(exc) or type(exc).__name__

def read_exr(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read every channel (name → (H, W) float array) and the mitsweep metadata.

    Parameters
    ----------
    path : str or Path
        An OpenEXR file (mitsweep's, or any other: its metadata is then empty).

    Returns
    -------
    channels : dict of str to ndarray
        Every channel, e.g. ``"R"``, ``"depth.Z"``, ``"mask.Y"``.
    metadata : dict
        The provenance mitsweep wrote into the header.
    """
    import OpenEXR

    p = Path(path)
    if not p.is_file():
        raise ExrError(f"{p}: no such file")
    try:
        with _openexr_chatter() as said:
            with OpenEXR.File(str(p), header_only=True) as f:
                declared = _declared_bytes(f.header())
            # the header's size, gated before a pixel is decoded (a small file may declare
            # a huge data window)
            check_allocation(f"{p}: decoding the EXR image", declared)
            with OpenEXR.File(str(p), separate_channels=True) as f:
                chans = {name: np.array(c.pixels) for name, c in f.channels().items()}
                meta = _metadata(f.header())
    except (ExrError, ResourceError):
        raise
    except Exception as exc:  # OpenEXR raises plain RuntimeError/IOError
        raise ExrError(f"{p}: not a readable EXR file ({_first_cause(said, exc)})") from None
    if said:
        logger.debug("%s: OpenEXR said: %s", p, " | ".join(said))
    return chans, meta


def _declared_bytes(header: dict) -> float:
    """Bytes the pixels of an EXR header's data window take decoded (4 a sample, the
    widest type, per channel; float: no integer overflow on hostile sizes)."""
    (x0, y0), (x1, y1) = header["dataWindow"]
    w, h = float(x1) - float(x0) + 1.0, float(y1) - float(y0) + 1.0
    if w <= 0 or h <= 0:
        return 0.0
    return w * h * max(1, len(header.get("channels", []))) * 4.0


def read_exr_header(path: str | Path) -> dict[str, Any]:
    """Only the mitsweep metadata of an EXR file.

    Parameters
    ----------
    path : str or Path
        An OpenEXR file.
    """
    import OpenEXR

    p = Path(path)
    if not p.is_file():
        raise ExrError(f"{p}: no such file")
    try:
        with _openexr_chatter() as said:
            with OpenEXR.File(str(p), header_only=True) as f:
                return _metadata(f.header())
    except Exception as exc:
        raise ExrError(f"{p}: not a readable EXR file ({_first_cause(said, exc)})") from None


def stack_channels(chans: Mapping[str, np.ndarray], names: Sequence[str] = ("R", "G", "B")
                  ) -> np.ndarray:
    """(H, W, C) from named channels, or (H, W) for a single ``Y`` channel.

    Parameters
    ----------
    chans : mapping of str to ndarray
        Channels by name, as :func:`read_exr` returns them.
    names : sequence of str, optional
        The channels to stack, in order (default RGB; EXR lists them B, G, R).
    """
    if "Y" in chans and not all(n in chans for n in names):
        return chans["Y"]
    missing = [n for n in names if n not in chans]
    if missing:
        raise ExrError(f"missing channels {missing}; present: {sorted(chans)}")
    return np.stack([chans[n] for n in names], axis=-1)
