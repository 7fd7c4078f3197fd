"""The planes/media TIFF's two encodings (docs/formats.md "Planes and media TIFFs"): the
8-bit default every TIFF reader opens, and the packed one (1 bit per dot and ink) that
`rip -o --planes-format packed` writes; every wideprint reader accepts both, and the same
halftone gives the same dots in either."""

import subprocess
import sys
import zlib

import numpy as np
import pytest
import tifffile

from support.images import PX, ROOT, random_planes, write_cmyk_tiff
from wideprint.app import cli
from wideprint.app.compare import compare
from wideprint.rip import pipeline
from wideprint.rip.planes import PlanesWriter, iter_planes, planes_format, read_planes
from wideprint.rip.swath import pack_dots

DPI = (300.0, 25400 / 68.55)


def _write(path, planes, fmt, kind="dots", step=50):
    h, w = planes.shape[:2]
    with PlanesWriter(path, w, h, *DPI, planes_format=fmt) as out:
        for y in range(0, h, step):
            if kind == "dots":
                out.write(planes[y:y + step])
            else:
                out.write_bits(pack_dots(planes[y:y + step]))
    return out.dots


@pytest.mark.parametrize("fmt", ["8bit", "packed"])
@pytest.mark.parametrize("kind", ["dots", "bits"])
@pytest.mark.parametrize("h, w", [(37, 45), (130, 2049), (64, 1024)])
def test_round_trip_either_encoding_from_dots_or_bits(tmp_path, fmt, kind, h, w):
    planes = random_planes(h, w, 0.3, seed=h + w)
    dots = _write(tmp_path / "p.tif", planes, fmt, kind)
    assert planes_format(tmp_path / "p.tif") == fmt
    whole = read_planes(tmp_path / "p.tif")
    assert whole.dtype == np.uint8 and np.array_equal(whole, planes)
    bands = list(iter_planes(tmp_path / "p.tif"))
    assert all(b.dtype == np.uint8 for b in bands)
    assert np.array_equal(np.concatenate(bands), planes)
    assert np.array_equal(dots, planes.reshape(-1, 4).sum(axis=0))


def test_packed_layout_is_tiffs_own(tmp_path):
    """BitsPerSample 1, 4 samples per pixel, contiguous: row bytes are the dots' C M Y K
    bits pixel after pixel, MSB first, each row padded to a byte (TIFF 6.0), strips of 64
    rows, deflate - checked on the raw strip bytes, not through our reader."""
    planes = random_planes(70, 45, 0.4, seed=3)
    _write(tmp_path / "p.tif", planes, "packed")
    with tifffile.TiffFile(tmp_path / "p.tif") as tf:
        page = tf.pages[0]
        assert (page.bitspersample, page.samplesperpixel, page.planarconfig) == (1, 4, 1)
        assert page.photometric == 5 and page.compression == 8 and page.rowsperstrip == 64
        fh = tf.filehandle
        strips = []
        for off, n in zip(page.dataoffsets, page.databytecounts):
            fh.seek(off)
            strips.append(zlib.decompress(fh.read(n)))
    rows = np.packbits(planes.reshape(70, 45 * 4), axis=1)           # 23 bytes a row
    assert strips[0] == rows[:64].tobytes() and strips[1] == rows[64:].tobytes()


def test_the_default_8bit_file_opens_in_every_reader(tmp_path):
    """The contract of the default: PIL and libvips read it as CMYK, one byte per dot."""
    from PIL import Image
    import pyvips
    planes = random_planes(80, 1500, 0.3)
    planes[5, 7, 2] = 2                                   # media can hold doubled dots
    _write(tmp_path / "p.tif", planes, "8bit")
    with Image.open(tmp_path / "p.tif") as im:
        assert im.mode == "CMYK" and np.array_equal(np.asarray(im), planes)
    assert np.array_equal(pyvips.Image.new_from_file(str(tmp_path / "p.tif")).numpy(), planes)
    assert np.array_equal(tifffile.imread(tmp_path / "p.tif"), planes)


def test_packed_refuses_a_doubled_dot_and_leaves_no_file(tmp_path):
    planes = np.zeros((10, 20, 4), np.uint8)
    planes[3, 4, 0] = 2
    with pytest.raises(ValueError, match="0 or 1 drop"):
        _write(tmp_path / "p.tif", planes, "packed")
    assert not (tmp_path / "p.tif").exists()


def test_compare_across_encodings(tmp_path):
    planes = random_planes(300, 2100, 0.3, seed=1)
    _write(tmp_path / "a.tif", planes, "8bit", step=300)
    _write(tmp_path / "b.tif", planes, "packed", step=7)
    same, text = compare(str(tmp_path / "a.tif"), str(tmp_path / "b.tif"))
    assert same, text
    other = planes.copy()
    other[150, 7, 2] ^= 1
    _write(tmp_path / "c.tif", other, "8bit")
    same, text = compare(str(tmp_path / "b.tif"), str(tmp_path / "c.tif"))
    assert not same and "1 dots differ (first at row 150, column 7, Y)" in text


@pytest.mark.parametrize("dither", ["fs", "bluenoise"])
def test_rip_writes_the_same_dots_in_either_encoding(tmp_path, capsys, dither):
    """`rip -o` 8-bit and packed, the error-diffusion and the fused ordered path: the same
    dots, the same drop counts reported."""
    rng = np.random.default_rng(4)
    img = tmp_path / "in.tif"
    tifffile.imwrite(img, rng.integers(0, 256, (150, 333, 3), dtype=np.uint8), photometric="rgb")
    said = {}
    import gc
    frozen = gc.get_freeze_count()
    for fmt in ("8bit", "packed"):
        assert cli.main(["rip", str(img), "-o", str(tmp_path / f"{fmt}.tif"), "--dither", dither,
                         "--size", "pixels", "--planes-format", fmt]) == 0
        said[fmt] = capsys.readouterr().out.split("drops")[1]
        # main() called in a process of the caller's leaves its garbage collector alone
        # (only the `wideprint` command's own process starts with it off: app/cli/process.py)
        assert gc.isenabled() and gc.get_freeze_count() == frozen
    assert planes_format(tmp_path / "packed.tif") == "packed"
    assert said["8bit"] == said["packed"]
    assert np.array_equal(read_planes(tmp_path / "8bit.tif"), read_planes(tmp_path / "packed.tif"))


def test_media_equals_packed_planes(tmp_path):
    """What landed (the emulator's 8-bit media) equals what the RIP meant, written packed."""
    planes = random_planes(120, 300, 0.3, seed=5)
    img = write_cmyk_tiff(tmp_path / "in.tif", planes)
    assert cli.main(["rip", str(img), "-o", str(tmp_path / "planes.tif"), "--size", "pixels",
                     "--planes-format", "packed", "--passes", "2"]) == 0
    assert cli.main(["print", str(img), "--device", "emulator", "--size", "pixels", "--passes", "2",
                     "--media-out", str(tmp_path / "media.tif")]) == 0
    assert planes_format(tmp_path / "media.tif") == "8bit"
    same, text = compare(str(tmp_path / "media.tif"), str(tmp_path / "planes.tif"))
    assert same, text
    assert np.array_equal(read_planes(tmp_path / "planes.tif"), planes)


def test_band_height_does_not_change_the_dots(tmp_path, monkeypatch, profile):
    """Wide images are ripped in shorter bands (RipJob.band_rows); the dots are the same."""
    rng = np.random.default_rng(6)
    img = tmp_path / "in.tif"
    tifffile.imwrite(img, rng.integers(0, 256, (100, 900, 3), dtype=np.uint8), photometric="rgb")
    out = {}
    for pixels in (1 << 20, 900 * 17):                    # 64-row bands, then 17-row ones
        monkeypatch.setattr(pipeline, "BAND_PIXELS", pixels)
        for dither in ("fs", "bayer"):
            job = pipeline.RipJob(str(img), pipeline.RipSettings(dither=dither, placement=PX), profile)
            assert job.band_rows == (64 if pixels > 900 * 64 else 17)
            job.write_planes(tmp_path / "p.tif", "packed")
            job.close()
            out[pixels, dither] = read_planes(tmp_path / "p.tif")
    for dither in ("fs", "bayer"):
        assert np.array_equal(out[1 << 20, dither], out[900 * 17, dither])


def test_numba_starts_without_scipy_linalg():
    """numba's BLAS probe is refused scipy.linalg (rip/__init__.py: ~0.25 s of every start);
    a kernel still runs, and, where scipy is installed (wideprint does not need it), np.dot
    in a kernel still compiles."""
    code = """
import sys, numpy as np
from wideprint.rip.color import Separator
Separator("rgb", 8).convert(np.zeros((2, 3, 3), np.uint8))
assert "scipy.linalg" not in sys.modules, "scipy.linalg was loaded"
import importlib.util, numba
if importlib.util.find_spec("scipy") is None:   # numba's np.dot needs scipy's BLAS: not ours
    print("ok")
    sys.exit(0)
@numba.njit
def dot(a, b):
    return np.dot(a, b)
assert dot(np.ones(3), np.ones(3)) == 3.0
print("ok")
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                       cwd=ROOT)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr
