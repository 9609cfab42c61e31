"""Design a focal sweep for your own mirror: from its numbers to a sweep and its IPSFs.

Give the mirror as a conic (vertex radius of curvature ``R``, conic constant ``k``, rim
radius, distance from the lens to its vertex) and the lens, sensor and depth range; the
script writes the setup TOML (``my_mirror.toml``, loadable by every ``mitsweep``
command), then computes

- the optimal sweep range (paper Eq. 8–9): the focus distances, the sensor travel and the
  exposure at the setup's velocity (:func:`mitsweep.workflows.compute_sweep_range`);
- the focal surfaces: meridional and sagittal image distances D_m, D_s from the lens
  (paper Eq. 6–7, :func:`mitsweep.optics.focal_image_axial_distances`) across the mirror
  at the depth range's two ends (``focal_surfaces.csv`` and ``focal_surfaces.png``, the
  paper's Fig. 6);
- a radial IPSF bank over the field and several depths
  (:func:`mitsweep.workflows.trace_ipsf_bank`, ``bank.npz``) and its depth invariance
  V_avg (paper Eq. 3) and the kurtosis of each IPSF's radial cross-section (Gaussian = 3;
  a focal sweep's IPSF is peakier).

Run::

    python examples/design_sweep_for_your_mirror.py               # the paper's paraboloid
    python examples/design_sweep_for_your_mirror.py --radius 50 --conic 0 --rim 25 \\
        --vertex-distance 327                                     # the paper's sphere
    python examples/design_sweep_for_your_mirror.py --quick --out /tmp/mine

Measured (the paper's paraboloid, R 28.2 mm, k −1, rim 28.25 mm, vertex 352 mm, 50 mm
f/2.8, FOV 167°, 0.3–10 m): focus 365.5 → 387.1 mm, sensor travel 0.509 mm (the paper:
366–387 mm, 0.50 mm), D_m and D_s between 365.5 and 396.7 mm; ``--quick`` (3 radii × 3
depths of 9 px kernels, 4096 rays): V_avg 82, radial kurtosis 5.0–5.8, in 7 s on 2
loaded cores.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

SETUP_TOML = """\
# Written by examples/design_sweep_for_your_mirror.py
[mirror]
kind = "conic"
radius = {radius!r}
conic = {conic!r}
rim_radius = {rim!r}
vertex_distance = {vertex_distance!r}

[lens]
focal_length = {focal_length!r}
f_number = {f_number!r}

[sensor]
resolution = [{resolution}, {resolution}]
pixel_pitch = {pixel_pitch!r}

[sweep]
fov_deg = {fov!r}
depth_min = {depth_min!r}
depth_max = {depth_max!r}
velocity = {velocity!r}
"""


def write_setup(path: Path, **numbers) -> Path:
    """The setup TOML of a conic mirror from its numbers (keys of :data:`SETUP_TOML`)."""
    path.write_text(SETUP_TOML.format(**numbers))
    return path


def focal_surfaces(setup, depths, n: int = 25) -> list[dict]:
    """D_m and D_s (mm from the lens) at ``n`` mirror radii from the axis to the rim, for
    each depth (mm from the mirror point)."""
    from mitsweep.optics import focal_image_axial_distances

    rho = np.linspace(0.0, setup.mirror.rim_radius, n)[1:]  # the axis itself is a limit
    rows = []
    for depth in depths:
        d_m, d_s = focal_image_axial_distances(setup, rho, depth)
        rows += [{"depth_mm": depth, "rho_mm": float(r), "D_m_mm": float(m), "D_s_mm": float(s)}
                 for r, m, s in zip(rho, d_m, d_s)]
    return rows


def bank_metrics(bank) -> dict:
    """V_avg of the bank (paper Eq. 3) and the kurtosis of each IPSF's radial section."""
    from mitsweep.tracer.metrics import cross_sections, kurtosis, v_avg

    kurt = [[kurtosis(cross_sections(k)[1]) for k in row] for row in bank.kernels]
    return {"v_avg": v_avg(bank.kernels), "kurtosis_min": float(np.min(kurt)),
            "kurtosis_max": float(np.max(kurt))}


def design(out: Path, *, quick: bool, **numbers) -> dict:
    """The sweep range with its plot (:func:`mitsweep.workflows.compute_sweep_range`,
    ``mitsweep sweep-range --plot``), the focal surfaces as a table, and an IPSF bank
    (:func:`mitsweep.workflows.trace_ipsf_bank`, ``mitsweep ipsf --bank radial``)."""
    from mitsweep.workflows import compute_sweep_range, resolve_setup, trace_ipsf_bank

    setup_file = write_setup(out / "my_mirror.toml", **numbers)
    setup = resolve_setup(setup_file)
    sweep = compute_sweep_range(setup_file, plot=out / "focal_surfaces.png").value
    ends = [setup.sweep.depth_min, setup.sweep.depth_max]
    rows = focal_surfaces(setup, ends)
    with open(out / "focal_surfaces.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    depths = [ends[0], 1000.0, ends[1]]
    bank = trace_ipsf_bank(setup_file, kind="radial", radii=3 if quick else 9, depths=depths,
                           rays=4096 if quick else 1 << 18, kernel_size=9 if quick else 31,
                           output=out / "bank.npz").value
    return {"setup": str(out / "my_mirror.toml"),
            "focus_mm": [sweep.focus_min, sweep.focus_max],
            "sensor_mm": [sweep.sensor_start, sweep.sensor_end],
            "translation_mm": sweep.translation, "exposure_s": sweep.exposure_s,
            "D_range_mm": [min(min(r["D_m_mm"], r["D_s_mm"]) for r in rows),
                           max(max(r["D_m_mm"], r["D_s_mm"]) for r in rows)],
            "bank": {"shape": list(bank.kernels.shape), "depths_mm": depths,
                     "radii_mm": [float(r) for r in bank.radii], **bank_metrics(bank)}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mirror = ap.add_argument_group("mirror (a conic; the defaults are the paper's paraboloid)")
    mirror.add_argument("--radius", type=float, default=28.2,
                        help="vertex radius of curvature R, mm (paraboloid: 2 × focal length)")
    mirror.add_argument("--conic", type=float, default=-1.0,
                        help="conic constant k (0 sphere, -1 paraboloid, < -1 hyperboloid)")
    mirror.add_argument("--rim", type=float, default=28.25, help="rim radius, mm")
    mirror.add_argument("--vertex-distance", type=float, default=352.0,
                        help="lens centre to mirror vertex, mm")
    ap.add_argument("--focal-length", type=float, default=50.0, help="lens, mm")
    ap.add_argument("--f-number", type=float, default=2.8)
    ap.add_argument("--pixel-pitch", type=float, default=0.02, help="mm")
    ap.add_argument("--resolution", type=int, default=512, help="sensor, px per side")
    ap.add_argument("--fov", type=float, default=167.0, help="field of view, degrees")
    ap.add_argument("--depth-min", type=float, default=300.0, help="mm from the mirror")
    ap.add_argument("--depth-max", type=float, default=10000.0, help="mm from the mirror")
    ap.add_argument("--velocity", type=float, default=1.0, help="sensor velocity, mm/s")
    ap.add_argument("--out", type=Path, help="output directory (default: a new temp dir)")
    ap.add_argument("--quick", action="store_true", help="a tiny bank (for the tests)")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="mitsweep_mirror_"))
    out.mkdir(parents=True, exist_ok=True)
    numbers = {k: getattr(args, k) for k in (
        "radius", "conic", "rim", "vertex_distance", "focal_length", "f_number",
        "pixel_pitch", "resolution", "fov", "depth_min", "depth_max", "velocity")}
    result = design(out, quick=args.quick, **numbers)
    if args.json:
        json.dump(result, sys.stdout, indent=1)
        print()
        return 0
    b = result["bank"]
    print(f"setup          {result['setup']}")
    print(f"focus          {result['focus_mm'][0]:.1f} -> {result['focus_mm'][1]:.1f} mm "
          f"from the lens")
    print(f"sensor         {result['sensor_mm'][0]:.4f} -> {result['sensor_mm'][1]:.4f} mm "
          f"(travel {result['translation_mm']:.3f} mm, exposure {result['exposure_s']:.3f} s)")
    print(f"focal surfaces D in {result['D_range_mm'][0]:.1f} .. {result['D_range_mm'][1]:.1f}"
          f" mm over the mirror ({out / 'focal_surfaces.csv'})")
    print(f"IPSF bank      {b['shape'][0]} depths x {b['shape'][1]} radii, "
          f"{b['shape'][2]} px kernels: V_avg {b['v_avg']:.4g}, radial kurtosis "
          f"{b['kurtosis_min']:.2f} .. {b['kurtosis_max']:.2f} ({out / 'bank.npz'})")
    return 0 if math.isfinite(b["v_avg"]) else 1


if __name__ == "__main__":
    sys.exit(main())
