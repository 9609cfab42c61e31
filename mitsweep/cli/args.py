"""Argument types and shared options of the commands: numbers refused with one line, and
the options of every command that reads a camera file."""

from __future__ import annotations

import argparse
from typing import TypeVar
from collections.abc import Callable

from ..deconv.noise import ILLUMINANCE_RANGE_LUX

__all__ = ["number_type", "positive_float", "illuminance_lux", "depth_mm", "positive_int",
           "add_photo_arguments", "photo_options"]

N = TypeVar("N", int, float)


def number_type(convert: Callable[[str], N], ok: Callable[[N], bool], expected: str,
                allowed: str, name: str) -> Callable[[str], N]:
    """An argparse ``type``: ``convert(text)``, refused unless ``ok`` of it.

    Messages: ``expected <expected>, got 'text'`` (not a number) and ``must be <allowed>,
    got text`` (out of range); argparse prefixes the option. ``ok`` must be False for NaN
    where NaN is not allowed (``x > 0`` is).
    """
    def parse(text: str) -> N:
        try:
            x = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not ok(x):
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text}")
        return x

    parse.__name__ = parse.__qualname__ = name
    return parse


#: A number > 0.
positive_float = number_type(float, lambda x: x > 0, "a number", "> 0", "positive_float")
#: A scene illuminance of a noise model, lux, in
#: :data:`mitsweep.deconv.noise.ILLUMINANCE_RANGE_LUX`.
illuminance_lux = number_type(
    float, lambda x: ILLUMINANCE_RANGE_LUX[0] <= x <= ILLUMINANCE_RANGE_LUX[1],
    "an illuminance in lux",
    f"an illuminance in [{ILLUMINANCE_RANGE_LUX[0]:g}, {ILLUMINANCE_RANGE_LUX[1]:g}] lux",
    "illuminance_lux")
#: An object depth in mm: a number > 0, ``inf`` allowed.
depth_mm = number_type(float, lambda x: x > 0, "a depth in mm (or inf)",
                       "> 0 mm (inf allowed)", "depth_mm")
#: An integer > 0.
positive_int = number_type(int, lambda x: x > 0, "an integer", "> 0", "positive_int")


def add_photo_arguments(p: argparse.ArgumentParser) -> None:
    """The options of every command that reads a camera file
    (:func:`mitsweep.io.camera.read_camera_image`): ``--pixel-pitch``,
    ``--white-balance`` (RAW) and ``--transfer`` (TIFF, PNG, JPEG); pass them on with
    :func:`photo_options`."""
    from ..io.camera import TRANSFERS, WHITE_BALANCES

    p.add_argument("--pixel-pitch", type=positive_float, metavar="MM",
                   help="the photo's pixel pitch, mm, when its metadata has none "
                        "(default: the file's, else the setup's sensor.pixel_pitch)")
    p.add_argument("--white-balance", choices=WHITE_BALANCES, default="camera",
                   help="RAW files: white balance of the decoding (default: camera, the "
                        "as-shot multipliers)")
    p.add_argument("--transfer", choices=TRANSFERS, default=None,
                   help="force the transfer function of a TIFF, PNG or JPEG (default: "
                        "from its metadata; see docs/reference/photos.md)")


def photo_options(args: argparse.Namespace) -> dict:
    """``read_camera_image`` keyword arguments from :func:`add_photo_arguments`'s options."""
    return {"pixel_pitch": args.pixel_pitch, "white_balance": args.white_balance,
            "transfer": args.transfer}
