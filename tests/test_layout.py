"""Layouts on the roll (docs/layout.md): a step-and-repeat, a nested sheet of different
images and a tiled image printed on the emulator, every item's region of the media
bit-exact against the planes of that file (or tile) ripped alone, marks where the
documented geometry puts them, and nothing anywhere else; the nest start rule, the media
saved, bounded composition and the refused combinations."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
import tifffile

from wideprint.app import api
from wideprint.rip import layout as L
from wideprint.rip.pipeline import RipJob
from wideprint.rip.settings import SettingsError, from_mapping

EXE = [sys.executable, "-m", "wideprint.app.cli"]
DPI = 150


def cols(mm: float) -> int:
    return int(np.floor(mm / 25.4 * DPI + 0.5))


def rows(mm: float, profile) -> int:
    return int(np.floor(mm * 1000 / profile.row_um + 0.5))


def rgb_tiff(path, w: int, h: int, seed: int):
    rng = np.random.default_rng(seed)
    tifffile.imwrite(path, (rng.random((h, w, 3)) * 255).astype(np.uint8))
    return path


def settings(**placement) -> dict:
    return {"dpi": DPI, "placement": {"size": "pixels", **placement}}


def alone(path, **placement) -> np.ndarray:
    """The planes of a file ripped alone, as `wideprint rip` makes them."""
    return api.rip(path, settings(**placement))


def paste(sheet: np.ndarray, planes: np.ndarray, x: int, y: int) -> None:
    sheet[y:y + planes.shape[0], x:x + planes.shape[1]] = planes


def assert_same(media: np.ndarray, want: np.ndarray) -> None:
    cmp = api.compare(media, want)
    assert cmp.equal, cmp.explain("media", "layout")


def frame(profile) -> tuple[int, int]:
    """The columns and rows of the frame for marks: MARK_OFFSET_MM + MARK_LENGTH_MM."""
    return cols(2) + cols(5), rows(2, profile) + rows(5, profile)


def crop_marks(sheet: np.ndarray, x: int, y: int, w: int, h: int, profile) -> None:
    """docs/layout.md, "Marks and the label": the image's edges continued outward, each
    line just inside the trim, MARK_OFFSET_MM away, MARK_LENGTH_MM long, black."""
    tc, tr = max(1, cols(0.25)), max(1, rows(0.25, profile))
    ox, oy, lx, ly = cols(2), rows(2, profile), cols(5), rows(5, profile)
    for yy in (y, y + h - tr):
        sheet[yy:yy + tr, x - ox - lx:x - ox, 3] = 1
        sheet[yy:yy + tr, x + w + ox:x + w + ox + lx, 3] = 1
    for xx in (x, x + w - tc):
        sheet[y - oy - ly:y - oy, xx:xx + tc, 3] = 1
        sheet[y + h + oy:y + h + oy + ly, xx:xx + tc, 3] = 1


# -- printed on the emulator ---------------------------------------------------------------------
def test_step_and_repeat_prints_every_copy_and_its_crop_marks(tmp_path, profile):
    src = rgb_tiff(tmp_path / "a.tif", 70, 45, seed=1)
    r = api.print_file(src, settings(repeat_across=3, repeat_along=2, gap_mm=3, marks="crop"),
                       passes=2, bidir=True)
    assert r.ok, r.message
    item = alone(src)
    h, w = item.shape[:2]
    mx, my = frame(profile)                     # the frame: offset + length
    bw, bh = w + 2 * mx, h + 2 * my
    gx, gy = cols(3), rows(3, profile)
    want = np.zeros((2 * bh + gy, 3 * bw + 2 * gx, 4), np.uint8)
    for j in range(2):
        for i in range(3):
            x, y = i * (bw + gx) + mx, j * (bh + gy) + my
            paste(want, item, x, y)
            crop_marks(want, x, y, w, h, profile)
    assert_same(r.media, want)
    assert r.report["layout"]["items"] == 6 and r.report["layout"]["mode"] == "repeat"
    assert r.report["drops"] == want.reshape(-1, 4).sum(axis=0).tolist()


def test_cli_nests_different_images_in_one_job_and_reports_the_media_saved(tmp_path, profile):
    rng = np.random.default_rng(7)
    a = rgb_tiff(tmp_path / "a.tif", 100, 60, seed=2)                 # RGB TIFF
    b = tmp_path / "b.png"                                            # PNG
    cv2.imwrite(str(b), (rng.random((40, 120, 3)) * 255).astype(np.uint8))
    c = tmp_path / "c.tif"                                            # CMYK TIFF
    tifffile.imwrite(c, (rng.random((50, 90, 4)) * 255).astype(np.uint8), photometric="separated")
    d = rgb_tiff(tmp_path / "d.tif", 200, 30, seed=3)
    media = tmp_path / "m.tif"
    r = subprocess.run(EXE + ["print", str(a), str(b), str(c), str(d), "--nest", "--nest-width-mm",
                              "40", "--gap-mm", "2", "--size", "pixels", "--dpi", str(DPI),
                              "--media-out", str(media), "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    reports = json.loads(r.stdout)
    assert len(reports) == 1 and reports[0]["files"] == [str(a), str(b), str(c), str(d)]
    # first-fit decreasing height into 236 columns (40 mm): a (60 rows) and c (50) share
    # the first shelf, b (40) the second, d (30, 200 wide) fits neither: a third shelf
    gx, gy = cols(2), rows(2, profile)
    assert cols(40) == 236 and 100 + gx + 90 <= 236 < 100 + gx + 90 + gx + 120
    spots = {a: (0, 0), c: (100 + gx, 0), b: (0, 60 + gy), d: (0, 60 + gy + 40 + gy)}
    want = np.zeros((60 + 40 + 30 + 2 * gy, 100 + gx + 90, 4), np.uint8)
    for f, (x, y) in spots.items():
        paste(want, alone(f), x, y)
    assert_same(api.read_planes(media), want)
    lay = reports[0]["layout"]
    seq_mm = (60 + 50 + 40 + 30 + 3 * gy) * profile.row_um / 1000
    length_mm = want.shape[0] * profile.row_um / 1000
    assert lay["shelves"] == 3 and lay["items"] == 4
    assert lay["sequential_length_mm"] == pytest.approx(seq_mm, abs=0.06)
    assert lay["saved_mm"] == pytest.approx(seq_mm - length_mm, abs=0.1) and lay["saved_mm"] > 0
    assert f"{lay['saved_mm']:.0f} mm of media saved" in r.stderr


def print_job(job: RipJob, media) -> tuple[dict, np.ndarray]:
    """A RipJob (here: a layout of several files) printed on the in-process emulator."""
    from wideprint.app.devices import open_device
    from wideprint.driver.job import PrintJob
    dev = open_device("emulator", job.profile, None, media_path=str(media))
    try:
        rep = PrintJob(dev, job).run()
    finally:
        dev.emulator.close()
        job.close()
    return rep.as_dict(), api.read_planes(media)


def test_nesting_turns_items_only_when_allowed(tmp_path, profile):
    long = str(rgb_tiff(tmp_path / "long.tif", 300, 40, seed=4))      # wider than 40 mm
    a = str(rgb_tiff(tmp_path / "a.tif", 100, 60, seed=5))
    nest = settings(nest=True, nest_width_mm=40, gap_mm=2)
    with pytest.raises(ValueError, match="long.tif is 51 mm wide, more than the 40 mm to nest into"):
        RipJob(long, from_mapping(nest, profile), profile, more=(a,))
    nest["placement"]["nest_rotate"] = True
    job = RipJob(long, from_mapping(nest, profile), profile, more=(a,))
    # long turned (40 x 300) opens the only shelf; a fits beside it either way and takes the
    # taller way (turned: 60 x 100) to fill the shelf
    gx = cols(2)
    assert {s.item.path: (s.x, s.y, s.item.turn) for s in job.layout.plan.slots} == {
        long: (0, 0, True), a: (40 + gx, 0, True)}
    assert job.layout.report["turned"] == 2
    rep, media = print_job(job, tmp_path / "m.tif")
    want = np.zeros((300, 40 + gx + 60, 4), np.uint8)
    paste(want, alone(long, rotate=90), 0, 0)
    paste(want, alone(a, rotate=90), 40 + gx, 0)
    assert_same(media, want)


def test_tiles_print_bit_exact_with_numbers_and_join_marks(tmp_path, profile):
    rng = np.random.default_rng(9)
    pixels = (rng.random((90, 200, 3)) * 255).astype(np.uint8)
    src = tmp_path / "big.tif"
    tifffile.imwrite(src, pixels)
    tile_mm = 80 * 25.4 / DPI                              # 80 columns
    r = api.print_file(src, settings(tile_width_mm=tile_mm, tile_overlap_mm=2, join_marks=True),
                       passes=2)
    assert r.ok, r.message
    # n = ceil((200 - 12) / (80 - 12)) = 3 tiles of ceil((200 + 2 * 12) / 3) = 75 columns
    # starting every 75 - 12 = 63: [0, 75), [63, 138), [126, 200)
    O = cols(2)
    assert O == 12
    spans = [(0, 75), (63, 138), (126, 200)]
    mx, my = frame(profile)
    label_top = my + rows(1.5, profile)
    label_rows = rows(3, profile)
    gx = cols(5)                                            # the default gap
    media = r.media
    assert media.shape == (my + 90 + my + rows(4.5, profile), sum(b - a + 2 * mx for a, b in spans)
                           + 2 * gx, 4)
    allowed = np.zeros(media.shape[:2], bool)
    tc, oy, ly = max(1, cols(0.25)), rows(2, profile), rows(5, profile)
    x = mx
    for i, (a, b) in enumerate(spans):
        tile = tmp_path / f"tile{i}.tif"
        tifffile.imwrite(tile, pixels[:, a:b])
        assert_same(media[my:my + 90, x:x + b - a], alone(tile))
        allowed[my:my + 90, x:x + b - a] = True
        ticks = ([spans[i + 1][0] - a] if i + 1 < len(spans) else []) + \
                ([spans[i - 1][1] - a] if i else [])
        assert ticks == ([63] if i < 2 else []) + ([12] if i else [])
        for t in ticks:                                     # above and below the tile, black
            for top in (my - oy - ly, my + 90 + oy):
                assert media[top:top + ly, x + t:x + t + tc, 3].all()
                assert not media[top:top + ly, x + t:x + t + tc, :3].any()
                allowed[top:top + ly, x + t:x + t + tc] = True
        top = my + 90 + label_top                           # "tile i/3 r1 ci", black
        zone = media[top:top + label_rows, x:x + b - a + mx]
        assert zone[..., 3].sum() > 50 and not zone[..., :3].any()
        allowed[top:top + label_rows, x:x + b - a + mx] = True
        x += b - a + 2 * mx + gx
    assert not media[~allowed].any()                        # nothing else on the sheet


def test_registration_marks_and_label_lie_outside_the_image(tmp_path, profile):
    src = rgb_tiff(tmp_path / "a.tif", 120, 80, seed=6)
    out = tmp_path / "p.tif"
    r = subprocess.run(EXE + ["rip", str(src), "-o", str(out), "--size", "pixels", "--dpi", str(DPI),
                              "--marks", "registration", "--label"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    planes = api.read_planes(out)
    mx, my = frame(profile)
    assert planes.shape == (80 + 2 * my + rows(4.5, profile), 120 + 2 * mx, 4)
    assert_same(planes[my:my + 80, mx:mx + 120], alone(src))
    marks = planes.copy()
    marks[my:my + 80, mx:mx + 120] = 0
    crop = np.zeros_like(planes)
    crop_marks(crop, mx, my, 120, 80, profile)
    assert (marks[..., 3] >= crop[..., 3]).all()            # every crop mark dot is there
    # the four targets: all four inks (the registration colour), in the frame
    cmy = marks[..., :3].any(axis=-1)
    assert cmy.any() and (marks[cmy] == 1).all()
    ys, xs = np.nonzero(cmy)
    assert {(y < my, y >= my + 80, x < mx, x >= mx + 120) for y, x in zip(ys, xs)} == {
        (True, False, False, False), (False, True, False, False),
        (False, False, True, False), (False, False, False, True)}
    # the label: black text below the lower frame
    text = marks[80 + 2 * my:]
    assert text[..., 3].sum() > 100 and not text[..., :3].any()


# -- the plan --------------------------------------------------------------------------------------
def test_nest_start_rule_by_count_and_length(tmp_path, profile):
    files = [str(rgb_tiff(tmp_path / f"{i}.tif", 150, 60, seed=i)) for i in range(5)]
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"not an image")
    rs = from_mapping(settings(nest=True, nest_count=2, nest_width_mm=40), profile)
    sheets, waiting, failed = L.nest_sheets([files[0], str(bad), *files[1:]], rs, profile)
    assert sheets == [files[0:2], files[2:4]] and waiting == files[4:] and list(failed) == [str(bad)]
    # 150 columns: one item per shelf in 40 mm; three shelves reach 3 * 60 + 2 * gap rows
    three_mm = (3 * 60 + 2 * rows(5, profile)) * profile.row_um / 1000
    rs = from_mapping(settings(nest=True, nest_length_mm=three_mm, nest_width_mm=40), profile)
    sheets, waiting, failed = L.nest_sheets(files, rs, profile)
    assert sheets == [files[:3]] and waiting == files[3:] and not failed


def test_composition_opens_items_when_reached_and_closes_them(tmp_path, profile, monkeypatch):
    files = [str(rgb_tiff(tmp_path / f"{i}.tif", 30, 20, seed=i)) for i in range(12)]
    rs = from_mapping(settings(nest=True, nest_width_mm=30, gap_mm=5), profile, band_rows=16)
    job = RipJob(files[0], rs, profile, more=tuple(files[1:]))
    most = []
    real = L.LayoutJob._job

    def counting(self, item):
        got = real(self, item)
        most.append(len(self._open))
        return got
    monkeypatch.setattr(L.LayoutJob, "_job", counting)
    try:
        per_shelf = {s.y for s in job.layout.plan.slots}
        assert len(per_shelf) == 4                          # 3 items a shelf, 4 shelves
        bands = list(job.halftone_bands())
        assert sum(b.shape[0] for b in bands) == job.height
        assert len(most) == 12 and max(most) <= 3           # one shelf's files at a time
        assert job.layout._open == []                       # all closed when done
    finally:
        job.close()


def test_printed_size_and_estimate_cover_the_whole_layout(tmp_path, profile):
    src = str(rgb_tiff(tmp_path / "a.tif", 70, 45, seed=1))
    rs = from_mapping(settings(repeat_across=2, repeat_along=20, gap_mm=0), profile)
    w, h, wmm, hmm = L.printed_size(src, rs, profile)
    assert (w, h) == (140, 900) and wmm == pytest.approx(140 * 25.4 / DPI)
    assert hmm == pytest.approx(900 * profile.row_um / 1000)
    job = RipJob(src, rs, profile)
    one = RipJob(src, from_mapping(settings(), profile), profile)
    try:
        assert (job.width, job.height) == (w, h)
        assert job.planner().total_strokes > one.planner().total_strokes
    finally:
        job.close()
        one.close()


@pytest.mark.parametrize("placement, phrase", [
    ({"tile_width_mm": 100, "nest": True}, "tiling .* cannot be combined with nest"),
    ({"tile_height_mm": 100, "repeat_along": 2}, "cannot be combined with repeat"),
    ({"nest": True, "repeat_across": 2}, "give nest_copies for copies"),
    ({"tile_width_mm": 10, "tile_overlap_mm": 10}, "tile_overlap_mm 10 must be smaller"),
    ({"repeat_across": 0}, "repeat_across 0 is out of range"),
    ({"marks": "bleed"}, "marks must be one of none, crop, registration"),
])
def test_refused_layouts_name_the_problem(placement, phrase):
    with pytest.raises(SettingsError, match=phrase):
        from_mapping({"placement": placement})


def test_several_files_need_nest(tmp_path, profile):
    a = str(rgb_tiff(tmp_path / "a.tif", 10, 10, seed=1))
    with pytest.raises(ValueError, match="2 files in one job need nest"):
        RipJob(a, from_mapping(settings(), profile), profile, more=(a,))
