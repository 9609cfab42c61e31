"""One memory gate before every large decode or allocation: hostile files and sizes are
refused in one line, before the memory is taken.

Each hostile file is built here, tiny, declaring a huge size (or inflating to one). A
case runs the real CLI under ``$MITSWEEP_MAX_MEMORY_GB=1`` and asserts the user-error
contract of :func:`cli_contract.refused` (exit 2, one line naming the file or option, no
traceback, no warning, nothing on stdout) and that nothing was written. The peak is
measured in a child process (its ``ru_maxrss``: Pillow and libpng allocate outside
tracemalloc's sight) and must stay under the 1 GiB cap: before the gate these files took
1.6 to 17 GiB.
"""

from __future__ import annotations

import hashlib
import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from cli_contract import refused
from mitsweep.resources import GIB, MAX_MEMORY_ENV, ResourceError, memory_cap_bytes

ROOT = Path(__file__).resolve().parents[1]
SPHERE = ROOT / "scenes" / "sphere.toml"
CAP_GB = 1


# -- hostile files ----------------------------------------------------------------------
def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + \
        struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_bytes(width: int, height: int, depth: int, color_type: int, idat: bytes,
              extra: bytes = b"") -> bytes:
    """A PNG of one IHDR (any declared size), ``extra`` chunks and one IDAT."""
    ihdr = struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + extra + _chunk(b"IDAT", idat)
            + _chunk(b"IEND", b""))


def zeros_deflated(nbytes: int, *, raw: bool = False) -> bytes:
    """``nbytes`` zero bytes, deflated (zlib stream, or raw deflate) in 16 MiB steps: the
    test never holds them."""
    z = zlib.compressobj(9, zlib.DEFLATED, -15 if raw else 15)
    step = bytes(1 << 24)
    parts = [z.compress(step[:min(len(step), nbytes - k)]) for k in range(0, nbytes, len(step))]
    return b"".join(parts) + z.flush()


def jpeg_declaring(path: Path, width: int, height: int) -> Path:
    """A small JPEG whose SOF0 header is patched to declare ``width`` x ``height``."""
    from PIL import Image

    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(path, format="JPEG")
    blob = bytearray(path.read_bytes())
    sof = blob.index(b"\xff\xc0")
    blob[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    path.write_bytes(bytes(blob))
    return path


def tiff_declaring(path: Path, width: int, height: int) -> Path:
    """A small zlib-compressed 16-bit RGB TIFF with its ImageWidth and ImageLength
    patched to declare ``width`` x ``height``."""
    import tifffile

    tifffile.imwrite(path, np.zeros((16, 16, 3), np.uint16), photometric="rgb",
                     compression="zlib")
    with tifffile.TiffFile(path) as tf:
        tags = tf.pages[0].tags
        spots = [(tags[name].valueoffset, tags[name].dtype) for name in
                 ("ImageWidth", "ImageLength")]
    blob = bytearray(path.read_bytes())
    for (offset, dtype), value in zip(spots, (width, height)):
        fmt = "<H" if int(dtype) == 3 else "<I"  # SHORT or LONG
        blob[offset:offset + struct.calcsize(fmt)] = struct.pack(fmt, value)
    path.write_bytes(bytes(blob))
    return path


@pytest.fixture(scope="module")
def gib_of_zeros():
    """1 GiB of zeros as a zlib stream (about 1 MiB): made once for the module."""
    return zeros_deflated(GIB)


def _photo_cases(tmp: Path, zeros: bytes) -> dict[str, Path]:
    return {
        # 8-bit through Pillow: 20000 x 20000 (Pillow's DecompressionBombError before)
        "png8-20000x20000": _write(tmp / "big8.png", png_bytes(20000, 20000, 8, 2, b"")),
        # 16-bit through libpng: 10000 x 9500 RGB (a 92 KB file reached 17 GB before)
        "png16-10000x9500": _write(tmp / "big16.png",
                                   png_bytes(10000, 9500, 16, 2, zlib.compress(bytes(1 << 16)))),
        # a 95 MP header, truncated (Pillow's DecompressionBombWarning before)
        "png8-95MP-truncated": _write(tmp / "trunc.png",
                                      png_bytes(10000, 9500, 8, 0, b"")[:40]),
        # 16-bit, 16000 x 16000 declared, its image data inflating to 1 GiB
        "png16-inflates-1GiB": _write(tmp / "inflate16.png", png_bytes(16000, 16000, 16, 2, zeros)),
        "jpeg-65000x65000": jpeg_declaring(tmp / "big.jpg", 65000, 65000),
        "tiff-60000x60000": tiff_declaring(tmp / "big.tif", 60000, 60000),
    }


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


PHOTO_CASES = ["png8-20000x20000", "png16-10000x9500", "png8-95MP-truncated",
               "png16-inflates-1GiB", "jpeg-65000x65000", "tiff-60000x60000"]


def _tree(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture
def capped(monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, str(CAP_GB))


# -- photos: declared sizes refused before decoding ---------------------------------------
@pytest.mark.parametrize("name", PHOTO_CASES)
@pytest.mark.parametrize("command", ["unwarp", "calibrate", "deconvolve"])
def test_hostile_photo_is_refused_naming_the_file(name, command, tmp_path, capsys, capped,
                                                  gib_of_zeros):
    photo = _photo_cases(tmp_path, gib_of_zeros)[name]
    out = tmp_path / "out.exr"
    argv = {"unwarp": ["unwarp", photo, "--setup", SPHERE, "--projection", "cylindrical",
                       "--out", out],
            "calibrate": ["calibrate", photo, "--setup", SPHERE],
            "deconvolve": ["deconvolve", photo, "--setup", SPHERE, "--out", out]}[command]
    before = _tree(tmp_path)
    line = refused(capsys, argv)
    assert photo.name in line, line
    assert _tree(tmp_path) == before


#: Run in a child: the CLI, then the child's peak resident memory from VmHWM, which
#: (unlike ``ru_maxrss``) starts afresh at exec, so the pytest parent's memory at the
#: fork does not count.
_MEASURED = """
import sys
from mitsweep.cli.main import main
try:
    rc = main(sys.argv[1:])
except SystemExit as exc:
    rc = exc.code
with open("/proc/self/status") as f:
    hwm = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
print(rc, hwm * 1024)
"""


def _peak_of(argv: list, code: str = _MEASURED) -> tuple[int, int, str]:
    """Run ``code`` with ARGV in a child under the cap: (its exit status or the CLI's,
    its peak resident bytes, its stderr)."""
    if not Path("/proc/self/status").is_file():
        pytest.skip("needs /proc/self/status (Linux) to read a process's peak memory")
    env = {**os.environ, MAX_MEMORY_ENV: str(CAP_GB), "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", code, *[str(a) for a in argv]], env=env,
                          capture_output=True, text=True, timeout=300)
    rc, peak = (int(x) for x in proc.stdout.split()[-2:])
    return rc, peak, proc.stderr


@pytest.mark.parametrize("name", PHOTO_CASES)
def test_hostile_photo_peak_stays_under_the_cap(name, tmp_path, gib_of_zeros):
    """The whole process, interpreter and libraries included (~65 MiB), stays far under
    the 1 GiB cap: the refusal comes before any decoding (before the gate: 2.1 GiB for
    the inflating PNG, 17 GB for the 16-bit one; 750 MiB while Pillow's ``getexif``
    still decoded a PNG's pixels to look for EXIF)."""
    photo = _photo_cases(tmp_path, gib_of_zeros)[name]
    rc, peak, err = _peak_of(["unwarp", photo, "--setup", SPHERE, "--projection",
                              "cylindrical", "--out", tmp_path / "out.exr"])
    assert rc == 2 and err.count("\n") == 1 and photo.name in err, err
    assert peak < 300 * 2**20, f"peak {peak / 2**20:.0f} MiB"


def test_image_data_inflating_past_the_declared_rows_costs_nothing(tmp_path, gib_of_zeros):
    """A 64 x 64 16-bit PNG whose image data inflates to 1 GiB: libpng stops at the rows
    the header declares (before: the whole stream was inflated, 2.1 GiB peak)."""
    photo = _write(tmp_path / "small.png", png_bytes(64, 64, 16, 2, gib_of_zeros))
    code = _MEASURED.replace("from mitsweep.cli.main import main", """
from mitsweep.io.camera import read_camera_image
def main(argv):
    im = read_camera_image(argv[0])
    print(im.shape, im.bit_depth)
    return 0""")
    rc, peak, err = _peak_of([photo], code)
    assert rc == 0 and err == "", err
    assert peak < 300 * 2**20, f"peak {peak / 2**20:.0f} MiB"


# -- panoramas ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_photo(tmp_path_factory) -> Path:
    from mitsweep.io.camera import write_display_image

    p = tmp_path_factory.mktemp("gate") / "photo.png"
    write_display_image(p, np.random.default_rng(0).random((256, 256)))
    return p


@pytest.mark.parametrize("size", [("100000", "100000"), ("6000", "30000"),
                                  ("2147483647", "2147483647")])
def test_huge_panorama_is_refused_before_it_is_made(size, small_photo, tmp_path, capsys,
                                                     capped):
    line = refused(capsys, ["unwarp", small_photo, "--setup", SPHERE, "--projection",
                            "cylindrical", "--size", *size, "--out", tmp_path / "p.exr"])
    assert f"panorama {size[0]}x{size[1]}" in line and "MITSWEEP_MAX_MEMORY_GB" in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow   # one of the longest default tests (15-40 s on 2 cores): in CI's slow run
def test_panorama_estimate_covers_the_measured_peak(small_photo, tmp_path):
    """A panorama the gate lets through stays within its estimate (the process's peak,
    interpreter included, against the estimate plus the interpreter's own ~100 MiB),
    and one it refuses is refused at no cost (before the gate: 1.7 GiB, exit 0, for
    6000 x 3000 under a 0.5 GiB cap)."""
    from mitsweep.io.camera import DISPLAY_BYTES_PER_SAMPLE
    from mitsweep.optics.panorama import panorama_bytes

    size = (4000, 2000)
    rc, peak, err = _peak_of(["unwarp", small_photo, "--setup", SPHERE, "--projection",
                              "cylindrical", "--size", *size, "--out", tmp_path / "p.png"])
    assert rc == 0, err
    estimate = panorama_bytes(size, (256, 256), 1, 4) + \
        size[0] * size[1] * DISPLAY_BYTES_PER_SAMPLE
    assert peak < estimate + 150 * 2**20, (peak / 2**20, estimate / 2**20)
    rc, peak, err = _peak_of(["unwarp", small_photo, "--setup", SPHERE, "--projection",
                              "cylindrical", "--size", "60000", "30000", "--out",
                              tmp_path / "q.exr"])
    assert rc == 2 and "panorama 60000x30000" in err and peak < 300 * 2**20, (err, peak)


# -- the cap's own value -------------------------------------------------------------------
@pytest.mark.parametrize("value", ["1e300", "inf", "nan", "-1", "0", "lots", "²", "1e7"])
def test_a_bad_cap_is_refused_naming_the_variable(value, small_photo, tmp_path, capsys,
                                                  monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, value)
    with pytest.raises(ResourceError, match=r"\$MITSWEEP_MAX_MEMORY_GB: expected a positive"):
        memory_cap_bytes()
    line = refused(capsys, ["unwarp", small_photo, "--setup", SPHERE, "--projection",
                            "cylindrical", "--out", tmp_path / "p.exr"])
    assert "$MITSWEEP_MAX_MEMORY_GB" in line and "at most" in line and repr(value) in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("value", ["0.001", "64", "1048576"])
def test_caps_in_range_are_taken(value, monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, value)
    assert memory_cap_bytes() == int(float(value) * GIB)


# -- validated before any work or write ------------------------------------------------------
@pytest.mark.parametrize("seed", ["-1", "4294967296", "1.5", "x"])
def test_figures_seed_is_refused_before_the_first_figure(seed, tmp_path, capsys):
    out = tmp_path / "f"
    line = refused(capsys, ["figures", "--out", out, "--quick", "--seed", seed])
    assert "--seed" in line
    assert not out.exists()


@pytest.mark.parametrize("k", ["33", "35", "101", "4", "1"])
def test_design_sweep_kernel_size_is_refused_before_tracing(k, tmp_path, capsys,
                                                            monkeypatch):
    import mitsweep.design

    def traced(*a, **kw):  # the refusal must come before the design starts
        raise AssertionError("design_sweep was called")

    monkeypatch.setattr(mitsweep.design, "design_sweep", traced)
    line = refused(capsys, ["design-sweep", SPHERE, "--kernel-size", k,
                            "--out", tmp_path / "p.json"])
    assert "--kernel-size" in line and "[3, 31]" in line
    assert list(tmp_path.iterdir()) == []


def test_calibration_work_arrays_are_gated(monkeypatch):
    """The calibration's working memory (~40 bytes a photo pixel) is checked against the
    cap before any is allocated: a photo that fits as read but not worked on is refused
    by name."""
    from mitsweep.photo import calibrate_photo
    from mitsweep.photo.free import find_circle
    from mitsweep.resources import ResourceError
    from mitsweep.config import load_setup
    from conftest import SCENES

    photo = np.zeros((3000, 3000, 3), np.float32)  # 108 MB as read; ~360 MB to work on
    monkeypatch.setenv("MITSWEEP_MAX_MEMORY_GB", "0.25")
    with pytest.raises(ResourceError, match="calibration of a 3000x3000 photo"):
        find_circle(photo)
    with pytest.raises(ResourceError, match="calibration of a 3000x3000 photo"):
        calibrate_photo(photo, load_setup(SCENES / "sphere.toml"))


def test_a_hostile_exr_is_gated_before_decoding(tmp_path, monkeypatch):
    """A 4x4 EXR whose header declares a 60001² data window: refused from the header."""
    from mitsweep.io.exr import read_exr, write_exr
    from mitsweep.resources import ResourceError

    small = tmp_path / "small.exr"
    write_exr(small, np.ones((4, 4, 3), np.float32))
    data = bytearray(small.read_bytes())
    at = data.find(b"dataWindow\x00box2i\x00") + len(b"dataWindow\x00box2i\x00") + 4
    assert struct.unpack("<4i", data[at:at + 16]) == (0, 0, 3, 3)
    data[at:at + 16] = struct.pack("<4i", 0, 0, 60000, 60000)
    huge = tmp_path / "huge.exr"
    huge.write_bytes(bytes(data))
    monkeypatch.setenv("MITSWEEP_MAX_MEMORY_GB", "1")
    with pytest.raises(ResourceError, match="huge.exr: decoding the EXR image"):
        read_exr(huge)
