"""``mitsweep dataset``: render a synthetic focal-sweep dataset (resumable)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from .common import (number_type, UsageError, check_outputs, illuminance_lux, load_setup_arg,
                     positive_int, print_json)
from .motion import add_motion_argument, motion_from_args

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
    p.add_argument("--family-param", action="append", type=_family_param, default=[],
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
    p.add_argument("--methods", type=_methods, default=("wiener",), metavar="M[,M...]",
                   help="restoration methods of the EDOF images, comma-separated (default "
                        "wiener; wiener writes edof*.exr, another method M edof_M*.exr)")
    p.add_argument("--executor", choices=["serial", "process", "dask"], default=None,
                   help="where tasks run: this process (default), --jobs local processes, "
                        "or Dask (a local cluster of --jobs workers, or --scheduler's)")
    p.add_argument("--jobs", type=positive_int, default=2,
                   help="processes or Dask workers of the local pool or cluster (default 2)")
    p.add_argument("--scheduler", type=_scheduler, metavar="tcp://HOST:PORT",
                   help="run on the Dask cluster of this scheduler (implies --executor dask)")
    p.add_argument("--shard", type=_shard, metavar="K/N",
                   help="make only shard K of N (scenes i with i mod N = K-1, and the "
                        "bank): for job arrays; the last shard to finish merges the "
                        "manifests")
    p.add_argument("--retries", type=_non_negative_int, default=2,
                   help="times a task is submitted again after its worker was lost "
                        "(default 2)")
    p.add_argument("--wait", nargs="?", type=_seconds, const=math.inf, default=None,
                   metavar="SECONDS",
                   help="if another run holds the directory, wait for it (for ever, or at "
                        "most SECONDS) instead of refusing at once")
    add_motion_argument(p)
    p.add_argument("--json", action="store_true", help="print the manifest as JSON")


_seconds = number_type(float, lambda x: x >= 0, "seconds", ">= 0 seconds", "seconds")


def _family_param(text: str) -> tuple[str, object]:
    """``KEY=VALUE``: the value as JSON where it is JSON (numbers), else a string."""
    import json

    key, sep, value = text.partition("=")
    if not (sep and key.strip()):
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        parsed = json.loads(value)
    except ValueError:
        parsed = value.strip()
    if not isinstance(parsed, (int, float, str)):
        parsed = value.strip()
    return key.strip(), parsed


def _methods(text: str) -> tuple[str, ...]:
    names = tuple(m.strip() for m in text.split(","))
    if not all(names):
        raise argparse.ArgumentTypeError(f"expected method names separated by commas, "
                                         f"got {text!r}")
    return names


def _scheduler(text: str) -> str:
    from ..pipeline import DatasetError
    from ..pipeline.executors import check_scheduler_address

    try:
        return check_scheduler_address(text)
    except DatasetError as exc:
        raise argparse.ArgumentTypeError(str(exc).partition(": ")[2]) from None


def _shard(text: str):
    from ..pipeline import DatasetError, Shard

    try:
        return Shard.parse(text)
    except DatasetError as exc:
        raise argparse.ArgumentTypeError(str(exc).partition(": ")[2]) from None


_non_negative_int = number_type(int, lambda n: n >= 0, "an integer", ">= 0",
                                "non_negative_int")


#: DatasetOptions fields → the options that set them, for messages.
_OPTION_OF = {"scenes": "--scenes", "seed": "--seed", "spp": "--spp",
              "light_levels_lux": "--lux", "methods": "--methods", "bank_rays": "--bank-rays",
              "family": "--family", "family_params": "--family-param",
              "scene_files": "--scenes-from", "scene_unit": "--scene-unit",
              "motion": "--motion"}


def _scene_options(args, setup) -> dict:
    """The DatasetOptions fields of the scene options (family, parameters, files)."""
    from ..pipeline.dataset import scene_files_from

    if args.scenes_from is None:
        if args.scene_unit is not None:
            raise UsageError("--scene-unit: applies to --scenes-from scenes only")
        family = args.family or "room"
        if args.family_param and family != "procedural":
            raise UsageError(f"--family-param: applies to --family procedural only, got "
                             f"--family {family}")
        return {"scenes": args.scenes or 1, "family": family,
                "family_params": dict(args.family_param)}
    for given, option in ((args.family, "--family"), (args.scenes, "--scenes"),
                          (args.family_param, "--family-param")):
        if given:
            raise UsageError(f"{option}: not with --scenes-from (each *.xml file of "
                             f"{args.scenes_from} is one scene)")
    files = scene_files_from(args.scenes_from, setup, unit=args.scene_unit)
    return {"scenes": len(files), "family": "xml", "scene_files": files,
            "scene_unit": args.scene_unit}


def check_dataset_outputs(inputs: list, out: Path, opts, shard=None) -> None:
    """:func:`check_outputs` for a dataset directory: no input is the directory, nor one
    of the files a run with ``opts`` writes in it (manifest, lock, items, logs)."""
    from ..pipeline.dataset import written_paths

    check_outputs(inputs, {"--out": out})
    written = None
    root = out.resolve()
    for inp in inputs:
        if inp is None:
            continue
        try:
            rel = Path(inp).resolve().relative_to(root).as_posix()
        except ValueError:
            continue  # not inside the directory
        written = written or written_paths(opts, shard)
        if rel in written:
            check_outputs([inp], [out / rel])


def run(args) -> int:
    from ..pipeline import DatasetError, DatasetOptions, build_dataset, item_names

    if args.out.strip() == "":
        raise UsageError("--out: must name a directory")
    setup = load_setup_arg(args.setup)
    scenes = _scene_options(args, setup)
    motion = motion_from_args(args, setup)
    if motion is not None:
        scenes["motion"] = {"times": motion.times.tolist(),
                            "positions_mm": motion.positions.tolist()}
    try:
        opts = DatasetOptions(seed=args.seed,
                              spp=dict(zip(("pinhole", "focused", "sweep", "stopped"), args.spp)),
                              light_levels_lux=tuple(args.lux), methods=args.methods,
                              bank_rays=args.bank_rays, **scenes)
    except DatasetError as exc:  # name the option, not the field
        field, _, rest = str(exc).partition(":")
        head = field.split("[")[0].split(".")[0]
        detail = field.partition(".")[2]
        rest = f" {detail}:{rest}" if detail else rest
        raise UsageError(f"{_OPTION_OF.get(head, field)}:{rest}") from None
    out = Path(args.out)
    if args.scheduler and args.executor not in (None, "dask"):
        raise UsageError(f"--scheduler: needs --executor dask (or no --executor), got "
                         f"--executor {args.executor}")
    check_dataset_outputs([args.setup, args.motion, *(f["path"] for f in opts.scene_files)],
                          out, opts, args.shard)
    manifest = build_dataset(setup, out, opts, executor=args.executor or "serial",
                             jobs=args.jobs, scheduler=args.scheduler, shard=args.shard,
                             retries=args.retries, wait=args.wait)
    if args.json:
        print_json(manifest)
    elif manifest.get("complete"):
        print(f"{len(manifest['items'])} items in {args.out}/ (manifest.json)")
    else:  # a shard whose dataset other shards have yet to finish
        print(f"{len(manifest['items'])} of {len(item_names(opts))} items in {args.out}/ "
              f"(shard {args.shard}; the last shard to finish completes manifest.json)")
    return 0
