"""The weight choice against the oracle, before and after (issue 27, item 2).

Prints, in one process, the chosen Wiener NSR's PSNR loss against the oracle NSR (the
best by search against the truth) for the former rule and the new ones: on the
independent spatially varying blur (:func:`mitsweep.deconv.weight_bench.synthetic_weight_bench`)
and on each dataset given (:func:`mitsweep.pipeline.weight_bench.dataset_weight_bench`).

    .venv/bin/python scripts/weight_bench.py --sizes 512 2048 --datasets DIR [DIR ...]

The ``calibrated`` column is the datasets' rule: the noise model and the bank's mismatch
profile measured on the dataset's own calibration scene (``calibration/mismatch.json``;
datasets made before it have none). ``--calibration-scene K`` measures the profile on
scene K instead (datasets of two scenes or more), the other scenes restored with it
(:func:`mitsweep.deconv.weights.mismatch_share`).

``--photos DIR`` adds the photos' restoration (:func:`mitsweep.workflows.restore_photo`,
``mitsweep deconvolve`` without ``--nsr``) on three renders of
``examples/your_scene_through_the_mirror.py`` (rendered into DIR, reused there): the
garden at 64 px (the example's ``--quick``) and 128 px, and the board-and-ball scene at
64 px, each restored with a radial bank at its median depth. Rules side by side: the
oracle; ``before``, the former default (the discrepancy principle,
:func:`mitsweep.deconv.regularization.calibrated_nsr`); ``estimate``
(:func:`mitsweep.deconv.estimate_nsr`, what the example passes); ``blind``
(:func:`mitsweep.deconv.weights.blind_nsr`); ``default``, what ``restore_photo`` chooses
now.

``--photo-datasets DIR ...`` does the same on each dataset's sweep images, restored as a
photo with the dataset's bank (no mirror mask known to the rules); ``model`` is
:func:`mitsweep.deconv.weights.model_nsr` with the noise model an image records.

    .venv/bin/python scripts/weight_bench.py --sizes --photos /tmp/photos \
        --photo-datasets DATASET [DATASET ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: (name, scene, unit, size px, spp) of the photo cases.
PHOTO_CASES = (("garden 64 px", "garden", "m", 64, 64),
               ("garden 128 px", "garden", "m", 128, 64),
               ("board 64 px", "dict", "mm", 64, 64))


def _rules(y, bank, meta: dict) -> dict:
    """The candidate NSRs of a photo without ``nsr``: the former default, the example's
    estimate, the blind rule and, where the image records its noise model, the model's."""
    from mitsweep.deconv import SensorNoise, estimate_nsr
    from mitsweep.deconv.regularization import calibrated_nsr
    from mitsweep.deconv.weights import blind_nsr, model_nsr

    out = {"before": calibrated_nsr(y, bank), "estimate": estimate_nsr(y),
           "blind": blind_nsr(y, bank)}
    if isinstance(meta.get("noise"), dict) and "white_level" in meta:
        out["model"] = model_nsr(y, bank, SensorNoise.from_dict(meta["noise"]),
                                 level=float(meta["white_level"]))
    return out


def dataset_photo_rows(root: Path) -> list[dict]:
    """:func:`photo_rows`' rules on a dataset's sweep images (scene_000), against its
    pinhole image inside its mirror mask."""
    import numpy as np

    from mitsweep.deconv import deconvolve
    from mitsweep.deconv.weight_bench import weight_rows
    from mitsweep.io import read_exr
    from mitsweep.io.bank import load_bank
    from mitsweep.io.camera import read_camera_image
    from mitsweep.pipeline.tasks import MISMATCH
    from mitsweep.workflows import restore_photo

    scene = root / "scene_000"
    bank = load_bank(root / "bank.npz")
    mask = read_exr(scene / "pinhole.exr")[0]["mask.Y"] > 0.5
    truth = read_camera_image(scene / "pinhole.exr").data
    white = float(np.percentile(truth[mask], 99.5))
    rows = []
    for path in sorted(scene.glob("sweep*.exr")):
        y = read_camera_image(path).data
        candidates = _rules(y, bank, read_exr(path)[1])
        if (root / MISMATCH).is_file():   # the datasets' rule, as deconvolve --mismatch
            candidates["calibrated"] = restore_photo(
                path, bank=root / "bank.npz", mismatch=root / MISMATCH).provenance["nsr"]
        default = restore_photo(path, bank=root / "bank.npz")
        r = weight_rows(y / white, truth / white,
                        lambda x, w: deconvolve(x, bank, nsr=w, prior="natural"),
                        candidates, mask=mask)
        p = -10 * np.log10(float(np.mean(((default.value - truth) / white)[mask] ** 2)))
        nsr = default.provenance["nsr"]
        r["default"] = {"weight": nsr if isinstance(nsr, float) else float("nan"),
                        "psnr_db": float(p), "loss_db": r["oracle"]["psnr_db"] - float(p)}
        rows.append({"case": f"{root.name} {path.stem}", **r})
    return rows


def photo_rows(root: Path) -> list[dict]:
    """Per photo case: the oracle NSR and each rule's NSR, PSNR and loss (dB, inside the
    mirror's image, against the pinhole render, data range the pinhole's 99.5 %)."""
    sys.path.insert(0, str(ROOT / "examples"))
    import numpy as np
    from your_scene_through_the_mirror import board_world, small_setup

    from mitsweep.deconv import deconvolve
    from mitsweep.deconv.weight_bench import weight_rows
    from mitsweep.io import read_exr
    from mitsweep.io.bank import load_bank
    from mitsweep.io.camera import read_camera_image
    from mitsweep.workflows import render_exr, restore_photo, trace_ipsf_bank

    rows = []
    for name, scene, unit, size, spp in PHOTO_CASES:
        out = root / name.replace(" ", "_")
        out.mkdir(parents=True, exist_ok=True)
        setup = small_setup(ROOT / "scenes" / "sphere.toml", size)
        src = board_world() if scene == "dict" else str(ROOT / "scenes" / "garden_m.xml")
        if not (out / "bank.npz").is_file():
            sweep = render_exr(setup, out / "sweep.exr", mode="sweep", spp=spp, seed=1,
                               scene=src, scene_unit=unit, aovs=("depth", "mask")).value
            render_exr(setup, out / "pinhole.exr", mode="pinhole", spp=spp, seed=2,
                       scene=src, scene_unit=unit)
            mask = sweep.aovs["mask"] > 0.5
            median = float(np.median(sweep.aovs["depth"][mask & (sweep.aovs["depth"] > 0)]))
            trace_ipsf_bank(setup, kind="radial", radii=9, depths=[median],
                            rays=1 << 14 if size <= 64 else 1 << 17, kernel_size=15,
                            output=out / "bank.npz")
        y = read_camera_image(out / "sweep.exr").data
        truth = read_camera_image(out / "pinhole.exr").data
        mask = read_exr(out / "sweep.exr")[0]["mask.Y"] > 0.5
        white = float(np.percentile(truth[mask], 99.5))
        bank = load_bank(out / "bank.npz")
        default = restore_photo(out / "sweep.exr", bank=out / "bank.npz")
        r = weight_rows(y / white, truth / white,
                        lambda x, w, bank=bank: deconvolve(x, bank, nsr=w, prior="natural"),
                        _rules(y, bank, read_exr(out / "sweep.exr")[1]), mask=mask)
        # what restore_photo restores without nsr, scored as the rules are
        p = -10 * np.log10(float(np.mean(((default.value - truth) / white)[mask] ** 2)))
        nsr = default.provenance["nsr"]
        r["default"] = {"weight": nsr if isinstance(nsr, float) else float("nan"),
                        "psnr_db": float(p), "loss_db": r["oracle"]["psnr_db"] - float(p)}
        rows.append({"case": f"photo {name}, {spp} spp", **r})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[512],
                    help="image sizes of the independent blur (default 512; none: skip)")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.005, 0.001])
    ap.add_argument("--datasets", nargs="*", default=[], help="complete dataset directories")
    ap.add_argument("--photos", type=Path, metavar="DIR",
                    help="also the photos' default (restore_photo without nsr) on three "
                         "renders, made in DIR (reused)")
    ap.add_argument("--photo-datasets", type=Path, nargs="*", default=[], metavar="DIR",
                    help="also the photos' rules on these datasets' sweep images")
    ap.add_argument("--calibration-scene", type=int, metavar="K",
                    help="also the 'calibrated' weight: the bank's mismatch profile "
                         "measured on each dataset's scene K (its noise-free sweep and "
                         "truth), the other scenes restored with it")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON")
    a = ap.parse_args(argv)
    from mitsweep.deconv.weight_bench import format_rows, synthetic_weight_bench
    from mitsweep.pipeline.weight_bench import dataset_weight_bench

    synth = synthetic_weight_bench(a.sizes, a.sigmas) if a.sizes else []
    data = [r for d in a.datasets
            for r in dataset_weight_bench(d, calibration_scene=a.calibration_scene)]
    photos = (photo_rows(a.photos) if a.photos else []) + [
        r for d in a.photo_datasets for r in dataset_photo_rows(d)]
    if a.json:
        print(json.dumps({"independent_blur": synth, "datasets": data, "photos": photos},
                         indent=1))
        return 0
    if synth:
        print("independent spatially varying blur (polar Wiener, natural prior); "
              "loss = oracle - chosen, dB")
        print(format_rows(synth, ("before", "model", "blind", "mirror")))
    if data:
        print("datasets (Wiener, natural prior, as the pipeline restores); "
              "before: max(variance estimate, model NSR at 0.5); after: noise model + the "
              "frame's spectrum; mirror: noise model + the mirror's spectrum"
              + ("; calibrated: noise model + the mismatch profile of scene "
                 f"{a.calibration_scene}" if a.calibration_scene is not None else
                 "; calibrated: noise model + the dataset's own profile (its calibration "
                 "scene, the datasets' rule)"))
        calibrated = any("calibrated" in r for r in data)
        print(format_rows(data, ("before", "after", "mirror")
                          + (("calibrated",) if calibrated else ())))
    if photos:
        print("photos (restore_photo, polar Wiener, natural prior); before: the former "
              "default (discrepancy principle); default: restore_photo without nsr now; "
              "calibrated: restore_photo with the dataset's mismatch profile "
              "(deconvolve --mismatch)")
        print(format_rows(photos, ("before", "estimate", "blind", "model", "default")
                          + (("calibrated",) if any("calibrated" in r for r in photos)
                             else ())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
