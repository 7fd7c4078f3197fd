"""The separation kernels (docs/color.md): an RGB pixel through the 3-D LUT by tetrahedral
interpolation, a grey one through a 1-D table, CMYK scaled, then the ink limit and the
curves, all in numba kernels (rip/compiled.py) that rip/color/separator.py and
rip/screen.py call band by band."""

from __future__ import annotations

import numpy as np

from ..compiled import kernel


def ink_limit_level(ink_limit: float) -> int:
    """Total area coverage limit in percent -> the largest allowed C+M+Y+K sum in 0..255 units."""
    return int(np.floor(ink_limit * 255.0 / 100.0 + 1e-9))


# Curves are tables of 1/16 levels (CURVE_ONE = 16 a level): the output level is rounded
# with this ordered pattern over the pixel index, so a budgeted amount such as 26 x 0.25 =
# 6.5 prints as 6.5 on average, not 6 (docs/color.md "Precision"); whole amounts are exact.
CURVE_ONE = 16
ROUND16 = np.array([0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15], np.int64)


@kernel(inline="always")
def _limit_curves(c, m, y, k, limit, curves, use_curves, p):
    if limit >= 0:
        s = c + m + y + k
        if s > limit:
            avail = limit - k
            if avail <= 0:
                c = 0
                m = 0
                y = 0
                if k > limit:
                    k = limit
            else:
                cmy = c + m + y
                nc = (c * avail) // cmy
                nm = (m * avail) // cmy
                ny = (y * avail) // cmy
                rc = (c * avail) % cmy
                rm = (m * avail) % cmy
                ry = (y * avail) % cmy
                rem = avail - nc - nm - ny
                while rem > 0:  # largest remainder first: the sum meets the limit exactly
                    if rc >= rm and rc >= ry:
                        nc += 1
                        rc = -1
                    elif rm >= ry:
                        nm += 1
                        rm = -1
                    else:
                        ny += 1
                        ry = -1
                    rem -= 1
                c = nc
                m = nm
                y = ny
    if use_curves:             # 1/16 levels, rounded by position (a phase per ink)
        c = (np.int64(curves[0, c]) + ROUND16[p & 15]) >> 4
        m = (np.int64(curves[1, m]) + ROUND16[(p + 5) & 15]) >> 4
        y = (np.int64(curves[2, y]) + ROUND16[(p + 10) & 15]) >> 4
        k = (np.int64(curves[3, k]) + ROUND16[(p + 15) & 15]) >> 4
    return c, m, y, k


def _tetra_offsets(n_grid: int) -> tuple[np.ndarray, np.ndarray]:
    """Offsets of the 2nd and 3rd tetrahedron vertices for the 8 outcomes of the comparisons
    (fr >= fg) * 4 + (fg >= fb) * 2 + (fr >= fb) (two outcomes are impossible)."""
    sr, sg, sb = n_grid * n_grid, n_grid, 1      # in nodes of the packed LUT
    d1 = np.zeros(8, np.uint64)
    d2 = np.zeros(8, np.uint64)
    for rg in (0, 1):
        for gb in (0, 1):
            for rb in (0, 1):
                if rg and gb:  # r >= g >= b
                    a, b = sr, sr + sg
                elif rg and rb:  # r >= b > g
                    a, b = sr, sr + sb
                elif rg:  # b > r >= g
                    a, b = sb, sr + sb
                elif not gb:  # b > g > r
                    a, b = sb, sg + sb
                elif not rb:  # g >= b > r
                    a, b = sg, sg + sb
                else:  # g > r >= b
                    a, b = sg, sr + sg
                d1[rg * 4 + gb * 2 + rb] = a
                d2[rg * 4 + gb * 2 + rb] = b
    return d1, d2


WEIGHT_BITS = 6       # tetrahedral weights in 1/64 of a grid cell
LANE_SCALE = 4        # LUT values in quarter levels: 255 * 4 * 64 < 2**16 per 16-bit lane


ROUND4 = np.uint64(1 << (WEIGHT_BITS + 1)) * np.uint64(0x0001000100010001)  # half of 4*64, per lane
NO_LIMIT = 1 << 30    # a limit no pixel reaches (C+M+Y+K <= 1020)


@kernel(inline="always")
def _tetra(r, g, b, lut, axes, nv, d12, s3):
    """C, M, Y, K of one RGB pixel through the 3-D LUT, tetrahedral interpolation, as
    (packed, total): packed = C | M << 8 | Y << 16 | K << 24 (the bytes C, M, Y, K in
    memory), total = C + M + Y + K.

    Each LUT node packs C, M, Y, K into the four 16-bit lanes of a uint64 (quarter levels),
    and the weights are integers summing to 64, so one node costs one load and one multiply
    for all four inks: 4 loads and 4 multiplies a pixel instead of 16 and 16.  No lane can
    carry into the next (255 * 4 * 64 + 128 < 65536), so rounding is one add and each
    ink is the high byte of its lane.  `axes[v + i * V]` (V values per axis) holds a value's
    grid cell, already multiplied by the axis stride, above its position in the cell
    (8 bits); `d12[t]` the two inner vertices' offsets of tetrahedron t.  All indices are
    unsigned, which spares numba's negative-index checks (measured 25 % faster), and the
    tables are few and flat, so the loop's pointers stay in registers.  No data-dependent
    branch: noisy images cost the same as flat ones."""
    m8 = np.uint64(0xFF)
    s8 = np.uint64(8)
    ar = np.uint64(axes[np.uint64(r)])
    ag = np.uint64(axes[np.uint64(g) + nv])
    ab = np.uint64(axes[np.uint64(b) + nv + nv])
    fr = ar & m8
    fg = ag & m8
    fb = ab & m8
    v0 = (ar >> s8) + (ag >> s8) + (ab >> s8)
    dd = d12[(fr >= fg) * 4 + (fg >= fb) * 2 + (fr >= fb)]
    wa = max(fr, max(fg, fb))
    wc = min(fr, min(fg, fb))
    wb = fr + fg + fb - wa - wc
    acc = (lut[v0] * (np.uint64(1 << WEIGHT_BITS) - wa)
           + lut[v0 + (dd & np.uint64(0xFFFFFFFF))] * (wa - wb)
           + lut[v0 + (dd >> np.uint64(32))] * (wb - wc) + lut[v0 + s3] * wc) + ROUND4
    x = (acc >> s8) & np.uint64(0x00FF00FF00FF00FF)          # the inks, one per 16-bit lane
    total = (x * np.uint64(0x0001000100010001)) >> np.uint64(48)
    x = (x | (x >> s8)) & np.uint64(0x0000FFFF0000FFFF)
    return np.uint32(x | (x >> np.uint64(16))), total


@kernel()
def _lut3_rows(src, lut, axes, d12, s3, limit, out):
    """src (n, 3) uint8/uint16 -> out (n,) uint32 packed CMYK through the 3-D LUT, before
    ink limit and curves; returns whether any pixel is over `limit` (< 0: none).  Kept free
    of branches (the ink limit lives in `_post_rows`): LLVM then schedules the loop well;
    with the limit inlined here it ran 2.5x slower."""
    lim = np.uint64(limit if limit >= 0 else NO_LIMIT)
    over = False
    nv = np.uint64(axes.shape[0] // 3)
    flat = src.reshape(-1)               # (n, 3) C-contiguous: constant strides, fewer registers
    for p in range(src.shape[0]):
        q = 3 * p
        v, total = _tetra(flat[q], flat[q + 1], flat[q + 2], lut, axes, nv, d12, s3)
        out[p] = v
        over = over | (total > lim)
    return over


@kernel()
def _post_rows(out, limit, curves, use_curves):
    """Ink limit and curves in place on (n, 4) uint8 CMYK; pixels under the limit with no
    curves are only read."""
    for p in range(out.shape[0]):
        c = np.int64(out[p, 0])
        m = np.int64(out[p, 1])
        y = np.int64(out[p, 2])
        k = np.int64(out[p, 3])
        if use_curves or (limit >= 0 and c + m + y + k > limit):
            c, m, y, k = _limit_curves(c, m, y, k, limit, curves, use_curves, p)
            out[p, 0] = c
            out[p, 1] = m
            out[p, 2] = y
            out[p, 3] = k


SEP_BLOCK = 4096      # pixels per separation block: its CMYK stays in L1 for the post step


@kernel()
def _sep3(src, lut, axes, d12, s3, limit, curves, use_curves, out, out32):
    """src (n, 3) uint8/uint16 -> out (n, 4) uint8 (out32: the same memory as (n,) uint32):
    3-D LUT, then ink limit and curves, block by block.  Within a level of LittleCMS
    (tests/test_color.py)."""
    n = src.shape[0]
    for a in range(0, n, SEP_BLOCK):
        b = min(n, a + SEP_BLOCK)
        if _lut3_rows(src[a:b], lut, axes, d12, s3, limit, out32[a:b]) or use_curves:
            _post_rows(out[a:b], limit, curves, use_curves)


@kernel()
def _sep1(src, table, limit, curves, use_curves, out):
    """src (n,) grey -> out (n, 4) through a 1-D table (V, 4) uint8."""
    n = src.shape[0]
    for p in range(n):
        v = src[p]
        c, m, y, k = _limit_curves(np.int64(table[v, 0]), np.int64(table[v, 1]), np.int64(table[v, 2]),
                                   np.int64(table[v, 3]), limit, curves, use_curves, p)
        out[p, 0] = c
        out[p, 1] = m
        out[p, 2] = y
        out[p, 3] = k


@kernel()
def _cmyk_post(src, scale, limit, curves, use_curves, out):
    """src (n, 4) CMYK uint8/uint16 -> out (n, 4) uint8: per-channel scale table, ink limit, curves."""
    n = src.shape[0]
    for p in range(n):
        c, m, y, k = _limit_curves(np.int64(scale[src[p, 0]]), np.int64(scale[src[p, 1]]),
                                   np.int64(scale[src[p, 2]]), np.int64(scale[src[p, 3]]), limit, curves,
                                   use_curves, p)
        out[p, 0] = c
        out[p, 1] = m
        out[p, 2] = y
        out[p, 3] = k


def apply_ink_limit(cmyk: np.ndarray, ink_limit: float) -> np.ndarray:
    """Ink limit on a (..., 4) uint8 CMYK array (new array): where C+M+Y+K exceeds the limit, C, M and
    Y are scaled down (K kept) so the sum equals the limit."""
    a = np.ascontiguousarray(cmyk, dtype=np.uint8)
    flat = a.reshape(-1, 4)
    out = np.empty_like(flat)
    _cmyk_post(flat, np.arange(256, dtype=np.uint8), ink_limit_level(ink_limit), np.zeros((4, 256), np.uint16),
               False, out)
    return out.reshape(a.shape)
