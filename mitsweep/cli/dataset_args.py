"""Argument types of ``mitsweep dataset``: a family parameter, method names, a Dask
scheduler, a shard, a count of retries and a wait."""

from __future__ import annotations

import argparse

from ..pipeline import Shard
from .args import number_type

__all__ = ["family_param", "method_names", "non_negative_int", "scheduler_address",
           "seconds", "shard"]


seconds = number_type(float, lambda x: x >= 0, "seconds", ">= 0 seconds", "seconds")


def family_param(text: str) -> tuple[str, object]:
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


def method_names(text: str) -> tuple[str, ...]:
    names = tuple(m.strip() for m in text.split(","))
    if not all(names):
        raise argparse.ArgumentTypeError(f"expected method names separated by commas, "
                                         f"got {text!r}")
    return names


def scheduler_address(text: str) -> str:
    from ..pipeline import DatasetError
    from ..pipeline.executors import check_scheduler_address

    try:
        return check_scheduler_address(text)
    except DatasetError as exc:
        raise argparse.ArgumentTypeError(str(exc).partition(": ")[2]) from None


def shard(text: str) -> Shard:
    from ..pipeline import DatasetError, Shard

    try:
        return Shard.parse(text)
    except DatasetError as exc:
        raise argparse.ArgumentTypeError(str(exc).partition(": ")[2]) from None


non_negative_int = number_type(int, lambda n: n >= 0, "an integer", ">= 0",
                                "non_negative_int")
