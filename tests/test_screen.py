"""The fast paths give the same bits as the reference ones: the fused ordered screen
(rip/screen.py) against Separator + Halftoner + pack_dots, and the block packer
against the general stroke packer."""

import numpy as np
import pytest

from wideprint.rip.color import Separator
from wideprint.rip.halftone import Halftoner
from wideprint.rip.screen import OrderedScreen, _drops4
from wideprint.rip.swath import pack_dots, unpack_dots

from support.packers import assert_same_strokes, plan_both

from numba import njit


def reference(sep, ht, band):
    return pack_dots(ht.process(sep.convert(band)))


def check_equal(make_sep, method, img, cuts):
    ref_sep, ref_ht = make_sep(), Halftoner(method, img.shape[1])
    screen = OrderedScreen(make_sep(), Halftoner(method, img.shape[1]))
    for a, b in zip(cuts, cuts[1:]):
        want = reference(ref_sep, ref_ht, img[a:b])
        got = screen.process(img[a:b])
        assert got.shape == want.shape
        assert np.array_equal(got, want), (method, a, b)
    return screen


@pytest.mark.parametrize("method", ["bayer", "bluenoise"])
@pytest.mark.parametrize("width", [1, 7, 8, 13, 129, 1001])
@pytest.mark.parametrize("limit,curved", [(None, False), (180.0, False), (300.0, True)])
def test_rgb_fused_equals_reference(method, width, limit, curved):
    rng = np.random.default_rng(width)
    curves = np.sort(rng.integers(0, 256, (4, 256)), axis=1).astype(np.uint8) if curved else None
    img = rng.integers(0, 256, (70, width, 3), dtype=np.uint8)
    img[10:20] = img[10, 0]                       # flat rows too
    check_equal(lambda: Separator("rgb", 8, ink_limit=limit, curves=curves), method, img,
                [0, 1, 17, 64, 70])


def test_rgb_fused_over_the_limit_everywhere():
    """Dark colours through the built-in profile exceed a 120 % limit: the post step runs
    on every row and its result is the one screened."""
    img = np.random.default_rng(3).integers(0, 60, (40, 300, 3), dtype=np.uint8)
    sep = Separator("rgb", 8, ink_limit=120.0)
    ink = sep.convert(img).reshape(-1, 4).astype(int).sum(axis=1)
    assert ink.max() == int(120 * 255 / 100)      # the limit binds
    check_equal(lambda: Separator("rgb", 8, ink_limit=120.0), "bluenoise", img, [0, 40])


@pytest.mark.parametrize("space,depth,channels", [("rgb", 16, 3), ("cmyk", 8, 4), ("cmyk", 16, 4),
                                                  ("grey", 8, 1)])
def test_other_inputs_equal_reference(space, depth, channels):
    rng = np.random.default_rng(7)
    hi = 65536 if depth == 16 else 256
    img = rng.integers(0, hi, (50, 203, channels)).astype(np.uint16 if depth == 16 else np.uint8)
    check_equal(lambda: Separator(space, depth, ink_limit=250.0), "bayer", img, [0, 9, 50])


def test_mask_phase_carries_across_bands():
    img = np.random.default_rng(1).integers(0, 256, (300, 64, 3), dtype=np.uint8)
    one = OrderedScreen(Separator("rgb"), Halftoner("bluenoise", 64)).process(img)
    screen = OrderedScreen(Separator("rgb"), Halftoner("bluenoise", 64))
    banded = np.concatenate([screen.process(img[a:b]) for a, b in [(0, 5), (5, 133), (133, 300)]])
    assert np.array_equal(one, banded)
    assert screen.row == 300


def test_rejects_a_band_of_the_wrong_width():
    screen = OrderedScreen(Separator("rgb"), Halftoner("bayer", 64))
    with pytest.raises(ValueError, match="64 px wide"):
        screen.process(np.zeros((4, 63, 3), np.uint8))
    with pytest.raises(ValueError):
        OrderedScreen(Separator("rgb"), Halftoner("fs", 64))


@njit
def _drops_all(ink, thr, out):
    for i in range(ink.size):
        out[i] = _drops4(ink[i], thr[i])


def test_four_lane_compare_is_exact():
    """Every (ink, threshold) byte pair, in every lane, with random neighbours."""
    a, b = np.meshgrid(np.arange(256, dtype=np.uint32), np.arange(256, dtype=np.uint32))
    a, b = a.ravel(), b.ravel()
    rng = np.random.default_rng(0)
    for lane in range(4):
        noise_a = rng.integers(0, 2**32, a.size, dtype=np.uint64).astype(np.uint32)
        noise_b = rng.integers(0, 2**32, a.size, dtype=np.uint64).astype(np.uint32)
        keep = np.uint32(~(0xFF << (8 * lane)) & 0xFFFFFFFF)
        ink = (noise_a & keep) | (a << np.uint32(8 * lane))
        thr = (noise_b & keep) | (b << np.uint32(8 * lane))
        out = np.empty_like(ink)
        _drops_all(ink, thr, out)
        want = np.zeros_like(ink)
        for k in range(4):
            gt = ((ink >> np.uint32(8 * k)) & 255) > ((thr >> np.uint32(8 * k)) & 255)
            want |= gt.astype(np.uint32) << np.uint32(8 * k + 7)
        assert np.array_equal(out, want)


def test_pack_unpack_round_trip():
    dots = (np.random.default_rng(2).random((9, 37, 4)) < 0.4).astype(np.uint8)
    bits = pack_dots(dots)
    assert bits.shape == (9, 4, 5)
    assert np.array_equal(bits, np.packbits(dots.transpose(0, 2, 1), axis=2))
    assert np.array_equal(unpack_dots(bits, 37), dots)


@pytest.mark.parametrize("width", [1, 7, 8, 9, 16, 17, 4099])
def test_pack_bits_any_width_any_value(width):
    """Eight dots a word for the four inks (rip/swath.py `_pack_bits`): every width, the
    partial last byte, and any non-zero value as a dot (a byte's high bits too)."""
    rng = np.random.default_rng(width)
    dots = (rng.random((3, width, 4)) < 0.4) * rng.choice([1, 2, 16, 128, 255], (3, width, 4))
    dots = dots.astype(np.uint8)
    assert np.array_equal(pack_dots(dots), np.packbits(dots.transpose(0, 2, 1) > 0, axis=2))


@pytest.mark.parametrize("width", [1, 9, 300, 1003])
@pytest.mark.parametrize("density", [0.02, 0.5, 1.0])
def test_block_packer_equals_general_packer(profile, width, density):
    rng = np.random.default_rng(width)
    dots = (rng.random((700, width, 4)) < density).astype(np.uint8)
    dots[100:180] = 0                              # blank rows: skipped strokes
    assert_same_strokes(*plan_both(profile, dots), dots)


@pytest.mark.parametrize("passes", [2, 3, 4, 6, 8])
@pytest.mark.parametrize("mask", ["checker", "random", "feather"])
def test_block_packer_equals_general_packer_multipass(profile, passes, mask):
    rng = np.random.default_rng(passes)
    dots = (rng.random((500, 259, 4)) < 0.4).astype(np.uint8)
    assert_same_strokes(*plan_both(profile, dots, passes, mask, bidir=passes % 2 == 0, band=37),
                       dots)


def test_block_packer_with_dead_nozzles(tmp_path):
    from support.printing import variant_profile
    prof = variant_profile(tmp_path, dead=[("M1", 57), ("K2", 3), ("C1", 10), ("C2", 10)])
    dots = (np.random.default_rng(9).random((400, 130, 4)) < 0.5).astype(np.uint8)
    for passes, mask in ((2, "checker"), (3, "feather"), (4, "random")):
        assert_same_strokes(*plan_both(prof, dots, passes, mask), dots)
