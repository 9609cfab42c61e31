"""Reference outputs of the tracer and the polar deconvolution, compared bit for bit.

A restructuring of :mod:`mitsweep.tracer` or :mod:`mitsweep.deconv.polar` must not change
a single bit of what they compute. This script computes small IPSFs (on-axis, off-axis,
infinite depth; the exact, continuous and N-plane methods; one PSF; a float64 one; an
even asphere), a radial bank (sphere, paraboloid), a grid bank (tilted paraboloid) and
polar deconvolutions (Wiener with a given and an estimated NSR, float32 and float64, RGB;
damped Richardson-Lucy) on the bundled setups, in about a minute on two cores.

Usage::

    python scripts/compare_outputs.py --save /tmp/ref.npz      # before the change
    python scripts/compare_outputs.py --check /tmp/ref.npz     # after: exit 1 on any bit

``--check`` compares every array with ``np.array_equal`` and prints the largest
absolute difference of those that differ.

Dr.Jit runs on one thread here: the deposits' float64 atomic sums are otherwise added in
the order the worker threads reach them, which moves their last bits from run to run
(measured: 2e-15 in the float64 info of the same code, run twice).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SETUPS = ("sphere", "paraboloid", "paraboloid_tilted")
RAYS = 1 << 15
K = 21


def _trace(**kw):
    """Keywords of the tracing functions: the sampling ones in a TraceSettings where the
    code has one, else as they were (so the script runs on the code before it too)."""
    try:
        from mitsweep.tracer import TraceSettings
    except ImportError:
        return kw
    names = {"rays", "kernel_size", "seed", "method", "time_samples", "n_planes"}
    settings = {k: kw.pop(k) for k in list(kw) if k in names}
    return {**kw, "settings": TraceSettings(**settings)}


def _setup(name):
    from mitsweep.config import load_setup

    return load_setup(ROOT / "scenes" / f"{name}.toml")


def tracer_outputs() -> dict[str, np.ndarray]:
    """IPSFs, PSFs and banks of the bundled setups (float arrays keyed by a name)."""
    from mitsweep.tracer import integrated_psf, ipsf_bank, psf
    from mitsweep.tracer.bank import field_radius
    from mitsweep.tracer.ipsf import integrated_psfs

    out = {}
    for name in SETUPS:
        setup = _setup(name)
        r = 0.6 * field_radius(setup)
        cases = [("axis-500-exact", 0.0, 0.0, 500.0, {}),
                 ("off-inf-exact", r, 0.0, np.inf, {}),
                 ("off-800-continuous", 0.0, r, 800.0, {"method": "continuous"}),
                 ("off-300-planes", -r, 0.0, 300.0, {"method": "planes", "n_planes": 5}),
                 ("off-500-double", r, 0.3 * r, 500.0, {"double": True, "seed": 3})]
        for label, u, v, d, kw in cases:
            k, info = integrated_psf(setup, u, v, d, **_trace(rays=RAYS, kernel_size=K, **kw))
            out[f"{name}/ipsf/{label}"] = k
            out[f"{name}/ipsf/{label}/info"] = np.array(
                [info["vignetted_fraction"], info["outside_kernel_fraction"],
                 info["rays_landed"], *info["centroid_px"]], dtype=np.float64)
        many = integrated_psfs(setup, [(0.0, 0.0, 500.0), (r, 0.0, np.inf), (0.0, r, 1e4)],
                               seeds=[0, 1, 2], **_trace(rays=RAYS, kernel_size=K))
        for j, res in enumerate(many):
            out[f"{name}/ipsfs/{j}"] = res[0]
        geometry_ref = integrated_psf(setup, 0.0, 0.0, 500.0, **_trace(rays=RAYS,
                                                                      kernel_size=K))[1]
        dist = geometry_ref["reference_sensor_distance_mm"]
        out[f"{name}/psf"] = psf(setup, r, 0.0, 500.0, dist + 0.4, rays=RAYS, kernel_size=K)[0]
        if name == "paraboloid_tilted":
            bank = ipsf_bank(setup, kind="grid", grid=(2, 3), depths=(500.0, np.inf),
                             **_trace(rays=1 << 14, kernel_size=15))
        else:
            bank = ipsf_bank(setup, n_radii=3, depths=(400.0, np.inf),
                             **_trace(rays=1 << 14, kernel_size=15))
        out[f"{name}/bank/kernels"] = bank.kernels
        out[f"{name}/bank/vignetted"] = bank.vignetted
        if name == "paraboloid":
            single = ipsf_bank(setup, n_radii=2, depths=(600.0,), batched=False,
                               **_trace(rays=1 << 13, kernel_size=11))
            out[f"{name}/bank-unbatched/kernels"] = single.kernels
            mirror = dataclasses.replace(setup.mirror, aspheric=(2e-6, -1e-9))
            asph = dataclasses.replace(setup, mirror=mirror)
            out[f"{name}/asphere/ipsf"] = integrated_psf(asph, r, 0.0, 500.0,
                                                         **_trace(rays=RAYS, kernel_size=K))[0]
    return out


def polar_outputs() -> dict[str, np.ndarray]:
    """Polar deconvolutions of a synthetic image blurred by a synthetic radial bank."""
    from mitsweep.deconv import deconvolve, from_polar, polar_deconvolve, polar_grid, to_polar
    from mitsweep.deconv.synthetic import synthetic_radial_bank

    out = {}
    rng = np.random.default_rng(7)
    shape = (96, 112)
    img = rng.random(shape)
    img = np.cumsum(np.cumsum(img, 0), 1)
    img = (img / img.max()).astype(np.float64)
    bank = synthetic_radial_bank(shape, size=9, r_max_px=48.0, n_radii=7)
    g = polar_grid(shape)
    out["polar/to_polar"] = to_polar(img, g)
    out["polar/roundtrip"] = from_polar(out["polar/to_polar"], g, shape)
    from mitsweep.deconv.operators import polar_operator

    op = polar_operator(bank, shape)
    y = np.asarray(op.forward(img)) + 1e-3 * rng.standard_normal(shape)
    out["polar/blurred"] = y
    out["polar/wiener64"] = polar_deconvolve(y, bank, nsr=1e-3)
    out["polar/wiener32"] = polar_deconvolve(y.astype(np.float32), bank, nsr=1e-3)
    out["polar/wiener-est"] = polar_deconvolve(y, bank)
    out["polar/wiener-off"] = polar_deconvolve(y, bank, nsr=1e-2, center=(50.3, 52.1),
                                               band_spacing=0.4, prior="constant")
    rgb = np.stack([y, y[::-1], y[:, ::-1]], -1).astype(np.float32)
    out["polar/wiener-rgb"] = polar_deconvolve(rgb, bank, nsr=1e-3)
    out["polar/rl"] = deconvolve(y, bank, method="rl", iterations=5)
    return out


def compute() -> dict[str, np.ndarray]:
    import drjit as dr

    dr.set_thread_count(1)
    t0 = time.perf_counter()
    out = {**polar_outputs(), **tracer_outputs()}
    print(f"{len(out)} arrays in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return {k: np.asarray(v) for k, v in out.items()}


def check(ref_path: str, out: dict[str, np.ndarray]) -> int:
    ref = dict(np.load(ref_path))
    bad = 0
    for key in sorted(set(ref) | set(out)):
        if key not in out or key not in ref:
            print(f"MISSING {key} ({'new' if key in out else 'gone'})")
            bad += 1
            continue
        a, b = ref[key], out[key]
        if a.shape != b.shape or a.dtype != b.dtype:
            print(f"DIFFER  {key}: {a.dtype}{a.shape} vs {b.dtype}{b.shape}")
            bad += 1
        elif not np.array_equal(a, b, equal_nan=True):
            diff = np.nanmax(np.abs(a.astype(np.float64) - b.astype(np.float64)))
            print(f"DIFFER  {key}: max |diff| {diff:.3g}")
            bad += 1
    print(f"{len(ref)} reference arrays, {bad} differ" if bad
          else f"all {len(ref)} arrays bit-identical")
    return 1 if bad else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    grp = ap.add_mutually_exclusive_group(required=True)
    grp.add_argument("--save", metavar="NPZ", help="write the outputs")
    grp.add_argument("--check", metavar="NPZ", help="compare the outputs with NPZ")
    args = ap.parse_args(argv)
    out = compute()
    if args.save:
        np.savez_compressed(args.save, **out)
        print(f"saved {len(out)} arrays to {args.save}")
        return 0
    return check(args.check, out)


if __name__ == "__main__":
    sys.exit(main())
