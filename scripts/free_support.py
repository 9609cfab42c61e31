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


def measure(names=None):
    """One dict per photo (all, or those in ``names``): ``name``, ``kind`` ("mirror" or
    "no mirror"), ``found`` (False where even the lowered bar finds nothing), ``limb``,
    ``centre`` and ``radius`` (px), ``support`` (None for a limb, judged by its own cue)
    and ``seconds``, with the bar lowered to 0 for the search."""
    logging.getLogger("mitsweep.io.camera").setLevel(logging.ERROR)  # 8-bit, JPEG: known
    bar = free.FREE_MIN_SUPPORT
    free.FREE_MIN_SUPPORT = 0.0
    try:
        for name, kind, load in photos():
            if names and name not in names:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                image = load()
                t = time.perf_counter()
                try:
                    fit, radius = free.find_circle(image)
                except NoMirrorError:
                    yield {"name": name, "kind": kind, "found": False, "limb": False,
                           "centre": None, "radius": None, "support": None,
                           "seconds": time.perf_counter() - t}
                    continue
            support = None if fit.limb else free.visible_support(
                fit, free.circle_outline(radius / fit.scale), image)
            yield {"name": name, "kind": kind, "found": True, "limb": bool(fit.limb),
                   "centre": fit.center_px, "radius": radius, "support": support,
                   "seconds": time.perf_counter() - t}
    finally:
        free.FREE_MIN_SUPPORT = bar


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", nargs="*", help="only these (file or sample names)")
    args = ap.parse_args(argv)
    bar = free.FREE_MIN_SUPPORT
    print(f"{'photo':28s} {'kind':9s} {'found':34s} {'support':>7s} {'time':>6s}  "
          f"with the bar ({bar:g})")
    for m in measure(args.photos):
        head = f"{m['name']:28s} {m['kind']:9s}"
        if not m["found"]:
            print(f"{head} {'none':34s} {'':>7s} {m['seconds']:5.1f}s  refused")
            continue
        what = (f"({m['centre'][0]:.1f}, {m['centre'][1]:.1f}) r {m['radius']:.1f}"
                + (" limb" if m["limb"] else ""))
        if m["support"] is None:   # a limb is judged by its own cue (FREE_LIMB_RADIAL_SHARE)
            print(f"{head} {what:34s} {'-':>7s} {m['seconds']:5.1f}s  kept (a limb)")
            continue
        print(f"{head} {what:34s} {m['support']:7.2f} {m['seconds']:5.1f}s  "
              f"{'kept' if m['support'] >= bar else 'refused'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
