"""PNG and ICC reading under damaged input: fuzzed, and the regressions that fuzzing found.

16-bit PNGs are decoded by libpng (imagecodecs) and their chunks read by Pillow; what
mitsweep still parses itself is the IHDR (``mitsweep.io.camera``'s own reader) and an
ICC profile's tone curve (:func:`mitsweep.io.camera.icc_transfer`). Whatever a file
holds, reading it either gives an image or raises :class:`CameraFileError` /
:class:`ResourceError` naming the file: never another exception, never a warning. The
fuzzing is mutational (hypothesis flips, truncates and splices bytes of valid files) and
its example counts are kept small so that the default run stays fast.
"""

from __future__ import annotations

import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli_contract import refused
from mitsweep.io.camera import (CameraFileError, icc_transfer, png16_bytes, read_camera_image,
                                write_display_image)
from mitsweep.resources import MAX_MEMORY_ENV, ResourceError
from test_memory_gate import _chunk, png_bytes

ROOT = Path(__file__).resolve().parents[1]
SPHERE = ROOT / "scenes" / "sphere.toml"

RNG = np.random.default_rng(7)
SEED_IMAGE16 = RNG.integers(0, 65536, (6, 5, 3), dtype=np.uint16)
#: Valid files the mutations start from: 16-bit RGB (libpng) and 8-bit grey (Pillow).
SEEDS = {
    "rgb16": png16_bytes(SEED_IMAGE16, {"mitsweep": '{"transfer": "linear"}'}),
    "grey8": png_bytes(4, 3, 8, 0, zlib.compress(b"".join(
        b"\x00" + bytes(9 * r + c for c in range(4)) for r in range(3)))),
}


def _read(tmp: Path, data: bytes):
    """Read ``data`` as a PNG: the image, or the refusal (any other exception and any
    warning fail the test)."""
    p = tmp / "fuzz.png"
    p.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            return read_camera_image(p)
        except (CameraFileError, ResourceError) as exc:
            line = str(exc)
            assert "\n" not in line and str(p) in line, line
            return exc


@st.composite
def mutated(draw, seed_names=tuple(SEEDS)):
    data = bytearray(SEEDS[draw(st.sampled_from(seed_names))])
    for _ in range(draw(st.integers(1, 4))):
        if not data:
            break
        op = draw(st.sampled_from(["flip", "truncate", "insert", "delete"]))
        i = draw(st.integers(0, max(0, len(data) - 1)))
        if op == "flip":
            data[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "truncate":
            del data[i:]
        elif op == "insert":
            data[i:i] = draw(st.binary(min_size=1, max_size=16))
        else:
            del data[i:i + draw(st.integers(1, 16))]
    return bytes(data)


@st.composite
def rechunked(draw):
    """A valid 16-bit PNG with a chunk of random type and content before its IDAT (valid
    CRC): the chunk readers meet contents no writer would give them."""
    kind = draw(st.sampled_from([b"gAMA", b"iCCP", b"sRGB", b"tEXt", b"zTXt", b"iTXt",
                                 b"eXIf", b"cHRM", b"pHYs", b"sBIT"]))
    body = draw(st.binary(max_size=64))
    seed = SEEDS["rgb16"]
    at = seed.index(b"IDAT") - 4
    return seed[:at] + _chunk(kind, body) + seed[at:]


FUZZ = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(data=mutated())
def test_mutated_png_is_read_or_refused(data, tmp_path):
    _read(tmp_path, data)


@FUZZ
@given(data=rechunked())
def test_any_ancillary_chunk_is_read_or_refused(data, tmp_path):
    _read(tmp_path, data)


@settings(max_examples=300, deadline=None)
@given(icc=st.one_of(st.binary(max_size=400),
                     st.builds(lambda head, n, tail: head + struct.pack(">I", n) + tail,
                               st.binary(min_size=128, max_size=128),
                               st.integers(0, 2**32 - 1), st.binary(max_size=300))))
def test_icc_tone_curve_reader_never_raises(icc):
    found = icc_transfer(icc)
    assert found is None or found[0] in ("linear", "gamma", "srgb")


# -- the regressions ---------------------------------------------------------------------
def _rgb16_with(extra: bytes) -> bytes:
    seed = SEEDS["rgb16"]
    at = seed.index(b"IDAT") - 4
    return seed[:at] + extra + seed[at:]


REFUSED = [
    ("gama-2-bytes", _rgb16_with(_chunk(b"gAMA", b"\x00\x01")), "gAMA"),
    ("width-0", png_bytes(0, 8, 16, 2, zlib.compress(b"\x00" * 8)), "fuzz.png"),
    ("height-0", png_bytes(8, 0, 16, 2, zlib.compress(b"")), "fuzz.png"),
    ("grey8-width-0", png_bytes(0, 8, 8, 0, zlib.compress(b"\x00" * 8)), "fuzz.png"),
    ("idat-short", png_bytes(8, 8, 16, 2, zlib.compress(b"\x00" * 20)), "fuzz.png"),
    ("idat-not-zlib", png_bytes(8, 8, 16, 2, b"not zlib at all"), "fuzz.png"),
    ("signature-only", b"\x89PNG\r\n\x1a\n", "fuzz.png"),
]


@pytest.mark.parametrize("data,words", [c[1:] for c in REFUSED], ids=[c[0] for c in REFUSED])
def test_damaged_png_is_refused_by_the_cli_in_one_line(data, words, tmp_path, capsys,
                                                        monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, "1")
    p = tmp_path / "fuzz.png"
    p.write_bytes(data)
    line = refused(capsys, ["unwarp", p, "--setup", SPHERE, "--projection", "cylindrical",
                            "--out", tmp_path / "o.exr"])
    assert "fuzz.png" in line and words in line, line
    assert sorted(x.name for x in tmp_path.iterdir()) == ["fuzz.png"]


def test_non_zlib_iccp_is_ignored_not_a_traceback(tmp_path):
    """Pillow drops an iCCP chunk it cannot inflate; the transfer falls to the next rule
    (here the file's own mitsweep chunk)."""
    im = _read(tmp_path, _rgb16_with(_chunk(b"iCCP", b"name\x00\x00garbage")))
    assert not isinstance(im, Exception)
    assert im.meta["transfer"] == "linear"
    np.testing.assert_array_equal(im.data, SEED_IMAGE16.astype(np.float32) / 65535)


@pytest.mark.parametrize("shape", [(7, 9), (7, 9, 3), (1, 1), (1, 300, 3)])
def test_display_png_round_trips_exactly_through_libpng(shape, tmp_path):
    """16 bits kept (Pillow would give 8): the file's samples come back unchanged."""
    img = np.random.default_rng(1).random(shape)
    p = write_display_image(tmp_path / "d.png", img, white=1.0)
    back = read_camera_image(p)
    assert back.bit_depth == 16 and back.meta["transfer"] == "srgb"
    # sRGB encoding to 16 bits and back: within one code value of the curve's slope
    np.testing.assert_allclose(back.data, img, atol=2e-4)


@pytest.mark.parametrize("color_type,channels", [(0, 1), (2, 3), (4, 2), (6, 4)])
def test_every_16_bit_colour_type_is_read_at_16_bits(color_type, channels, tmp_path):
    a = RNG.integers(0, 65536, (3, 4, channels), dtype=np.uint16)
    rows = np.concatenate([np.zeros((3, 1), np.uint8),
                           a.astype(">u2").view(np.uint8).reshape(3, -1)], axis=1)
    im = _read(tmp_path, png_bytes(4, 3, 16, color_type, zlib.compress(rows.tobytes())))
    assert not isinstance(im, Exception), im
    assert im.bit_depth == 16
    # alpha dropped; grey stays (H, W): the samples are the file's, linear after sRGB
    from mitsweep.io.camera import srgb_to_linear

    colour = a[..., 0] if channels in (1, 2) else a[..., :3]
    np.testing.assert_allclose(im.data, srgb_to_linear(colour / 65535.0), atol=1e-6)
