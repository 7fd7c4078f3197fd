"""Variable-coefficient error diffusion with threshold modulation, and its colour-aware form.

``vced`` (rip/halftone.py), the RIP's default for photographs, and ``vector``:

* **Variable coefficients** (Ostromoukhov 2001): three taps - the next pixel in scan
  direction, the pixel below and behind it ("down-left" for a left-to-right row), and the
  pixel below - whose weights depend on the pixel's *input* level, optimised so that flat
  tints get a blue-noise spectrum.  We use the key-level weights of Zhou and Fang 2003
  (Table 1 of "Improving mid-tone quality of variable-coefficient error diffusion using
  threshold modulation", SIGGRAPH 2003; linear between the key levels, mirrored above 127),
  with the next pixel's weight x ``NEXT_BOOST`` = 1.15 and renormalised: the device grid's rows
  are 0.81 of a column apart, so the row below is physically nearer than the next column and
  the error is better kept a little more in the row (measured: photo RMSE -1.5 % fine, -3.5 %
  coarse against 1.0).  Ostromoukhov's own 128-entry table (Appendix I of "A simple and
  efficient error-diffusion algorithm", SIGGRAPH 2001) is ``OSTROMOUKHOV``: the reference
  the quality bench compares against.
* **Threshold modulation** (Zhou-Fang 2003): the threshold is ``128 + strength(level) *
  (noise - 128) / 2`` levels, which breaks up the regular lines, grids and checkerboard
  domains that variable coefficients alone settle into at some tints.  Zhou and Fang draw
  ``noise`` from ``rand()`` and use one strength curve; here ``noise`` is a blue-noise
  mask (resources/masks/bluenoise256.npy) read at the pixel's absolute position with
  channel-dependent offsets - deterministic, independent of the banding, and high-frequency
  itself - and the strength is tuned per level (``TUNED_STRENGTH``, ``tune_strength``): the
  least that leaves no periodic structure (``structure_peak``), so the modulation adds as
  little noise as it can.  A floor of 0.02 keeps two inks of equal amount from getting the
  same pattern (dot on dot).
* **Serpentine scan** on the absolute row index, integer fixed-point arithmetic: bit-exact
  and platform independent, identical for any band split (the error rows are carried between
  bands, as for ``fs``).  ``vced`` diffuses the four inks of CMYK in one loop (their
  dependency chains overlap: two inks in a loop are ~1.5x the speed of one at a time, four
  another 1.15x), other channel counts two at a time.
* **Colour-aware placement** (``vector``, ``joint=True``): C and M are diffused as a pair in one
  pass (semi-vector error diffusion, after Shaked et al.'s minimum-brightness-variation
  quadruples).  Each ink keeps its own error, but the *decision* is joint: where the pair's
  input sum is at most full coverage (``c + m <= 255``) a pixel gets at most one of the two
  dots - one when the pair's combined value reaches the threshold, given to the ink further
  above its own threshold -, and where the sum is more than full coverage at least one, both
  when the combined value minus one full dot reaches the threshold.  The combined process is
  itself a variable-coefficient diffusion at the combined level (``c + m``, or ``c + m - 255``),
  with that level's weights and modulation, so the two inks' dots together form one
  blue-noise pattern: light mixed tints lay C and M side by side with 35-50 % less grain, and
  each ink's tone is kept by its own error.  Which ink a single dot goes to is a binary
  halftone of its own (at C = M, half the single dots each), and left to the inks' errors
  it settles into checkerboard and line domains where the single dots are dense (C = M
  around 50 %); its decision is modulated like a threshold, by a noise of its own at
  ``SPLIT_BOOST`` x the ink's own strength.  Y and K are diffused on their own (K must keep
  its own best pattern; Y hardly shows).  With one ink of the pair at 0 this is that ink's
  own error diffusion.

Fixed point: error in units of 1/``UNIT`` level; a pixel's value is ``V = ink * UNIT + acc``
with ``acc`` (the error diffused into it) clamped to ``[-127 UNIT, +127 UNIT]`` (the C/M pair:
``+-254 UNIT``); a drop is placed when ``V >= T`` and then ``V -= 255 UNIT``; the remaining
error is split as ``e_next = (V * w_next) >> 16``, ``e_dl = (V * w_dl) >> 16``, ``e_down = V -
e_next - e_dl`` (the weights in 1/65536), so no error is lost or created except at the left
and right edges, where a share that would leave the image is dropped.  The modulation is zero
at ink 0 and 255 and the clamp keeps ``|acc| <= 127 UNIT``, so ink 0 never gets a drop and ink
255 always gets one, pixel by pixel (the pair's decision applies that rule last).
"""

from __future__ import annotations

import numpy as np
from .compiled import kernel
from .serpentine import _end_row, _rows4, _serpentine

__all__ = ["OSTROMOUKHOV", "ZHOU_FANG_KEYS", "ZHOU_FANG_STRENGTH", "TUNED_STRENGTH", "UNIT",
           "WEIGHT_BITS", "MODULATION", "NEXT_BOOST", "VCDiffuser", "coefficient_table",
           "strength_table", "weight_tables", "modulation_table", "structure_peak",
           "tune_strength", "SPLIT_BOOST"]

UNIT = 256          # error units per ink level
WEIGHT_BITS = 16    # the weights are in 1/65536
MODULATION = 1.0    # scale of the strength table
NEXT_BOOST = 1.15   # the next pixel's weight x 1.15: the grid's rows are 0.81 columns apart

# Ostromoukhov 2001, Appendix I: (next, down-behind, down) for input levels 0..127, each
# triple over its own sum; level 255 - i uses the triple of level i.
OSTROMOUKHOV = (
    (13, 0, 5), (13, 0, 5), (21, 0, 10), (7, 0, 4), (8, 0, 5), (47, 3, 28), (23, 3, 13),
    (15, 3, 8), (22, 6, 11), (43, 15, 20), (7, 3, 3), (501, 224, 211), (249, 116, 103),
    (165, 80, 67), (123, 62, 49), (489, 256, 191), (81, 44, 31), (483, 272, 181), (60, 35, 22),
    (53, 32, 19), (237, 148, 83), (471, 304, 161), (3, 2, 1), (481, 314, 185), (354, 226, 155),
    (1389, 866, 685), (227, 138, 125), (267, 158, 163), (327, 188, 220), (61, 34, 45),
    (627, 338, 505), (1227, 638, 1075), (20, 10, 19), (1937, 1000, 1767), (977, 520, 855),
    (657, 360, 551), (71, 40, 57), (2005, 1160, 1539), (337, 200, 247), (2039, 1240, 1425),
    (257, 160, 171), (691, 440, 437), (1045, 680, 627), (301, 200, 171), (177, 120, 95),
    (2141, 1480, 1083), (1079, 760, 513), (725, 520, 323), (137, 100, 57), (2209, 1640, 855),
    (53, 40, 19), (2243, 1720, 741), (565, 440, 171), (759, 600, 209), (1147, 920, 285),
    (2311, 1880, 513), (97, 80, 19), (335, 280, 57), (1181, 1000, 171), (793, 680, 95),
    (599, 520, 57), (2413, 2120, 171), (405, 360, 19), (2447, 2200, 57), (11, 10, 0),
    (158, 151, 3), (178, 179, 7), (1030, 1091, 63), (248, 277, 21), (318, 375, 35),
    (458, 571, 63), (878, 1159, 147), (5, 7, 1), (172, 181, 37), (97, 76, 22), (72, 41, 17),
    (119, 47, 29), (4, 1, 1), (4, 1, 1), (4, 1, 1), (4, 1, 1), (4, 1, 1), (4, 1, 1), (4, 1, 1),
    (4, 1, 1), (4, 1, 1), (65, 18, 17), (95, 29, 26), (185, 62, 53), (30, 11, 9), (35, 14, 11),
    (85, 37, 28), (55, 26, 19), (80, 41, 29), (155, 86, 59), (5, 3, 2), (5, 3, 2), (5, 3, 2),
    (5, 3, 2), (5, 3, 2), (5, 3, 2), (5, 3, 2), (5, 3, 2), (5, 3, 2), (5, 3, 2), (5, 3, 2),
    (5, 3, 2), (5, 3, 2), (305, 176, 119), (155, 86, 59), (105, 56, 39), (80, 41, 29),
    (65, 32, 23), (55, 26, 19), (335, 152, 113), (85, 37, 28), (115, 48, 37), (35, 14, 11),
    (355, 136, 109), (30, 11, 9), (365, 128, 107), (185, 62, 53), (25, 8, 7), (95, 29, 26),
    (385, 112, 103), (65, 18, 17), (395, 104, 101), (4, 1, 1),
)

# Zhou-Fang 2003, Table 1: key input levels and their (next, down-behind, down) weights
# (normalised; linear in between, mirrored above 127) ...
ZHOU_FANG_KEYS = (
    (0, (0.722222, 0.000000, 0.277778)), (1, (0.722562, 0.000000, 0.277438)),
    (2, (0.682418, 0.000915, 0.316668)), (3, (0.637626, 0.000000, 0.362374)),
    (4, (0.619999, 0.000000, 0.380001)), (10, (0.539424, 0.227902, 0.232674)),
    (22, (0.466135, 0.319173, 0.214692)), (32, (0.474825, 0.306173, 0.219002)),
    (44, (0.430322, 0.421390, 0.148288)), (64, (0.364114, 0.432194, 0.203692)),
    (72, (0.384778, 0.538441, 0.076782)), (77, (0.405038, 0.515480, 0.079482)),
    (85, (0.358654, 0.341083, 0.300263)), (95, (0.341173, 0.368994, 0.289833)),
    (102, (0.351327, 0.360597, 0.288076)), (107, (0.329547, 0.376208, 0.294246)),
    (112, (0.333603, 0.379544, 0.286853)), (127, (0.352694, 0.360664, 0.286643)),
)
# ... and the modulation strength at key levels (0..1 of the threshold's 0..127 range).
ZHOU_FANG_STRENGTH = ((0, 0.0), (44, 0.34), (64, 0.50), (80, 1.0), (85, 1.0), (95, 0.17),
                      (102, 0.50), (107, 0.70), (112, 0.79), (127, 1.0))


# The modulation strength per input level 0..127 (mirrored above), tuned for this printer's
# grid: at each level the least strength (of STRENGTH_STEPS) whose flat tint shows no
# periodic structure (structure_peak < STRUCTURE_LIMIT on two 256 x 256 windows), widened to the
# largest of the levels within +-3; ``tune_strength()`` recomputes it (a few seconds):
# ``python -m wideprint.rip.diffusion --tune``.  Zero where plain variable coefficients
# already give a clean pattern (most levels), up to 0.5 around 1/3 and 1/2 coverage.
TUNED_STRENGTH = (
    0, 0, 0, 0, 0, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.1, 0.1, 0.1, 0.1,
    0.1, 0.1, 0.1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.05, 0.05, 0.05,
    0.05, 0.05, 0.05, 0.05, 0, 0, 0, 0, 0, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.1, 0.1, 0.3,
    0.4, 0.4, 0.4, 0.4, 0.4, 0.4, 0.4, 0.4, 0.25, 0.25, 0.2, 0.2, 0.15, 0.15, 0.15, 0.5, 0.5,
    0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.4, 0.25, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.05, 0.15, 0.2, 0.25, 0.3, 0.4, 0.4, 0.4, 0.5,
    0.5, 0.5, 0.5, 0.5,
)
# ... and at least this much at every level but 0 and 255: with no modulation at all, two
# inks of equal amount (a neutral grey, C = M) would get identical patterns - every dot of
# one on a dot of the other; +-1.5 levels of threshold jitter from the inks' different noise
# offsets makes their patterns as unrelated as independent ones (measured: C = M 5 % overlapped
# 19.8x more than independent patterns would, with the floor 0.91-1.0x).
STRENGTH_FLOOR = 0.02
STRENGTH_STEPS = (0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0, 1.2, 1.5)
STRUCTURE_LIMIT = 15.0


def _mirror(half: np.ndarray) -> np.ndarray:
    """128 entries for levels 0..127 -> 256, level 255 - i = level i."""
    return np.concatenate([half, half[::-1]], axis=0)


def coefficient_table(name: str = "zhoufang", next_boost: float = 1.0) -> np.ndarray:
    """(256, 3) float64 normalised weights (next, down-behind, down) per input level; the
    next pixel's weight times ``next_boost`` before normalising (see ``NEXT_BOOST``)."""
    if name == "ostromoukhov":
        t = np.asarray(OSTROMOUKHOV, np.float64)
        half = t / t.sum(axis=1, keepdims=True)
    elif name == "zhoufang":
        lv = np.array([k for k, _ in ZHOU_FANG_KEYS], np.float64)
        w = np.array([c for _, c in ZHOU_FANG_KEYS], np.float64)
        w /= w.sum(axis=1, keepdims=True)
        x = np.arange(128, dtype=np.float64)
        half = np.stack([np.interp(x, lv, w[:, k]) for k in range(3)], axis=1)
        half /= half.sum(axis=1, keepdims=True)
    else:
        raise ValueError(f"unknown coefficient table {name!r}")
    half = half.copy()
    half[:, 0] *= next_boost
    half /= half.sum(axis=1, keepdims=True)
    return _mirror(half)


def strength_table(name: str = "tuned") -> np.ndarray:
    """(256,) float64 modulation strength per input level: "tuned" (``TUNED_STRENGTH``),
    "zhoufang" (their curve) or "ostromoukhov" (none)."""
    if name == "ostromoukhov":
        return np.zeros(256)
    if name == "tuned":
        t = _mirror(np.maximum(np.asarray(TUNED_STRENGTH, np.float64), STRENGTH_FLOOR))
        t[0] = t[255] = 0.0
        return t
    if name != "zhoufang":
        raise ValueError(f"unknown strength table {name!r}")
    lv, s = zip(*ZHOU_FANG_STRENGTH)
    return _mirror(np.interp(np.arange(128, dtype=np.float64), lv, s))


def weight_tables(coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-point (1/65536) weights of the next and the down-behind taps, int64 (256,) each;
    the down tap takes the rest, so the three always sum to the whole error."""
    one = 1 << WEIGHT_BITS
    wn = np.rint(coeffs[:, 0] * one).astype(np.int64)
    wdl = np.rint(coeffs[:, 1] * one).astype(np.int64)
    if (wn + wdl > one).any() or (wn < 0).any() or (wdl < 0).any():
        raise ValueError("weights out of range")
    return wn, wdl


def modulation_table(strength: np.ndarray, scale: float = MODULATION) -> np.ndarray:
    """int64 (256,): threshold rise, in error units, per unit of the 0..255 noise value:
    ``T = 128 UNIT + mod[level] * noise``, at most ``scale * strength * 127.5`` levels."""
    mod = np.rint(np.asarray(strength, np.float64) * scale * UNIT / 2.0).astype(np.int64)
    mod[0] = mod[255] = 0   # the extremes stay exact (see the module docstring)
    return mod


# --------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------
# Shared arguments: src/dst (rows, width, channels) uint8 (ink 0..255 in, 0/1 dots out);
# err (channels, 2, width + 4) int32, per channel a ring of two error rows (this row, the
# next), indexed by absolute row & 1, 2 spare columns at each side; row0 the absolute row
# of src[0]; wn, wdl (256,) int64 weights; mod (256,) int64; noise (n, n) uint8 with n a
# power of two; offs (channels, 2) int64 per-channel noise offsets (ox, oy).

_U = UNIT
_LIM = 127 * UNIT
_T0 = 128 * UNIT
_FULL = 255 * UNIT
_SH = WEIGHT_BITS
PAIR_LIMIT = 254 * UNIT     # error clamp of the colour-aware pairs
# Which ink of a pair gets a single dot is itself a binary halftone (at C = M: half the
# single dots each); left to the inks' errors it settles into checkerboard and line domains
# where the single dots are dense (C = M ~ 45-55 %: structure_peak 57).  The split's
# threshold is modulated by a noise of its own (the mask a quarter tile along from the
# first ink's), at SPLIT_BOOST x the first ink's own modulation: measured, C = M 50 %
# 57 -> 13 (1.0x: 18), light C = M grain and overlap unchanged, tints' coarse noise +2.6 %.
SPLIT_BOOST = 1.5


@kernel()
def _vc_plane(src, dst, c, err, row0, wn, wdl, mod, noise, ox, oy):  # pragma: no cover - compiled
    rows, width = src.shape[0], src.shape[1]
    nm = noise.shape[0] - 1
    for i in range(rows):
        r = row0 + i
        cur = err[r & 1]
        nxt = err[(r + 1) & 1]      # all zero here: cleared after its last use
        nrow = noise[(r + oy) & nm]
        carry = 0                   # the next-pixel share for this pixel
        pend = 0                    # pending total for the row-below cell under the previous pixel
        if (r & 1) == 0:
            for x in range(width):
                p = x + 2
                lvl = src[i, x, c]
                a = cur[p] + carry
                a = min(max(a, -_LIM), _LIM)
                v = np.int64(lvl) * _U + a
                t = _T0 + mod[lvl] * (np.int64(nrow[(x + ox) & nm]) - 128)
                dot = 1 if v >= t else 0
                dst[i, x, c] = dot
                v -= dot * _FULL
                en = (v * wn[lvl]) >> _SH
                edl = (v * wdl[lvl]) >> _SH
                carry = en
                nxt[p - 1] = pend + edl
                pend = v - en - edl
            nxt[width + 1] = pend
        else:
            for x in range(width - 1, -1, -1):
                p = x + 2
                lvl = src[i, x, c]
                a = cur[p] + carry
                a = min(max(a, -_LIM), _LIM)
                v = np.int64(lvl) * _U + a
                t = _T0 + mod[lvl] * (np.int64(nrow[(x + ox) & nm]) - 128)
                dot = 1 if v >= t else 0
                dst[i, x, c] = dot
                v -= dot * _FULL
                en = (v * wn[lvl]) >> _SH
                edl = (v * wdl[lvl]) >> _SH
                carry = en
                nxt[p + 1] = pend + edl
                pend = v - en - edl
            nxt[2] = pend
        cur[:] = 0


@kernel()
def vc_planes(src, dst, err, row0, c0, c1, wn, wdl, mod, noise, offs):  # pragma: no cover
    """Independent planes c0..c1-1."""
    for c in range(c0, c1):
        _vc_plane(src, dst, c, err[c], row0, wn, wdl, mod, noise, offs[c, 0], offs[c, 1])


@kernel(inline="always")
def _pair_decide(la, lb, va, vb, ta, tb, t, split):
    """The joint decision for one pixel of a pair: (dot a, dot b).  va, vb the values
    (ink + error), ta, tb their own (modulated) thresholds, la, lb the input inks, t the
    pair's threshold (modulated for the pair's combined level), ``split`` the modulation of
    which ink a single dot goes to (see ``SPLIT_BOOST``)."""
    da = va - ta            # how far each ink is above its own threshold
    db = vb - tb + split
    s = va + vb             # the pair's combined value
    if la + lb <= 255:      # at most one dot
        if s >= t:
            if da >= db:
                oa, ob = 1, 0
            else:
                oa, ob = 0, 1
        else:
            oa, ob = 0, 0
    else:                   # at least one dot
        if s - _FULL >= t:
            oa, ob = 1, 1
        elif da >= db:
            oa, ob = 1, 0
        else:
            oa, ob = 0, 1
    # the extremes are exact, whatever the other ink did
    if la == 0:
        oa = 0
    elif la == 255:
        oa = 1
    if lb == 0:
        ob = 0
    elif lb == 255:
        ob = 1
    return oa, ob


@kernel()
def _vc_pair(src, dst, ca, cb, erra, errb, row0, wn, wdl, mod, smod, noise, oxa, oya, oxb, oyb,
             lim):  # pragma: no cover
    rows, width = src.shape[0], src.shape[1]
    ch = np.uint64(src.shape[2])
    cau, cbu = np.uint64(ca), np.uint64(cb)
    nm = np.uint64(noise.shape[0] - 1)
    oxau, oxbu = np.uint64(oxa), np.uint64(oxb)
    oxsu = np.uint64(oxa + noise.shape[0] // 4)     # the split's noise: a quarter tile along
    for i in range(rows):
        r = row0 + i
        srow = src[i].reshape(-1)
        drow = dst[i].reshape(-1)
        cura = erra[r & 1]
        nxta = erra[(r + 1) & 1]
        curb = errb[r & 1]
        nxtb = errb[(r + 1) & 1]
        nra = noise[(r + oya) & (noise.shape[0] - 1)]
        nrb = noise[(r + oyb) & (noise.shape[0] - 1)]
        carrya = 0
        penda = 0
        carryb = 0
        pendb = 0
        fwd = (r & 1) == 0
        for k in range(width):
            x, p, q = _serpentine(k, width, fwd)
            o = x * ch
            la = srow[o + cau]
            lb = srow[o + cbu]
            aa = min(max(cura[p] + carrya, -lim), lim)
            ab = min(max(curb[p] + carryb, -lim), lim)
            va = np.int64(la) * _U + aa
            vb = np.int64(lb) * _U + ab
            ta = _T0 + mod[la] * (np.int64(nra[(x + oxau) & nm]) - 128)
            tb = _T0 + mod[lb] * (np.int64(nrb[(x + oxbu) & nm]) - 128)
            # The pair's combined process - the sum of the two values, one dot or none
            # (a + b <= 255), one or two (a + b > 255) - is itself a variable-coefficient
            # diffusion at level a + b (or a + b - 255): its threshold is modulated for
            # that level and both inks' errors go with that level's weights, so the two
            # inks' dots together form that level's pattern (measured: 35-50 % less grain
            # in light C = M tints than with each ink's own weights).
            lc = np.int64(la) + np.int64(lb)
            if lc > 255:
                lc -= 255
            t = _T0 + mod[lc] * (np.int64(nra[(x + oxbu) & nm]) - 128)
            split = smod[la] * (np.int64(nra[(x + oxsu) & nm]) - 128)
            oa, ob = _pair_decide(la, lb, va, vb, ta, tb, t, split)
            if 16 <= lc <= 239:
                ka = lc
                kb = lc
            else:   # the pair's pattern is (almost) empty or full: what shows is which
                ka = np.int64(la)   # ink each dot is, so each ink keeps its own weights
                kb = np.int64(lb)
            drow[o + cau] = oa
            drow[o + cbu] = ob
            va -= oa * _FULL
            vb -= ob * _FULL
            ena = (va * wn[ka]) >> _SH
            edla = (va * wdl[ka]) >> _SH
            enb = (vb * wn[kb]) >> _SH
            edlb = (vb * wdl[kb]) >> _SH
            carrya = ena
            carryb = enb
            nxta[q] = penda + edla
            nxtb[q] = pendb + edlb
            penda = va - ena - edla
            pendb = vb - enb - edlb
        _end_row(cura, nxta, penda, width, fwd)
        _end_row(curb, nxtb, pendb, width, fwd)


@kernel(inline="always")
def _step(lvl, a, nz, tab):
    """One pixel of one ink: (dot, next-pixel share, down-behind share, down share)."""
    v = np.int64(lvl) * _U + min(max(a, -_LIM), _LIM)
    t = _T0 + tab[lvl, 2] * (np.int64(nz) - 128)
    dot = 1 if v >= t else 0
    v -= dot * _FULL
    en = (v * tab[lvl, 0]) >> _SH
    edl = (v * tab[lvl, 1]) >> _SH
    return dot, en, edl, v - en - edl


@kernel()
def _vc_two(src, dst, ca, cb, erra, errb, row0, tab, noise, oxa, oya, oxb, oyb):  # pragma: no cover
    """Two inks diffused independently in one loop (their dependency chains overlap); the
    same arithmetic as ``_vc_plane``, scanned through ``_serpentine``.  src/dst must be
    C-contiguous; the indices are unsigned (numba checks signed ones for wrap-around)."""
    rows, width = src.shape[0], src.shape[1]
    ch = np.uint64(src.shape[2])
    cau, cbu = np.uint64(ca), np.uint64(cb)
    nm = np.uint64(noise.shape[0] - 1)
    oxau, oxbu = np.uint64(oxa), np.uint64(oxb)
    for i in range(rows):
        r = row0 + i
        srow = src[i].reshape(-1)
        drow = dst[i].reshape(-1)
        cura = erra[r & 1]
        nxta = erra[(r + 1) & 1]
        curb = errb[r & 1]
        nxtb = errb[(r + 1) & 1]
        nra = noise[(r + oya) & (noise.shape[0] - 1)]
        nrb = noise[(r + oyb) & (noise.shape[0] - 1)]
        ca_ = 0
        pa = 0
        cb_ = 0
        pb = 0
        fwd = (r & 1) == 0
        for k in range(width):
            x, p, q = _serpentine(k, width, fwd)
            o = x * ch
            da, ena, edla, eda = _step(srow[o + cau], cura[p] + ca_, nra[(x + oxau) & nm], tab)
            db, enb, edlb, edb = _step(srow[o + cbu], curb[p] + cb_, nrb[(x + oxbu) & nm], tab)
            drow[o + cau] = da
            drow[o + cbu] = db
            ca_ = ena
            cb_ = enb
            nxta[q] = pa + edla
            nxtb[q] = pb + edlb
            pa = eda
            pb = edb
        _end_row(cura, nxta, pa, width, fwd)
        _end_row(curb, nxtb, pb, width, fwd)


@kernel()
def vc_four(src, dst, err, row0, tab, noise, offs):  # pragma: no cover - compiled
    """Four inks (channels 0..3 of 4) diffused independently in one loop: ``_vc_two``'s
    arithmetic, bit for bit, with four dependency chains for the CPU to overlap instead of
    two (2.74 -> 2.34 ns an ink-pixel on one core): the least CPU for a band, where
    ``vc_twos`` on two threads is the shortest wall time."""
    rows, width = src.shape[0], src.shape[1]
    nm = np.uint64(noise.shape[0] - 1)
    m = noise.shape[0] - 1
    u1, u2, u3, u4 = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4)
    x0, x1, x2, x3 = np.uint64(offs[0, 0]), np.uint64(offs[1, 0]), np.uint64(offs[2, 0]), np.uint64(offs[3, 0])
    for i in range(rows):
        r = row0 + i
        srow = src[i].reshape(-1)
        drow = dst[i].reshape(-1)
        c0, n0, c1, n1, c2, n2, c3, n3 = _rows4(err, r)
        z0 = noise[(r + offs[0, 1]) & m]
        z1 = noise[(r + offs[1, 1]) & m]
        z2 = noise[(r + offs[2, 1]) & m]
        z3 = noise[(r + offs[3, 1]) & m]
        k0 = k1 = k2 = k3 = 0       # the next pixel's shares
        p0 = p1 = p2 = p3 = 0       # the row below: the cell under this pixel, so far
        fwd = (r & 1) == 0
        for k in range(width):
            x, p, q = _serpentine(k, width, fwd)
            o = x * u4
            d0, e0, l0, w0 = _step(srow[o], c0[p] + k0, z0[(x + x0) & nm], tab)
            d1, e1, l1, w1 = _step(srow[o + u1], c1[p] + k1, z1[(x + x1) & nm], tab)
            d2, e2, l2, w2 = _step(srow[o + u2], c2[p] + k2, z2[(x + x2) & nm], tab)
            d3, e3, l3, w3 = _step(srow[o + u3], c3[p] + k3, z3[(x + x3) & nm], tab)
            drow[o] = d0
            drow[o + u1] = d1
            drow[o + u2] = d2
            drow[o + u3] = d3
            k0, k1, k2, k3 = e0, e1, e2, e3
            n0[q] = p0 + l0
            n1[q] = p1 + l1
            n2[q] = p2 + l2
            n3[q] = p3 + l3
            p0, p1, p2, p3 = w0, w1, w2, w3
        _end_row(c0, n0, p0, width, fwd)
        _end_row(c1, n1, p1, width, fwd)
        _end_row(c2, n2, p2, width, fwd)
        _end_row(c3, n3, p3, width, fwd)


@kernel()
def vc_twos(src, dst, err, row0, pairs, p0, p1, tab, noise, offs):  # pragma: no cover
    """Pairs p0..p1-1 of ``pairs``, each two independent inks in one loop."""
    for k in range(p0, p1):
        ca = pairs[k, 0]
        cb = pairs[k, 1]
        _vc_two(src, dst, ca, cb, err[ca], err[cb], row0, tab, noise,
                offs[ca, 0], offs[ca, 1], offs[cb, 0], offs[cb, 1])


@kernel()
def vc_pairs(src, dst, err, row0, pairs, p0, p1, wn, wdl, mod, smod, noise, offs, lim):  # pragma: no cover
    """Pairs p0..p1-1 of ``pairs`` ((k, 2) int64 channel indices), each decided jointly (the
    colour-aware decision; independent inks go through ``vc_twos``)."""
    for k in range(p0, p1):
        ca = pairs[k, 0]
        cb = pairs[k, 1]
        _vc_pair(src, dst, ca, cb, err[ca], err[cb], row0, wn, wdl, mod, smod, noise,
                 offs[ca, 0], offs[ca, 1], offs[cb, 0], offs[cb, 1], lim)


# --------------------------------------------------------------------------
# the diffuser
# --------------------------------------------------------------------------

def noise_offsets(n: int, channels: int) -> np.ndarray:
    """(channels, 2) int64 per-channel offsets (ox, oy) into the n x n noise tile: the
    channels read far-apart parts of the tile (half a tile apart in one axis or both)."""
    base = ((0, 0), (n // 2, n // 2), (n // 2, 0), (0, n // 2))
    k = np.arange(channels)
    extra = (k // 4) * 37        # more than 4 channels: shift further, still deterministic
    off = np.array([base[i % 4] for i in k], np.int64).reshape(-1, 2)
    return (off + extra[:, None]) % n


class VCDiffuser:
    """Band-by-band variable-coefficient error diffusion of (rows, width, channels) uint8 ink.

    ``table``: "zhoufang" or "ostromoukhov" (the weights), the next pixel's weight times
    ``next_boost``; ``strength``: the threshold modulation per level, "tuned" (vced's),
    "zhoufang", "ostromoukhov" (= none) or a (256,) array, times ``scale``; ``noise``: (n, n)
    uint8 tile (n a power of two) read at the absolute
    position; ``joint``: the colour-aware decision for channels 0 and 1 (C with M); the
    others are diffused each on its own (four channels of CMYK in one loop, else two per
    loop all the same: their dependency chains overlap).  State (error rows, the
    absolute row) carries across ``process`` calls."""

    def __init__(self, width: int, channels: int, noise: np.ndarray, *, table: str = "zhoufang",
                 strength="tuned", scale: float = MODULATION, joint: bool = False,
                 next_boost: float = NEXT_BOOST, lim: int | None = None):
        n = noise.shape[0]
        if noise.ndim != 2 or noise.shape[1] != n or n & (n - 1) or noise.dtype != np.uint8:
            raise ValueError("noise must be a square uint8 tile whose side is a power of two")
        self.width, self.channels = int(width), int(channels)
        self.noise = np.ascontiguousarray(noise)
        self.offsets = noise_offsets(n, self.channels)
        self.wn, self.wdl = weight_tables(coefficient_table(table, next_boost))
        st = strength_table(strength) if isinstance(strength, str) else np.asarray(strength, np.float64)
        self.mod = modulation_table(st, scale)
        # the colour-aware pair's split modulation (SPLIT_BOOST x the ink's own)
        self.smod = np.rint(self.mod * SPLIT_BOOST).astype(np.int64)
        # per level: next weight, down-behind weight, modulation (and padding): one cache line
        self.tab = np.ascontiguousarray(np.stack([self.wn, self.wdl, self.mod, self.mod * 0], axis=1))
        self.err = np.zeros((self.channels, 2, self.width + 4), np.int32)
        self.row = 0
        self.joint = bool(joint)
        # the pairs' decision enforces the extremes itself, so their error may run further
        self.lim = int(lim if lim is not None else (PAIR_LIMIT if joint else _LIM))
        pairs = tuple((a, a + 1) for a in range(0, self.channels - 1, 2))
        self.pairs = np.array(pairs, np.int64).reshape(-1, 2)
        self.singles = (self.channels - 1,) if self.channels % 2 else ()

    def jobs(self, band: np.ndarray, out: np.ndarray, groups: int):
        """Callables that together diffuse ``band`` into ``out`` (at most ``groups`` of them,
        independent of each other: the pairs, and a last single channel, split in order; for
        four independent inks one callable, ``vc_four``)."""
        row0 = self.row
        if self.channels == 4 and not self.joint:
            # CMYK, each ink on its own: one loop of four inks on one thread, whatever
            # `groups`.  15 % less CPU than two pairs on two threads, and no longer: the
            # RIP's other stages (separation, packing, the planes coder; in a print the
            # emulator) run beside it in any case.  `rip -o vced`, 12,000 x 4,000, wall
            # 0.84-0.90 -> 0.83-0.88 s from RGB, 0.78-0.81 -> 0.75-0.77 s from CMYK; a
            # full-width print 1.62-1.71 -> 1.54-1.72 s, CPU 2.3-2.5 -> 2.2-2.4 s.
            return [lambda: vc_four(band, out, self.err, row0, self.tab, self.noise, self.offsets)]
        units = [("pair", k) for k in range(len(self.pairs))] + [("single", c) for c in self.singles]
        groups = max(1, min(groups, len(units)))
        bounds = np.linspace(0, len(units), groups + 1).astype(int)
        args = (self.wn, self.wdl, self.mod, self.noise, self.offsets)
        out_jobs = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            chunk = units[a:b]

            def job(chunk=chunk):
                for kind, k in chunk:
                    if kind == "pair" and self.joint and k == 0:       # C with M only
                        vc_pairs(band, out, self.err, row0, self.pairs, k, k + 1, self.wn,
                                 self.wdl, self.mod, self.smod, self.noise, self.offsets, self.lim)
                    elif kind == "pair":
                        vc_twos(band, out, self.err, row0, self.pairs, k, k + 1, self.tab,
                                self.noise, self.offsets)
                    else:
                        vc_planes(band, out, self.err, row0, k, k + 1, *args)
            out_jobs.append(job)
        return out_jobs

    def process(self, band: np.ndarray) -> np.ndarray:
        """One band, in the calling thread."""
        out = np.empty(band.shape, np.uint8)
        for job in self.jobs(np.ascontiguousarray(band), out, 1):
            job()
        self.row += band.shape[0]
        return out


# --------------------------------------------------------------------------
# tuning the modulation: the least strength that leaves no periodic structure
# --------------------------------------------------------------------------

def structure_peak(pattern: np.ndarray) -> float:
    """How periodic a flat-tint pattern is: the largest 3 x 3-averaged bin of its power
    spectrum (mean removed) over the mean bin.  Blue or white noise gives 5-12; the
    regular domains, lines and checkerboards that plain error diffusion settles into at
    some tints give 30 to over 1000 (Floyd-Steinberg at 50 %: ~1500)."""
    a = np.asarray(pattern, np.float64)
    a = a - a.mean()
    p = np.abs(np.fft.rfft2(a)) ** 2
    p[0, 0] = 0.0
    q = np.pad(p, 1, mode="wrap")
    sm = sum(q[dy:dy + p.shape[0], dx:dx + p.shape[1]] for dy in range(3) for dx in range(3)) / 9
    pos = p[p > 0]
    return float(sm.max() / pos.mean()) if pos.size else 0.0


def tune_strength(noise: np.ndarray, next_boost: float = NEXT_BOOST, size: int = 256,
                  limit: float = STRUCTURE_LIMIT, steps=STRENGTH_STEPS, widen: int = 3) -> np.ndarray:
    """(128,) strengths for levels 0..127: per level the least of ``steps`` whose flat tint
    has ``structure_peak < limit`` in two size x size windows, one just after 64 rows and
    columns of start-up and one ``size / 2`` further on, then the largest within
    +-``widen`` levels."""
    smin = np.zeros(128)
    h = size * 3 // 2 + 64
    for v in range(1, 128):
        for st in steps:
            d = VCDiffuser(h, 1, noise, strength=np.full(256, float(st)), scale=1.0,
                           next_boost=next_boost)
            out = d.process(np.full((h, h, 1), v, np.uint8))[:, :, 0]
            a, b = out[64:64 + size, 64:64 + size], out[h - size:, h - size:]
            if max(structure_peak(a), structure_peak(b)) < limit:
                break
        smin[v] = st
    out = np.array([smin[max(0, v - widen):v + widen + 1].max() for v in range(128)])
    out[0] = 0.0
    return out


if __name__ == "__main__":  # pragma: no cover - an offline tool
    import sys
    if sys.argv[1:] != ["--tune"]:
        sys.exit("usage: python -m wideprint.rip.diffusion --tune")
    from .masks import modulation_noise
    table = tune_strength(modulation_noise())
    print("TUNED_STRENGTH = (" + ", ".join(f"{x:g}" for x in table) + ")")
    print("as shipped:", bool(np.array_equal(table, np.asarray(TUNED_STRENGTH))))
