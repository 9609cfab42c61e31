"""IPSF banks on disk: the contract between the tracer (writer) and deconvolution (reader).

A bank holds unit-sum IPSF kernels for a set of image points and depths, expressed on the
pixel grid of the reference sensor distance and centred on the chief-ray image of each
point at that distance (docs/design.md).

Layout conventions
------------------
- ``kernels``: (n_depths, n_points, K, K) float32, K odd, each kernel sums to 1; array
  rows go down the image (−v), columns right (+u), the chief-ray image at [K//2, K//2].
- ``points_uv``: (n_points, 2) upright image coordinates (u, v), mm, at the reference
  sensor distance.
- ``kind = "radial"``: points on the +u half-axis (angle 0) at ``radii_mm``; the IPSF at
  polar angle θ (counter-clockwise from +u in upright coordinates) is the kernel rotated
  by θ counter-clockwise (rotational symmetry of an untilted mirror).
- ``kind = "grid"``: points on a regular (rows × cols) grid over the field,
  ``grid_shape`` = (rows, cols), points in row-major order (rows top to bottom).
- ``depths_mm``: (n_depths,) depth l of the point source, > 0 (inf allowed)
  (:attr:`IPSFBank.depths`).
- ``radii_mm``: (n_points,) radial banks: finite, >= 0, strictly increasing
  (:attr:`IPSFBank.radii`).
- ``vignetted``: (n_depths, n_points) fraction in [0, 1] of the source's traced energy lost.
- Every array is numeric and finite where the above does not allow inf; a bank that is
  not is refused whole when it is made or loaded (:class:`BankError` naming the array).
- Loading checks each archive member's declared size against the memory cap
  (:func:`mitsweep.resources.check_allocation`) before reading it.
- ``metadata``: provenance (setup dict, sweep range, rays, seed, version, motion profile).
- ``optics``: the sections of the setup the bank was traced for (``mirror``, ``lens``,
  ``sensor``, ``sweep`` as :func:`mitsweep.config.setup_to_dict` writes them, and the
  stage ``motion``), stored with their SHA-256 fingerprint (:func:`optics_fingerprint`)
  so that a bank is never used on an image from other optics without saying so.
  ``None`` for banks traced for no optics (synthetic ones, ``metadata["synthetic"]``).

Stored as NPZ (``.npz``; arrays plus a JSON header as a 0-d string array), written
atomically. Format 2 adds the optics and their fingerprint; format 1 banks still load,
with ``fingerprinted = False``. The arrays keep their ``*_mm`` names in the file
(``depths_mm``, ``radii_mm``) whatever the Python names, so that every bank written
before still reads and a cached bank's bytes do not change.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any
from collections.abc import Mapping

import numpy as np

from ..deprecation import renamed_fields
from ..resources import ResourceError, require_regular_file
from .atomic import atomic_path

__all__ = ["IPSFBank", "save_bank", "load_bank", "BankError", "optics_sections",
           "optics_fingerprint", "OPTICS_SECTIONS", "bank_kernel_size", "fill_off_mirror_nodes"]

BANK_FORMAT = "mitsweep-ipsf-bank/2"
#: Formats :func:`load_bank` reads; /1 predates the optics fingerprint.
READABLE_FORMATS = ("mitsweep-ipsf-bank/1", BANK_FORMAT)
#: The setup sections (and the stage motion) whose values shape the IPSFs.
OPTICS_SECTIONS = ("mirror", "lens", "sensor", "sweep", "motion")


def _plain(o: Any) -> Any:
    """JSON-ready copy: tuples → lists, NumPy scalars → Python, non-finite floats → "inf"."""
    if isinstance(o, Mapping):
        return {str(k): _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, np.ndarray)):
        return [_plain(v) for v in o]
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return "nan" if math.isnan(o) else ("inf" if o > 0 else "-inf")
    return o


def optics_sections(setup_dict: Mapping[str, Any], motion: Mapping[str, Any] | None = None
                    ) -> dict[str, Any]:
    """The optics of a setup as a bank records them.

    Parameters
    ----------
    setup_dict : mapping
        :func:`mitsweep.config.setup_to_dict` of the setup (or the ``setup`` of an image's
        provenance, which is the same dict).
    motion : mapping, optional
        :meth:`mitsweep.optics.motion.MotionProfile.as_dict` of the stage motion.

    Returns
    -------
    dict
        ``mirror``, ``lens``, ``sensor``, ``sweep`` (those present) and ``motion``
        (when given), JSON-ready (infinite depths as ``"inf"``).
    """
    out = {k: _plain(setup_dict[k]) for k in OPTICS_SECTIONS[:-1] if k in setup_dict}
    if motion is not None:
        out["motion"] = _plain(motion)
    return out


def optics_fingerprint(optics: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of the canonical JSON of :func:`optics_sections` (sorted keys, no
    spaces): equal for equal optics, whatever the dict order or tuple/list spelling.

    Parameters
    ----------
    optics : mapping
        The optics as :func:`optics_sections` returns them (or as a bank header holds
        them).
    """
    text = json.dumps(_plain(optics), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


class BankError(ValueError):
    """A bank file is missing, malformed, or does not match what it is used with."""


@renamed_fields(depths_mm="depths", radii_mm="radii")
@dataclass(frozen=True)
class IPSFBank:
    """IPSF kernels over image points and depths; see the module docstring for the layout.

    ``optics`` is the dict of :func:`optics_sections` the bank was traced for (``None``:
    no optics, or a format-1 file that predates fingerprints: ``fingerprinted`` is then
    False).

    Attributes
    ----------
    kernels : (n_depths, n_points, K, K) ndarray
        Unit-sum IPSFs, K odd (float32 on disk), the chief-ray image at [K//2, K//2].
    points_uv : (n_points, 2) ndarray
        Upright image coordinates (u, v) of the points, mm, at the reference sensor
        distance.
    depths : (n_depths,) ndarray
        Depth l of the point source of each row of kernels, mm, > 0 (``inf`` allowed).
        Formerly ``depths_mm`` (still accepted and readable, with a warning; the file's
        array keeps that name).
    pixel_pitch : float
        Pixel pitch of the kernels' grid, mm.
    reference_sensor_distance : float
        The sensor distance whose pixel grid the kernels are on, mm.
    kind : {"radial", "grid"}
        Points on the +u half-axis (rotated for other angles) or on a regular grid.
    radii : (n_points,) ndarray, optional
        Radial banks: the points' distances from the centre, mm, strictly increasing.
        Formerly ``radii_mm`` (as ``depths``).
    grid_shape : (int, int), optional
        Grid banks: (rows, cols), rows * cols = n_points.
    vignetted : (n_depths, n_points) ndarray, optional
        Fraction in [0, 1] of each source's traced energy lost.
    metadata : dict
        Provenance (setup, sweep range, rays, seed, version, motion), JSON-ready.
    optics : dict, optional
        :func:`optics_sections` of the optics the bank was traced for.
    fingerprinted : bool
        False for a format-1 file, which predates optics fingerprints.
    """

    kernels: np.ndarray           # (n_depths, n_points, K, K) float32
    points_uv: np.ndarray         # (n_points, 2) mm
    depths: np.ndarray            # (n_depths,) mm
    pixel_pitch: float            # mm
    reference_sensor_distance: float  # mm
    kind: str                     # "radial" | "grid"
    radii: np.ndarray | None = None        # (n_points,) mm, for radial banks
    grid_shape: tuple[int, int] | None = None
    vignetted: np.ndarray | None = None    # (n_depths, n_points)
    metadata: dict[str, Any] = field(default_factory=dict)
    optics: dict[str, Any] | None = None
    fingerprinted: bool = True

    def __post_init__(self) -> None:
        k = np.asarray(self.kernels)
        if k.ndim != 4 or k.shape[2] != k.shape[3] or k.shape[2] % 2 == 0:
            raise BankError(f"kernels must be (n_depths, n_points, K, K) with K odd, got {k.shape}")
        if k.shape[0] < 1 or k.shape[1] < 1:
            raise BankError(f"the bank holds no kernels: shape {k.shape}")
        if not np.issubdtype(k.dtype, np.floating):
            raise BankError(f"kernels must be floating point, got {k.dtype}")
        for name in ("pixel_pitch", "reference_sensor_distance"):
            value = getattr(self, name)
            ok = isinstance(value, (int, float, np.number)) and not isinstance(value, bool) \
                and math.isfinite(float(value)) and float(value) > 0
            if not ok:
                raise BankError(f"{name} must be a positive number (mm), got {value!r}")
        if not isinstance(self.metadata, dict):
            raise BankError(f"metadata must be a JSON object, got {type(self.metadata).__name__}")
        if self.optics is not None and not isinstance(self.optics, dict):
            raise BankError(f"optics must be a JSON object, got {type(self.optics).__name__}")
        if np.asarray(self.points_uv).shape != (k.shape[1], 2):
            raise BankError(f"points_uv must be ({k.shape[1]}, 2), got {np.shape(self.points_uv)}")
        if np.asarray(self.depths).shape != (k.shape[0],):
            raise BankError(f"depths (the file's depths_mm) must be ({k.shape[0]},), got "
                            f"{np.shape(self.depths)}")
        if self.kind not in ("radial", "grid"):
            raise BankError(f"kind must be 'radial' or 'grid', got {self.kind!r}")
        if self.kind == "radial" and (self.radii is None or
                                      np.shape(self.radii) != (k.shape[1],)):
            raise BankError("a radial bank needs radii (the file's radii_mm) of shape "
                            "(n_points,)")
        if self.kind == "grid" and (self.grid_shape is None or
                                    int(np.prod(self.grid_shape)) != k.shape[1]):
            raise BankError("a grid bank needs grid_shape with rows*cols == n_points")
        if not np.all(np.isfinite(k)):
            raise BankError("kernels hold NaN or inf values")
        _check_values(self, k.shape[0], k.shape[1])

    @property
    def kernel_size(self) -> int:
        return int(self.kernels.shape[-1])


def _numbers(name: str, value: Any) -> np.ndarray:
    """``value`` as a float64 array, or a :class:`BankError` naming the array."""
    a = np.asarray(value)
    if a.dtype.kind not in "fiu":
        raise BankError(f"{name} must hold numbers, got an array of {a.dtype} "
                        f"({a.dtype.kind!r} kind)")
    return a.astype(np.float64, copy=False)


def _check_values(bank: IPSFBank, n_depths: int, n_points: int) -> None:
    """Every array of a bank holds what its layout allows (the shapes are checked)."""
    if not np.all(np.isfinite(_numbers("points_uv", bank.points_uv))):
        raise BankError("points_uv hold NaN or inf values; finite mm expected")
    depths = _numbers("depths_mm", bank.depths)
    if not np.all(depths > 0):  # NaN fails too
        raise BankError(f"depths_mm must be > 0 mm (inf allowed), got "
                        f"{depths[~(depths > 0)][0]:g}")
    if bank.radii is not None:
        radii = _numbers("radii_mm", bank.radii)
        if radii.ndim != 1 or not np.all(np.isfinite(radii)) or np.any(radii < 0):
            raise BankError("radii_mm must be finite and >= 0 mm")
        if np.any(np.diff(radii) <= 0):
            raise BankError("radii_mm must increase strictly (the points from the centre "
                            "outwards)")
    if bank.vignetted is not None:
        vig = _numbers("vignetted", bank.vignetted)
        if vig.shape != (n_depths, n_points):
            raise BankError(f"vignetted must be ({n_depths}, {n_points}), got {vig.shape}")
        if not np.all((vig >= 0) & (vig <= 1)):  # NaN fails too
            raise BankError("vignetted must hold fractions in [0, 1] (no NaN)")


def save_bank(path: str | Path, bank: IPSFBank, *, reproducible: bool = True) -> Path:
    """Write ``bank`` to ``path`` (.npz) atomically.

    Parameters
    ----------
    path : str or Path
        The bank file; must end in ``.npz``.
    bank : IPSFBank
        The bank; a format-1 bank (``fingerprinted`` False) is refused.
    reproducible : bool, optional
        Store every archive member with one fixed timestamp (1980-01-01, the ZIP epoch)
        instead of the time of writing, so that one bank always gives the same bytes
        (datasets and caches compare files by SHA-256); default True. False keeps
        NumPy's timestamps.

    Returns
    -------
    Path
        ``path``.
    """
    p = Path(path)
    if p.suffix != ".npz":
        raise BankError(f"{p}: a bank file must end in .npz")
    arrays: dict[str, np.ndarray] = {
        "kernels": np.asarray(bank.kernels, dtype=np.float32),
        "points_uv": np.asarray(bank.points_uv, dtype=np.float64),
        "depths_mm": np.asarray(bank.depths, dtype=np.float64),   # the file's names
    }
    if bank.radii is not None:
        arrays["radii_mm"] = np.asarray(bank.radii, dtype=np.float64)
    if bank.vignetted is not None:
        arrays["vignetted"] = np.asarray(bank.vignetted, dtype=np.float64)
    if not bank.fingerprinted:
        raise BankError(f"{p}: this bank predates optics fingerprints (format 1); trace it "
                        f"again rather than re-save it")
    optics = None if bank.optics is None else _plain(bank.optics)
    header = {
        "format": BANK_FORMAT, "kind": bank.kind, "pixel_pitch": float(bank.pixel_pitch),
        "reference_sensor_distance": float(bank.reference_sensor_distance),
        "grid_shape": list(bank.grid_shape) if bank.grid_shape else None,
        "optics": optics,
        "optics_sha256": None if optics is None else optics_fingerprint(optics),
        "metadata": bank.metadata,
    }
    arrays["header"] = np.array(json.dumps(header, default=_default))
    with atomic_path(p, suffix=".npz") as tmp:
        with open(tmp, "wb") as f:
            if reproducible:
                _savez_fixed_time(f, arrays)
            else:
                # numpy's stub reads a ** mapping as possibly holding allow_pickle (a bool)
                np.savez_compressed(f, **arrays)  # type: ignore[arg-type]
    return p


#: The archive members' timestamp of a reproducible bank: the earliest a ZIP can hold.
_ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)


def _savez_fixed_time(f, arrays: Mapping[str, np.ndarray]) -> None:
    """What ``np.savez_compressed`` writes, with every member dated :data:`_ZIP_EPOCH`
    (NumPy dates them by the clock)."""
    import zipfile

    with zipfile.ZipFile(f, mode="w", compression=zipfile.ZIP_DEFLATED,
                         allowZip64=True) as zf:
        for key, value in arrays.items():
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_ZIP_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)


def _default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def load_bank(path: str | Path) -> IPSFBank:
    """Read a bank written by :func:`save_bank`; raises :class:`BankError` if malformed.

    Parameters
    ----------
    path : str or Path
        A ``.npz`` bank of a format in :data:`READABLE_FORMATS`.
    """
    p = require_regular_file(path, "IPSF bank")
    if not p.is_file():
        raise BankError(f"{p}: no such bank file")
    with open(p, "rb") as f:
        magic = f.read(4)
    if magic != b"PK\x03\x04":  # NPZ files are zip archives
        raise BankError(f"{p}: not an IPSF bank (expected a .npz file written by "
                        f"`mitsweep ipsf --bank` or mitsweep.io.bank.save_bank)")
    data = _read_npz(p)
    header = _header(p, data.pop("header", None))
    fmt = header.get("format")
    if fmt not in READABLE_FORMATS:
        raise BankError(f"{p}: unknown bank format {fmt!r}, expected {BANK_FORMAT!r}")
    for name in ("kind", "pixel_pitch", "reference_sensor_distance"):
        if name not in header:
            raise BankError(f"{p}: the bank header lacks {name!r}")
    for name in ("kernels", "points_uv", "depths_mm"):
        if name not in data:
            raise BankError(f"{p}: the bank lacks the {name!r} array")
    gs = header.get("grid_shape")
    if gs is not None and not (isinstance(gs, list) and len(gs) == 2
                               and all(isinstance(n, int) and n >= 1 for n in gs)):
        raise BankError(f"{p}: grid_shape must be [rows, cols], got {gs!r}")
    fingerprinted = fmt == BANK_FORMAT
    optics = header.get("optics") if fingerprinted else None
    if fingerprinted:
        if "optics_sha256" not in header or "optics" not in header:
            raise BankError(f"{p}: the bank header lacks 'optics' and 'optics_sha256'")
        digest = header["optics_sha256"]
        if (optics is None) != (digest is None) or (
                optics is not None and (not isinstance(optics, dict)
                                        or optics_fingerprint(optics) != digest)):
            raise BankError(f"{p}: the bank's optics do not match their fingerprint "
                            f"(the header was edited); trace the bank again")
    try:
        return IPSFBank(kernels=data["kernels"], points_uv=data["points_uv"],
                        depths=data["depths_mm"], pixel_pitch=header["pixel_pitch"],
                        reference_sensor_distance=header["reference_sensor_distance"],
                        kind=header["kind"], radii=data.get("radii_mm"),
                        grid_shape=tuple(gs) if gs else None, vignetted=data.get("vignetted"),
                        metadata=header.get("metadata", {}), optics=optics,
                        fingerprinted=fingerprinted)
    except BankError as exc:
        raise BankError(f"{p}: {exc}") from None


def _read_npz(p: Path) -> dict[str, np.ndarray]:
    """The arrays of an NPZ file, each member's declared size checked before it is read.

    An NPZ is a zip of ``.npy`` members; ``np.load`` inflates a member that is not one
    whole, so a small archive can expand to any size. Here every member must be ``.npy``;
    its header (shape, dtype) gives the bytes it will take, and their sum passes
    :func:`mitsweep.resources.check_allocation` before any array is read. A member is
    then read from its stream for exactly the bytes its header declares.
    """
    import zipfile

    from ..resources import check_allocation

    try:
        with zipfile.ZipFile(p) as zf:
            members = zf.infolist()
            declared = {}
            for info in members:
                name = info.filename
                if not name.endswith(".npy") or info.is_dir():
                    raise BankError(f"{p}: not an IPSF bank (member {name!r} is not a .npy "
                                    f"array)")
                with zf.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    read_header = {(1, 0): np.lib.format.read_array_header_1_0,
                                   (2, 0): np.lib.format.read_array_header_2_0}.get(version)
                    if read_header is None:
                        raise BankError(f"{p}: not an IPSF bank (member {name!r} is .npy "
                                        f"format {version[0]}.{version[1]}; 1.0 or 2.0 "
                                        f"expected)")
                    shape, _, dtype = read_header(f)
                if dtype.hasobject:
                    raise BankError(f"{p}: not an IPSF bank (member {name!r} holds Python "
                                    f"objects)")
                declared[name] = (shape, dtype)
            nbytes = sum(float(np.prod(shape, dtype=float)) * dtype.itemsize
                         for shape, dtype in declared.values())
            check_allocation(f"{p}: the bank's {len(declared)} arrays", nbytes)
            data = {}
            for info in members:
                with zf.open(info) as f:
                    data[info.filename[:-4]] = np.lib.format.read_array(f, allow_pickle=False)
    except (BankError, ResourceError):
        raise
    except Exception as exc:  # zipfile, zlib and NumPy format errors alike
        cause = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise BankError(f"{p}: not an IPSF bank ({cause})") from None
    return data


def _header(p: Path, raw) -> dict:
    """The JSON header: a 0-d string array (format 2) or UTF-8 bytes (format 1)."""
    if raw is None:
        raise BankError(f"{p}: not an IPSF bank (no header)")
    try:
        text = str(raw[()]) if raw.dtype.kind == "U" else bytes(raw).decode()
        header = json.loads(text)
    except (ValueError, TypeError) as exc:
        raise BankError(f"{p}: the bank header is not JSON ({exc})") from None
    if not isinstance(header, dict):
        raise BankError(f"{p}: the bank header must be a JSON object")
    return header


def bank_kernel_size(pixel_pitch: float) -> int:
    """Kernel size K (odd, px) that holds the IPSFs of the paper's sweeps.

    31 px at the demo's 18 µm pixels (the largest peripheral IPSF spans ~0.5 mm on the
    sensor), scaled inversely with the pitch (mm) so finer pixels do not truncate the
    kernels; never below 31.

    Parameters
    ----------
    pixel_pitch : float
        Pixel pitch of the kernels' grid, mm (> 0).
    """
    half = int(math.ceil(15 * 0.018 / pixel_pitch))
    return 2 * max(half, 15) + 1


def fill_off_mirror_nodes(bank: IPSFBank) -> IPSFBank:
    """A grid bank whose nodes off the mirror take the kernel of the nearest traced node.

    The tracer gives a grid node whose chief ray misses the mirror a centred delta
    kernel and marks it invalid (``metadata["valid"]``); the product-convolution would
    blend that delta into the cells around it, under-deconvolving the mirror's image near
    its rim. Beyond the rim there is no image to restore, so the nearest traced kernel
    (in the sensor plane; the first of equally near ones) is the bank's best knowledge
    of the blur at every node. The nodes stay marked invalid; ``metadata["filled_nodes"]``
    lists those filled and ``metadata["filled_from"]`` the node each copies. Radial banks
    and grid banks with every node (or none) valid are returned unchanged. The same
    filling as :func:`mitsweep.deconv.kernels.fill_invalid_nodes`.

    Parameters
    ----------
    bank : IPSFBank
        The bank; its ``metadata["valid"]`` (one flag per point) marks the traced nodes.
    """
    valid = np.asarray((bank.metadata or {}).get("valid", []), dtype=bool)
    if bank.kind != "grid" or valid.size != len(bank.points_uv) or valid.all() \
            or not valid.any():
        return bank
    pts = np.asarray(bank.points_uv, dtype=np.float64)
    good = np.flatnonzero(valid)
    bad = np.flatnonzero(~valid)
    d = np.hypot(pts[bad, None, 0] - pts[None, good, 0], pts[bad, None, 1] - pts[None, good, 1])
    src = good[np.argmin(d, axis=1)]
    kernels = np.array(bank.kernels, copy=True)
    kernels[:, bad] = kernels[:, src]
    meta = {**bank.metadata, "filled_nodes": bad.tolist(), "filled_from": src.tolist()}
    return replace(bank, kernels=kernels, metadata=meta)
