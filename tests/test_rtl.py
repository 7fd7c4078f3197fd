"""HP RTL input (docs/rtl.md): files written by the test suite's own encoder
(tests/support/rtl_encode.py) in every compression mode and both colour configurations decode to
exactly their bitmaps, print bit-exact on the emulator, contone RTL goes through the
normal RIP, and malformed files fail with the byte offset."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

from support import corpus
from support.images import DEVICE_PPI, random_planes
from support.rtl_encode import CONFIGS, ESC, encode_bits, encode_contone, expected_dots
from wideprint.rip.inputs import sniff_input
from wideprint.rip.load import ImageError
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes
from wideprint.rip.rtl import RtlSource
from wideprint.rip.settings import Placement

EXE = [sys.executable, "-m", "wideprint.app.cli"]
SINGLE = [c for c, (_, order) in CONFIGS.items() if len(order) == 1]


def dots_pattern(h: int, w: int, seed: int = 0) -> np.ndarray:
    """Random dots with blank rows, repeated rows and a blank band: every encoder path."""
    d = random_planes(h, w, density=0.3, seed=seed)
    if h > 40:
        d[5:9] = 0
        d[20:24] = d[19]
        d[h - 10:] = 0
    return d


def decode(path, rows=13) -> np.ndarray:
    src = RtlSource(path)
    return np.concatenate(list(src.bands(rows)), axis=0)


@pytest.mark.parametrize("config, mode", [(c, m) for c in CONFIGS for m in (0, 1, 2, 3, 5)
                                          if m != 5 or c in SINGLE])   # adaptive: single plane
def test_every_mode_and_configuration_decodes_to_its_bitmap(tmp_path, config, mode):
    dots = dots_pattern(83, 203, seed=mode)
    p = tmp_path / "a.rtl"
    for combine in ((False, True) if mode != 5 else (False,)):
        p.write_bytes(encode_bits(dots, config, mode, combine=combine, blocks=2))
        src = RtlSource(p)
        assert src.prescreened and (src.width, src.height) == (203, 83)
        assert src.resolution == 300 and mode in src.modes
        want = expected_dots(dots, config)
        assert np.array_equal(decode(p), want)
        packed = np.concatenate(list(src.packed_bands(16)), axis=0)
        assert np.array_equal(packed, np.packbits(want.transpose(0, 2, 1), axis=2))


@pytest.mark.parametrize("width", [1, 7, 8, 9, 64, 65])
def test_widths_that_end_inside_a_byte(tmp_path, width):
    dots = dots_pattern(30, width, seed=width)
    for config in ("simple-rgb", "simple-kcmy"):      # RGB planes are inverted: pad bits matter
        p = tmp_path / f"{config}.rtl"
        p.write_bytes(encode_bits(dots, config, 2))
        assert np.array_equal(decode(p, rows=7), expected_dots(dots, config))


def test_hpgl2_pjl_and_stray_commands_are_skipped(tmp_path):
    dots = dots_pattern(20, 40)
    body = encode_bits(dots, "simple-kcmy", 1, header=True, hpgl=True)
    # an HP-GL/2 label with text, cursor moves and a font download before the raster
    extra = (ESC + b"%1BIN;SP1;LBhello\x03;PA10,10;" + ESC + b"%1A" + ESC + b"*p100x200Y"
             + ESC + b"(s5W" + b"\x1b\x1b\x1b\x1b\x1b" + ESC + b"&l0O")
    i = body.index(ESC + b"*r-4U")
    p = tmp_path / "x.rtl"
    p.write_bytes(body[:i] + extra + body[i:])
    src = RtlSource(p)
    assert np.array_equal(decode(p), dots)
    assert any("HP-GL/2" in w for w in src.warnings)
    assert any("ESC*p200Y is ignored" in w for w in src.warnings)
    assert not any("outside escape sequences" in w for w in src.warnings)     # PJL lines are expected


def test_commands_and_data_across_read_chunks(tmp_path, monkeypatch):
    """The reader works on the file in chunks: escape sequences, HP-GL/2 ends and data that
    straddle chunk boundaries decode the same (here 5-byte chunks)."""
    from wideprint.rip import rtl
    dots = dots_pattern(40, 77, seed=8)
    p = tmp_path / "c.rtl"
    for config, mode in (("simple-kcmy", 3), ("simple-k", 5), ("cid-rgb-direct", 1)):
        p.write_bytes(encode_bits(dots, config, mode, combine=mode != 5, blocks=2))
        want = decode(p)
        monkeypatch.setattr(rtl, "CHUNK", 5)
        assert np.array_equal(decode(p), want)
        assert np.array_equal(want, expected_dots(dots, config))
        monkeypatch.setattr(rtl, "CHUNK", 1 << 20)
    big = np.random.default_rng(0).integers(0, 256, (3, 40000, 3), dtype=np.uint8)   # 120 kB rows
    p.write_bytes(encode_contone(big, "rgb", 0))
    monkeypatch.setattr(rtl, "CHUNK", 1 << 12)
    assert np.array_equal(decode(p, rows=2), big)


# -- printing -----------------------------------------------------------------------------------
@pytest.mark.parametrize("config, mode", [
    ("simple-kcmy", 0), ("cid-kcmy", 1), ("simple-cmy", 2), ("cid-rgb-direct", 3), ("simple-k", 5),
    ("cid-k", 5),
])
def test_rtl_prints_bit_exact_on_the_emulator(tmp_path, profile, config, mode):
    from support.printing import print_on_emulator
    dots = dots_pattern(260, 333, seed=mode + 10)
    p = tmp_path / "job.rtl"
    p.write_bytes(encode_bits(dots, config, mode))
    media = tmp_path / "m.tif"
    rep, emu = print_on_emulator(p, RipSettings(passes=2, bidir=True), profile, media)
    want = expected_dots(dots, config)
    got = read_planes(media)
    assert got.shape == want.shape and np.array_equal(got, want)
    assert emu.jobs_done[1]["stray"] == 0
    assert rep.drops == want.reshape(-1, 4).sum(axis=0).tolist()


def test_cli_prints_rtl_by_content_whatever_its_name(tmp_path):
    dots = dots_pattern(120, 150, seed=3)
    p = tmp_path / "plot.tif"                 # a wrong name: detection is by content
    p.write_bytes(encode_bits(dots, "simple-kcmy", 3))
    assert sniff_input(p) == "rtl"
    media, planes = tmp_path / "m.tif", tmp_path / "p.tif"
    r = subprocess.run(EXE + ["print", str(p), "--media-out", str(media), "--dither", "bayer"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    r = subprocess.run(EXE + ["rip", str(p), "-o", str(planes)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert np.array_equal(read_planes(media), dots) and np.array_equal(read_planes(planes), dots)


def test_rotation_and_mirror_of_halftoned_rtl_keep_every_dot(tmp_path, profile):
    dots = dots_pattern(70, 90, seed=5)
    p = tmp_path / "r.rtl"
    p.write_bytes(encode_bits(dots, "simple-kcmy", 2))
    for rotate, mirror, want in ((90, False, np.rot90(dots, -1)), (180, True, dots[::-1]),
                                 (0, True, dots[:, ::-1])):
        job = RipJob(str(p), RipSettings(placement=Placement(rotate=rotate, mirror=mirror)), profile)
        got = np.concatenate(list(job.halftone_bands()), axis=0)
        assert np.array_equal(got, want), (rotate, mirror)
        bits = np.concatenate(list(job.packed_bands()), axis=0)
        assert np.array_equal(bits, np.packbits(want.transpose(0, 2, 1), axis=2))


def test_halftoned_rtl_is_not_rescreened_or_resized(tmp_path, profile):
    dots = dots_pattern(40, 50)
    p = tmp_path / "d.rtl"
    p.write_bytes(encode_bits(dots, "simple-kcmy", 2, resolution=600))
    with pytest.raises(ImageError, match=r"halftoned at 600 dpi .* job is at 300 dpi: print it with --dpi 600"):
        RipJob(str(p), RipSettings(), profile)
    job = RipJob(str(p), RipSettings(dpi=600, dither="fs", ink_limit=50), profile)   # no screen, no limit
    assert np.array_equal(np.concatenate(list(job.halftone_bands())), dots)
    with pytest.raises(ImageError, match=r"cannot be resized \(width_mm\)"):
        RipJob(str(p), RipSettings(dpi=600, placement=Placement(width_mm=100)), profile)


def test_contone_rtl_goes_through_the_normal_rip(tmp_path, profile):
    """8-bit RGB RTL at 300 dpi rips exactly like a TIFF of the same pixels with the same
    resolution: the same placement (resampled to 370.53 rows per inch), separation, screen."""
    import tifffile
    rgb = np.random.default_rng(2).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    rgb[:, :10] = 255
    p = tmp_path / "c.rtl"
    tif = tmp_path / "c.tif"
    tifffile.imwrite(tif, rgb, photometric="rgb", resolution=(300, 300), resolutionunit="INCH")
    for mode in (0, 1, 2, 3, 5):
        p.write_bytes(encode_contone(rgb, "rgb", mode, resolution=300))
        src = RtlSource(p)
        assert not src.prescreened and src.colorspace == "rgb" and (src.xres, src.yres) == (300, 300)
        a = RipJob(str(p), RipSettings(dither="bluenoise"), profile)
        b = RipJob(str(tif), RipSettings(dither="bluenoise"), profile)
        assert (a.width, a.height) == (b.width, b.height) == (80, round(60 / 300 * DEVICE_PPI[1]))
        assert np.array_equal(np.concatenate(list(a.halftone_bands())), np.concatenate(list(b.halftone_bands())))
    cmy = tmp_path / "cmy.rtl"
    cmy.write_bytes(encode_contone(rgb, "cmy", 2, yoffset_rows=4))
    src = RtlSource(cmy)
    got = np.concatenate(list(src.bands(16)))
    assert src.colorspace == "cmyk" and not got[:4].any()          # skipped rows: no ink
    assert np.array_equal(got[4:, :, :3], rgb) and not got[..., 3].any()


# -- malformed files ----------------------------------------------------------------------------
def _bad(tmp_path, data: bytes, match: str):
    p = tmp_path / "bad.rtl"
    p.write_bytes(data)
    with pytest.raises(ImageError, match=match) as e:
        RtlSource(p)
    assert str(e.value).startswith(f"{p}: RTL: ")
    return str(e.value)


def test_malformed_rtl_names_the_byte_offset(tmp_path):
    good = encode_bits(dots_pattern(10, 40), "simple-kcmy", 0, header=False, hpgl=False)
    head = ESC + b"E" + ESC + b"*r-4U" + ESC + b"*r40S" + ESC + b"*r1A"
    # truncated: the file ends inside a row's data
    cut = good.index(ESC + b"*b", len(head) + 20) + 4
    msg = _bad(tmp_path, good[: cut + 3], r"announces \d+ bytes but the file ends after \d+: a truncated file "
                                          r"\(byte %d\)" % (cut - 4))
    # an unsupported compression method
    data = head + ESC + b"*b7M" + ESC + b"*b2W\x00\x00"
    _bad(tmp_path, data, r"compression method 7 is not supported \(supported: 0, 1, 2, 3, 5\) \(byte %d\)"
         % len(head))
    _bad(tmp_path, head + ESC + b"*b9M", "9 = replacement delta row")
    # a row wider than ESC*r#S: 40 px = 5 bytes, the 6th byte is non-zero
    data = head + ESC + b"*b0M" + ESC + b"*b6W" + b"\xff" * 6
    off = len(head) + len(ESC + b"*b0M" + ESC + b"*b6W") + 5
    _bad(tmp_path, data, r"row 1, plane 1: ESC\*b6W: the row is wider than the source raster width of "
                         r"40 px \(5 bytes per plane\) \(byte %d\)" % off)
    # the same through run-length: 7 x 0xFF
    data = head + ESC + b"*b1M" + ESC + b"*b2W" + b"\x06\xff"
    _bad(tmp_path, data, r"wider than the source raster width .* \(byte %d\)" % (len(data) - 2))
    _bad(tmp_path, head + ESC + b"*b1M" + ESC + b"*b3W\x01\xff\x00", r"odd length 3")
    # PackBits literal run that runs past the row's data
    data = head + ESC + b"*b2M" + ESC + b"*b2W" + b"\x05\xff"
    _bad(tmp_path, data, r"ends inside a run \(byte %d\)" % (len(data) - 2))
    # delta row: a replacement cut short
    data = head + ESC + b"*b3M" + ESC + b"*b2W" + b"\xe0\xff"
    _bad(tmp_path, data, r"ends inside a replacement \(byte %d\)" % (len(data) - 2))
    # more planes than configured
    data = head + ESC + b"*b0M" + (ESC + b"*b1V\x00") * 4 + ESC + b"*b1W\x00"
    _bad(tmp_path, data, r"more planes in a row than the 4 of KCMY")
    # no source width
    _bad(tmp_path, ESC + b"E" + ESC + b"*r1A" + ESC + b"*b1W\x00", r"before the source raster width \(ESC\*r#S\)")
    # adaptive compression with four planes; adaptive rows cut short
    _bad(tmp_path, head + ESC + b"*b5M" + ESC + b"*b3W\x04\x00\x01", r"mode 5\) with 4 planes")
    one = ESC + b"E" + ESC + b"*r1U" + ESC + b"*r40S" + ESC + b"*r1A" + ESC + b"*b5M"
    _bad(tmp_path, one + ESC + b"*b5W\x00\x00\x09\xff\xff", r"a row of 9 bytes runs past the end of the block "
                                                            r"\(byte %d\)" % (len(one) + 5))
    _bad(tmp_path, one + ESC + b"*b2W\x00\x00", r"row header is cut short")
    _bad(tmp_path, one + ESC + b"*b3W\x07\x00\x00", r"unknown row command 7")
    # colour set-ups we do not do
    _bad(tmp_path, ESC + b"*r4U", r"simple colour ESC\*r4U is not supported")
    _bad(tmp_path, ESC + b"*v6W\x03\x03\x00\x08\x08\x08", r"colour space CIE L\*a\*b\* is not supported")
    _bad(tmp_path, ESC + b"*v6W\x00\x01\x04\x08\x08\x08", r"pixel encoding mode 1 \(indexed by pixel\)")
    _bad(tmp_path, ESC + b"*v2W\x00\x01", r"needs 6 bytes")
    _bad(tmp_path, ESC + b"*v6W" + bytes([0, 3, 8, 8, 8, 8]) + ESC + b"*v255a0b0c1I", r"palette entries")
    _bad(tmp_path, head + ESC + b"*r1U", r"colour configuration changes inside a raster block")
    # not raster at all
    _bad(tmp_path, ESC + b"E" + ESC + b"%0BIN;PU0,0;PD1000,1000;" + ESC + b"E",
         r"no raster data in the file \(it holds HP-GL/2 vector data")
    _bad(tmp_path, ESC + b"%-12345X@PJL ENTER LANGUAGE=POSTSCRIPT\r\n%!PS\nshowpage\n",
         r"PJL header switches to POSTSCRIPT")
    _bad(tmp_path, head + ESC + b"*b1.2.3W", r"malformed")
    _bad(tmp_path, head + ESC + b"\x01", r"not an escape sequence")
    _bad(tmp_path, ESC + b"*t300R" + ESC + b"*t600R", r"resolution changes from 300 to 600 dpi")
    _bad(tmp_path, ESC + b"*r0S", r"source raster width 0 px is out of range")
    _bad(tmp_path, head + ESC + b"*b-5Y", r"negative y offset")
    del msg


def test_mixed_raster_kinds_are_refused(tmp_path):
    bits = encode_bits(dots_pattern(5, 8), "simple-k", 0, header=False, hpgl=False)
    cont = encode_contone(np.zeros((3, 4, 3), np.uint8), "rgb", 0, resolution=300)
    p = tmp_path / "m.rtl"
    p.write_bytes(bits + cont)
    with pytest.raises(ImageError, match="mixes 1-bit and contone"):
        RtlSource(p)


def test_fuzzed_rtl_never_crashes_or_hangs(tmp_path):
    samples = {
        "kcmy3": encode_bits(dots_pattern(30, 50, 1), "simple-kcmy", 3),
        "k5": encode_bits(dots_pattern(30, 50, 2), "simple-k", 5),
        "rgb2": encode_bits(dots_pattern(30, 50, 3), "cid-rgb-direct", 2, combine=True),
        "contone": encode_contone(np.random.default_rng(1).integers(0, 256, (20, 30, 3), dtype=np.uint8), "rgb", 5),
    }
    bad = corpus.fuzz_failures(samples, tmp_path, 60, RtlSource, ".rtl")
    assert not bad, "\n".join(bad)


def test_decoding_speed_is_per_row_not_per_pixel(tmp_path):
    """A 3.2 m wide (37,795 dots) KCMY row costs well under a millisecond: rows are decoded
    by compiled kernels."""
    dots = np.zeros((400, 37795, 4), np.uint8)
    dots[:] = random_planes(1, 37795, 0.2, seed=4)
    dots[::3] = 0
    p = tmp_path / "wide.rtl"
    p.write_bytes(encode_bits(dots, "simple-kcmy", 3, header=False, hpgl=False))
    src = RtlSource(p)
    list(src.packed_bands(64))                            # compile
    t0 = time.perf_counter()
    n = sum(b.shape[0] for b in src.packed_bands(64))
    per_row = (time.perf_counter() - t0) / n
    assert n == 400 and per_row < 2e-3, f"{per_row * 1e6:.0f} us per row"
