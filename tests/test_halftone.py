"""Tests for wideprint.rip.halftone and the blue-noise mask generator."""

from __future__ import annotations

import numpy as np
import pytest

from wideprint.rip import bluenoise
from wideprint.rip.halftone import (
    BLUENOISE_PATH,
    METHODS,
    Halftoner,
    bayer_matrix,
    load_bluenoise_mask,
    load_screen_mask,
    mask_offsets,
    screen_layout,
)

ED_METHODS = ("fs", "jarvis", "stucki")
ORDERED_METHODS = ("bayer", "bluenoise")


def test_methods_tuple_is_the_published_interface():
    assert METHODS == ("vced", "vector", "dbs", "fs", "jarvis", "stucki", "bayer", "bluenoise",
                       "joint")


def halftone_in_bands(method, img, heights, seed=0):
    h = Halftoner(method, img.shape[1], img.shape[2], seed=seed)
    parts = []
    r = 0
    for k in heights:
        parts.append(h.process(img[r:r + k]))
        r += k
    assert r == img.shape[0]
    return np.concatenate(parts, axis=0)


def random_heights(rng, total, max_height):
    heights = []
    while sum(heights) < total:
        heights.append(int(min(rng.integers(0, max_height + 1), total - sum(heights))))
    return heights


def mixed_image(rng, rows, width, channels):
    """Random ink with flat areas, full 0/255 areas and a gradient, so every code path runs."""
    img = rng.integers(0, 256, (rows, width, channels), dtype=np.uint8)
    img[: rows // 4, : width // 3] = 0
    img[rows // 4: rows // 2, width // 3: 2 * width // 3] = 255
    img[rows // 2:, : width // 2] = np.linspace(0, 255, width // 2).round().astype(np.uint8)[None, :, None]
    img[rows // 3: rows // 2, 2 * width // 3:] = 128
    return img


# --------------------------------------------------------------------------
# band-splitting invariance
# --------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_band_splitting_gives_identical_bits(method):
    rng = np.random.default_rng(1234)
    # 300 x 301 x 4 = 361k px: the one-call run takes the multi-threaded path,
    # small bands the single-threaded one; both must give the same bits.
    img = mixed_image(rng, 300, 301, 4)
    ref = Halftoner(method, 301, 4).process(img)
    assert ref.shape == img.shape and ref.dtype == np.uint8
    assert set(np.unique(ref)) <= {0, 1}
    for trial in range(4):
        heights = random_heights(rng, 300, (1, 7, 40, 150)[trial])
        got = halftone_in_bands(method, img, heights)
        assert np.array_equal(got, ref), f"{method}: band split {heights[:12]}... differs"


@pytest.mark.parametrize("method", METHODS)
def test_state_carries_across_calls(method):
    """A second band must depend on the first (tile phase / error rows), i.e.
    restarting a fresh Halftoner per band is NOT what process() does."""
    img = np.full((64, 97, 2), 77, np.uint8)
    one = Halftoner(method, 97, 2).process(img)
    h = Halftoner(method, 97, 2)
    h.process(img[:13])
    second = h.process(img[13:])
    assert np.array_equal(second, one[13:])
    fresh = Halftoner(method, 97, 2).process(img[13:])
    assert not np.array_equal(fresh, one[13:])


@pytest.mark.parametrize("method", METHODS)
def test_empty_band_and_row_counter(method):
    h = Halftoner(method, 10, 3)
    out = h.process(np.zeros((0, 10, 3), np.uint8))
    assert out.shape == (0, 10, 3) and out.dtype == np.uint8
    assert h.row == 0
    h.process(np.zeros((5, 10, 3), np.uint8))
    assert h.row == 5


@pytest.mark.parametrize("method", METHODS)
def test_non_contiguous_input(method):
    rng = np.random.default_rng(5)
    base = mixed_image(rng, 40, 90, 4)
    ref = Halftoner(method, 90, 4).process(np.ascontiguousarray(base))
    fortran = np.asfortranarray(base)
    assert not fortran.flags.c_contiguous
    assert np.array_equal(Halftoner(method, 90, 4).process(fortran), ref)
    big = np.zeros((80, 180, 8), np.uint8)
    big[::2, ::2, 1::2] = base
    view = big[::2, ::2, 1::2]
    assert not view.flags.c_contiguous
    assert np.array_equal(Halftoner(method, 90, 4).process(view), ref)
    planes_last = np.ascontiguousarray(base.transpose(2, 0, 1)).transpose(1, 2, 0)
    assert np.array_equal(Halftoner(method, 90, 4).process(planes_last), ref)


# --------------------------------------------------------------------------
# extremes: 0 -> no drop, 255 -> a drop, pixel by pixel
# --------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("width", [1, 2, 3, 64, 257])
def test_zero_gives_no_dots_full_gives_all_dots(method, width):
    h0 = Halftoner(method, width, 4)
    h1 = Halftoner(method, width, 4)
    for rows in (1, 7, 64):
        assert not h0.process(np.zeros((rows, width, 4), np.uint8)).any()
        assert h1.process(np.full((rows, width, 4), 255, np.uint8)).all()


@pytest.mark.parametrize("method", METHODS)
def test_extremes_hold_pixelwise_in_mixed_images(method):
    """Ink 0 never gets a drop and ink 255 always gets one, whatever the error
    diffused from the neighbours (this is what the error clamp guarantees),
    including the first/last columns and rows."""
    rng = np.random.default_rng(99)
    img = rng.choice(np.array([0, 0, 255, 255, 1, 254, 127, 128, 200, 30], np.uint8), size=(200, 131, 4))
    img[:, :3] = rng.integers(0, 256, (200, 3, 4), dtype=np.uint8)
    img[:, 0, :2] = 0
    img[:, -1, 2:] = 255
    out = Halftoner(method, 131, 4).process(img)
    assert not out[img == 0].any()
    assert out[img == 255].all()


@pytest.mark.parametrize("method", ED_METHODS)
def test_error_clamp(method):
    """White-box: even with an absurd pending error in the kept error rows,
    the clamp to +-127 levels keeps ink 0 dot-free and ink 255 fully inked."""
    h = Halftoner(method, 16, 2)
    h._err[:] = 10 ** 6
    assert not h.process(np.zeros((4, 16, 2), np.uint8)).any()
    h = Halftoner(method, 16, 2)
    h._err[:] = -(10 ** 6)
    assert h.process(np.full((4, 16, 2), 255, np.uint8)).all()
    h = Halftoner(method, 16, 2)
    h._err[:] = 10 ** 6
    assert h.process(np.ones((1, 16, 2), np.uint8)).all()  # +127 + 1 reaches the threshold


# --------------------------------------------------------------------------
# density
# --------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_constant_density(method):
    """Every ink value 0..255 on a 256x256 patch: mean dot density within
    0.5 % of v/255 over the patch and within 1 % in each 64-row block."""
    img = np.empty((256, 256, 4), np.uint8)
    for v0 in range(0, 256, 4):
        img[:] = np.arange(v0, v0 + 4, dtype=np.uint8)  # channel k holds v0 + k
        out = Halftoner(method, 256, 4).process(img)
        for k in range(4):
            v = v0 + k
            plane = out[:, :, k].astype(np.float64)
            assert abs(plane.mean() - v / 255) < 0.005, (method, v, plane.mean())
            blocks = plane.reshape(4, 64, 256).mean(axis=(1, 2))
            assert np.abs(blocks - v / 255).max() < 0.01, (method, v, blocks)
            if 0 < v:
                assert plane.any(), (method, v)
            if v < 255:
                assert not plane.all(), (method, v)


@pytest.mark.parametrize("method", METHODS)
def test_gradient_density(method):
    """Horizontal 0..255 ramp: density of each 16-column block within 1 % of
    the block's mean ink; vertical ramp: each 32-row block within 2 %."""
    ramp = np.arange(256, dtype=np.uint8)
    expected = (ramp / 255).reshape(16, 16).mean(axis=1)
    img = np.broadcast_to(ramp[None, :, None], (256, 256, 1))
    out = Halftoner(method, 256, 1).process(img)[:, :, 0].astype(np.float64)
    assert abs(out.mean() - 127.5 / 255) < 0.002
    cols = out.reshape(256, 16, 16).mean(axis=(0, 2))
    assert np.abs(cols - expected).max() < 0.01, cols - expected

    img = np.broadcast_to(ramp[:, None, None], (256, 256, 1))
    out = Halftoner(method, 256, 1).process(img)[:, :, 0].astype(np.float64)
    rows = out.reshape(8, 32, 256).mean(axis=(1, 2))
    expected8 = (ramp / 255).reshape(8, 32).mean(axis=1)
    assert np.abs(rows - expected8).max() < 0.02, rows - expected8


@pytest.mark.parametrize("method", ORDERED_METHODS)
def test_ordered_exact_count_per_tile(method):
    """For a constant ink v every n x n tile (any phase) has exactly
    ceil((v N - 127) / 255) drops, i.e. floor or ceil of v N / 255."""
    n = 16 if method == "bayer" else 256
    N = n * n
    values = np.arange(256, dtype=np.uint8)
    # one channel per value would be 256 channels: use 4 channels, 64 passes
    for v0 in range(0, 256, 4):
        img = np.empty((n + 5, n + 3, 4), np.uint8)
        img[:] = values[v0:v0 + 4]
        out = Halftoner(method, n + 3, 4).process(img)
        for k in range(4):
            v = v0 + k
            want = max(0, -(-(v * N - 127) // 255))
            assert int(np.floor(v * N / 255)) <= want <= int(np.ceil(v * N / 255))
            for y0, x0 in ((0, 0), (5, 3), (2, 1)):
                tile = out[y0:y0 + n, x0:x0 + n, k]
                assert int(tile.sum()) == want, (method, v, y0, x0)


def test_bayer_matrix_is_the_recursive_index_matrix():
    m2 = bayer_matrix(2)
    assert m2.tolist() == [[0, 2], [3, 1]]
    m4 = bayer_matrix(4)
    assert m4.tolist() == [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]]
    m16 = bayer_matrix(16)
    assert m16.shape == (16, 16)
    assert sorted(m16.reshape(-1).tolist()) == list(range(256))
    with pytest.raises(ValueError):
        bayer_matrix(12)


# --------------------------------------------------------------------------
# error diffusion arithmetic
# --------------------------------------------------------------------------

def test_fs_hand_computed_3x3():
    """Worked by hand from the documented algorithm (units of 1/16 level):

    row 0, left to right, input 200 90 60:
      x0: V=3200 >= 2048 -> 1, V=-880, e=-55: right -385, below 5e=-275 / ahead e=-55
      x1: V=1440-385=1055 -> 0, e=65 r=15: right 470; below-behind gets -275+195=-80
      x2: V=960+470=1430 -> 0, e=89 r=6; errors for row 1 = [-80, 537, 510]
    row 1, right to left, input 70 150 100:
      x2: V=1600+510=2110 -> 1, V=-1970, e=-124 r=14: next (x1) gets -854
      x1: V=2400+537-854=2083 -> 1, V=-1997, e=-125 r=3: x0 gets -872
      x0: V=1120-80-872=168 -> 0, e=10; errors for row 2 = [-75, -719, -995]
    row 2, left to right, input 40 180 130:
      x0: V=640-75=565 -> 0, e=35 r=5: x1 gets 250
      x1: V=2880-719+250=2411 -> 1, V=-1669, e=-105 r=11: x2 gets -724
      x2: V=2080-995-724=361 -> 0
    (a plain left-to-right scan would give row 1 = 0 1 0 instead)
    """
    img = np.array([[200, 90, 60], [70, 150, 100], [40, 180, 130]], np.uint8)[:, :, None]
    expected = np.array([[1, 0, 0], [0, 1, 1], [0, 1, 0]], np.uint8)
    out = Halftoner("fs", 3, 1).process(img)
    assert out[:, :, 0].tolist() == expected.tolist()
    # the same in three one-row bands, and in another channel of a 2-channel band
    h = Halftoner("fs", 3, 1)
    rows = [h.process(img[i:i + 1]) for i in range(3)]
    assert np.concatenate(rows)[:, :, 0].tolist() == expected.tolist()
    two = np.concatenate([np.zeros_like(img), img], axis=2)
    assert Halftoner("fs", 3, 2).process(two)[:, :, 1].tolist() == expected.tolist()


def test_fs_hand_computed_2x3():
    """Row 0 (L->R) 100 200 50: x0 V=1600 -> 0, e=100 (right 700, below 500/100);
    x1 V=3200+700=3900 -> 1, V=-180, e=-12 r=12 (right -72); x2 V=800-72=728 -> 0.
    Errors for row 1: [464, 175, 213].  Row 1 (R->L) 30 160 90: x2 V=1440+213=1653
    -> 0, e=103 r=5 (next 726); x1 V=2560+175+726=3461 -> 1; x0 V=480+464-268=676 -> 0."""
    img = np.array([[100, 200, 50], [30, 160, 90]], np.uint8)[:, :, None]
    out = Halftoner("fs", 3, 1).process(img)
    assert out[:, :, 0].tolist() == [[0, 1, 0], [0, 1, 0]]


_TAPS = {  # (divisor, [(dy, dx, weight)]) for a left-to-right scan
    "fs": (16, [(0, 1, 7), (1, -1, 3), (1, 0, 5), (1, 1, 1)]),
    "jarvis": (48, [(0, 1, 7), (0, 2, 5),
                    (1, -2, 3), (1, -1, 5), (1, 0, 7), (1, 1, 5), (1, 2, 3),
                    (2, -2, 1), (2, -1, 3), (2, 0, 5), (2, 1, 3), (2, 2, 1)]),
    "stucki": (42, [(0, 1, 8), (0, 2, 4),
                    (1, -2, 2), (1, -1, 4), (1, 0, 8), (1, 1, 4), (1, 2, 2),
                    (2, -2, 1), (2, -1, 2), (2, 0, 4), (2, 1, 2), (2, 2, 1)]),
}


def reference_error_diffusion(plane: np.ndarray, method: str) -> np.ndarray:
    """Slow, plain transcription of the module docstring's algorithm."""
    D, taps = _TAPS[method]
    M = round(2 ** 20 / D)
    rows, width = plane.shape
    acc = [[0] * (width + 4) for _ in range(rows + 3)]  # 2 spare columns each side
    out = np.zeros((rows, width), np.uint8)
    for y in range(rows):
        d = 1 if y % 2 == 0 else -1
        for x in (range(width) if d == 1 else range(width - 1, -1, -1)):
            a = min(max(acc[y][x + 2], -127 * D), 127 * D)
            v = int(plane[y, x]) * D + a
            if v >= 128 * D:
                out[y, x] = 1
                v -= 255 * D
            e = (v * M) >> 20
            for dy, dx, w in taps:
                acc[y + dy][x + 2 + d * dx] += w * e
            acc[y][x + 2 + d] += v - e * D
    return out


@pytest.mark.parametrize("method", ED_METHODS)
def test_error_diffusion_matches_reference_model(method):
    rng = np.random.default_rng(11)
    img = mixed_image(rng, 37, 29, 2)
    img[5:9] = rng.choice(np.array([0, 255, 3, 252], np.uint8), size=(4, 29, 2))
    got = halftone_in_bands(method, img, [3, 1, 10, 0, 23])
    for c in range(2):
        want = reference_error_diffusion(img[:, :, c], method)
        assert np.array_equal(got[:, :, c], want), (method, c)


@pytest.mark.parametrize("method", ED_METHODS)
def test_error_diffusion_channels_are_independent(method):
    rng = np.random.default_rng(3)
    img = mixed_image(rng, 120, 700, 4)  # 336k px: the threaded path
    out = Halftoner(method, 700, 4).process(img)
    for c in range(4):
        alone = Halftoner(method, 700, 1).process(img[:, :, c:c + 1])
        assert np.array_equal(out[:, :, c:c + 1], alone), (method, c)
    same = np.repeat(img[:, :, :1], 4, axis=2)
    out = Halftoner(method, 700, 4).process(same)
    assert all(np.array_equal(out[:, :, 0], out[:, :, c]) for c in range(1, 4))


@pytest.mark.parametrize("method", ED_METHODS)
def test_serpentine_depends_on_absolute_row(method):
    """Row direction alternates with the absolute row index: halftoning rows
    1.. of an image after row 0 differs from starting a fresh image at row 1
    even when row 0 is blank (no error to carry), because the direction flips."""
    rng = np.random.default_rng(8)
    img = rng.integers(90, 170, (20, 50, 1), dtype=np.uint8)
    img[0] = 0  # row 0 diffuses no error at all
    h = Halftoner(method, 50, 1)
    h.process(img[:1])
    shifted = h.process(img[1:])
    fresh = Halftoner(method, 50, 1).process(img[1:])
    assert not np.array_equal(shifted, fresh)
    flipped = Halftoner(method, 50, 1).process(img[1:, ::-1])[:, ::-1]
    # not an exact mirror everywhere (error shares are floored), but the first row is
    assert np.array_equal(shifted[0], flipped[0])


# --------------------------------------------------------------------------
# ordered dither: offsets / decorrelation
# --------------------------------------------------------------------------

def test_default_offsets_are_documented_ones():
    assert mask_offsets(128, 4).tolist() == [[0, 0], [49, 64], [98, 17], [19, 81]]
    assert mask_offsets(16, 4).tolist() == [[0, 0], [5, 8], [10, 1], [15, 9]]
    seeded = mask_offsets(128, 4, seed=7)
    assert seeded.tolist() == mask_offsets(128, 4, seed=7).tolist()
    assert seeded.tolist() != mask_offsets(128, 4).tolist()
    assert ((seeded >= 0) & (seeded < 128)).all()


def test_ordered_threshold_layout_matches_offsets():
    """Channel k, pixel (y, x) has a drop iff v*N > r_k[(y+oy)%n, (x+ox)%n]*255 + 127, with
    r_k the screen mask, inverted (N-1-r) for the second channel of each pair."""
    ranks = load_screen_mask().astype(np.int64)
    n, N = 256, 256 * 256
    offsets, inverted = screen_layout(n, 4)
    assert offsets.tolist() == [[0, 0], [0, 0], [128, 128], [128, 128]]
    assert inverted.tolist() == [False, True, False, True]
    for v in (90, 200):
        img = np.full((300, 290, 4), v, np.uint8)
        h = Halftoner("bluenoise", 290, 4)
        out = np.concatenate([h.process(img[:61]), h.process(img[61:])])
        y = np.arange(300)[:, None]
        x = np.arange(290)[None, :]
        for k, (ox, oy) in enumerate(offsets):
            r = ranks[(y + oy) % n, (x + ox) % n]
            if inverted[k]:
                r = N - 1 - r
            assert np.array_equal(out[:, :, k], (v * N > r * 255 + 127).astype(np.uint8)), (v, k)


@pytest.mark.parametrize("method", ORDERED_METHODS)
def test_ordered_channels_differ_for_same_input(method):
    for v in (40, 64, 100, 200):
        img = np.full((128, 256, 4), v, np.uint8)
        out = Halftoner(method, 256, 4).process(img)
        for i in range(4):
            for j in range(i + 1, 4):
                frac = (out[:, :, i] != out[:, :, j]).mean()
                assert frac > 0.1, (method, v, i, j, frac)


def test_bayer_channels_interleave():
    """Bayer offsets have four different phases mod 2: at 25 % ink the four
    channels' dots are disjoint; at 50 % channels 0 and 1 are complementary."""
    out = Halftoner("bayer", 64, 4).process(np.full((64, 64, 4), 64, np.uint8))
    assert (out.mean(axis=(0, 1)) == 0.25).all()
    assert (out.sum(axis=2) == 1).all()
    out = Halftoner("bayer", 64, 4).process(np.full((64, 64, 4), 128, np.uint8))
    assert (out[:, :, 0] != out[:, :, 1]).mean() > 0.98


def test_bluenoise_channel_relations():
    """C and M (and Y and K) are complementary: where the pair's inks sum to at most full
    coverage their dots never coincide, beyond it they overlap as little as possible
    (c + m - 1).  Across the pairs the patterns are uncorrelated: at ~25 % ink a C and a Y
    dot coincide about 25 % x 25 % of the time, as independent patterns would."""
    for v in (13, 64, 127):
        out = Halftoner("bluenoise", 256, 4).process(np.full((256, 256, 4), v, np.uint8))
        assert not (out[:, :, 0] & out[:, :, 1]).any(), v
        assert not (out[:, :, 2] & out[:, :, 3]).any(), v
    out = Halftoner("bluenoise", 256, 4).process(np.full((256, 256, 4), 180, np.uint8))
    both = (out[:, :, 0] & out[:, :, 1]).mean()
    assert abs(both - (2 * 180 / 255 - 1)) < 0.002, both         # the least possible overlap
    out = Halftoner("bluenoise", 256, 4).process(np.full((256, 256, 4), 64, np.uint8)).astype(np.float64)
    p = out.mean()
    for i, j in ((0, 2), (0, 3), (1, 2), (1, 3)):
        both = (out[:, :, i] * out[:, :, j]).mean()
        assert abs(both - p * p) < 0.015, (i, j, both, p * p)


@pytest.mark.parametrize("method", ORDERED_METHODS)
def test_seed_changes_ordered_output_deterministically(method):
    img = np.full((64, 64, 4), 100, np.uint8)
    a = Halftoner(method, 64, 4, seed=3).process(img)
    b = Halftoner(method, 64, 4, seed=3).process(img)
    c = Halftoner(method, 64, 4, seed=0).process(img)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


# --------------------------------------------------------------------------
# blue-noise mask
# --------------------------------------------------------------------------

def _low_frequency_fraction(a: np.ndarray, cutoff: float = 0.1) -> float:
    a = a.astype(np.float64) - a.mean()
    n = a.shape[0]
    f = np.fft.fftfreq(n)
    r = np.hypot(f[:, None], f[None, :])
    p = np.abs(np.fft.fft2(a)) ** 2
    return float(p[(r > 0) & (r < cutoff)].sum() / p.sum())


def test_shipped_mask_is_a_permutation():
    mask = np.load(BLUENOISE_PATH)
    assert mask.shape == (128, 128)
    assert mask.dtype == np.uint16
    assert np.array_equal(np.sort(mask.reshape(-1)), np.arange(128 * 128))
    assert np.array_equal(load_bluenoise_mask(), mask)


def test_shipped_mask_has_blue_noise_spectrum():
    """Thresholded at several levels, the mask has far less power at low
    frequencies (|f| < 0.1 cycles/px) than a white-noise permutation."""
    mask = load_bluenoise_mask().astype(np.int64)
    N = mask.size
    white = np.random.default_rng(0).permutation(N).reshape(mask.shape)
    for level in (0.05, 0.1, 0.25, 0.5, 0.75, 0.9):
        k = int(level * N)
        blue_lf = _low_frequency_fraction(mask < k)
        white_lf = _low_frequency_fraction(white < k)
        assert blue_lf < 0.2 * white_lf, (level, blue_lf, white_lf)
    assert _low_frequency_fraction(mask) < 0.05 * _low_frequency_fraction(white)


def test_shipped_mask_is_reproducible_from_generator():
    """The README says the file is regenerated bit for bit by the generator."""
    again = bluenoise.void_and_cluster(128, 1.5, 0)
    assert np.array_equal(again, load_bluenoise_mask())


def test_generator_small_mask(tmp_path):
    a = bluenoise.void_and_cluster(32, seed=5)
    b = bluenoise.void_and_cluster(32, seed=5)
    c = bluenoise.void_and_cluster(32, seed=6)
    assert a.shape == (32, 32) and a.dtype == np.uint16
    assert np.array_equal(np.sort(a.reshape(-1)), np.arange(1024))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    white = np.random.default_rng(1).permutation(1024).reshape(32, 32)
    assert _low_frequency_fraction(a < 256, 0.15) < 0.3 * _low_frequency_fraction(white < 256, 0.15)
    out = tmp_path / "m" / "bn16.npy"
    assert bluenoise.main(["--size", "16", "--seed", "2", "--out", str(out)]) == 0
    m = np.load(out)
    assert np.array_equal(np.sort(m.reshape(-1)), np.arange(256))
    bluenoise.check_permutation(m)
    with pytest.raises(ValueError):
        bluenoise.check_permutation(np.zeros((4, 4), np.uint16))


# --------------------------------------------------------------------------
# argument checking
# --------------------------------------------------------------------------

def test_unknown_method_names_valid_ones():
    with pytest.raises(ValueError) as exc:
        Halftoner("atkinson", 100)
    for m in METHODS:
        assert m in str(exc.value)


@pytest.mark.parametrize("method", METHODS)
def test_bad_bands_raise(method):
    h = Halftoner(method, 10, 4)
    with pytest.raises(ValueError):
        h.process(np.zeros((3, 10, 4), np.uint16))
    with pytest.raises(ValueError):
        h.process(np.zeros((3, 10, 4), np.float32))
    with pytest.raises(ValueError):
        h.process(np.zeros((3, 10), np.uint8))
    with pytest.raises(ValueError):
        h.process(np.zeros((3, 11, 4), np.uint8))
    with pytest.raises(ValueError):
        h.process(np.zeros((3, 10, 3), np.uint8))
    with pytest.raises(ValueError):
        h.process(np.zeros((1, 3, 10, 4), np.uint8))
    with pytest.raises(ValueError):
        h.process([[[0] * 4] * 10] * 3)
    assert h.row == 0  # rejected bands do not advance the state


def test_bad_constructor_arguments():
    with pytest.raises(ValueError):
        Halftoner("fs", 0)
    with pytest.raises(ValueError):
        Halftoner("bayer", 10, channels=0)


def test_fs_four_ink_loop_is_one_plane_at_a_time_bit_for_bit():
    """Floyd-Steinberg's CMYK loop (`_fs_four`) against `_fs_plane` on each plane and
    `_fs_planes` (two a loop), band after band with the error rows carried."""
    from wideprint.rip import halftone as H
    rng = np.random.default_rng(5)
    w = 901
    img = np.concatenate([rng.integers(0, 256, (9, w, 4), dtype=np.uint8),
                          np.full((6, w, 4), (1, 127, 128, 254), np.uint8),
                          rng.integers(100, 140, (8, w, 4), dtype=np.uint8)])
    errs = [np.zeros((4, 2, w + 4), np.int32) for _ in range(3)]
    outs = [np.zeros_like(img) for _ in range(3)]
    for a, b in ((0, 9), (9, 10), (10, 23)):
        band = np.ascontiguousarray(img[a:b])
        H._fs_four(band, outs[0][a:b], errs[0], a)
        H._fs_planes(band, outs[1][a:b], errs[1], a, 0, 4)
        for c in range(4):
            o = np.zeros(band.shape[:2], np.uint8)
            H._fs_plane(np.ascontiguousarray(band[:, :, c]), o, errs[2][c], a)
            outs[2][a:b, :, c] = o
    assert np.array_equal(outs[0], outs[1]) and np.array_equal(outs[0], outs[2])
    assert np.array_equal(errs[0], errs[1])
    assert 0 < outs[0].mean() < 1
