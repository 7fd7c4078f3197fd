"""Tests for wideprint.rip.place: sizes on the anisotropic device grid, rotation/mirror,
streamed resampling (band invariance, no seams), CMYK/16-bit, bounded memory, identity."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import pyvips
import tifffile

from wideprint.rip import place as P
from wideprint.rip.load import ImageError, open_image
from wideprint.rip.place import Placement, PlacedSource, place

from support.corpus import bmp_rgb24, gradient_rgb
from support.images import read_bands as read_all

ROW_UM = 68.55  # default profile: 137.1 um nozzle pitch / 2 heads per colour -> 370.53 rows/inch


def vips_resize(arr: np.ndarray, w: int, h: int, kernel: str, interpretation: str | None = None) -> np.ndarray:
    """Whole-image reference: libvips resize of the array held in memory (random access)."""
    img = pyvips.Image.new_from_array(arr)
    if interpretation:
        img = img.copy(interpretation=interpretation)
    hs = 1.0 if w == arr.shape[1] else w / arr.shape[1]
    vs = 1.0 if h == arr.shape[0] else h / arr.shape[0]
    out = img.resize(hs, vscale=vs, kernel=kernel).numpy()
    return out.reshape(h, w, -1)


def write_tiff(path, arr, ppi=None, unit="INCH", **kw) -> Path:
    if arr.ndim == 3 and arr.shape[2] == 4:
        kw.setdefault("photometric", "separated")
    elif arr.ndim == 3:
        kw.setdefault("photometric", "rgb")
    else:
        kw.setdefault("photometric", "minisblack")
    if ppi is not None:
        kw.update(resolution=ppi if isinstance(ppi, tuple) else (ppi, ppi), resolutionunit=unit)
    tifffile.imwrite(path, arr, **kw)
    return Path(path)


# ------------------------------------------------------------------------------ target sizes
# The grid: columns at dpi per inch, rows at 68.55 um = 25400 / 68.55 = 370.532 rows per inch.
# Rounding: nearest, halves up.

@pytest.mark.parametrize("kw, dpi, want", [
    # 600 x 300 px at 300 ppi = 2 x 1 in: 600 columns; 1 in = 370.53 -> 371 rows
    (dict(), 300, (600, 371)),
    (dict(), 600, (1200, 371)),
    (dict(), 150, (300, 371)),
    # pixels: 1 px = 1 dot, whatever the dpi
    (dict(size="pixels"), 600, (600, 300)),
    (dict(size="pixels", rotate=90), 300, (300, 600)),
    (dict(size="pixels", rotate=180), 300, (600, 300)),
    # width 254 mm = 10 in -> 3000 columns; aspect 2:1 -> 5 in = 1852.66 -> 1853 rows
    (dict(width_mm=254), 300, (3000, 1853)),
    # height 100 mm = 100000 / 68.55 = 1458.79 -> 1459 rows; width 200 mm = 7.874 in = 2362.2 -> 2362
    (dict(height_mm=100), 300, (2362, 1459)),
    # both: stretched; 500 mm = 19.685 in = 5905.5 -> 5906 columns
    (dict(width_mm=500, height_mm=100), 300, (5906, 1459)),
    # scale 0.5: 1 x 0.5 in -> 300 columns, 185.27 -> 185 rows
    (dict(scale=0.5), 300, (300, 185)),
    # scale 2.5 at 600 dpi: 5 x 2.5 in -> 3000 columns, 926.33 -> 926 rows
    (dict(scale=2.5), 600, (3000, 926)),
    # fit to 3300 mm (3.4 m paper less margins): 38976.4 -> 38976 columns;
    # height 1650 mm = 1650000 / 68.55 = 24070.02 -> 24070 rows
    (dict(fit_width_mm=3300), 300, (38976, 24070)),
    # rotated 90: 1 in wide, 2 in tall -> 300 columns, 741.06 -> 741 rows
    (dict(rotate=90), 300, (300, 741)),
    (dict(rotate=270), 600, (600, 741)),
    # width is the device width after rotation: 100 mm = 1181.1 -> 1181; 200 mm = 2917.6 -> 2918 rows
    (dict(rotate=90, width_mm=100), 300, (1181, 2918)),
])
def test_target_size_by_hand(kw, dpi, want):
    assert Placement(**kw).target_size(600, 300, 300.0, 300.0, dpi, ROW_UM) == want


def test_target_size_resolution_cases():
    p = Placement()
    # no resolution tags: DEFAULT_PPI = 300
    assert p.target_size(600, 300, None, None, 300, ROW_UM) == (600, 371)
    # 150 ppi: 4 x 2 in -> 1200 columns, 741.06 -> 741 rows
    assert p.target_size(600, 300, 150.0, 150.0, 300, ROW_UM) == (1200, 741)
    # non-square pixels 300 x 150 ppi: 2 x 2 in -> 600 columns, 741 rows
    assert p.target_size(600, 300, 300.0, 150.0, 300, ROW_UM) == (600, 741)
    # only one tag: square pixels
    assert p.target_size(600, 300, 150.0, None, 300, ROW_UM) == (1200, 741)
    # width_mm keeps the physical (not the pixel) aspect ratio: 2 x 2 in -> 254 x 254 mm
    # -> 3000 columns, 254000 / 68.55 = 3705.3 -> 3705 rows
    assert Placement(width_mm=254).target_size(600, 300, 300.0, 150.0, 300, ROW_UM) == (3000, 3705)


def test_target_size_from_files(tmp_path):
    a = np.zeros((500, 1000, 3), np.uint8)
    # no tags at all (tifffile writes unit NONE): 300 ppi -> 1000 columns, 500 / 300 in = 617.55 -> 618 rows
    src = open_image(write_tiff(tmp_path / "none.tif", a))
    assert (src.xres, src.yres) == (None, None)
    assert Placement().target_size(src.width, src.height, src.xres, src.yres, 300, ROW_UM) == (1000, 618)
    # 100 px/cm: 1000 x 500 px = 100 x 50 mm -> 1181.1 -> 1181 columns; 50000 / 68.55 = 729.4 -> 729 rows
    src = open_image(write_tiff(tmp_path / "cm.tif", a, ppi=100, unit="CENTIMETER"))
    assert src.xres == pytest.approx(254.0)
    assert Placement().target_size(src.width, src.height, src.xres, src.yres, 300, ROW_UM) == (1181, 729)
    ps = place(src, Placement(), 300, ROW_UM)
    assert (ps.width, ps.height) == (1181, 729)
    assert (ps.xres, ps.yres) == (300.0, pytest.approx(370.532, abs=1e-3))


@pytest.mark.parametrize("kw, phrase", [
    (dict(scale=2000), "limit of 1,000,000"),        # 4000 in = 1.2 M columns
    (dict(width_mm=1e12), "limit of 1,000,000"),
    (dict(scale=1e-4), "0 px"),                       # 0.06 columns
    (dict(height_mm=0.001), "0 px"),
    (dict(size="pixels", scale=2), "cannot be combined"),
    (dict(scale=2, width_mm=100), "only one of"),
    (dict(fit_width_mm=3300, height_mm=100), "only one of"),
    (dict(scale=-1), "positive"),
    (dict(width_mm=float("nan")), "positive"),
    (dict(rotate=45), "rotate"),
    (dict(filter="bicubic"), "filter"),
    (dict(size="inches"), "size"),
    (dict(align="middle"), "align must be one of left, center, right"),
    (dict(x_mm=float("inf")), "x_mm must be a finite number"),
    (dict(top_mm=-1), "top_mm must not be negative"),
    (dict(margin_mm=-0.5), "margin_mm must not be negative"),
    (dict(margin_mm="wide"), "margin_mm must be a number"),
])
def test_bad_options_refused(kw, phrase):
    with pytest.raises(ValueError, match=phrase):
        Placement(**kw).target_size(600, 300, 300.0, 300.0, 300, ROW_UM)


def test_absurd_pixels_and_resolution_refused(tmp_path):
    with pytest.raises(ValueError, match="1,000,000"):
        Placement(size="pixels").target_size(1_200_000, 10, None, None, 300, ROW_UM)
    # a file claiming 0.01 ppi is 100,000 in wide
    with pytest.raises(ValueError, match="1,000,000"):
        Placement().target_size(1000, 1000, 0.01, 0.01, 300, ROW_UM)
    src = open_image(write_tiff(tmp_path / "a.tif", np.zeros((4, 4, 3), np.uint8)))
    with pytest.raises(ValueError, match="0 px"):
        place(src, Placement(scale=1e-3), 300, ROW_UM)


# ------------------------------------------------------------------------------ identity


def test_identity_returns_the_source_itself(tmp_path):
    src = open_image(write_tiff(tmp_path / "a.tif", gradient_rgb(20, 30), ppi=300))
    assert place(src, Placement(size="pixels"), 300, ROW_UM) is src
    assert place(src, Placement(size="pixels", filter="nearest"), 600, ROW_UM) is src
    # a file whose resolution already is the device grid places 1:1 too
    src2 = open_image(write_tiff(tmp_path / "grid.tif", gradient_rgb(100, 30), ppi=(300, 25400 / ROW_UM)))
    assert place(src2, Placement(), 300, ROW_UM) is src2
    assert isinstance(place(src, Placement(size="pixels", mirror=True), 300, ROW_UM), PlacedSource)
    assert isinstance(place(src, Placement(), 300, ROW_UM), PlacedSource)


# ------------------------------------------------------------------------------ rotation / mirror


@pytest.mark.parametrize("rotate", [0, 90, 180, 270])
@pytest.mark.parametrize("mirror", [False, True])
@pytest.mark.parametrize("tile", [5, 128])
def test_rotate_mirror_exact(tmp_path, monkeypatch, rotate, mirror, tile):
    monkeypatch.setattr(P, "SPOOL_TILE", tile)  # small tiles: many partial tiles in the spool
    a = np.random.default_rng(rotate + mirror).integers(0, 256, (23, 37, 3), dtype=np.uint8)
    path = write_tiff(tmp_path / "a.tif", a, rowsperstrip=4)
    want = np.rot90(a, -rotate // 90)  # numpy rot90 is counter-clockwise
    if mirror:
        want = np.fliplr(want)
    ps = place(open_image(path), Placement(size="pixels", rotate=rotate, mirror=mirror, filter="nearest"),
               300, ROW_UM, tmp_dir=str(tmp_path))
    assert (ps.width, ps.height) == (want.shape[1], want.shape[0])
    for rows in (1, 4, 256):  # read again: the spool is reused
        got = read_all(ps, rows)
        np.testing.assert_array_equal(got, want)
    ps.close()


def test_rotate_with_resampling_is_rotated_resample(tmp_path, monkeypatch):
    monkeypatch.setattr(P, "SPOOL_TILE", 16)
    a = gradient_rgb(45, 71, seed=3)
    path = write_tiff(tmp_path / "a.tif", a, ppi=300)
    for rotate in (90, 180, 270):
        ps = place(open_image(path), Placement(rotate=rotate, mirror=True), 300, ROW_UM)
        sw, sh = (ps.height, ps.width) if rotate != 180 else (ps.width, ps.height)
        want = np.fliplr(np.rot90(vips_resize(a, sw, sh, "lanczos3"), -rotate // 90))
        np.testing.assert_array_equal(read_all(ps, 10), want)


def test_spool_is_removed_on_close(tmp_path):
    a = gradient_rgb(30, 40)
    ps = place(open_image(write_tiff(tmp_path / "a.tif", a)), Placement(size="pixels", rotate=90), 300,
               ROW_UM, tmp_dir=str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    read_all(ps)
    assert ps.spool_bytes > 0
    assert len(list((tmp_path / "tmp").iterdir())) == 1
    ps.close()
    assert list((tmp_path / "tmp").iterdir()) == []


def test_not_enough_disk_for_rotation(tmp_path, monkeypatch):
    monkeypatch.setattr(P, "DISK_RESERVE", 1 << 62)
    ps = place(open_image(write_tiff(tmp_path / "a.tif", gradient_rgb(8, 8))),
               Placement(size="pixels", rotate=180), 300, ROW_UM)
    with pytest.raises(ImageError, match="not enough disk space"):
        read_all(ps)


# ------------------------------------------------------------------------------ resampling


@pytest.mark.parametrize("kernel", ["nearest", "linear", "cubic", "lanczos3"])
def test_streamed_equals_whole_image_and_band_invariant(tmp_path, kernel):
    a = gradient_rgb(61, 47, seed=1)
    path = write_tiff(tmp_path / "a.tif", a, ppi=(200, 300), rowsperstrip=3)
    ps = place(open_image(path), Placement(scale=1.7, filter=kernel), 300, ROW_UM)
    # 47 px / 200 ppi * 1.7 * 300 = 119.85 -> 120 columns; 61/300 * 1.7 * 370.53 = 128.07 -> 128 rows
    assert (ps.width, ps.height) == (120, 128)
    ref = vips_resize(a, 120, 128, kernel)
    outs = [read_all(ps, rows) for rows in (1, 2, 7, 64, 1000)]
    for o in outs:
        np.testing.assert_array_equal(o, outs[0])  # band height never changes a pixel: no seams
    assert np.abs(outs[0].astype(int) - ref).max() <= 1


def test_downscale_both_axes(tmp_path):
    a = gradient_rgb(300, 410, seed=2)
    path = write_tiff(tmp_path / "a.tif", a, ppi=600)
    ps = place(open_image(path), Placement(), 150, ROW_UM)
    # 410/600 in at 150 dpi = 102.5 -> 103 columns; 300/600 in = 185.27 -> 185 rows
    assert (ps.width, ps.height) == (103, 185)
    got = [read_all(ps, r) for r in (5, 100)]
    np.testing.assert_array_equal(got[0], got[1])
    assert np.abs(got[0].astype(int) - vips_resize(a, 103, 185, "lanczos3")).max() <= 1


def test_cmyk_and_16bit_survive(tmp_path):
    # CMYK ink amounts: a flat field stays exactly the same ink everywhere
    flat = np.empty((40, 30, 4), np.uint8)
    flat[:] = (30, 0, 200, 10)
    ps = place(open_image(write_tiff(tmp_path / "flat.tif", flat, ppi=300)), Placement(), 300, ROW_UM)
    got = read_all(ps)
    assert (ps.colorspace, ps.channels, ps.depth) == ("cmyk", 4, 8)
    assert (got == np.array([30, 0, 200, 10], np.uint8)).all()
    # CMYK with detail: equals a resample of the ink values
    c = np.random.default_rng(5).integers(0, 256, (40, 30, 4), dtype=np.uint8)
    ps = place(open_image(write_tiff(tmp_path / "c.tif", c, ppi=300)), Placement(), 300, ROW_UM)
    assert np.abs(read_all(ps).astype(int) - vips_resize(c, ps.width, ps.height, "lanczos3", "cmyk")).max() <= 1
    # 16-bit RGB: stays 16-bit, values above 255 survive
    g = (gradient_rgb(40, 30).astype(np.uint16) * 257)
    g[:, :, 2] = 40000
    ps = place(open_image(write_tiff(tmp_path / "g16.tif", g, ppi=250)), Placement(), 300, ROW_UM)
    got = read_all(ps)
    assert got.dtype == np.uint16 and ps.depth == 16
    assert (got[..., 2] == 40000).all()
    assert np.abs(got.astype(int) - vips_resize(g, ps.width, ps.height, "lanczos3")).max() <= 1
    # 16-bit CMYK through rotation
    c16 = c.astype(np.uint16) * 257
    ps = place(open_image(write_tiff(tmp_path / "c16.tif", c16)), Placement(rotate=270), 300, ROW_UM)
    want = np.rot90(vips_resize(c16, ps.height, ps.width, "lanczos3", "cmyk"), 1)
    assert ps.colorspace == "cmyk" and ps.depth == 16
    assert np.abs(read_all(ps).astype(int) - want).max() <= 1


def test_cmyk_jpeg_keeps_the_loader_convention(tmp_path):
    """load.py un-inverts Adobe CMYK JPEG; the placed image must be a resample of exactly the
    ink values ImageSource.bands() gives, not of the raw (inverted) samples."""
    yy, xx = np.mgrid[0:48, 0:64]
    ink = np.stack([xx * 4, yy * 5, np.full_like(xx, 40), np.full_like(xx, 200)], -1).astype(np.uint8)
    path = tmp_path / "cmyk.jpg"
    pyvips.Image.new_from_array(ink).copy(interpretation="cmyk").jpegsave(str(path), Q=95)
    src = open_image(path)
    assert src.colorspace == "cmyk"
    inks = read_all(src)
    assert abs(float(inks[..., 3].mean()) - 200) < 10  # ink amounts, not inverted
    ps = place(open_image(path), Placement(scale=0.8), 300, ROW_UM)
    want = vips_resize(inks, ps.width, ps.height, "lanczos3", "cmyk")
    assert np.abs(read_all(ps).astype(int) - want).max() <= 1


def test_bmp_is_resampled_too(tmp_path):
    """BMP has no libvips loader: its bands are spooled to a TIFF and resampled by libvips."""
    a = gradient_rgb(33, 50, seed=4)
    path = tmp_path / "a.bmp"
    path.write_bytes(bmp_rgb24(a, ppm=(5906, 5906)))  # 150 ppi
    src = open_image(path)
    np.testing.assert_array_equal(read_all(src), a)
    ps = place(src, Placement(mirror=True), 300, ROW_UM, tmp_dir=str(tmp_path))
    # 50 px / 150.01 ppi = 0.3333 in -> 100 columns; 33 / 150.01 in -> 81.5 -> 82 rows
    assert (ps.width, ps.height) == (100, 82)
    want = np.fliplr(vips_resize(a, 100, 82, "lanczos3"))
    got = [read_all(ps, r) for r in (3, 82)]
    np.testing.assert_array_equal(got[0], got[1])
    assert np.abs(got[0].astype(int) - want).max() <= 1
    ps.close()


def test_grey_image(tmp_path):
    a = gradient_rgb(20, 25)[..., 0]
    ps = place(open_image(write_tiff(tmp_path / "g.tif", a, ppi=300)), Placement(rotate=90), 300, ROW_UM)
    got = read_all(ps)
    assert ps.channels == 1 and got.shape[2] == 1
    want = np.rot90(vips_resize(a[..., None], ps.height, ps.width, "lanczos3"), -1)
    assert np.abs(got.astype(int) - want).max() <= 1


# ------------------------------------------------------------------------------ memory


def test_tall_image_memory_is_bounded(tmp_path):
    """2000 x 30000 px at 300 ppi -> 2000 x 37053 dots: 222 MB placed (RGB 8-bit), 180 MB source.
    Peak RSS growth must stay far below either, for straight and rotated placement."""
    script = textwrap.dedent(f"""
        import json, resource, numpy as np, tifffile
        def rss():
            return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        W, H = 2000, 30000
        def strips():
            x = np.arange(W, dtype=np.uint32)
            for y in range(0, H, 500):
                yy = np.arange(y, y + 500, dtype=np.uint32)[:, None]
                b = np.empty((500, W, 3), np.uint8)
                b[..., 0] = (x * 7 + yy * 3) & 255
                b[..., 1] = (x ^ yy) & 255
                b[..., 2] = (yy // 100) & 255
                yield b
        path = {str(tmp_path / "tall.tif")!r}
        tifffile.imwrite(path, strips(), shape=(H, W, 3), dtype=np.uint8, photometric="rgb",
                         rowsperstrip=500, resolution=(300, 300), resolutionunit="INCH")
        from wideprint.rip.load import open_image
        from wideprint.rip.place import Placement, place
        import pyvips
        base = rss()
        out = {{}}
        for rot in (0, 90):
            ps = place(open_image(path), Placement(rotate=rot), 300, 68.55, tmp_dir={str(tmp_path)!r})
            rows = 0
            last = None
            for b in ps.bands(256):
                rows += b.shape[0]
                last = b
            out[rot] = dict(size=[ps.width, ps.height], rows=rows, growth=rss() - base,
                            corner=int(last[-1, -1, 1]))
            ps.close()
        print(json.dumps(out))
    """)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    import json
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert res["0"]["size"] == [2000, 37053] and res["0"]["rows"] == 37053
    assert res["90"]["size"] == [30000, 2470] and res["90"]["rows"] == 2470
    assert res["0"]["growth"] < 120, res    # MB; measured ~30
    assert res["90"]["growth"] < 160, res   # MB; measured ~90


def test_mixed_down_and_up_scale(tmp_path):
    # 300 ppi at 150 dpi: columns halve (0.5) while rows grow (1.235)
    a = gradient_rgb(50, 80, seed=6)
    ps = place(open_image(write_tiff(tmp_path / "a.tif", a, ppi=300)), Placement(), 150, ROW_UM)
    # 80/300 in at 150 dpi = 40 columns; 50/300 in = 61.76 -> 62 rows
    assert (ps.width, ps.height) == (40, 62)
    got = [read_all(ps, r) for r in (1, 9, 62)]
    np.testing.assert_array_equal(got[0], got[1])
    np.testing.assert_array_equal(got[0], got[2])
    assert np.abs(got[0].astype(int) - vips_resize(a, 40, 62, "lanczos3")).max() <= 1


def test_alpha_png_is_composited_like_the_loader(tmp_path):
    rgba = np.concatenate([gradient_rgb(30, 40), np.tile(np.arange(40, dtype=np.uint8)[None, :, None] * 6,
                                                           (30, 1, 1))], -1)
    path = tmp_path / "a.png"
    pyvips.Image.new_from_array(rgba).copy(interpretation="srgb").pngsave(str(path))
    src = open_image(path)
    flat = read_all(src)
    assert src.channels == 3
    ps = place(open_image(path), Placement(scale=1.5, filter="cubic"), 300, ROW_UM)
    assert np.abs(read_all(ps).astype(int) - vips_resize(flat, ps.width, ps.height, "cubic")).max() <= 1
