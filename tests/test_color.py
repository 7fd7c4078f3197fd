"""Tests for wideprint.rip.color: ICC separation through the LUT, passthrough, grey, ink limit, curves."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import pyvips
import tifffile
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from wideprint.rip.color import Separator, apply_ink_limit, ink_limit_level
from wideprint.rip.load import open_image

RNG = np.random.default_rng(7)


def _builtin_profile(name: str) -> bytes:
    im = pyvips.Image.new_from_array(np.zeros((2, 2, 3), np.uint8)).copy(interpretation="srgb")
    return bytes(im.icc_transform(name, input_profile="srgb").get("icc-profile-data"))


@pytest.fixture(scope="module")
def profiles(tmp_path_factory):
    d = tmp_path_factory.mktemp("icc")
    out = {}
    for name in ("srgb", "cmyk", "p3"):
        data = _builtin_profile(name)
        (d / f"{name}.icc").write_bytes(data)
        out[name] = str(d / f"{name}.icc")
        out[name + "_bytes"] = data
    return out


def rgb(*px) -> np.ndarray:
    return np.array([px], np.uint8)


# ---------------------------------------------------------------------------------------------- RGB


def test_white_black_cyan():
    s = Separator("rgb")
    out = s.convert(rgb((255, 255, 255), (0, 0, 0), (0, 255, 255), (255, 0, 255), (255, 255, 0)))
    assert out.dtype == np.uint8 and out.shape == (1, 5, 4) and out.flags.c_contiguous
    white, black, cyan, magenta, yellow = out[0].astype(int)
    assert white.tolist() == [0, 0, 0, 0]  # paper
    assert black.sum() > 400 and black[3] >= 240  # heavy ink, mostly K
    assert cyan[0] == cyan.max() and cyan[0] > 2 * max(cyan[1], cyan[3])  # mostly C
    assert magenta[1] == magenta.max()
    assert yellow[2] == yellow.max()


@pytest.mark.parametrize("intent", ["perceptual", "relative", "saturation", "absolute"])
def test_lut_agrees_with_direct_lcms(intent):
    s = Separator("rgb", intent=intent)
    band = RNG.integers(0, 256, (200, 300, 3), dtype=np.uint8)
    lut, direct = s.convert(band).astype(int), s.convert_direct(band).astype(int)
    d = np.abs(lut - direct)
    assert d.max() <= 3 and d.mean() < 0.5, (d.max(), d.mean())
    # every grey level and the cube corners
    g = np.arange(256, dtype=np.uint8)
    ramp = np.stack([g, g, g], -1)[None]
    assert np.abs(s.convert(ramp).astype(int) - s.convert_direct(ramp)).max() <= 3


def test_lut_16bit_agrees_with_direct_lcms():
    s = Separator("rgb", 16)
    band = RNG.integers(0, 65536, (150, 200, 3), dtype=np.uint16)
    d = np.abs(s.convert(band).astype(int) - s.convert_direct(band))
    assert d.max() <= 3 and d.mean() < 0.5
    # 16-bit values that round to the same 8-bit value still interpolate at full precision
    s8 = Separator("rgb")
    b8 = RNG.integers(0, 256, (50, 60, 3), dtype=np.uint8)
    assert np.abs(s.convert(b8.astype(np.uint16) * 257).astype(int) - s8.convert(b8)).max() <= 1


def test_user_profiles_and_embedded(profiles):
    band = RNG.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    default = Separator("rgb").convert(band)
    files = Separator("rgb", input_icc=profiles["srgb"], output_icc=profiles["cmyk"]).convert(band)
    assert np.abs(default.astype(int) - files).max() <= 1
    # an embedded wide-gamut profile changes the separation, and matches lcms with that profile
    p3 = Separator("rgb", embedded_icc=profiles["p3_bytes"])
    assert p3.input_profile.data == profiles["p3_bytes"]
    out = p3.convert(band)
    assert np.abs(out.astype(int) - default).mean() > 1
    assert np.abs(out.astype(int) - p3.convert_direct(band)).max() <= 3
    via_file = Separator("rgb", input_icc=profiles["p3"]).convert(band)
    assert np.abs(via_file.astype(int) - out).max() <= 1
    # input_icc overrides the embedded profile
    over = Separator("rgb", embedded_icc=profiles["p3_bytes"], input_icc=profiles["srgb"]).convert(band)
    assert np.abs(over.astype(int) - default).max() <= 1


def test_bad_embedded_profile_falls_back_with_warning(profiles):
    band = RNG.integers(0, 256, (16, 16, 3), dtype=np.uint8)
    for bad in (b"garbage" * 30, profiles["cmyk_bytes"]):  # not ICC / wrong colour space
        s = Separator("rgb", embedded_icc=bad)
        assert s.warnings and "embedded ICC profile ignored" in s.warnings[0]
        np.testing.assert_array_equal(s.convert(band), Separator("rgb").convert(band))


def test_bad_icc_files(tmp_path, profiles):
    missing = tmp_path / "missing.icc"
    with pytest.raises(ValueError, match=f"{missing}: cannot read output ICC profile"):
        Separator("rgb", output_icc=str(missing))
    text = tmp_path / "text.icc"
    text.write_text("this is not a colour profile\n" * 20)
    with pytest.raises(ValueError, match=f"{text}: not an ICC profile"):
        Separator("rgb", input_icc=str(text))
    short = tmp_path / "short.icc"
    short.write_bytes(profiles["cmyk_bytes"][:5000])
    with pytest.raises(ValueError, match=f"{short}: truncated ICC profile"):
        Separator("rgb", output_icc=str(short))
    with pytest.raises(ValueError, match="output ICC profile is for RGB, need CMYK"):
        Separator("rgb", output_icc=profiles["srgb"])
    with pytest.raises(ValueError, match="input ICC profile is for CMYK, need RGB"):
        Separator("rgb", input_icc=profiles["cmyk"])
    # a valid header over a destroyed tag table: lcms refuses it, we name the file
    data = bytearray(profiles["srgb_bytes"])
    data[128:] = b"\xff" * (len(data) - 128)
    broken = tmp_path / "broken.icc"
    broken.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=f"{broken}"):
        Separator("rgb", input_icc=str(broken))


def test_argument_checks():
    with pytest.raises(ValueError):
        Separator("lab")
    with pytest.raises(ValueError):
        Separator("rgb", 12)
    with pytest.raises(ValueError):
        Separator("rgb", intent="colorimetric")
    with pytest.raises(ValueError):
        Separator("rgb", ink_limit=0)
    with pytest.raises(ValueError):
        Separator("rgb", curves=np.zeros((3, 256), np.uint8))
    s = Separator("rgb")
    with pytest.raises(ValueError):
        s.convert(np.zeros((4, 4, 4), np.uint8))
    with pytest.raises(ValueError):
        s.convert(np.zeros((4, 4, 3), np.uint16))
    assert s.convert(np.zeros((0, 7, 3), np.uint8)).shape == (0, 7, 4)


# ---------------------------------------------------------------------------------------------- CMYK


def test_cmyk_passthrough_bit_exact():
    band = RNG.integers(0, 256, (97, 131, 4), dtype=np.uint8)
    out = Separator("cmyk").convert(band)
    assert out.dtype == np.uint8 and out.flags.c_contiguous
    np.testing.assert_array_equal(out, band)
    view = band[:, ::2]  # non-contiguous input still comes out C-contiguous and exact
    out = Separator("cmyk").convert(view)
    assert out.flags.c_contiguous
    np.testing.assert_array_equal(out, view)


def test_cmyk16_rounds_to_8bit():
    band = RNG.integers(0, 65536, (40, 50, 4), dtype=np.uint16)
    band[0, :4] = [[0, 0, 0, 0], [65535] * 4, [128] * 4, [129] * 4]
    out = Separator("cmyk", 16).convert(band)
    np.testing.assert_array_equal(out, np.round(band / 257.0).astype(np.uint8))


def test_cmyk_to_cmyk_with_output_profile(profiles):
    band = RNG.integers(0, 256, (40, 50, 4), dtype=np.uint8)
    s = Separator("cmyk", output_icc=profiles["cmyk"])
    out = s.convert(band)
    assert out.shape == band.shape and out.dtype == np.uint8
    ref = pyvips.Image.new_from_array(band).copy(interpretation="cmyk").icc_transform(
        profiles["cmyk"], input_profile="cmyk", intent="relative").numpy()
    np.testing.assert_array_equal(out, ref)
    assert not np.array_equal(out, band)


def test_cmyk_tiff_end_to_end_is_exact(tmp_path):
    ink = RNG.integers(0, 256, (300, 120, 4), dtype=np.uint8)
    p = tmp_path / "c.tif"
    tifffile.imwrite(p, ink, photometric="separated", compression="lzw", rowsperstrip=16)
    src = open_image(p)
    sep = Separator(src.colorspace, src.depth, embedded_icc=src.icc)
    out = np.concatenate([sep.convert(b) for b in src.bands(64)])
    np.testing.assert_array_equal(out, ink)


# ---------------------------------------------------------------------------------------------- grey


def test_grey_k_only():
    g = np.arange(256, dtype=np.uint8).reshape(1, 256, 1)
    out = Separator("grey").convert(g)
    assert (out[..., :3] == 0).all()
    np.testing.assert_array_equal(out[0, :, 3], 255 - np.arange(256))
    g16 = (np.arange(65536, dtype=np.uint32)[::7]).astype(np.uint16).reshape(1, -1, 1)
    out16 = Separator("grey", 16).convert(g16)
    assert (out16[..., :3] == 0).all()
    np.testing.assert_array_equal(out16[0, :, 3], 255 - np.round(g16[0, :, 0] / 257.0).astype(int))
    # 2-D bands are accepted for grey
    assert Separator("grey").convert(np.zeros((3, 5), np.uint8)).shape == (3, 5, 4)


def test_grey_through_icc_matches_rgb_path():
    g = np.arange(256, dtype=np.uint8)
    sg = Separator("grey", grey_mode="icc")
    out = sg.convert(g.reshape(1, 256, 1)).astype(int)
    via_rgb = Separator("rgb").convert(np.stack([g, g, g], -1)[None]).astype(int)
    assert np.abs(out - via_rgb).max() <= 1
    assert out[0, 255].tolist() == [0, 0, 0, 0]
    out16 = Separator("grey", 16, grey_mode="icc").convert((g.astype(np.uint16) * 257).reshape(1, 256, 1))
    assert np.abs(out16.astype(int) - out).max() <= 1


# ---------------------------------------------------------------------------------------------- ink limit, curves


def test_ink_limit_exact_on_rgb():
    band = RNG.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    band[:5] = 0  # black: over any sensible limit
    free = Separator("rgb").convert(band).astype(int)
    lim = Separator("rgb", ink_limit=250).convert(band).astype(int)
    level = ink_limit_level(250)
    assert level == 637
    s_free, s_lim = free.sum(-1), lim.sum(-1)
    over = s_free > level
    assert over.sum() > 100
    assert (s_lim <= level).all()
    assert (s_lim[over] == level).all()  # meets the limit exactly
    np.testing.assert_array_equal(lim[~over], free[~over])  # untouched below the limit
    np.testing.assert_array_equal(lim[..., 3], free[..., 3])  # K kept
    assert (lim[..., :3] <= free[..., :3]).all()


def test_ink_limit_on_cmyk_and_below_100_percent():
    band = RNG.integers(0, 256, (64, 64, 4), dtype=np.uint8)
    for limit in (300.0, 180.5, 60.0):
        out = Separator("cmyk", ink_limit=limit).convert(band).astype(int)
        level = ink_limit_level(limit)
        assert (out.sum(-1) <= level).all()
        over = band.astype(int).sum(-1) > level
        if limit >= 100:
            assert (out.sum(-1)[over] == level).all()
            np.testing.assert_array_equal(out[..., 3], band[..., 3])
        else:  # K alone may exceed the limit: then there is no room for C, M, Y and K is clipped
            assert (out[..., 3] == np.minimum(band[..., 3], level)).all()
        np.testing.assert_array_equal(out[~over], band[~over])


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(np.uint8, st.tuples(st.integers(1, 6), st.integers(1, 6), st.just(4))),
       st.floats(100.0, 400.0))
def test_ink_limit_property(cmyk, limit):
    out = apply_ink_limit(cmyk, limit).astype(int)
    src = cmyk.astype(int)
    level = ink_limit_level(limit)
    assert (out.sum(-1) <= level).all()
    over = src.sum(-1) > level
    assert (out.sum(-1)[over] == level).all()
    assert (out[..., 3] == src[..., 3]).all()
    assert (out <= src).all()
    # proportions kept to within rounding: C, M, Y scale by the same factor
    f = (level - src[..., 3]) / np.maximum(src[..., :3].sum(-1), 1)
    exp = src[..., :3] * f[..., None]
    assert (np.abs(out[..., :3] - exp)[over] < 1.0 + 1e-9).all()


def test_curves_applied_last():
    curves = np.stack([np.arange(256) // 2, 255 - np.arange(256), np.full(256, 7),
                       np.arange(256)]).astype(np.uint8)
    band = RNG.integers(0, 256, (50, 70, 3), dtype=np.uint8)
    plain = Separator("rgb").convert(band)
    curved = Separator("rgb", curves=curves).convert(band)
    for ch in range(4):
        np.testing.assert_array_equal(curved[..., ch], curves[ch][plain[..., ch]])
    limited = Separator("rgb", ink_limit=200).convert(band)
    both = Separator("rgb", ink_limit=200, curves=curves).convert(band)
    for ch in range(4):
        np.testing.assert_array_equal(both[..., ch], curves[ch][limited[..., ch]])
    # curves on CMYK passthrough and on grey too
    cm = RNG.integers(0, 256, (10, 10, 4), dtype=np.uint8)
    out = Separator("cmyk", curves=curves).convert(cm)
    for ch in range(4):
        np.testing.assert_array_equal(out[..., ch], curves[ch][cm[..., ch]])
    g = np.arange(256, dtype=np.uint8).reshape(16, 16, 1)
    np.testing.assert_array_equal(Separator("grey", curves=curves).convert(g)[..., 3], 255 - g[..., 0])


# ---------------------------------------------------------------------------------------------- speed, threads


def test_throughput_and_threads(capsys):
    s = Separator("rgb")
    rng = np.random.default_rng(1)
    small = rng.integers(0, 256, (16, 64, 3), dtype=np.uint8)
    yy, xx = np.mgrid[0:512, 0:4096]
    photo = np.stack([(xx // 16) % 256, (yy // 2) % 256, ((xx + yy) // 20) % 256], -1).astype(np.uint8)
    photo = np.clip(photo.astype(int) + rng.integers(-2, 3, photo.shape), 0, 255).astype(np.uint8)
    noise = rng.integers(0, 256, (512, 4096, 3), dtype=np.uint8)
    s.convert(small)  # compile / load the kernel
    rates = {}
    for name, band in (("random", noise), ("gradient+noise", photo)):
        best = 1e9
        for _ in range(3):
            t0 = time.perf_counter()
            s.convert(band)
            best = min(best, time.perf_counter() - t0)
        rates[name] = band.shape[0] * band.shape[1] / best / 1e6
    t0 = time.perf_counter()
    s.convert_direct(noise)
    rates["direct lcms (threaded)"] = noise.shape[0] * noise.shape[1] / (time.perf_counter() - t0) / 1e6
    with capsys.disabled():
        print("\nSeparator.convert RGB 8-bit, one core: " + ", ".join(f"{k} {v:.0f} Mpx/s" for k, v in rates.items()))
    assert rates["random"] > 5  # loose: shared CI machines are noisy

    # nogil kernel: two threads give the same result as one
    halves = np.array_split(noise, 2)
    res = [None, None]

    def work(i):
        res[i] = s.convert(halves[i])

    ts = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    np.testing.assert_array_equal(np.concatenate(res), s.convert(noise))


# ------------------------------------------------------------------------------ the LUT cache


def test_lut_cache_reads_back_the_same_lut_and_keys_on_what_makes_it(profiles, tmp_path, monkeypatch):
    """rip/color/lutcache.py keeps each transform's 3-D LUT between processes (docs/color.md "The LUT
    cache"): the second Separator of a transform reads it instead of asking lcms, bit for
    bit the same table; another intent, profile or profile content is another file; a
    damaged file is made again; an empty WIDEPRINT_CACHE_DIR turns it off; a folder that
    cannot be written is no error."""
    from wideprint.rip import color
    from wideprint.rip.color import lutcache
    monkeypatch.setenv("WIDEPRINT_CACHE_DIR", str(tmp_path / "c"))
    calls = []
    real = color.Separator._lut_eval
    monkeypatch.setattr(color.Separator, "_lut_eval",
                        lambda self, grid, bands: calls.append(1) or real(self, grid, bands))
    first = Separator("rgb")
    files = sorted((tmp_path / "c" / "lut3").iterdir())
    assert len(files) == 1 and len(calls) == 1
    again = Separator("rgb")
    assert len(calls) == 1                                  # read, not made
    assert np.array_equal(first._lut, again._lut) and again._lut.dtype == np.uint64
    band = RNG.integers(0, 256, (16, 64, 3), dtype=np.uint8)
    assert np.array_equal(first.convert(band), again.convert(band))
    Separator("rgb", intent="perceptual")
    Separator("rgb", input_icc=profiles["p3"])
    assert len(calls) == 3 and len(list((tmp_path / "c" / "lut3").iterdir())) == 3
    # the same file name with other bytes is another transform
    moved = tmp_path / "mine.icc"
    moved.write_bytes(profiles["p3_bytes"])
    Separator("rgb", input_icc=str(moved))
    assert len(calls) == 3                                  # the same bytes: the same LUT
    moved.write_bytes(profiles["srgb_bytes"])
    Separator("rgb", input_icc=str(moved))
    assert len(calls) == 4
    # damaged: made again, and the file mended
    files[0].write_bytes(b"\x93NUMPY not really")
    mended = Separator("rgb")
    assert len(calls) == 5 and np.array_equal(mended._lut, first._lut)
    assert np.array_equal(np.load(files[0]), first._lut)
    # bounded: the least recently used go (a read counts as a use)
    monkeypatch.setattr(lutcache, "LUT_CACHE_FILES", 3)
    import os
    for i, f in enumerate(sorted((tmp_path / "c" / "lut3").iterdir())):
        os.utime(f, (1000 + i, 1000 + i))
    Separator("rgb")                                        # the default's file: used now
    Separator("rgb", intent="saturation")                   # a fifth transform: two go
    left = {f.name for f in (tmp_path / "c" / "lut3").iterdir()}
    assert len(left) == 3 and files[0].name in left
    calls.clear()
    Separator("rgb")
    assert calls == []
    # off, and unwritable
    monkeypatch.setenv("WIDEPRINT_CACHE_DIR", "")
    assert np.array_equal(Separator("rgb")._lut, first._lut) and len(calls) == 1
    blocked = tmp_path / "file-not-folder"
    blocked.write_text("x")
    monkeypatch.setenv("WIDEPRINT_CACHE_DIR", str(blocked))
    assert np.array_equal(Separator("rgb")._lut, first._lut) and len(calls) == 2
