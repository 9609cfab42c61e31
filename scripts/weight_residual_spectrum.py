"""What a dataset's blur model leaves unexplained, frequency by frequency (issue 27).

For the noise-free sweep of a dataset's first scene: the ring periodogram of the sweep
``P(f)``, of the pinhole truth ``T(f)`` and the bank's mean transfer ``H²(f)`` over the
mirror's image (:func:`mitsweep.deconv.weights.ring_spectrum` through
:func:`~mitsweep.deconv.weights.spectrum_window`, the traced kernels weighted by
:func:`~mitsweep.deconv.weights.kernel_shares` with ``stand_ins=False``), and the
residual ``P - H² T``: what the model's blur of the truth does not explain. White noise
reads flat; the bank's mismatch with the render does not. A diagnostic: it needs the
truth, which a weight rule does not have.

    .venv/bin/python scripts/weight_residual_spectrum.py DATASET [DATASET ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def residual_rows(directory: Path, every: int = 3) -> list[tuple[float, float, float, float]]:
    """(f, P, H², P - H² T) for every ``every``-th ring of the dataset's noise-free sweep."""
    from mitsweep.deconv import weights as W
    from mitsweep.io.bank import load_bank
    from mitsweep.pipeline.weight_bench import (BANK, checked_items, load_manifest,
                                                read_finite, white_level)

    files = checked_items(directory, load_manifest(directory))
    bank = load_bank(files[BANK])
    gt, chans, _ = read_finite(files["scene_000/pinhole.exr"])
    mask = chans["mask.Y"] > 0.5
    level = white_level(gt, chans["mask.Y"])
    sweep = read_finite(files["scene_000/sweep.exr"])[0] / level
    window = W.spectrum_window(mask)
    f, P = W.ring_spectrum(sweep, window=window)
    _, T = W.ring_spectrum(gt / level, window=window)
    shares = W.kernel_shares(bank, mask.shape, mask=mask, stand_ins=False)
    keep = shares > 0
    L = 128
    H2 = np.tensordot(shares[keep], W._kernel_power(bank.kernels[0][keep].astype(float), L), 1)
    H2r = W.ring_average(H2, f)
    return [(f[i], P[i], H2r[i], P[i] - H2r[i] * T[i]) for i in range(0, len(f), every)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    a = ap.parse_args(argv)
    for d in a.datasets:
        print(d)
        print(f"  {'f c/px':>7} {'P':>10} {'H2':>7} {'P - H2 T':>10}")
        for f, P, H2, res in residual_rows(d):
            print(f"  {f:7.3f} {P:10.3g} {H2:7.3f} {res:10.3g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
