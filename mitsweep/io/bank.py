"""IPSF banks on disk: the contract between the tracer (writer) and deconvolution (reader).

A bank holds unit-sum IPSF kernels for a set of image points and depths, expressed on the
pixel grid of the reference sensor distance and centred on the chief-ray image of each
point at that distance (DESIGN.md).

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
- ``depths_mm``: (n_depths,) depth l of the point source (inf allowed).
- ``vignetted``: (n_depths, n_points) fraction of the source's traced energy lost.
- ``metadata``: provenance (setup dict, sweep range, rays, seed, version, motion profile).

Stored as NPZ (``.npz``; arrays plus the metadata as a JSON string), written atomically.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path

__all__ = ["IPSFBank", "save_bank", "load_bank", "BankError"]

BANK_FORMAT = "mitsweep-ipsf-bank/1"


class BankError(ValueError):
    """A bank file is missing, malformed, or does not match what it is used with."""


@dataclass(frozen=True)
class IPSFBank:
    kernels: np.ndarray           # (n_depths, n_points, K, K) float32
    points_uv: np.ndarray         # (n_points, 2) mm
    depths_mm: np.ndarray         # (n_depths,)
    pixel_pitch: float            # mm
    reference_sensor_distance: float  # mm
    kind: str                     # "radial" | "grid"
    radii_mm: np.ndarray | None = None     # (n_points,) for radial banks
    grid_shape: tuple[int, int] | None = None
    vignetted: np.ndarray | None = None    # (n_depths, n_points)
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        k = np.asarray(self.kernels)
        if k.ndim != 4 or k.shape[2] != k.shape[3] or k.shape[2] % 2 == 0:
            raise BankError(f"kernels must be (n_depths, n_points, K, K) with K odd, got {k.shape}")
        if np.asarray(self.points_uv).shape != (k.shape[1], 2):
            raise BankError(f"points_uv must be ({k.shape[1]}, 2), got {np.shape(self.points_uv)}")
        if np.asarray(self.depths_mm).shape != (k.shape[0],):
            raise BankError(f"depths_mm must be ({k.shape[0]},), got {np.shape(self.depths_mm)}")
        if self.kind not in ("radial", "grid"):
            raise BankError(f"kind must be 'radial' or 'grid', got {self.kind!r}")
        if self.kind == "radial" and (self.radii_mm is None or
                                      np.shape(self.radii_mm) != (k.shape[1],)):
            raise BankError("a radial bank needs radii_mm of shape (n_points,)")
        if self.kind == "grid" and (self.grid_shape is None or
                                    int(np.prod(self.grid_shape)) != k.shape[1]):
            raise BankError("a grid bank needs grid_shape with rows*cols == n_points")
        if not np.all(np.isfinite(k)):
            raise BankError("kernels hold NaN or inf values")

    @property
    def kernel_size(self) -> int:
        return int(self.kernels.shape[-1])


def save_bank(path: str | Path, bank: IPSFBank) -> Path:
    """Write ``bank`` to ``path`` (.npz) atomically."""
    p = Path(path)
    if p.suffix != ".npz":
        raise BankError(f"{p}: a bank file must end in .npz")
    arrays = {
        "kernels": np.asarray(bank.kernels, dtype=np.float32),
        "points_uv": np.asarray(bank.points_uv, dtype=np.float64),
        "depths_mm": np.asarray(bank.depths_mm, dtype=np.float64),
    }
    if bank.radii_mm is not None:
        arrays["radii_mm"] = np.asarray(bank.radii_mm, dtype=np.float64)
    if bank.vignetted is not None:
        arrays["vignetted"] = np.asarray(bank.vignetted, dtype=np.float64)
    header = {
        "format": BANK_FORMAT, "kind": bank.kind, "pixel_pitch": float(bank.pixel_pitch),
        "reference_sensor_distance": float(bank.reference_sensor_distance),
        "grid_shape": list(bank.grid_shape) if bank.grid_shape else None,
        "metadata": bank.metadata,
    }
    arrays["header"] = np.frombuffer(json.dumps(header, default=_default).encode(), dtype=np.uint8)
    with atomic_path(p, suffix=".npz") as tmp:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)
    return p


def _default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def load_bank(path: str | Path) -> IPSFBank:
    """Read a bank written by :func:`save_bank`; raises :class:`BankError` if malformed."""
    p = Path(path)
    if not p.is_file():
        raise BankError(f"{p}: no such bank file")
    with open(p, "rb") as f:
        magic = f.read(4)
    if magic != b"PK\x03\x04":  # NPZ files are zip archives
        raise BankError(f"{p}: not an IPSF bank (expected a .npz file written by "
                        f"`mitsweep ipsf --bank` or mitsweep.io.bank.save_bank)")
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        header = json.loads(bytes(data.pop("header")).decode())
    except Exception as exc:
        raise BankError(f"{p}: not an IPSF bank ({exc})") from None
    if header.get("format") != BANK_FORMAT:
        raise BankError(f"{p}: unknown bank format {header.get('format')!r}, "
                        f"expected {BANK_FORMAT!r}")
    gs = header.get("grid_shape")
    return IPSFBank(kernels=data["kernels"], points_uv=data["points_uv"],
                    depths_mm=data["depths_mm"], pixel_pitch=header["pixel_pitch"],
                    reference_sensor_distance=header["reference_sensor_distance"],
                    kind=header["kind"], radii_mm=data.get("radii_mm"),
                    grid_shape=tuple(gs) if gs else None, vignetted=data.get("vignetted"),
                    metadata=header.get("metadata", {}))
