"""The weight choice against the oracle, before and after (issue 27, item 2).

Prints, in one process, the chosen Wiener NSR's PSNR loss against the oracle NSR (the
best by search against the truth) for the former rule and the new ones: on the
independent spatially varying blur (:func:`mitsweep.deconv.weight_bench.synthetic_weight_bench`)
and on each dataset given (:func:`mitsweep.pipeline.weight_bench.dataset_weight_bench`).

    .venv/bin/python scripts/weight_bench.py --sizes 512 2048 --datasets DIR [DIR ...]
"""

from __future__ import annotations

import argparse
import json
import sys


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[512],
                    help="image sizes of the independent blur (default 512; none: skip)")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.005, 0.001])
    ap.add_argument("--datasets", nargs="*", default=[], help="complete dataset directories")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON")
    a = ap.parse_args(argv)
    from mitsweep.deconv.weight_bench import format_rows, synthetic_weight_bench
    from mitsweep.pipeline.weight_bench import dataset_weight_bench

    synth = synthetic_weight_bench(a.sizes, a.sigmas) if a.sizes else []
    data = [r for d in a.datasets for r in dataset_weight_bench(d)]
    if a.json:
        print(json.dumps({"independent_blur": synth, "datasets": data}, indent=1))
        return 0
    if synth:
        print("independent spatially varying blur (polar Wiener, natural prior); "
              "loss = oracle - chosen, dB")
        print(format_rows(synth, ("before", "model", "blind")))
    if data:
        print("datasets (Wiener, natural prior, as the pipeline restores); "
              "before: max(variance estimate, model NSR at 0.5); after: noise model + spectrum")
        print(format_rows(data, ("before", "after")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
