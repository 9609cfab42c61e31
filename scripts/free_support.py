"""How much of its outline a circle found without a setup is fitted to
(:func:`mitsweep.photo.free.visible_support`, the measure
:data:`mitsweep.photo.free.FREE_MIN_SUPPORT` judges): on the real photos of mirrors in
``tests/data/real`` and on scikit-image's sample photos, which show none.

The search runs with the bar lowered to 0, so that each photo shows the outline
``--free`` would take without it and that outline's support.

Usage::

    .venv/bin/python scripts/free_support.py [--photos NAME ...]

About three minutes on two cores. Prints one line per photo: where, its support, the
search's time, and whether the bar keeps it.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from real_corpus import corpus  # noqa: E402
from sample_photos import FREE_REFUSED, FREE_ROUND_THINGS, sample_photo  # noqa: E402

from mitsweep.io.camera import read_camera_image  # noqa: E402
from mitsweep.photo import free  # noqa: E402
from mitsweep.photo.rim import NoMirrorError  # noqa: E402


def photos() -> list[tuple[str, str, object]]:
    """(name, kind, loader) of every photo measured."""
    out = [(e["name"], "mirror", lambda e=e: read_camera_image(e["path"]).data)
           for e in corpus(with_outline=True)]
    out += [(n, "no mirror", lambda n=n: sample_photo(n))
            for n in sorted([*FREE_REFUSED, *FREE_ROUND_THINGS])]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", nargs="*", help="only these (file or sample names)")
    args = ap.parse_args(argv)
    logging.getLogger("mitsweep.io.camera").setLevel(logging.ERROR)  # 8-bit, JPEG: known
    bar = free.FREE_MIN_SUPPORT
    free.FREE_MIN_SUPPORT = 0.0
    print(f"{'photo':28s} {'kind':9s} {'found':34s} {'support':>7s} {'time':>6s}  "
          f"with the bar ({bar:g})")
    for name, kind, load in photos():
        if args.photos and name not in args.photos:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            image = load()
            t = time.perf_counter()
            try:
                fit, radius = free.find_circle(image)
            except NoMirrorError:
                print(f"{name:28s} {kind:9s} {'none':34s} {'':>7s} "
                      f"{time.perf_counter() - t:5.1f}s  refused")
                continue
        dt = time.perf_counter() - t
        what = (f"({fit.center_px[0]:.1f}, {fit.center_px[1]:.1f}) r {radius:.1f}"
                + (" limb" if fit.limb else ""))
        if fit.limb:   # a limb is judged by its own cue (FREE_LIMB_RADIAL_SHARE)
            print(f"{name:28s} {kind:9s} {what:34s} {'-':>7s} {dt:5.1f}s  kept (a limb)")
            continue
        support = free.visible_support(fit, free.circle_outline(radius / fit.scale), image)
        print(f"{name:28s} {kind:9s} {what:34s} {support:7.2f} {dt:5.1f}s  "
              f"{'kept' if support >= bar else 'refused'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
