"""``mitsweep dataset``: render a synthetic focal-sweep dataset (resumable); a thin
wrapper over :func:`mitsweep.workflows.build_dataset`."""

from __future__ import annotations

import argparse
import math

from ..workflows.dataset import build_dataset
from .args import illuminance_lux, positive_int
from .common import print_json
from .dataset_args import (family_param, method_names, non_negative_int, scheduler_address,
                           seconds, shard)
from .motion import add_motion_argument

NAME = "dataset"
HELP = ("render a synthetic dataset of the built-in room, the procedural scene family or a "
        "folder of Mitsuba scenes: ground truth, focused, sweep and stopped images, depth "
        "AOV, IPSF bank, noisy versions and EDOF images, with a manifest (resumable)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file")
    p.add_argument("--out", required=True, help="dataset directory")
    p.add_argument("--scenes", type=positive_int, default=None,
                   help="scene variations (default 1; with --scenes-from, the directory's "
                        "files)")
    p.add_argument("--family", choices=("room", "procedural"), default=None,
                   help="the scenes: the built-in textured room (default; texture layout "
                        "scene.texture_seed + i) or the procedural family (random shapes, "
                        "materials and lights over the depth range; scene seed --seed + i)")
    p.add_argument("--family-param", action="append", type=family_param, default=[],
                   metavar="KEY=VALUE",
                   help="a parameter of the procedural family (repeatable), e.g. "
                        "objects=64, shapes=sphere,cube, envmap=none")
    p.add_argument("--scenes-from", metavar="DIR",
                   help="the scenes: every *.xml Mitsuba scene in DIR, sorted by name, one "
                        "scene each (checked before any work starts)")
    p.add_argument("--scene-unit", choices=("mm", "cm", "m"), default=None,
                   help="length unit of the --scenes-from scenes (default: the setup's "
                        "[scene] unit, else mm)")
    p.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    p.add_argument("--spp", type=positive_int, nargs=4, metavar=("PINHOLE", "FOCUSED", "SWEEP", "STOPPED"),
                   default=[16, 64, 128, 64], help="samples per pixel per mode (default 16 64 128 64)")
    p.add_argument("--lux", type=illuminance_lux, nargs="*", default=[50.0, 2.0, 0.5],
                   help="light levels for the noisy images, lux (default 50 2 0.5)")
    p.add_argument("--bank-rays", type=positive_int, default=None, metavar="N",
                   help="rays traced per IPSF of the bank (default: the tracer's)")
    p.add_argument("--methods", type=method_names, default=("wiener",), metavar="M[,M...]",
                   help="restoration methods of the EDOF images, comma-separated (default "
                        "wiener; wiener writes edof*.exr, another method M edof_M*.exr)")
    p.add_argument("--executor", choices=["serial", "process", "dask"], default=None,
                   help="where tasks run: this process (default), --jobs local processes, "
                        "or Dask (a local cluster of --jobs workers, or --scheduler's)")
    p.add_argument("--jobs", type=positive_int, default=2,
                   help="processes or Dask workers of the local pool or cluster (default 2)")
    p.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT",
                   help="run on the Dask cluster of this scheduler (implies --executor dask)")
    p.add_argument("--shard", type=shard, metavar="K/N",
                   help="make only shard K of N (scenes i with i mod N = K-1, and the "
                        "bank): for job arrays; the last shard to finish merges the "
                        "manifests")
    p.add_argument("--retries", type=non_negative_int, default=2,
                   help="times a task is submitted again after its worker was lost "
                        "(default 2)")
    p.add_argument("--wait", nargs="?", type=seconds, const=math.inf, default=None,
                   metavar="SECONDS",
                   help="if another run holds the directory, wait for it (for ever, or at "
                        "most SECONDS) instead of refusing at once")
    add_motion_argument(p)
    p.add_argument("--json", action="store_true", help="print the manifest as JSON")


def run(args) -> int:
    result = build_dataset(
        args.setup, args.out, scenes=args.scenes, family=args.family,
        family_params=args.family_param, scenes_from=args.scenes_from,
        scene_unit=args.scene_unit, seed=args.seed, spp=args.spp, lux=args.lux,
        methods=args.methods, bank_rays=args.bank_rays, motion=args.motion,
        executor=args.executor, jobs=args.jobs, scheduler=args.scheduler, shard=args.shard,
        retries=args.retries, wait=args.wait)
    manifest = result.value
    if args.json:
        print_json(manifest)
    elif manifest.get("complete"):
        print(f"{len(manifest['items'])} items in {args.out}/ (manifest.json)")
    else:  # a shard whose dataset other shards have yet to finish
        n = result.provenance["items_expected"]
        print(f"{len(manifest['items'])} of {n} items in {args.out}/ "
              f"(shard {args.shard}; the last shard to finish completes manifest.json)")
    return 0
