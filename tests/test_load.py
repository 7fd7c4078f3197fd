"""Tests for wideprint.rip.load: formats, exact round trips, streaming, memory, hostile files."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import textwrap
import time

import cv2
import imagecodecs
import numpy as np
import pytest
import pyvips
import tifffile

from wideprint.rip.load import ImageError, ImageSource, open_image

from support import corpus
from support.corpus import (bmp_bytes, bmp_indexed, bmp_packed, bmp_rgb24, bmp_rle, gradient_rgb,
                            strip_app14)
from support.images import read_bands


def read_all(path, rows=37) -> tuple[ImageSource, np.ndarray]:
    src = open_image(path)
    return src, read_bands(src, rows)


@pytest.fixture(scope="module")
def srgb_icc() -> bytes:
    im = pyvips.Image.new_from_array(np.zeros((2, 2, 3), np.uint8)).copy(interpretation="srgb")
    return bytes(im.icc_transform("srgb", input_profile="srgb").get("icc-profile-data"))


# ------------------------------------------------------------------------------------------------- TIFF

RNG = np.random.default_rng(42)
IMG = gradient_rgb(101, 83)


@pytest.mark.parametrize("compression", [None, "lzw", "deflate", "packbits"])
@pytest.mark.parametrize("tiled", [False, True])
def test_tiff_rgb8_lossless(tmp_path, compression, tiled):
    p = tmp_path / "rgb.tif"
    kw = dict(tile=(32, 32)) if tiled else dict(rowsperstrip=7)
    tifffile.imwrite(p, IMG, photometric="rgb", compression=compression, **kw)
    src, arr = read_all(p)
    assert (src.width, src.height, src.channels, src.colorspace, src.depth) == (83, 101, 3, "rgb", 8)
    assert src.format == "tiff"
    np.testing.assert_array_equal(arr, IMG)


def test_tiff_jpeg_compressed(tmp_path):
    p = tmp_path / "jpeg.tif"
    img = gradient_rgb(64, 96)
    tifffile.imwrite(p, img, photometric="rgb", compression="jpeg", rowsperstrip=16)
    src, arr = read_all(p)
    assert src.colorspace == "rgb"
    assert np.abs(arr.astype(int) - img).mean() < 4


@pytest.mark.parametrize("compression", [None, "lzw", "deflate"])
def test_tiff_rgb16_tiled(tmp_path, compression):
    img = RNG.integers(0, 65536, (70, 90, 3), dtype=np.uint16)
    p = tmp_path / "rgb16.tif"
    tifffile.imwrite(p, img, photometric="rgb", compression=compression, tile=(32, 48))
    src, arr = read_all(p, rows=16)
    assert src.depth == 16 and src.colorspace == "rgb"
    np.testing.assert_array_equal(arr, img)


def test_tiff_planar_separate(tmp_path):
    p = tmp_path / "planar.tif"
    tifffile.imwrite(p, np.moveaxis(IMG, -1, 0), photometric="rgb", planarconfig="separate", compression="lzw")
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, IMG)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("compression", [None, "lzw", "packbits"])
def test_tiff_cmyk_exact(tmp_path, dtype, compression):
    hi = 256 if dtype == np.uint8 else 65536
    img = RNG.integers(0, hi, (57, 75, 4), dtype=dtype)
    p = tmp_path / "cmyk.tif"
    tifffile.imwrite(p, img, photometric="separated", compression=compression, rowsperstrip=5)
    src, arr = read_all(p)
    assert src.colorspace == "cmyk" and src.channels == 4 and src.depth == (8 if dtype == np.uint8 else 16)
    np.testing.assert_array_equal(arr, img)  # ink values, bit-exact


def test_tiff_cmyk_alpha_composited(tmp_path):
    img = RNG.integers(0, 256, (20, 30, 5), dtype=np.uint8)
    p = tmp_path / "cmyka.tif"
    tifffile.imwrite(p, img, photometric="separated", extrasamples=[2])
    src, arr = read_all(p)
    assert src.channels == 4
    exp = np.round(img[..., :4].astype(float) * img[..., 4:] / 255)
    assert np.abs(arr - exp).max() <= 1  # no ink where transparent


def test_tiff_rgba_on_white(tmp_path):
    img = RNG.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    img[0, 0, 3] = 0
    img[0, 1, 3] = 255
    p = tmp_path / "rgba.tif"
    tifffile.imwrite(p, img, photometric="rgb", extrasamples=[2])
    src, arr = read_all(p)
    assert src.channels == 3
    a = img[..., 3:].astype(float) / 255
    exp = np.round(img[..., :3] * a + 255 * (1 - a))
    assert np.abs(arr - exp).max() <= 1
    np.testing.assert_array_equal(arr[0, 0], [255, 255, 255])
    np.testing.assert_array_equal(arr[0, 1], img[0, 1, :3])


def test_tiff_rgb_unspecified_extra_is_dropped(tmp_path):
    img = RNG.integers(0, 256, (10, 12, 4), dtype=np.uint8)
    p = tmp_path / "rgbx.tif"
    tifffile.imwrite(p, img, photometric="rgb", extrasamples=[0])
    src, arr = read_all(p)
    np.testing.assert_array_equal(arr, img[..., :3])


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_tiff_grey(tmp_path, dtype):
    hi = 256 if dtype == np.uint8 else 65536
    img = RNG.integers(0, hi, (33, 44), dtype=dtype)
    p = tmp_path / "g.tif"
    tifffile.imwrite(p, img, photometric="minisblack", compression="deflate")
    src, arr = read_all(p)
    assert src.colorspace == "grey" and src.channels == 1
    np.testing.assert_array_equal(arr[..., 0], img)


@pytest.mark.parametrize("photometric", ["minisblack", "miniswhite"])
def test_tiff_1bit(tmp_path, photometric):
    bits = RNG.integers(0, 2, (17, 29)).astype(bool)
    p = tmp_path / "bw.tif"
    tifffile.imwrite(p, bits, photometric=photometric, compression="packbits")
    src, arr = read_all(p)
    assert src.colorspace == "grey" and src.depth == 8
    white = ~bits if photometric == "miniswhite" else bits
    np.testing.assert_array_equal(arr[..., 0], np.where(white, 255, 0))


def test_tiff_palette(tmp_path):
    cmap = RNG.integers(0, 256, (3, 256), dtype=np.uint16) * 257
    idx = RNG.integers(0, 256, (16, 24), dtype=np.uint8)
    p = tmp_path / "pal.tif"
    tifffile.imwrite(p, idx, photometric="palette", colormap=cmap)
    src, arr = read_all(p)
    assert src.colorspace == "rgb"
    np.testing.assert_array_equal(arr, (cmap[:, idx] // 257).transpose(1, 2, 0))


def test_tiff_resolution_and_icc(tmp_path, srgb_icc):
    p = tmp_path / "res.tif"
    tifffile.imwrite(p, IMG, photometric="rgb", resolution=(300, 150), resolutionunit="INCH", iccprofile=srgb_icc)
    src = open_image(p)
    assert src.xres == pytest.approx(300) and src.yres == pytest.approx(150)
    assert src.icc == srgb_icc
    p2 = tmp_path / "rescm.tif"
    tifffile.imwrite(p2, IMG, photometric="rgb", resolution=(100, 100), resolutionunit="CENTIMETER")
    src = open_image(p2)
    assert src.xres == pytest.approx(254) and src.yres == pytest.approx(254)
    p3 = tmp_path / "nores.tif"
    tifffile.imwrite(p3, IMG, photometric="rgb", resolution=(72, 72), resolutionunit="NONE")
    assert open_image(p3).xres is None


def test_tiff_multipage_reads_first(tmp_path):
    p = tmp_path / "multi.tif"
    with tifffile.TiffWriter(p) as tw:
        tw.write(IMG, photometric="rgb")
        tw.write(np.zeros((10, 10, 3), np.uint8), photometric="rgb")
    src, arr = read_all(p)
    np.testing.assert_array_equal(arr, IMG)


# ------------------------------------------------------------------------------------------------- JPEG


def test_jpeg_rgb_and_density(tmp_path):
    img = gradient_rgb(80, 120)
    p = tmp_path / "a.jpg"
    pyvips.Image.new_from_array(img).copy(interpretation="srgb", xres=300 / 25.4, yres=300 / 25.4) \
        .jpegsave(str(p), Q=95)
    src, arr = read_all(p)
    assert (src.format, src.colorspace, src.channels) == ("jpeg", "rgb", 3)
    assert src.xres == pytest.approx(300, abs=0.5)
    assert np.abs(arr.astype(int) - img).mean() < 3


def test_jpeg_grey(tmp_path):
    img = gradient_rgb(40, 50)[..., 0]
    p = tmp_path / "g.jpg"
    cv2.imwrite(str(p), img, [cv2.IMWRITE_JPEG_QUALITY, 95])
    src, arr = read_all(p)
    assert src.colorspace == "grey"
    assert np.abs(arr[..., 0].astype(int) - img).mean() < 3


def _smooth_cmyk(h=64, w=96):
    yy, xx = np.mgrid[0:h, 0:w]
    return np.stack([xx * 2, yy * 3, np.full_like(xx, 40), np.full_like(xx, 200)], -1).astype(np.uint8)


def test_jpeg_cmyk_adobe_inverted(tmp_path):
    ink = _smooth_cmyk()
    # Photoshop convention: Adobe APP14 marker present and the samples stored inverted
    data = imagecodecs.jpeg8_encode(255 - ink, level=95, colorspace="CMYK", outcolorspace="CMYK")
    assert b"Adobe" in data
    assert np.abs(imagecodecs.jpeg8_decode(data).astype(int) - (255 - ink)).mean() < 2  # stored inverted
    p = tmp_path / "adobe.jpg"
    p.write_bytes(data)
    src, arr = read_all(p)
    assert src.colorspace == "cmyk" and src.channels == 4
    d = np.abs(arr.astype(int) - ink)
    assert d.mean() < 2 and d.max() < 16  # ink amounts, not inverted


def test_jpeg_cmyk_written_by_libvips(tmp_path):
    ink = _smooth_cmyk()
    p = tmp_path / "vips.jpg"
    pyvips.Image.new_from_array(ink).copy(interpretation="cmyk").jpegsave(str(p), Q=95)
    _, arr = read_all(p)
    assert np.abs(arr.astype(int) - ink).mean() < 2


def test_jpeg_cmyk_plain_not_inverted(tmp_path):
    ink = _smooth_cmyk()
    data = strip_app14(imagecodecs.jpeg8_encode(ink, level=95, colorspace="CMYK", outcolorspace="CMYK"))
    assert b"Adobe" not in data
    p = tmp_path / "plain.jpg"
    p.write_bytes(data)
    src, arr = read_all(p)
    assert src.colorspace == "cmyk"
    assert np.abs(arr.astype(int) - ink).mean() < 2


# ------------------------------------------------------------------------------------------------- PNG


def test_png_variants(tmp_path):
    rgb16 = RNG.integers(0, 65536, (20, 30, 3), dtype=np.uint16)
    p = tmp_path / "a.png"
    cv2.imwrite(str(p), rgb16[..., ::-1])
    src, arr = read_all(p)
    assert src.depth == 16 and src.format == "png"
    np.testing.assert_array_equal(arr, rgb16)

    rgba = RNG.integers(0, 256, (20, 30, 4), dtype=np.uint8)
    cv2.imwrite(str(p), rgba[..., [2, 1, 0, 3]])
    src, arr = read_all(p)
    a = rgba[..., 3:].astype(float) / 255
    assert np.abs(arr - np.round(rgba[..., :3] * a + 255 * (1 - a))).max() <= 1

    grey = RNG.integers(0, 256, (20, 30), dtype=np.uint8)
    cv2.imwrite(str(p), grey)
    src, arr = read_all(p)
    assert src.colorspace == "grey"
    np.testing.assert_array_equal(arr[..., 0], grey)


def test_png_resolution(tmp_path):
    p = tmp_path / "r.png"
    pyvips.Image.new_from_array(IMG).copy(interpretation="srgb", xres=600 / 25.4, yres=600 / 25.4).pngsave(str(p))
    assert open_image(p).xres == pytest.approx(600, abs=0.1)


def test_format_by_magic_not_extension(tmp_path):
    p = tmp_path / "looks_like.tif"
    cv2.imwrite(str(tmp_path / "x.png"), IMG[..., ::-1])
    p.write_bytes((tmp_path / "x.png").read_bytes())
    src, arr = read_all(p)
    assert src.format == "png"
    np.testing.assert_array_equal(arr, IMG)
    q = tmp_path / "looks_like.jpg"
    q.write_bytes(bmp_rgb24(IMG))
    src, arr = read_all(q)
    assert src.format == "bmp"
    np.testing.assert_array_equal(arr, IMG)


# ------------------------------------------------------------------------------------------------- BMP

COLOUR_PAL = RNG.integers(0, 256, (256, 3), dtype=np.uint8)
GREY_PAL = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, 1)


@pytest.mark.parametrize("bpp", [1, 2, 4, 8])
@pytest.mark.parametrize("top_down", [False, True])
@pytest.mark.parametrize("grey", [False, True])
def test_bmp_indexed(tmp_path, bpp, top_down, grey):
    h, w = 23, 37  # odd width: row padding and partial bytes
    n = 1 << bpp
    pal = (GREY_PAL[:: 256 // n] if grey else COLOUR_PAL[:n]).copy()
    idx = RNG.integers(0, n, (h, w), dtype=np.uint8)
    p = tmp_path / "i.bmp"
    p.write_bytes(bmp_indexed(idx, pal, bpp, top_down=top_down, ppm=(11811, 11811)))
    src, arr = read_all(p, rows=5)
    assert src.format == "bmp" and src.depth == 8
    assert src.xres == pytest.approx(300, abs=0.1)
    if grey:
        assert src.colorspace == "grey"
        np.testing.assert_array_equal(arr[..., 0], pal[idx, 0])
    else:
        assert src.colorspace == "rgb"
        np.testing.assert_array_equal(arr, pal[idx])


def test_bmp_core_header(tmp_path):
    idx = RNG.integers(0, 256, (9, 13), dtype=np.uint8)
    p = tmp_path / "os2.bmp"
    p.write_bytes(bmp_indexed(idx, COLOUR_PAL, 8, header_size=12))
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, COLOUR_PAL[idx])
    rgb = gradient_rgb(9, 13)
    p.write_bytes(bmp_rgb24(rgb, header_size=12))
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, rgb)


@pytest.mark.parametrize("top_down", [False, True])
def test_bmp_24(tmp_path, top_down):
    rgb = gradient_rgb(31, 45)
    p = tmp_path / "a.bmp"
    p.write_bytes(bmp_rgb24(rgb, top_down=top_down))
    src, arr = read_all(p, rows=8)
    assert src.colorspace == "rgb" and src.xres is None
    np.testing.assert_array_equal(arr, rgb)


def _expand(v, mask):
    shift = (mask & -mask).bit_length() - 1
    bits = bin(mask).count("1")
    x = (v.astype(np.uint64) & mask) >> shift
    mx = (1 << bits) - 1
    return ((x * 255 + mx // 2) // mx).astype(np.uint8)


@pytest.mark.parametrize("kind", ["555", "565", "555-v5"])
@pytest.mark.parametrize("top_down", [False, True])
def test_bmp_16(tmp_path, kind, top_down):
    v = RNG.integers(0, 65536, (12, 21), dtype=np.uint16)
    p = tmp_path / "a.bmp"
    if kind == "555":
        p.write_bytes(bmp_packed(v, 16, top_down=top_down))
        masks = (0x7C00, 0x3E0, 0x1F)
    elif kind == "565":
        masks = (0xF800, 0x7E0, 0x1F)
        p.write_bytes(bmp_packed(v, 16, masks=masks + (0,), compression=3, top_down=top_down))
    else:
        masks = (0x7C00, 0x3E0, 0x1F)
        p.write_bytes(bmp_packed(v, 16, masks=masks + (0,), compression=3, top_down=top_down, header_size=124))
    _, arr = read_all(p, rows=5)
    exp = np.stack([_expand(v, m) for m in masks], -1)
    np.testing.assert_array_equal(arr, exp)


def test_bmp_32_rgb_ignores_4th_byte(tmp_path):
    bgra = RNG.integers(0, 256, (11, 17, 4), dtype=np.uint8)
    words = bgra.copy().view("<u4")[..., 0]
    p = tmp_path / "a.bmp"
    p.write_bytes(bmp_packed(words, 32))
    src, arr = read_all(p)
    assert src.channels == 3
    np.testing.assert_array_equal(arr, bgra[..., 2::-1])


@pytest.mark.parametrize("header_size,compression", [(108, 3), (124, 3), (40, 6)])
def test_bmp_32_alpha_bitfields(tmp_path, header_size, compression):
    bgra = RNG.integers(0, 256, (11, 17, 4), dtype=np.uint8)
    bgra[0, 0, 3] = 0
    words = bgra.copy().view("<u4")[..., 0]
    p = tmp_path / "a.bmp"
    masks = (0x00FF0000, 0x0000FF00, 0x000000FF, 0xFF000000)
    p.write_bytes(bmp_packed(words, 32, masks=masks, compression=compression, header_size=header_size))
    _, arr = read_all(p)
    a = bgra[..., 3:].astype(np.uint32)
    exp = (bgra[..., 2::-1].astype(np.uint32) * a + 255 * (255 - a) + 127) // 255
    np.testing.assert_array_equal(arr, exp)
    np.testing.assert_array_equal(arr[0, 0], [255, 255, 255])


def test_bmp_32_odd_masks(tmp_path):
    v = RNG.integers(0, 2**32, (7, 9), dtype=np.uint32)
    masks = (0x3FF00000, 0x000FFC00, 0x000003FF, 0)  # 10-bit channels
    p = tmp_path / "a.bmp"
    p.write_bytes(bmp_packed(v, 32, masks=masks, compression=3))
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, np.stack([_expand(v, m) for m in masks[:3]], -1))


def test_bmp_v5_icc(tmp_path, srgb_icc):
    rgb = gradient_rgb(8, 8)
    p = tmp_path / "icc.bmp"
    p.write_bytes(bmp_bytes(width=8, height=8, bpp=24, header_size=124, icc=srgb_icc,
                            pixel_data=b"".join(r[:, ::-1].tobytes() for r in rgb[::-1])))
    src, arr = read_all(p)
    assert src.icc == srgb_icc
    np.testing.assert_array_equal(arr, rgb)


def _cv2_rgb(path):
    bgr = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_COLOR)
    return bgr[..., ::-1]


@pytest.mark.parametrize("rle4", [False, True])
def test_bmp_rle(tmp_path, rle4):
    h, w = 29, 51
    n = 16 if rle4 else 256
    idx = RNG.integers(0, n, (h, w), dtype=np.uint8)
    idx[5:15, 10:40] = 3  # runs
    idx[20, :] = 7
    pal = COLOUR_PAL[:n]
    p = tmp_path / "rle.bmp"
    p.write_bytes(bmp_rle(idx, pal, rle4))
    src, arr = read_all(p, rows=4)
    np.testing.assert_array_equal(arr, pal[idx])
    np.testing.assert_array_equal(arr, _cv2_rgb(p))  # an independent decoder agrees


def test_bmp_rle_delta_and_early_eol(tmp_path):
    # 6 x 4 image (bottom-up): row 0: run of 3 x idx1, EOL; row 1: delta (2, 1) -> row 2 x=2, run 2 x idx2; EOB
    data = bytes([3, 1, 0, 0, 0, 2, 2, 1, 2, 2, 0, 1])
    idx = np.zeros((4, 6), np.uint8)
    p = tmp_path / "delta.bmp"
    p.write_bytes(bmp_rle(idx, COLOUR_PAL, False, data=data))
    _, arr = read_all(p)
    exp_idx = np.zeros((4, 6), np.uint8)  # file order is bottom-up
    exp_idx[3, :3] = 1
    exp_idx[1, 2:4] = 2
    np.testing.assert_array_equal(arr, COLOUR_PAL[exp_idx])
    np.testing.assert_array_equal(arr, _cv2_rgb(p))


def test_bmp_rle_runs_may_cover_the_row_padding(tmp_path):
    """ImageMagick encodes each RLE8 row padded to 4 bytes (a 5 px row: 5 pixels and a run of
    3 zeros): the padding is dropped, only a run past it is an error."""
    data = bytes([3, 1, 2, 2, 3, 0, 0, 0,      # row 0: 1 1 1 2 2 + 3 padding pixels
                  0, 5, 4, 5, 6, 7, 8, 0, 0, 0,   # row 1: absolute 4..8 (padded to 16 bits) + EOL
                  0, 1])
    p = tmp_path / "im.bmp"
    p.write_bytes(bmp_rle(np.zeros((2, 5), np.uint8), COLOUR_PAL, False, data=data))
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, COLOUR_PAL[np.array([[4, 5, 6, 7, 8], [1, 1, 1, 2, 2]])])
    p.write_bytes(bmp_rle(np.zeros((2, 5), np.uint8), COLOUR_PAL, False,
                          data=bytes([3, 1, 2, 2, 4, 0, 0, 1])))
    with pytest.raises(ImageError, match="the RLE run of 4 pixels at byte 1082 overruns row 1 "
                                         r"\(it starts at column 5, the image is 5 wide, 8 with"):
        read_all(p)


def test_bmp_palette_ends_where_the_pixels_start(tmp_path):
    """No colour count in the header (2^bpp), but only 16 entries before the pixel data: the
    palette is those 16, not 256 entries of which 240 are pixels."""
    idx = (np.arange(6 * 7).reshape(6, 7) % 16).astype(np.uint8)
    data = bytearray(bmp_indexed(idx, COLOUR_PAL[:16], 8))
    data[46:50] = bytes(4)                         # biClrUsed = 0
    p = tmp_path / "short_palette.bmp"
    p.write_bytes(bytes(data))
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, COLOUR_PAL[idx])
    idx[2, 3] = 20
    data = bytearray(bmp_indexed(idx, COLOUR_PAL[:16], 8))
    data[46:50] = bytes(4)
    p.write_bytes(bytes(data))
    with pytest.raises(ImageError, match=r"colour index 20 at byte \d+ \(row 2, column 3\) is outside "
                                         "the palette of 16 colours"):
        read_all(p)


@pytest.mark.parametrize("kind", ["tif", "jpg", "png", "bmp", "rle"])
def test_non_utf8_file_names_decode_the_same(tmp_path, kind):
    """A name that is not UTF-8 (Latin-1 bytes, as an old share or camera writes them) is a
    valid file: libvips gets it as a descriptor, the pixels are the same."""
    samples = _valid_samples(tmp_path)
    data = samples[kind]
    plain = tmp_path / f"plain.{kind}"
    plain.write_bytes(data)
    odd = tmp_path / os.fsdecode(b"caf\xe9-\xff\x80." + kind.encode())
    odd.write_bytes(data)
    _, want = read_all(plain)
    src, got = read_all(odd)
    assert src.path == str(odd)
    np.testing.assert_array_equal(got, want)
    _, got_b = read_all(os.fsencode(odd))          # a bytes path too
    np.testing.assert_array_equal(got_b, want)


def test_bmp_written_by_opencv(tmp_path):
    rgb = gradient_rgb(27, 35)
    p = tmp_path / "cv.bmp"
    cv2.imwrite(str(p), rgb[..., ::-1])
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, rgb)
    cv2.imwrite(str(p), rgb[..., 0])
    src, arr = read_all(p)
    assert src.colorspace == "grey"
    np.testing.assert_array_equal(arr[..., 0], rgb[..., 0])


def test_bmp_missing_last_row_padding_is_fine(tmp_path):
    rgb = gradient_rgb(5, 5)  # 15 bytes per row + 1 padding byte
    data = bmp_rgb24(rgb, top_down=True)
    p = tmp_path / "nopad.bmp"
    p.write_bytes(data[:-1])
    _, arr = read_all(p)
    np.testing.assert_array_equal(arr, rgb)


# ------------------------------------------------------------------------------------------------- streaming


def test_bands_concatenate_to_whole_image(tmp_path):
    img = gradient_rgb(1000, 300)
    p = tmp_path / "big.tif"
    tifffile.imwrite(p, img, photometric="rgb", compression="lzw", rowsperstrip=64)
    src = open_image(p)
    for rows in (1, 7, 256, 999, 1000, 5000):
        parts = list(src.bands(rows))
        assert [b.shape[0] for b in parts[:-1]] == [rows] * (len(parts) - 1)
        assert parts[-1].shape[0] == 1000 - rows * (len(parts) - 1)
        np.testing.assert_array_equal(np.concatenate(parts), img)
    assert all(b.flags.c_contiguous for b in src.bands(100))
    src.close()
    with pytest.raises(ValueError):
        src.bands()
    with pytest.raises(ValueError):
        open_image(p).bands(0)


def test_open_reads_header_only(tmp_path):
    img = gradient_rgb(200, 100)
    p = tmp_path / "lazy.tif"
    tifffile.imwrite(p, img, photometric="rgb", compression="lzw", rowsperstrip=8)
    data = bytearray(p.read_bytes())
    tif = tifffile.TiffFile(p)
    off = int(tif.pages[0].dataoffsets[20])
    tif.close()
    data[off: off + 200] = b"\x00" * 200  # damage strip 21
    p.write_bytes(bytes(data))
    src = open_image(p)  # fine: nothing decoded yet
    it = src.bands(8)
    for _ in range(20):
        next(it)  # strips 1..20 decode
    with pytest.raises(ImageError) as ei:
        list(it)
    assert str(p) in str(ei.value)


def test_memory_bounded_for_tall_image(tmp_path):
    """A 4000 x 40000 RGB LZW TIFF (480 MB of pixels) streams in far less memory."""
    p = tmp_path / "tall.tif"
    x = pyvips.Image.xyz(4000, 40000)
    xx, yy = x[0], x[1]
    rgb = ((xx % 256).bandjoin([(yy % 256), ((xx + yy) // 3) % 256])).cast("uchar").copy(interpretation="srgb")
    rgb.tiffsave(str(p), compression="lzw", strip=True)  # streamed write
    script = textwrap.dedent(f"""
        import json, time, numpy as np
        from wideprint.rip.load import open_image
        def rss_kb(key):
            for line in open('/proc/self/status'):
                if line.startswith(key):
                    return int(line.split()[1])
        src = open_image({str(p)!r})
        # warm up: first band (loads libvips' loader, allocates the line cache)
        it = src.bands(256)
        first = next(it)
        base = rss_kb('VmRSS:')
        t0 = time.perf_counter()
        n = first.shape[0]
        ok = bool((first[:, :, 0] == (np.arange(4000) % 256)).all())
        for b in it:
            y0 = n
            n += b.shape[0]
            ok &= bool((b[:, 5, 1] == (np.arange(y0, n) % 256)).all())
        dt = time.perf_counter() - t0
        print(json.dumps(dict(rows=n, ok=ok, base_kb=base, hwm_kb=rss_kb('VmHWM:'), seconds=dt)))
    """)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=240)
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout.strip().splitlines()[-1])
    assert r["rows"] == 40000 and r["ok"]
    growth_mb = (r["hwm_kb"] - r["base_kb"]) / 1024
    image_mb = 4000 * 40000 * 3 / 2**20
    print(f"\nbands(): 4000x40000 LZW TIFF in {r['seconds']:.2f} s = {160 / r['seconds']:.0f} Mpx/s; "
          f"peak RSS growth {growth_mb:.1f} MB for a {image_mb:.0f} MB image")
    assert growth_mb < 100, growth_mb


# ------------------------------------------------------------------------------------------------- errors


def test_image_error_format_and_pickle():
    e = ImageError("/x/y.tif", "empty file (0 bytes)")
    assert str(e) == "/x/y.tif: empty file (0 bytes)"
    assert (e.path, e.problem) == ("/x/y.tif", "empty file (0 bytes)")
    e2 = pickle.loads(pickle.dumps(e))
    assert str(e2) == str(e) and e2.path == e.path


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    d = tmp_path_factory.mktemp("corpus")
    return corpus.write_corpus(d)


def test_hostile_corpus(hostile):
    assert len(hostile) >= 35
    failures = []
    for case in hostile:
        t0 = time.perf_counter()
        try:
            src = open_image(case.path)
            for _ in src.bands(64):
                pass
            failures.append(f"{case.name}: no error")
            continue
        except ImageError as e:
            msg = str(e)
            if not (msg.startswith(case.path + ": ") and case.phrase in msg and e.path == case.path):
                failures.append(f"{case.name}: {msg!r} lacks {case.phrase!r}")
        except Exception as e:  # anything else is a crash
            failures.append(f"{case.name}: crashed with {type(e).__name__}: {e}")
        if time.perf_counter() - t0 > 5:
            failures.append(f"{case.name}: took {time.perf_counter() - t0:.1f} s")
    assert not failures, "\n".join(failures)


def test_limits_are_configurable(tmp_path):
    p = tmp_path / "a.bmp"
    p.write_bytes(bmp_rgb24(gradient_rgb(20, 30)))
    with pytest.raises(ImageError, match="exceeds the limit of 500 px"):
        open_image(p, max_pixels=500)
    with pytest.raises(ImageError, match="limit of 25 px per side"):
        open_image(p, max_side=25)
    assert open_image(p, max_pixels=600, max_side=30).width == 30


def _valid_samples(tmp_path) -> dict[str, bytes]:
    img = gradient_rgb(48, 40)
    out = {}
    p = tmp_path / "s.tif"
    tifffile.imwrite(p, img, photometric="rgb", compression="lzw", rowsperstrip=4)
    out["tif"] = p.read_bytes()
    tifffile.imwrite(p, img, photometric="rgb", compression="deflate", tile=(16, 16))
    out["tiled"] = p.read_bytes()
    out["jpg"] = pyvips.Image.new_from_array(img).copy(interpretation="srgb").jpegsave_buffer(Q=80)
    out["png"] = pyvips.Image.new_from_array(img).copy(interpretation="srgb").pngsave_buffer()
    out["bmp"] = bmp_rgb24(img)
    idx = (img[..., 0] // 40).astype(np.uint8)
    out["rle"] = bmp_rle(idx, COLOUR_PAL, False)
    out["bmp4"] = bmp_indexed(idx % 16, COLOUR_PAL[:16], 4)
    return out


def test_fuzzed_files_never_crash(tmp_path):
    """Mutated valid files either decode or raise ImageError: never another exception, never a hang."""
    samples = _valid_samples(tmp_path)
    bad = corpus.fuzz_failures(samples, tmp_path, 40, open_image)
    assert not bad, "\n".join(bad)


# --------------------------------------------------------------------------
# plain strip TIFFs: read strip by strip (rip/load/tiff.py _StripReader), not through libvips
# --------------------------------------------------------------------------

@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels,photometric", [(1, "minisblack"), (3, "rgb"), (4, "separated")])
@pytest.mark.parametrize("compression,predictor", [(None, False), ("zlib", False), ("zlib", True),
                                                   ("lzw", False), ("lzw", True), ("packbits", False)])
def test_strip_tiffs_read_the_samples_libvips_reads(tmp_path, dtype, channels, photometric,
                                                    compression, predictor):
    from wideprint.rip.load.tiff import _StripReader
    from wideprint.rip.load.vips import _VipsReader
    rng = np.random.default_rng(channels * 7 + np.dtype(dtype).itemsize)
    for i, (h, w, rps) in enumerate(((61, 47, 7), (5, 3, 1), (40, 33, 1000))):
        a = rng.integers(0, np.iinfo(dtype).max + 1, (h, w, channels)[:3 if channels > 1 else 2],
                         dtype=dtype)
        path = tmp_path / f"s{i}.tif"
        kw = dict(photometric=photometric, rowsperstrip=rps, byteorder=">" if i == 1 else "<")
        if compression:
            kw.update(compression=compression, predictor=predictor)
        tifffile.imwrite(path, a, **kw)
        src = open_image(path)
        assert isinstance(src._reader, _StripReader)
        for rows in (1, 5, 256):
            bands = list(src.bands(rows))
            assert [b.shape[0] for b in bands[:-1]] == [rows] * (len(bands) - 1)
            got = np.concatenate(bands)
            assert np.array_equal(got.reshape(a.shape), a)
            vips = np.concatenate(list(_VipsReader(str(path), "tiff", src._reader.plan).bands(rows)))
            assert np.array_equal(got, vips)


def test_strip_tiff_with_a_damaged_deflate_strip_fails_naming_the_strip(tmp_path):
    a = np.random.default_rng(1).integers(0, 256, (64, 50, 3), dtype=np.uint8)
    path = tmp_path / "damaged.tif"
    tifffile.imwrite(path, a, photometric="rgb", rowsperstrip=16, compression="zlib")
    page = tifffile.TiffFile(path).pages[0]
    off, cnt = int(page.dataoffsets[2]), int(page.databytecounts[2])
    data = bytearray(path.read_bytes())
    data[off + cnt // 2:off + cnt // 2 + 8] = bytes(8)
    path.write_bytes(bytes(data))
    src = open_image(path)
    with pytest.raises(ImageError, match=r"damaged.tif: corrupt TIFF data: strip 3 of 4"):
        list(src.bands(16))


def test_strip_tiff_band_memory_does_not_grow_with_the_strips_read(tmp_path):
    """About one strip and one band are held: the bands of a tall file come in the band's
    size, and reading is not a whole-image decode."""
    h, w = 2000, 300
    a = np.random.default_rng(2).integers(0, 256, (h, w, 3), dtype=np.uint8)
    path = tmp_path / "tall.tif"
    tifffile.imwrite(path, a, photometric="rgb", rowsperstrip=64)
    src = open_image(path)
    import tracemalloc
    tracemalloc.start()
    try:
        for band in src.bands(32):
            assert band.shape == (32, w, 3) or band.shape[0] == h % 32
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 * 64 * w * 3, peak          # a few strips' worth, not the 1.8 MB image


def test_one_strip_tiffs_uncompressed_by_rows_compressed_over_16_mb_through_libvips(tmp_path):
    """A whole image in one strip (some RIPs write them): uncompressed, it is still read a
    few rows at a time; compressed, it would be decoded whole, so it stays with libvips."""
    from wideprint.rip.load.tiff import _StripReader
    from wideprint.rip.load.vips import _VipsReader
    a = np.random.default_rng(3).integers(0, 256, (800, 9000, 3), dtype=np.uint8)   # 21.6 MB
    for compression, reader in ((None, _StripReader), ("zlib", _VipsReader)):
        path = tmp_path / f"one_{compression}.tif"
        tifffile.imwrite(path, a, photometric="rgb", rowsperstrip=800, compression=compression)
        src = open_image(path)
        assert type(src._reader) is reader
        assert np.array_equal(np.concatenate(list(src.bands(64))), a)


def test_uncompressed_strip_tiff_read_in_whole_bands_and_a_cut_file_named(tmp_path):
    """Uncompressed strips are read a band at a time straight into the band's array (no
    re-cutting copies): the bands are the file's rows, writable, and a file cut short fails
    naming the file and the strip."""
    a = np.random.default_rng(4).integers(0, 256, (300, 500, 3), dtype=np.uint8)
    path = tmp_path / "plain.tif"
    tifffile.imwrite(path, a, photometric="rgb", rowsperstrip=100)
    src = open_image(path)
    bands = list(src.bands(43))
    assert [b.shape[0] for b in bands] == [43] * 6 + [42]
    assert all(b.flags.writeable and b.flags.c_contiguous for b in bands)
    assert np.array_equal(np.concatenate(bands), a)
    cut = tmp_path / "cut.tif"
    data = path.read_bytes()
    page = tifffile.TiffFile(path).pages[0]
    cut.write_bytes(data[:int(page.dataoffsets[2]) + 1000])      # strip 3 of 3 cut short
    with pytest.raises(ImageError, match=r"cut.tif: truncated TIFF: strip 3 of 3 is cut short"):
        list(open_image(cut).bands(43))
