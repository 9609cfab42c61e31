#!/usr/bin/env python3
"""Pictures of the procedural scene family for the README: pinhole renders through the
mirror, one PNG per scene seed.

    scripts/procedural_pictures.py                       # docs/images/procedural_{0..3}.png
    scripts/procedural_pictures.py --seeds 5 6 --size 512 --spp 256 --setup scenes/paraboloid.toml

The frame is ``--size`` pixels with the setup's sensor size (the pitch scaled), so the
mirror's image fills it as in the full-resolution setup. Each PNG's caption line (the
seed and the parameters that regenerate it) is printed, and the provenance is in a JSON
sidecar beside it.
"""

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mitsweep.config import load_setup  # noqa: E402


def render_picture(setup, seed: int, *, size: int, spp: int, out: Path) -> dict:
    """Render procedural scene ``seed`` (pinhole, ``size``² px) to the PNG ``out``;
    return its provenance."""
    from mitsweep.config import Sensor
    from mitsweep.io.png import write_png
    from mitsweep.render import render_image
    from mitsweep.render.procedural import FAMILY, procedural_scene

    W, _ = setup.sensor.resolution
    small = replace(setup, sensor=Sensor(resolution=(size, size),
                                         pixel_pitch=setup.sensor.pixel_pitch * W / size))
    objects, params = procedural_scene(small, seed)
    result = render_image(small, "pinhole", spp=spp, seed=seed,
                          scene={"type": "scene", **objects}, max_depth=params["max_depth"])
    write_png(out, result.image)
    meta = {"family": FAMILY, "seed": seed, "params": params, "setup": setup.name,
            "resolution": [size, size], "spp": spp, "render_s": result.metadata["render_s"]}
    out.with_suffix(".json").write_text(json.dumps(meta, indent=1) + "\n")
    return meta


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--setup", default=str(ROOT / "scenes" / "sphere.toml"))
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--out", default=str(ROOT / "docs" / "images"))
    args = p.parse_args(argv)
    setup = load_setup(args.setup)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        meta = render_picture(setup, seed, size=args.size, spp=args.spp,
                              out=out / f"procedural_{seed}.png")
        print(f"procedural_{seed}.png: seed {seed}, {meta['resolution'][0]} px, {args.spp} spp, "
              f"{meta['render_s']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
