"""Copy the PNGs of a ``mitsweep figures`` run into the docs gallery, made small.

    python scripts/gallery_images.py /tmp/figs_full            # -> docs/images/figures/

Each PNG is scaled down to at most :data:`MAX_WIDTH` pixels wide (Lanczos) and stored
with a 256-colour palette (median cut, no dithering: dithering would add a noise of its
own to Fig. 10, which compares noise), optimised: the 23 figures of the three setups
take about 5 MiB instead of 15. The run's ``figures.json`` is copied beside them
(quality, seed, version and timings).
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
#: Widest picture in the gallery, pixels.
MAX_WIDTH = 1200


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run", type=Path, help="output directory of `mitsweep figures`")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "figures")
    args = p.parse_args(argv)
    pngs = sorted(args.run.glob("*.png"))
    if not pngs:
        print(f"{args.run}: no PNG figures", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    total = 0
    for src in pngs:
        im = Image.open(src).convert("RGB")
        if im.width > MAX_WIDTH:
            im = im.resize((MAX_WIDTH, round(im.height * MAX_WIDTH / im.width)),
                           Image.Resampling.LANCZOS)
        im = im.quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        dst = args.out / src.name
        im.save(dst, optimize=True)
        total += dst.stat().st_size
        print(f"{dst.relative_to(ROOT) if dst.is_relative_to(ROOT) else dst}: "
              f"{im.width}x{im.height}, {dst.stat().st_size / 1024:.0f} KiB")
    if (args.run / "figures.json").is_file():
        shutil.copy2(args.run / "figures.json", args.out / "figures.json")
    print(f"{len(pngs)} pictures, {total / 2**20:.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
