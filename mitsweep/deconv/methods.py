"""The restoration methods' names (shared by the package and :mod:`.restore`)."""

from __future__ import annotations

__all__ = ["METHODS"]

#: Restoration methods :func:`~mitsweep.deconv.deconvolve` accepts (``method=``); every
#: command that makes an EDOF image offers these names.
METHODS: tuple[str, ...] = ("wiener", "rl", "tv", "hyperlaplacian")
