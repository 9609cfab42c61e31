"""Camera files in (RAW, TIFF, PNG, JPEG, EXR) as linear images, display images out.

Every file is written here: a DNG with tifffile (tests/camera_files.py) that LibRaw
reads, TIFFs with tifffile, PNG/JPEG with Pillow, 16-bit PNG with an independent
filtering encoder below. Tolerances are the storage's quantisation step in the linear
domain (stated at each assertion) unless said otherwise.
"""

from __future__ import annotations

import logging
import struct
import zlib

import numpy as np
import pytest

from camera_files import write_dng
from mitsweep.io import write_exr
from mitsweep.io.camera import (CameraFileError, read_camera_image, srgb_to_linear,
                                write_display_image)
from mitsweep.io.png import linear_to_srgb


def ramp_image(h: int = 48, w: int = 64) -> np.ndarray:
    """A smooth linear RGB test image in [0.02, 0.9] (no clipping, no flat channels)."""
    y, x = np.mgrid[0:h, 0:w]
    return np.stack([0.02 + 0.88 * x / (w - 1), 0.02 + 0.88 * y / (h - 1),
                     0.02 + 0.44 * (x + y) / (w + h - 2)], axis=-1)


def srgb_levels(linear: np.ndarray, bits: int) -> np.ndarray:
    return np.round(linear_to_srgb(linear) * (2 ** bits - 1)).astype(
        np.uint8 if bits == 8 else np.uint16)


# ------------------------------------------------------------------------------- RAW

@pytest.mark.parametrize("white_balance, expected_gain", [
    ("camera", (1.0, 1.0, 1.0)),        # as-shot neutral undone: grey stays grey
    ("none", (0.5, 1.0, 0.8)),          # the sensor's raw response
    ("auto", (1.0, 1.0, 1.0)),          # grey world on a grey card
])
def test_dng_is_linear_with_levels_applied_and_stated_white_balance(tmp_path, white_balance,
                                                                     expected_gain):
    grey = np.full((32, 48, 3), 0.4)
    path = write_dng(tmp_path / "grey.dng", grey, black=512, white=15000,
                     neutral=(0.5, 1.0, 0.8))
    im = read_camera_image(path, white_balance=white_balance)
    assert im.kind == "raw" and im.data.dtype == np.float32 and im.data.shape == (32, 48, 3)
    assert im.meta["black_level"] == [512] * 4 and im.meta["white_level"] == 15000
    assert im.meta["white_balance"]["mode"] == white_balance
    # One raw step is 1/14488 of white; LibRaw's 16-bit output adds 1/65535.
    np.testing.assert_allclose(im.data[8:-8, 8:-8].mean(axis=(0, 1)),
                               0.4 * np.asarray(expected_gain), atol=3e-4)
    assert im.warnings == []


def test_dng_keeps_a_linear_ramp_linear(tmp_path):
    rgb = ramp_image(64, 96)
    im = read_camera_image(write_dng(tmp_path / "ramp.dng", rgb), white_balance="camera")
    inner = (slice(4, -4), slice(4, -4))  # demosaicing at the border is one-sided
    # Smooth ramps demosaic almost exactly; 2e-3 is ~30 raw steps of 1/14488.
    np.testing.assert_allclose(im.data[inner], rgb[inner], atol=2e-3)


def test_dng_pixel_pitch_from_exif_wins_over_the_argument(tmp_path, caplog):
    path = write_dng(tmp_path / "p.dng", np.full((32, 32, 3), 0.3), pitch_mm=0.0064)
    assert read_camera_image(path).pixel_pitch == pytest.approx(0.0064, rel=1e-6)
    with caplog.at_level(logging.WARNING, logger="mitsweep.io.camera"):
        im = read_camera_image(path, pixel_pitch=0.02)
    assert im.pixel_pitch == pytest.approx(0.0064, rel=1e-6)
    assert im.meta["pixel_pitch_source"] == "file"
    assert any("pixel pitch" in w for w in im.warnings)
    assert any("pixel pitch" in r.getMessage() for r in caplog.records)


def test_pitch_falls_back_to_the_argument_then_none(tmp_path):
    path = write_dng(tmp_path / "nopitch.dng", np.full((32, 32, 3), 0.3))
    assert read_camera_image(path, pixel_pitch=0.02).pixel_pitch == 0.02
    assert read_camera_image(path, pixel_pitch=0.02).meta["pixel_pitch_source"] == "argument"
    assert read_camera_image(path).pixel_pitch is None


def test_clipped_raw_pixels_are_warned(tmp_path):
    rgb = np.full((32, 32, 3), 0.3)
    rgb[:8] = 1.5  # over the white level
    im = read_camera_image(write_dng(tmp_path / "clip.dng", rgb))
    assert any("clipped" in w for w in im.warnings)


# ------------------------------------------------------------------------------ TIFF

def test_16bit_srgb_tiff_decodes_to_linear(tmp_path):
    import tifffile

    rgb = ramp_image()
    tifffile.imwrite(tmp_path / "s.tif", srgb_levels(rgb, 16), photometric="rgb")
    im = read_camera_image(tmp_path / "s.tif")
    assert (im.kind, im.bit_depth, im.meta["transfer"]) == ("tiff", 16, "srgb")
    # Half a 16-bit sRGB step, times the sRGB curve's steepest slope (12.92⁻¹... ≤ 2.4).
    np.testing.assert_allclose(im.data, rgb, atol=2.4 / 65535)
    assert im.warnings == []


def test_float_tiff_is_linear_as_stored(tmp_path):
    import tifffile

    rgb = ramp_image().astype(np.float32) * 3.0  # HDR: above 1 is kept
    tifffile.imwrite(tmp_path / "f.tif", rgb, photometric="rgb")
    im = read_camera_image(tmp_path / "f.tif")
    assert (im.bit_depth, im.meta["transfer"]) == (32, "linear")
    np.testing.assert_array_equal(im.data, rgb)


def _icc_with_gray_curve(gamma: float | None) -> bytes:
    """A minimal ICC profile whose kTRC is the identity (None) or a pure gamma."""
    curve = b"curv\0\0\0\0" + (struct.pack(">I", 0) if gamma is None else
                               struct.pack(">IH", 1, int(round(gamma * 256))) + b"\0\0")
    table = struct.pack(">I", 1) + struct.pack(">4sII", b"kTRC", 144, len(curve))
    body = table + curve
    header = struct.pack(">I", 128 + len(body)) + b"\0" * 124
    return header + body


@pytest.mark.parametrize("gamma, decode", [
    (None, lambda x: x),               # identity curve: linear
    (1.0, lambda x: x),                # gamma 1.0: linear
    (2.2, lambda x: x ** (563 / 256)),  # u8Fixed8 stores 2.2 as 563/256
])
def test_tiff_icc_tone_curve_decides_the_transfer(tmp_path, gamma, decode):
    import tifffile

    grey = np.linspace(0, 65535, 4096).astype(np.uint16).reshape(64, 64)
    tifffile.imwrite(tmp_path / "icc.tif", grey, photometric="minisblack",
                     extratags=[(34675, "B", 0, _icc_with_gray_curve(gamma), True)])
    im = read_camera_image(tmp_path / "icc.tif")
    assert im.meta["transfer_reason"] == "ICC profile"
    # decoded to float32: measured <= 1.0e-7 off (the 2.2 curve), 3e-8 (linear)
    np.testing.assert_allclose(im.data, decode(grey / 65535.0), atol=1e-6)


def test_transfer_can_be_forced(tmp_path):
    import tifffile

    grey = np.linspace(0, 65535, 256).astype(np.uint16).reshape(16, 16)
    tifffile.imwrite(tmp_path / "g.tif", grey)
    # one division, stored as float32: measured 3.0e-8 off (half an ulp of 1.0: 6e-8)
    np.testing.assert_allclose(read_camera_image(tmp_path / "g.tif", transfer="linear").data,
                               grey / 65535.0, atol=1e-7)


def test_8bit_tiff_warns_that_it_limits_the_restoration(tmp_path, caplog):
    import tifffile

    tifffile.imwrite(tmp_path / "e.tif", srgb_levels(ramp_image(), 8), photometric="rgb")
    with caplog.at_level(logging.WARNING, logger="mitsweep.io.camera"):
        im = read_camera_image(tmp_path / "e.tif")
    assert im.bit_depth == 8 and any("8-bit" in w for w in im.warnings)
    assert any("8-bit" in r.getMessage() for r in caplog.records)


# ------------------------------------------------------------------------ PNG / JPEG

def test_8bit_png_decodes_srgb_and_warns(tmp_path):
    from PIL import Image

    rgb = ramp_image()
    Image.fromarray(srgb_levels(rgb, 8)).save(tmp_path / "e.png")
    im = read_camera_image(tmp_path / "e.png")
    assert (im.kind, im.bit_depth) == ("png", 8)
    np.testing.assert_allclose(im.data, rgb, atol=2.4 / 255)  # half an 8-bit step × slope
    assert any("8-bit" in w for w in im.warnings)


def _png16_filtered(img16: np.ndarray, filters) -> bytes:
    """An independent 16-bit RGB PNG encoder: row r uses filter ``filters[r % n]``
    (0 None, 1 Sub, 2 Up, 3 Average, 4 Paeth; PNG spec Sec. 9), per byte."""
    h, w, c = img16.shape
    bpp = 2 * c
    rows = [bytes(img16[r].astype(">u2").tobytes()) for r in range(h)]
    out = b""
    for r, row in enumerate(rows):
        f = filters[r % len(filters)]
        up = rows[r - 1] if r else bytes(len(row))
        enc = bytearray()
        for i, x in enumerate(row):
            a = row[i - bpp] if i >= bpp else 0
            b = up[i]
            cc = up[i - bpp] if i >= bpp else 0
            if f == 0:
                pred = 0
            elif f == 1:
                pred = a
            elif f == 2:
                pred = b
            elif f == 3:
                pred = (a + b) // 2
            else:
                p = a + b - cc
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - cc)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else cc)
            enc.append((x - pred) & 0xFF)
        out += bytes([f]) + bytes(enc)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(
            ">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(out)) + chunk(b"IEND", b""))


def test_16bit_colour_png_keeps_16_bits_through_every_filter(tmp_path):
    rng = np.random.default_rng(3)
    img16 = rng.integers(0, 65536, size=(10, 7, 3), dtype=np.uint16)
    (tmp_path / "f.png").write_bytes(_png16_filtered(img16, [0, 1, 2, 3, 4]))
    im = read_camera_image(tmp_path / "f.png", transfer="linear")
    assert im.bit_depth == 16
    np.testing.assert_array_equal(np.round(im.data * 65535).astype(np.uint16), img16)


def test_jpeg_decodes_srgb_and_warns_twice(tmp_path):
    from PIL import Image

    rgb = np.zeros((64, 64, 3))
    rgb[:32], rgb[32:] = (0.2, 0.5, 0.05), (0.7, 0.1, 0.3)  # flat blocks: JPEG keeps them
    Image.fromarray(srgb_levels(rgb, 8)).save(tmp_path / "b.jpg", quality=98)
    im = read_camera_image(tmp_path / "b.jpg")
    assert (im.kind, im.bit_depth) == ("jpeg", 8)
    inner = np.concatenate([im.data[4:28], im.data[36:60]])
    want = np.concatenate([rgb[4:28], rgb[36:60]])
    np.testing.assert_allclose(inner, want, atol=0.01)  # lossy + chroma subsampling
    assert any("8-bit" in w for w in im.warnings) and any("JPEG" in w for w in im.warnings)


def test_jpeg_pixel_pitch_from_exif(tmp_path):
    from PIL import Image

    exif = Image.Exif()
    ifd = exif.get_ifd(0x8769)
    ifd[0xA20E] = 250.0    # FocalPlaneXResolution, pixels per unit
    ifd[0xA210] = 3        # unit: cm → 0.04 mm pitch
    Image.fromarray(np.full((16, 16, 3), 128, np.uint8)).save(tmp_path / "p.jpg",
                                                              exif=exif.tobytes())
    assert read_camera_image(tmp_path / "p.jpg").pixel_pitch == pytest.approx(0.04)


# ------------------------------------------------------------------------------- EXR

def test_exr_reads_linear_with_its_header_and_the_setups_pitch(tmp_path):
    rgb = (ramp_image() * 4).astype(np.float32)
    write_exr(tmp_path / "r.exr", rgb, metadata={"setup": {"sensor": {"pixel_pitch": 0.02}},
                                                 "mode": "sweep"})
    im = read_camera_image(tmp_path / "r.exr")
    assert (im.kind, im.bit_depth, im.pixel_pitch) == ("exr", 32, 0.02)
    assert im.meta["exr_header"]["mode"] == "sweep"
    np.testing.assert_array_equal(im.data, rgb)


# ------------------------------------------------------------------ display outputs

@pytest.mark.parametrize("suffix", [".tif", ".png"])
def test_display_image_round_trips_to_linear(tmp_path, suffix):
    rgb = ramp_image()
    path = write_display_image(tmp_path / f"d{suffix}", rgb * 2.0, white=2.0,
                               metadata={"setup": "paraboloid"})
    im = read_camera_image(path)
    assert (im.bit_depth, im.meta["transfer"]) == (16, "srgb")
    # half a 16-bit sRGB step times the curve's steepest slope (as for the TIFF above)
    np.testing.assert_allclose(im.data, rgb, atol=2.4 / 65535)
    assert [p.name for p in tmp_path.iterdir()] == [f"d{suffix}"]  # no temporary left


def test_display_image_refuses_non_finite_and_unknown_formats(tmp_path):
    bad = ramp_image()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        write_display_image(tmp_path / "n.png", bad)
    with pytest.raises(ValueError, match=r"\.tif, \.tiff or \.png"):
        write_display_image(tmp_path / "n.jpg", ramp_image())
    assert list(tmp_path.iterdir()) == []


def test_srgb_decode_inverts_the_encoder():
    x = np.linspace(0, 1, 1001)
    # srgb_to_linear returns float32: measured 2.7e-7 off at most
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-6)


# --------------------------------------------------------------------------- bad input

def _valid_file(tmp_path, suffix):
    rgb = ramp_image()
    if suffix == ".dng":
        return write_dng(tmp_path / "v.dng", rgb)
    if suffix == ".exr":
        return write_exr(tmp_path / "v.exr", rgb.astype(np.float32))
    if suffix == ".jpg":
        from PIL import Image

        Image.fromarray(srgb_levels(rgb, 8)).save(tmp_path / "v.jpg")
        return tmp_path / "v.jpg"
    return write_display_image(tmp_path / f"v{suffix}", rgb, white=1.0)


@pytest.mark.parametrize("suffix", [".dng", ".tif", ".png", ".jpg", ".exr"])
@pytest.mark.parametrize("damage", ["truncated", "junk", "empty"])
def test_unreadable_files_fail_with_one_line_naming_the_file(tmp_path, capfd, suffix, damage):
    good = _valid_file(tmp_path, suffix)
    blob = good.read_bytes()
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes({"truncated": blob[:len(blob) // 2], "junk": b"not an image " * 40,
                     "empty": b""}[damage])
    capfd.readouterr()
    with pytest.raises(CameraFileError) as err:
        read_camera_image(bad)
    message = str(err.value)
    assert str(bad) in message and "\n" not in message
    assert isinstance(err.value, ValueError)
    out, errout = capfd.readouterr()
    assert out == "" and errout == ""  # the libraries' own chatter is kept off the terminal


@pytest.mark.parametrize("name, match", [
    ("photo.bmp", "unknown camera file type"),
    ("missing.tif", "no such file"),
])
def test_unknown_type_or_missing_file(tmp_path, name, match):
    if name.endswith(".bmp"):
        (tmp_path / name).write_bytes(b"BM")
    with pytest.raises(CameraFileError, match=match):
        read_camera_image(tmp_path / name)


def test_bad_arguments_name_what_is_allowed(tmp_path):
    path = write_dng(tmp_path / "a.dng", np.full((32, 32, 3), 0.3))
    with pytest.raises(CameraFileError, match="camera, daylight, auto, none"):
        read_camera_image(path, white_balance="tungsten")
    with pytest.raises(CameraFileError, match="> 0 mm"):
        read_camera_image(path, pixel_pitch=-1.0)
