"""Colour separation: image bands -> CMYK ink amounts (uint8, 0 = no ink, 255 = full ink).

Design (see docs/color.md):

* RGB -> CMYK goes through ICC with LittleCMS (pyvips ``icc_transform``), but not per pixel: at
  construction a 33 x 33 x 33 grid of RGB values (16-bit exact node positions) is sent once through
  lcms and each pixel is then found by tetrahedral interpolation in a numba kernel.  lcms itself
  uses a 33-point grid for 8-bit RGB input, so the result matches a direct lcms transform to within
  one level, at several times the speed.
* CMYK input with an output profile (CMYK -> CMYK) goes through lcms per band (libvips, threaded).
* CMYK input without an output profile passes through bit-exact (16-bit is rounded to 8-bit).
* Grey input defaults to K only (ink = 255 - grey); ``grey_mode="icc"`` sends it through ICC
  (a 1-D table, so no interpolation error).
* Ink limit (total area coverage) then curves are applied in the same pass.
"""

from __future__ import annotations

import contextlib
import logging
import os
import struct
from typing import Any

import numpy as np

from .parallel import run_parallel, split
from .compiled import kernel

__all__ = ["Separator", "INTENTS", "ink_limit_level"]

log = logging.getLogger(__name__)

from .settings import INTENTS  # noqa: E402 - declared with the settings schema
LUT3_SIZE = 33  # grid for 3-channel input (same as lcms for 8-bit RGB)


# The shipped default media's ICC output profile (docs/media.md, made by `wideprint media
# create` on the default emulated printer): separations of RGB and grey use it when a job
# names neither a media nor an output profile.  CMYK files still print as they are.
DEFAULT_OUTPUT_ICC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                  "resources", "media", "vinyl-300", "profile.icc")


def default_output_icc(colorspace: str) -> str | None:
    """The output profile of a job that names none: the default media's for RGB and grey
    (None for CMYK, or if the file is not installed: then libvips' built-in `cmyk`)."""
    return DEFAULT_OUTPUT_ICC if colorspace != "cmyk" and os.path.isfile(DEFAULT_OUTPUT_ICC) else None


def ink_limit_level(ink_limit: float) -> int:
    """Total area coverage limit in percent -> the largest allowed C+M+Y+K sum in 0..255 units."""
    return int(np.floor(ink_limit * 255.0 / 100.0 + 1e-9))


# --------------------------------------------------------------------------------------
# numba kernels


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


# --------------------------------------------------------------------------------------
# ICC helpers

_SPACE_NAMES = {b"RGB ": "RGB", b"CMYK": "CMYK", b"GRAY": "grey", b"Lab ": "LAB", b"XYZ ": "XYZ"}


def _icc_header_problem(data: bytes) -> str | None:
    if len(data) < 132:
        return f"not an ICC profile (only {len(data)} bytes)"
    if data[36:40] != b"acsp":
        return "not an ICC profile (no 'acsp' signature)"
    (declared,) = struct.unpack(">I", data[:4])
    if declared > len(data):
        return f"truncated ICC profile (header says {declared} bytes, there are {len(data)})"
    if declared < 132:
        return f"corrupt ICC profile (header says {declared} bytes)"
    return None


def _icc_space(data: bytes) -> bytes:
    return bytes(data[16:20])


def _vips():
    import pyvips

    return pyvips


def _vips_detail(e: Exception) -> str:
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip() and not ln.strip().startswith("unable to call")]
    return "; ".join(dict.fromkeys(lines)) or str(e)


class _Profile:
    """An input or output profile: a libvips built-in name, a file, or embedded bytes."""

    def __init__(self, name: str | None = None, path: str | None = None, data: bytes | None = None,
                 space: bytes = b"RGB ", digest: bytes | None = None):
        self.name, self.path, self.data, self.space = name, path, data, space
        self.digest = digest        # of a file's bytes, as read when it was checked

    def identity(self) -> bytes:
        """What the profile's transform depends on: its bytes' digest, or for a built-in
        one its name (the libvips that holds it is in the cache key too)."""
        import hashlib
        if self.data is not None:
            return hashlib.sha256(self.data).digest()
        if self.path is not None:
            if self.digest is None:
                with open(self.path, "rb") as f:
                    self.digest = hashlib.sha256(f.read()).digest()
            return self.digest
        return f"built-in {self.name}".encode()

    def describe(self) -> str:
        if self.path:
            return self.path
        if self.data is not None:
            return "embedded profile"
        return f"built-in {self.name}"


_INTERP = {1: ("b-w", "grey16"), 3: ("srgb", "rgb16"), 4: ("cmyk", "cmyk")}


def _icc_transform(arr: np.ndarray, bands: int, inp: _Profile, out: _Profile, intent: str, bpc: bool,
                   depth: int, out_depth: int) -> np.ndarray:
    """(h, w, bands) uint8/uint16 -> (h, w, 4|...) through lcms (pyvips)."""
    pv = _vips()
    img = pv.Image.new_from_array(np.ascontiguousarray(arr))
    img = img.copy(interpretation=_INTERP[bands][1 if depth == 16 else 0])
    kw: dict[str, Any] = dict(intent=intent, depth=out_depth, black_point_compensation=bpc)
    if inp.data is not None:
        img.set_type(pv.GValue.blob_type, "icc-profile-data", inp.data)
        kw["embedded"] = True
        if bands in (3, 4):
            kw["input_profile"] = "srgb" if bands == 3 else "cmyk"
    else:
        kw.update(embedded=False, input_profile=inp.path or inp.name)
    res = img.icc_transform(out.path or out.name, **kw)
    return res.numpy()


# --------------------------------------------------------------------------------------
# The LUT cache (docs/color.md "The LUT cache"): lcms makes a transform's 33^3 grid in
# ~15 ms, a tenth of a small job's start-up; the grid, once made, is read back in ~0.2 ms.

LUT_CACHE_VERSION = 1    # raised whenever the LUT's values would come out differently
LUT_CACHE_FILES = 64     # transforms kept (18 MB); the least recently used go first


def cache_dir() -> str | None:
    """$WIDEPRINT_CACHE_DIR, else $XDG_CACHE_HOME/wideprint, else ~/.cache/wideprint; an
    empty $WIDEPRINT_CACHE_DIR turns the cache off."""
    env = os.environ.get("WIDEPRINT_CACHE_DIR")
    if env is not None:
        return env or None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "wideprint")


def _read_lut(path: str | None, size: int) -> np.ndarray | None:
    """The cached LUT, or None if there is none usable (missing, damaged, another shape:
    it is then made again and the file replaced)."""
    if path is None:
        return None
    try:
        lut = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None
    if lut.dtype != np.uint64 or lut.shape != (size,):
        return None
    with contextlib.suppress(OSError):
        os.utime(path)                  # recently used: kept when the cache is trimmed
    return np.ascontiguousarray(lut)


def _write_lut(path: str | None, lut: np.ndarray) -> None:
    """Kept for the next process: written whole under a temporary name, then renamed
    (rip/planes.py `output_file`, as every output file), so a reader never sees half a
    file; a cache that cannot be written is no error."""
    if path is None:
        return
    from .planes import output_file
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with output_file(path) as tmp, open(tmp, "wb") as f:
            np.save(f, lut, allow_pickle=False)
        _trim(os.path.dirname(path))
    except OSError as exc:
        log.debug("LUT cache not written (%s): %s", path, exc)


def _trim(folder: str) -> None:
    """At most LUT_CACHE_FILES transforms: each job with a profile of its own (a file's
    embedded one) adds one, so the oldest used go."""
    entries = []
    for e in os.scandir(folder):
        if e.name.endswith(".npy"):
            with contextlib.suppress(OSError):
                entries.append((e.stat().st_mtime, e.path))
    for _, stale in sorted(entries)[:max(0, len(entries) - LUT_CACHE_FILES)]:
        with contextlib.suppress(OSError):
            os.unlink(stale)


class Separator:
    """Converts bands from :meth:`ImageSource.bands` to C, M, Y, K ink (uint8 (h, w, 4), C-contiguous).

    colorspace: 'grey' | 'rgb' | 'cmyk'; depth: 8 | 16 (the band dtype).
    embedded_icc: the file's profile (used unless ``input_icc`` is given); input_icc / output_icc: ICC
    files; default profiles are libvips' built-in sRGB (input) and CMYK (output).
    intent: perceptual | relative | saturation | absolute.  ink_limit: total area coverage in percent.
    curves: (4, 256) per-channel linearisation, applied last: uint8 levels, or float levels
    with fractions (rounded by pixel position, an ordered pattern of 16; docs/color.md).
    grey_mode: 'k' (default, ink = 255 - grey on the K channel only) or 'icc'.
    black_point_compensation: passed to lcms (off by default).
    """

    def __init__(self, colorspace: str, depth: int = 8, *, embedded_icc: bytes | None = None,
                 input_icc: str | None = None, output_icc: str | None = None, intent: str = "relative",
                 ink_limit: float | None = None, curves: np.ndarray | None = None, grey_mode: str = "k",
                 black_point_compensation: bool = False):
        if colorspace not in ("grey", "rgb", "cmyk"):
            raise ValueError(f"colorspace must be 'grey', 'rgb' or 'cmyk', not {colorspace!r}")
        if depth not in (8, 16):
            raise ValueError(f"depth must be 8 or 16, not {depth!r}")
        if intent not in INTENTS:
            raise ValueError(f"intent must be one of {', '.join(INTENTS)}, not {intent!r}")
        if grey_mode not in ("k", "icc"):
            raise ValueError(f"grey_mode must be 'k' or 'icc', not {grey_mode!r}")
        self.colorspace = colorspace
        self.depth = depth
        self.intent = intent
        self.grey_mode = grey_mode
        self.bpc = bool(black_point_compensation)
        self.warnings: list[str] = []
        self.channels = {"grey": 1, "rgb": 3, "cmyk": 4}[colorspace]

        if ink_limit is not None:
            ink_limit = float(ink_limit)
            if not (0.0 < ink_limit <= 400.0):
                raise ValueError(f"ink_limit must be in (0, 400] percent, not {ink_limit}")
            self._limit = ink_limit_level(ink_limit)
        else:
            self._limit = -1
        self.ink_limit = ink_limit
        if curves is not None:
            c = np.asarray(curves)
            if c.shape != (4, 256):
                raise ValueError(f"curves must have shape (4, 256), not {c.shape}")
            if np.issubdtype(c.dtype, np.floating):   # levels with fractions (profile_curves)
                if not np.isfinite(c).all() or c.min() < 0 or c.max() > 255:
                    raise ValueError("curves must be levels 0..255")
                c = np.rint(c * CURVE_ONE).astype(np.uint16)
            elif not np.issubdtype(c.dtype, np.integer) or c.min() < 0 or c.max() > 255:
                raise ValueError("curves must be uint8 (integers 0..255) or levels 0..255")
            else:
                c = c.astype(np.uint16) * CURVE_ONE
            self._curves = np.ascontiguousarray(c)
            self._use_curves = True
        else:
            self._curves = np.zeros((4, 256), np.uint16)
            self._use_curves = False
        self.curves = self._curves if self._use_curves else None

        maxv = 65535 if depth == 16 else 255
        self._maxv = maxv
        # --- profiles ---------------------------------------------------------------
        self.output_profile: _Profile | None = None
        if output_icc is not None:
            self.output_profile = self._load_icc_file(output_icc, "output", (b"CMYK",))
        need_icc = colorspace == "rgb" or (colorspace == "grey" and grey_mode == "icc") or \
            (colorspace == "cmyk" and output_icc is not None)
        self.input_profile: _Profile | None = None
        if need_icc:
            spaces = {"rgb": (b"RGB ",), "grey": (b"GRAY", b"RGB "), "cmyk": (b"CMYK",)}[colorspace]
            if input_icc is not None:
                self.input_profile = self._load_icc_file(input_icc, "input", spaces)
            elif embedded_icc is not None:
                self.input_profile = self._embedded(embedded_icc, spaces)
            if self.input_profile is None:
                self.input_profile = _Profile(name="srgb") if colorspace != "cmyk" else \
                    _Profile(name="cmyk", space=b"CMYK")
            if self.output_profile is None:
                self.output_profile = _Profile(name="cmyk", space=b"CMYK")
        elif input_icc is not None:
            # CMYK passthrough or grey K-only: the input profile is not used, but a bad file is still an error
            self._load_icc_file(input_icc, "input", (b"RGB ", b"CMYK", b"GRAY"))

        # --- tables -----------------------------------------------------------------------
        self.mode = ""
        if colorspace == "rgb":
            self._build_lut3()
        elif colorspace == "cmyk":
            if self.output_profile is not None and output_icc is not None:
                # CMYK -> CMYK: lcms per band.  A 17^4 LUT was tried: it was slower than libvips'
                # threaded transform and up to 10 levels off (see docs/color.md).
                self.mode = "direct4"
            else:
                self.mode = "passthrough"
                if depth == 8:
                    self._scale = np.arange(256, dtype=np.uint8)
                else:
                    v = np.arange(65536, dtype=np.uint32)
                    self._scale = ((v * 255 + 32767) // 65535).astype(np.uint8)
        else:
            self._build_grey()

    # ------------------------------------------------------------------------------------
    def _load_icc_file(self, path, role: str, spaces: tuple[bytes, ...]) -> _Profile:
        path = os.fspath(path)
        try:
            with open(path, "rb") as f:
                data = f.read()
        except OSError as e:
            raise ValueError(f"{path}: cannot read {role} ICC profile: {e.strerror or e}") from None
        problem = _icc_header_problem(data)
        if problem:
            raise ValueError(f"{path}: {problem}")
        space = _icc_space(data)
        if space not in spaces:
            want = " or ".join(_SPACE_NAMES.get(s, s.decode("latin-1").strip()) for s in spaces)
            got = _SPACE_NAMES.get(space, space.decode("latin-1", "replace").strip())
            raise ValueError(f"{path}: {role} ICC profile is for {got}, need {want}")
        if data[12:16] == b"link":
            raise ValueError(f"{path}: device-link ICC profiles are not supported")
        import hashlib
        prof = _Profile(path=path, space=space, digest=hashlib.sha256(data).digest())
        self._trial(prof, role, space)
        return prof

    def _trial(self, prof: _Profile, role: str, space: bytes) -> None:
        """Run a few pixels through lcms so that a broken profile fails now, with its file name.
        libvips only *warns* about an input profile lcms cannot parse (and falls back to a default), so
        its warnings are captured too."""
        pv = _vips()
        bands = {b"RGB ": 3, b"CMYK": 4, b"GRAY": 1}.get(space, 3)
        captured: list[str] = []

        class _Grab(logging.Handler):
            def emit(self, record):
                captured.append(record.getMessage())

        grab = _Grab(logging.WARNING)
        vlog = logging.getLogger("pyvips")
        old_level, old_disabled = vlog.level, vlog.disabled
        vlog.addHandler(grab)
        vlog.setLevel(logging.WARNING)  # even if the application silenced libvips' warnings
        vlog.disabled = False
        try:
            self._trial_transform(prof, role, bands)
        except pv.Error as e:
            raise ValueError(f"{prof.describe()}: unusable {role} ICC profile: {_vips_detail(e)}") from None
        finally:
            vlog.removeHandler(grab)
            vlog.setLevel(old_level)
            vlog.disabled = old_disabled
        bad = [m for m in captured if "profile" in m.lower()]
        if bad:
            detail = bad[0].replace("VIPS:", "").strip()
            raise ValueError(f"{prof.describe()}: unusable {role} ICC profile: {detail}")

    def _trial_transform(self, prof: _Profile, role: str, bands: int) -> None:
        if role == "output":
            _icc_transform(np.zeros((1, 2, 3), np.uint8), 3, _Profile(name="srgb"), prof, self.intent, self.bpc, 8, 8)
        else:
            _icc_transform(np.zeros((1, 2, bands), np.uint8), bands, prof, _Profile(name="cmyk", space=b"CMYK"),
                           self.intent, self.bpc, 8, 8)

    def _embedded(self, data: bytes, spaces: tuple[bytes, ...]) -> _Profile | None:
        data = bytes(data)
        problem = _icc_header_problem(data)
        if problem is None and _icc_space(data) not in spaces:
            problem = f"it is for {_SPACE_NAMES.get(_icc_space(data), 'another colour space')}"
        if problem is None:
            prof = _Profile(data=data, space=_icc_space(data))
            try:
                self._trial(prof, "input", _icc_space(data))
                return prof
            except ValueError as e:
                problem = str(e)
        msg = f"embedded ICC profile ignored ({problem}); using the default input profile"
        self.warnings.append(msg)
        log.warning(msg)
        return None

    def _positions(self, n_grid: int) -> tuple[np.ndarray, np.ndarray]:
        """Per input value: the grid cell below it and its position in the cell, in 1/64."""
        v = np.arange(self._maxv + 1, dtype=np.float64)
        pos = v * (n_grid - 1) / self._maxv
        base = np.minimum(np.floor(pos), n_grid - 2).astype(np.int64)
        fracw = np.rint((pos - base) * (1 << WEIGHT_BITS)).astype(np.int64)
        return base, fracw

    @staticmethod
    def _nodes(n_grid: int) -> np.ndarray:
        return np.round(np.arange(n_grid) * 65535.0 / (n_grid - 1)).astype(np.uint16)

    def _lut_eval(self, grid: np.ndarray, bands: int) -> np.ndarray:
        """grid (h, w, bands) uint16 -> float32 ink 0..255 (h, w, 4) through lcms, 16-bit output."""
        pv = _vips()
        try:
            res = _icc_transform(grid, bands, self.input_profile, self.output_profile, self.intent, self.bpc, 16, 16)
        except pv.Error as e:
            raise ValueError(f"cannot build the colour transform {self.input_profile.describe()} -> "
                             f"{self.output_profile.describe()}: {_vips_detail(e)}") from None
        if res.ndim != 3 or res.shape[2] != 4:
            raise ValueError(f"{self.output_profile.describe()}: the output profile does not produce CMYK")
        return res.astype(np.float32) * np.float32(255.0 / 65535.0)

    def _build_lut3(self) -> None:
        n = LUT3_SIZE
        cached = self._lut_file()
        self._lut = _read_lut(cached, n ** 3)
        if self._lut is None:
            g = self._nodes(n)
            r, gg, b = np.meshgrid(g, g, g, indexing="ij")
            grid = np.stack([r, gg, b], -1).reshape(n * n, n, 3)
            ink = np.rint(self._lut_eval(grid, 3).reshape(-1, 4) * LANE_SCALE).astype(np.uint64)
            self._lut = np.ascontiguousarray(ink[:, 0] | ink[:, 1] << np.uint64(16)
                                             | ink[:, 2] << np.uint64(32) | ink[:, 3] << np.uint64(48))
            _write_lut(cached, self._lut)
        base, frac = self._positions(n)
        self._axes = np.concatenate([(base * stride) << 8 | frac for stride in (n * n, n, 1)]).astype(np.uint32)
        d1, d2 = _tetra_offsets(n)
        self._d12 = d1 | d2 << np.uint64(32)
        self._s3 = np.uint64(n * n + n + 1)       # the cell's far corner
        self.mode = "lut3"

    def _lut_file(self) -> str | None:
        """Where the 3-D LUT of this transform is kept between processes: named by what
        it is made from (docs/color.md "The LUT cache"); None when there is no cache."""
        import hashlib
        folder = cache_dir()
        if folder is None:
            return None
        h = hashlib.sha256()
        try:
            for prof in (self.input_profile, self.output_profile):
                h.update(prof.identity())
        except OSError:                 # a profile file gone since it was checked: no cache
            return None
        pv = _vips()          # its LittleCMS makes the values
        h.update(f"|{self.intent}|{self.bpc}|{LUT3_SIZE}|{LANE_SCALE}|{LUT_CACHE_VERSION}|libvips "
                 f"{pv.version(0)}.{pv.version(1)}.{pv.version(2)}".encode())
        return os.path.join(folder, "lut3", h.hexdigest()[:40] + ".npy")

    def _build_grey(self) -> None:
        maxv = self._maxv
        v = np.arange(maxv + 1, dtype=np.uint32)
        if self.grey_mode == "k":
            table = np.zeros((maxv + 1, 4), np.uint8)
            table[:, 3] = 255 - ((v * 255 + maxv // 2) // maxv).astype(np.uint8)
            self.mode = "grey-k"
        else:
            dtype = np.uint16 if self.depth == 16 else np.uint8
            ramp = v.astype(dtype)
            if self.input_profile.space == b"GRAY":
                arr, bands = ramp.reshape(1, -1, 1), 1
            else:
                arr, bands = np.repeat(ramp.reshape(1, -1, 1), 3, axis=2), 3
            pv = _vips()
            try:
                res = _icc_transform(arr, bands, self.input_profile, self.output_profile, self.intent, self.bpc,
                                     self.depth, 8)
            except pv.Error as e:
                raise ValueError(f"cannot build the grey transform: {_vips_detail(e)}") from None
            table = np.ascontiguousarray(res.reshape(-1, 4).astype(np.uint8))
            self.mode = "grey-icc"
        self._table = table

    # ------------------------------------------------------------------------------------
    def check_band(self, band: np.ndarray) -> np.ndarray:
        """The band as a C-contiguous (h, w, channels) array of this separator's depth, or
        ValueError naming what does not match."""
        band = np.asarray(band)
        want = np.uint16 if self.depth == 16 else np.uint8
        if band.dtype != want:
            raise ValueError(f"band dtype {band.dtype} does not match depth {self.depth}")
        if band.ndim == 2 and self.channels == 1:
            band = band[..., None]
        if band.ndim != 3 or band.shape[2] != self.channels:
            raise ValueError(f"band shape {band.shape} does not match {self.colorspace} "
                             f"({self.channels} channel{'s' if self.channels > 1 else ''})")
        return np.ascontiguousarray(band)

    def convert(self, band: np.ndarray) -> np.ndarray:
        """band (h, w, channels) from ImageSource.bands() -> uint8 (h, w, 4) C, M, Y, K, C-contiguous."""
        band = self.check_band(band)
        h, w, ch = band.shape
        if self.mode == "passthrough" and self.depth == 8 and self._limit < 0 and not self._use_curves:
            return band  # bit-exact, no copy
        out = np.empty((h * w, 4), np.uint8)
        if h * w:
            if self.mode == "lut3":
                src = band.reshape(-1, 3)
                out32 = out.view(np.uint32).reshape(-1)
                run_parallel(
                    (lambda a=a, b=b: _sep3(src[a:b], *self.lut3_tables(), *self.post_tables(),
                                            out[a:b], out32[a:b]))
                    for a, b in split(h * w, minimum=65536))
            elif self.mode == "direct4":
                return self.convert_direct(band)
            elif self.mode == "passthrough":
                _cmyk_post(band.reshape(-1, 4), self._scale, self._limit, self._curves, self._use_curves, out)
            else:
                _sep1(band.reshape(-1), self._table, self._limit, self._curves, self._use_curves, out)
        return out.reshape(h, w, 4)

    __call__ = convert

    def lut3_tables(self) -> tuple:
        """The 3-D LUT kernel's tables (rip/screen.py fuses it with screening)."""
        return self._lut, self._axes, self._d12, self._s3

    def post_tables(self) -> tuple:
        """(limit level or -1, curves (4, 256), use_curves) for `_post_rows`."""
        return self._limit, self._curves, self._use_curves

    def convert_direct(self, band: np.ndarray) -> np.ndarray:
        """Reference path: the same conversion with lcms applied to every pixel (pyvips icc_transform), no
        LUT.  Slow; used to check the LUT and as a fallback."""
        band = self.check_band(band)
        h, w, ch = band.shape
        if self.mode in ("lut3", "direct4"):
            res = _icc_transform(band, ch, self.input_profile, self.output_profile, self.intent, self.bpc,
                                 self.depth, 8)
            flat = np.ascontiguousarray(res.reshape(-1, 4).astype(np.uint8))
            out = np.empty_like(flat)
            _cmyk_post(flat, np.arange(256, dtype=np.uint8), self._limit, self._curves, self._use_curves, out)
            return out.reshape(h, w, 4)
        return self.convert(band).copy()

    def __repr__(self) -> str:
        return (f"Separator({self.colorspace!r}, depth={self.depth}, mode={self.mode!r}, intent={self.intent!r}, "
                f"ink_limit={self.ink_limit}, curves={'yes' if self._use_curves else 'no'})")
