"""Previews (`print --preview`, rip/planes.py preview_image): true physical aspect on the
anisotropic device grid, area-averaged (no aliasing), built in bands (memory bounded by a
band and the picture, whatever the print's length)."""

import subprocess
import sys

import numpy as np
import pytest

from wideprint.rip.planes import PlanesWriter, preview_image

DPI_X, DPI_Y = 300.0, 25400 / 68.55


def _write(path, planes):
    with PlanesWriter(path, planes.shape[1], planes.shape[0], DPI_X, DPI_Y) as w:
        for y in range(0, planes.shape[0], 100):
            w.write(planes[y:y + 100])


def test_a_square_previews_square(tmp_path):
    """60 mm x 60 mm of ink: 709 columns by 875 rows on the grid, one square in the picture."""
    cols, rows = round(60 / 25.4 * DPI_X), round(60 / 25.4 * DPI_Y)
    planes = np.zeros((rows, cols, 4), np.uint8)
    planes[..., 3] = 1
    _write(tmp_path / "sq.tif", planes)
    img = preview_image(tmp_path / "sq.tif", max_side=500)
    assert abs(img.shape[0] - img.shape[1]) <= 1, img.shape


def test_fine_patterns_average_instead_of_aliasing(tmp_path):
    """Stripes of 1 dot on, 2 off (the old every-third-dot sampling saw all or nothing):
    the preview is an even tint at a third of the ink, with no streaks."""
    planes = np.zeros((3000, 6000, 4), np.uint8)
    planes[:, ::3, 1] = 1                               # magenta every third column
    planes[::3, :, 0] = 1                               # cyan every third row
    _write(tmp_path / "stripes.tif", planes)
    img = preview_image(tmp_path / "stripes.tif", max_side=800).astype(float)
    inner = img[2:-2, 2:-2]
    assert inner.std(axis=(0, 1)).max() < 4.0               # even (1.5 %): no streaks
    green = inner[..., 1].mean()                            # magenta absorbs green
    assert 120 < green < 225                                # a tint, neither white nor solid


def test_memory_is_bounded_by_the_band_not_the_length(tmp_path):
    """A 5.4 m long, 1 m wide print (11,811 x 80,000 dots, 3.8 GB of dots): the preview
    grows the process by far less than the print, which it never holds."""
    script = f"""
import resource, sys, numpy as np
from wideprint.rip.planes import PlanesWriter, preview_image
w, h = 11811, 80000                        # 1 m x 5.4 m at 300 x 370.5
with PlanesWriter({str(tmp_path / 'long.tif')!r}, w, h, {DPI_X}, {DPI_Y}) as out:
    band = np.zeros((4000, w, 4), np.uint8)
    band[::7, ::5, 2] = 1
    for y in range(0, h, 4000):
        out.write(band[:min(4000, h - y)])
with PlanesWriter({str(tmp_path / 'small.tif')!r}, 64, 64, {DPI_X}, {DPI_Y}) as out:
    out.write(np.zeros((64, 64, 4), np.uint8))
preview_image({str(tmp_path / 'small.tif')!r})      # the kernel loaded: its memory is not the print's
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
img = preview_image({str(tmp_path / 'long.tif')!r}, max_side=2000)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(img.shape[0], img.shape[1], base, peak)
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    ph, pw, base, peak = map(int, r.stdout.split())
    assert ph == 2000 and abs(pw / ph - (1000 / (80000 / 370.5 * 25.4))) < 0.01
    # the print is 3.8 GB of dots; the preview may not grow the process by more than 150 MB
    assert peak - base < 150_000, (base, peak)


def test_a_layout_previews_its_items_marks_and_gaps(tmp_path):
    """The job preview of a step-and-repeat (app/jobpreview.py, the server's and so the
    GUI's): every slot of the plan carries the item's ink, the gaps between them none, the
    crop marks are there, and the estimate is the whole sheet's."""
    from support.images import random_planes, write_cmyk_tiff
    from wideprint.app.jobpreview import compute_preview
    from wideprint.rip.profile import load_profile
    from wideprint.rip.settings import from_mapping
    from wideprint.rip.layout import plan_layout
    prof = load_profile()
    f = write_cmyk_tiff(tmp_path / "item.tif", random_planes(120, 160, density=0.5, seed=3))
    rs = from_mapping({"placement": {"size": "pixels", "repeat_across": 3, "repeat_along": 2,
                                     "gap_mm": 10, "marks": "crop"}}, prof)
    pd = compute_preview(str(f), rs, prof, max_px=600)
    plan = plan_layout([str(f)], rs, prof)
    assert (pd.width_dots, pd.height_rows) == (plan.width, plan.height)
    d = pd.dots.any(axis=2)
    sx, sy = d.shape[1] / plan.width, d.shape[0] / plan.height
    assert len(plan.slots) == 6
    covered = np.zeros_like(d)
    for s in plan.slots:
        x0, y0 = int(s.x * sx) + 1, int(s.y * sy) + 1
        x1, y1 = int((s.x + s.item.width) * sx) - 1, int((s.y + s.item.height) * sy) - 1
        assert d[y0:y1, x0:x1].mean() > 0.5, s           # the item's ink (50 % per ink)
        bx, by, bw, bh = s.box
        covered[max(0, int(by * sy) - 1):int((by + bh) * sy) + 1,
                max(0, int(bx * sx) - 1):int((bx + bw) * sx) + 1] = True
    assert not d[~covered].any()                          # gaps between the slots: paper
    marks = [m for m in plan.marks() if m.kind == "crop"]
    assert marks and all(d[int(m.y * sy):int((m.y + m.h) * sy) + 1,
                           int(m.x * sx):int((m.x + m.w) * sx) + 1].any() for m in marks)
    whole = pd.estimate
    assert whole.area_m2 == pytest.approx(plan.width_mm * plan.height_mm * 1e-6)


def _preview_whole(path, max_side=2000):
    """The preview as it was made before it streamed (every box of the print held, then
    cv2's GaussianBlur and INTER_AREA resize on the whole): the reference for the streamed one."""
    import cv2
    import tifffile
    from wideprint.rip.planes import _LUT, _box_sums, _resolution, iter_planes
    with tifffile.TiffFile(str(path)) as tf:
        page = tf.pages[0]
        h, w = page.shape[:2]
        xres, yres = _resolution(page, "XResolution", 300.0), _resolution(page, "YResolution", 300.0)
    scale = min(max_side / max(w / xres, h / yres), max(xres, yres))
    out_w, out_h = max(1, round(w / xres * scale)), max(1, round(h / yres * scale))
    bx, by = max(1, w // out_w), max(1, h // out_h)
    inter_w, inter_h = -(-w // bx), -(-h // by)
    sums = np.zeros((inter_h, inter_w, 3), np.uint32)
    y = 0
    for band in iter_planes(path):
        _box_sums(band, y, by, bx, _LUT, sums)
        y += band.shape[0]
    cols = np.full(inter_w, float(bx), np.float32)
    cols[-1] = w - (inter_w - 1) * bx
    rows = np.full(inter_h, float(by), np.float32)
    rows[-1] = h - (inter_h - 1) * by
    inter = np.divide(sums, (rows[:, None] * cols[None, :])[..., None], dtype=np.float32)
    sx, sy = inter.shape[1] / out_w, inter.shape[0] / out_h
    inter = cv2.GaussianBlur(inter, (0, 0), sigmaX=0.7 * max(sx, 1.0), sigmaY=0.7 * max(sy, 1.0))
    out = cv2.resize(inter, (out_w, out_h), interpolation=cv2.INTER_AREA)
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("shape, max_side", [((3000, 4100), 800), ((1234, 2345), 2000),
                                             ((90, 70), 2000), ((5, 3000), 300)])
def test_the_streamed_preview_is_the_whole_one(tmp_path, shape, max_side):
    """Made band by band, the picture is the one the whole-array filter made: within one
    level of 255 (float sums in another order), downscaled, upscaled (a small print: the
    picture finer than the dots) and a sliver."""
    from support.images import random_planes
    h, w = shape
    planes = random_planes(h, w, density=0.35, seed=h)
    planes[h // 3: h // 2, :, 2] = 1                          # a yellow bar: edges to keep
    _write(tmp_path / "p.tif", planes)
    a = preview_image(tmp_path / "p.tif", max_side=max_side).astype(int)
    b = _preview_whole(tmp_path / "p.tif", max_side=max_side).astype(int)
    assert a.shape == b.shape
    assert np.abs(a - b).max() <= 1 and np.abs(a - b).mean() < 0.01


def test_the_preview_of_a_quarter_square_metre_needs_little_memory(tmp_path):
    """`print --preview` of a 0.25 m2 print (50 x 50 cm: 5,906 x 7,295 dots) grew the
    process by ~220 MB (every box of the print, then two float copies of them, and all the
    compressed tiles read at once) against the print's own ~120 MB; now by the picture
    (12 MB) and a few bands: under 50 MB."""
    script = f"""
import resource, numpy as np
from wideprint.rip.planes import PlanesWriter, preview_image
w, h = 5906, 7295
with PlanesWriter({str(tmp_path / 'q.tif')!r}, w, h, {DPI_X}, {DPI_Y}) as out:
    rng = np.random.default_rng(1)
    band = (rng.random((64, w, 4)) < 0.3).astype(np.uint8)
    for y in range(0, h, 64):
        out.write(band[:min(64, h - y)])
with PlanesWriter({str(tmp_path / 'small.tif')!r}, 64, 64, {DPI_X}, {DPI_Y}) as out:
    out.write(np.zeros((64, 64, 4), np.uint8))
preview_image({str(tmp_path / 'small.tif')!r})      # the kernel loaded: its memory is not the print's
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
img = preview_image({str(tmp_path / 'q.tif')!r})
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(img.shape[0], img.shape[1], base, peak)
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    ph, pw, base, peak = map(int, r.stdout.split())
    assert max(ph, pw) == 2000
    assert peak - base < 50_000, (base, peak)


@pytest.mark.parametrize("shape", [(1, 1), (255, 3), (600, 901)])
def test_the_png_holds_the_picture_exactly(shape):
    """write_preview's PNG (zlib and the Up filter, rows in groups of 256: no cv2, whose
    import alone is ~37 MB) decodes to the very picture."""
    import cv2
    from wideprint.rip.planes import png_bytes
    rgb = np.random.default_rng(shape[0]).integers(0, 256, (*shape, 3), dtype=np.uint8)
    rgb[: shape[0] // 2, : shape[1] // 2] = (200, 30, 90)
    back = cv2.imdecode(np.frombuffer(png_bytes(rgb), np.uint8), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(back[:, :, ::-1], rgb)
