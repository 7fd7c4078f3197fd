"""Colour separation (the Separator): image bands -> CMYK ink amounts (uint8, 0 = no ink, 255 = full ink).

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

import logging

import numpy as np

from ..parallel import run_parallel, split
from ..settings import INTENTS  # declared with the settings schema
from .icc import _icc_transform, _Profile, _vips, _vips_detail, embedded_profile, load_icc_file
from .kernels import (CURVE_ONE, LANE_SCALE, WEIGHT_BITS, _cmyk_post, _sep1, _sep3, _tetra_offsets,
                      ink_limit_level)
from .lutcache import _read_lut, _write_lut, lut_file

log = logging.getLogger(__name__)

LUT3_SIZE = 33  # grid for 3-channel input (same as lcms for 8-bit RGB)


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
            self.output_profile = load_icc_file(output_icc, "output", (b"CMYK",), intent, self.bpc)
        need_icc = colorspace == "rgb" or (colorspace == "grey" and grey_mode == "icc") or \
            (colorspace == "cmyk" and output_icc is not None)
        self.input_profile: _Profile | None = None
        if need_icc:
            spaces = {"rgb": (b"RGB ",), "grey": (b"GRAY", b"RGB "), "cmyk": (b"CMYK",)}[colorspace]
            if input_icc is not None:
                self.input_profile = load_icc_file(input_icc, "input", spaces, intent, self.bpc)
            elif embedded_icc is not None:
                self.input_profile, ignored = embedded_profile(embedded_icc, spaces, intent, self.bpc)
                if ignored:
                    self.warnings.append(ignored)
                    log.warning(ignored)
            if self.input_profile is None:
                self.input_profile = _Profile(name="srgb") if colorspace != "cmyk" else \
                    _Profile(name="cmyk", space=b"CMYK")
            if self.output_profile is None:
                self.output_profile = _Profile(name="cmyk", space=b"CMYK")
        elif input_icc is not None:
            # CMYK passthrough or grey K-only: the input profile is not used, but a bad file is still an error
            load_icc_file(input_icc, "input", (b"RGB ", b"CMYK", b"GRAY"), intent, self.bpc)

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
        inp, out = self._profiles()
        try:
            res = _icc_transform(grid, bands, inp, out, self.intent, self.bpc, 16, 16)
        except pv.Error as e:
            raise ValueError(f"cannot build the colour transform {inp.describe()} -> "
                             f"{out.describe()}: {_vips_detail(e)}") from None
        if res.ndim != 3 or res.shape[2] != 4:
            raise ValueError(f"{out.describe()}: the output profile does not produce CMYK")
        return res.astype(np.float32) * np.float32(255.0 / 65535.0)

    def _build_lut3(self) -> None:
        n = LUT3_SIZE
        cached = lut_file(self._profiles(), self.intent, self.bpc, LUT3_SIZE, LANE_SCALE)
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

    def _profiles(self) -> tuple[_Profile, _Profile]:
        """The input and output profiles of a separation through ICC (both set by __init__
        whenever one is needed)."""
        assert self.input_profile is not None and self.output_profile is not None
        return self.input_profile, self.output_profile

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
            inp, out = self._profiles()
            if inp.space == b"GRAY":
                arr, bands = ramp.reshape(1, -1, 1), 1
            else:
                arr, bands = np.repeat(ramp.reshape(1, -1, 1), 3, axis=2), 3
            pv = _vips()
            try:
                res = _icc_transform(arr, bands, inp, out, self.intent, self.bpc, self.depth, 8)
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
            res = _icc_transform(band, ch, *self._profiles(), self.intent, self.bpc,
                                 self.depth, 8)
            flat = np.ascontiguousarray(res.reshape(-1, 4).astype(np.uint8))
            out = np.empty_like(flat)
            _cmyk_post(flat, np.arange(256, dtype=np.uint8), self._limit, self._curves, self._use_curves, out)
            return out.reshape(h, w, 4)
        return self.convert(band).copy()

    def __repr__(self) -> str:
        return (f"Separator({self.colorspace!r}, depth={self.depth}, mode={self.mode!r}, intent={self.intent!r}, "
                f"ink_limit={self.ink_limit}, curves={'yes' if self._use_curves else 'no'})")
