"""The emulated scanner (docs/physical.md): renders the drops of one job, placed by the
physical media model (physical.py), as an 8-bit RGB or greyscale TIFF at a chosen
resolution — dot gain, the media's spectra (spectral.py, the spectrophotometer's model)
seen through an RGB sensor's spectral sensitivities and its tone response, the scanner's
blur, rotation, scale error, placement and noise, all seeded.

Drops are splatted as they are fired into a rolling accumulator at the scan resolution
(bilinear weights, so each drop keeps its exact centroid) and never kept; rows are
rendered once the paper has carried them past the heads and written once every scan row
that samples them can be made.  Memory is bounded by the job's width, never its length.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import tifffile
from ..rip.compiled import kernel

from .faults import Faults
from .physical import JobGeometry
from .spectral import SpectralMedia, demichel

MARGIN_UM = 3000.0                 # paper around the image area in the scan (--inject scan-margin)
STRIP = 64                         # scan rows made at a time (and the noise's seed block)
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)           # Rec. 709
# The sensor: each channel's spectral sensitivity (its filter, the lamp and the CCD
# together), a Gaussian (peak nm, sigma nm): a typical flatbed's, far from the CIE
# observer's (no linear map makes it a colorimeter), normalised to 1 on a perfect white.
SENSOR = ((605.0, 28.0), (535.0, 32.0), (455.0, 24.0))
FLARE = 0.004                      # stray light over the whole field (share of white)
TONE_GAMMA = 1 / 2.2               # the scanner's tone response: 255 (flare + signal)^gamma
LUT_NODES = 17                     # the coverage -> sensor table: nodes per ink


@kernel()
def _splat(acc, base, channel, px, py):
    """Add one unit of ink per drop at (px, py) (pixel coordinates, pixel centres on
    integers) with bilinear weights; returns the drops that fell on rows already rendered."""
    rows, width = acc.shape[0], acc.shape[1]
    late = 0
    for i in range(px.shape[0]):
        j0 = int(math.floor(py[i]))
        i0 = int(math.floor(px[i]))
        fy = py[i] - j0
        fx = px[i] - i0
        if j0 + 1 < base:
            late += 1
            continue
        for dj in range(2):
            r = j0 + dj - base
            if r < 0 or r >= rows:
                continue
            wy = fy if dj else 1.0 - fy
            for di in range(2):
                c = i0 + di
                if 0 <= c < width:
                    acc[r, c, channel] += wy * (fx if di else 1.0 - fx)
    return late


@kernel()
def _sense(cov, lut, white, out):
    """Coverages (rows, width, 4) -> the sensor's linear signal (rows, width, 3),
    interpolated in the coverage -> sensor table (nodes^4, 3: quadrilinear, exact on the
    nodes)."""
    g = lut.shape[0] - 1
    idx = np.empty(4, np.int64)
    fr = np.empty(4, np.float32)
    for r in range(cov.shape[0]):
        for c in range(cov.shape[1]):
            blank = True
            for i in range(4):
                x = cov[r, c, i] * g
                if x > 0.0:
                    blank = False
                k = min(int(x), g - 1)
                idx[i] = k
                fr[i] = x - k
            if blank:
                for b in range(3):
                    out[r, c, b] = white[b]
                continue
            for b in range(3):
                out[r, c, b] = 0.0
            for corner in range(16):
                w = np.float32(1.0)
                for i in range(4):
                    w *= fr[i] if corner >> i & 1 else 1.0 - fr[i]
                if w == 0.0:
                    continue
                i0 = idx[0] + (corner & 1)
                i1 = idx[1] + (corner >> 1 & 1)
                i2 = idx[2] + (corner >> 2 & 1)
                i3 = idx[3] + (corner >> 3 & 1)
                for b in range(3):
                    out[r, c, b] += w * lut[i0, i1, i2, i3, b]


def sensor_weights(wavelengths: np.ndarray) -> np.ndarray:
    """(3, bands): the sensor's channels, each summing to 1 (a perfect white reads 1)."""
    s = np.array([np.exp(-0.5 * ((wavelengths - mu) / sd) ** 2) for mu, sd in SENSOR])
    return s / s.sum(axis=1, keepdims=True)


_SENSOR_LUTS: dict = {}


def sensor_lut(media: SpectralMedia) -> np.ndarray:
    """(nodes, nodes, nodes, nodes, 3) float32: the sensor's linear signal of a spot with
    these C, M, Y, K coverages (Demichel weights, Yule-Nielsen spectral Neugebauer)."""
    key = (media.name, media.n)
    lut = _SENSOR_LUTS.get(key)
    if lut is None:
        g = np.linspace(0.0, 1.0, LUT_NODES)
        cov = np.stack(np.meshgrid(g, g, g, g, indexing="ij"), axis=-1).reshape(-1, 4)
        refl = media.reflectance(demichel(cov))
        lut = (refl @ sensor_weights(media.wavelengths).T).astype(np.float32)
        lut = _SENSOR_LUTS[key] = lut.reshape((LUT_NODES,) * 4 + (3,))
    return lut


def scanner_tone(signal: np.ndarray) -> np.ndarray:
    """The scanner's tone response: linear signal (white 1) -> 8-bit levels (float)."""
    v = FLARE + (1.0 - FLARE) * np.clip(signal, 0.0, 1.0)
    return np.power(v, TONE_GAMMA) * 255.0


def disc_kernel(diameter_px: float, oversample: int = 8) -> np.ndarray:
    """A disc of this diameter: each pixel holds the fraction of its area inside it."""
    r = diameter_px / 2.0
    n = int(math.ceil(r + 0.5))
    sub = (np.arange(oversample) + 0.5) / oversample - 0.5
    g = np.arange(-n, n + 1)
    yy = (g[:, None, None, None] + sub[None, None, :, None])
    xx = (g[None, :, None, None] + sub[None, None, None, :])
    inside = (xx * xx + yy * yy) <= r * r
    return inside.mean(axis=(2, 3)).astype(np.float32)


def ring_kernel(diameter_px: float, half: int, eps: float = 0.05, oversample: int = 32) -> np.ndarray:
    """How the disc grows with its diameter: d disc(D (1 + s)) / ds at s = 0, on the disc
    kernel's grid (2 half + 1 square).  A drop whose dot is s larger adds s x this ring
    (docs/physical.md "The machine": first order in s, within 0.1 % of a dot's area at 8 %)."""
    sub = (np.arange(oversample) + 0.5) / oversample - 0.5
    g = np.arange(-half, half + 1)
    yy = (g[:, None, None, None] + sub[None, None, :, None])
    rr = yy * yy + (g[None, :, None, None] + sub[None, None, None, :]) ** 2
    r = diameter_px / 2.0
    outer = (rr <= (r * (1 + eps)) ** 2).mean(axis=(2, 3))
    inner = (rr <= (r * (1 - eps)) ** 2).mean(axis=(2, 3))
    return ((outer - inner) / (2 * eps)).astype(np.float32)


LUT_SIZE = 1 << 16
_TONE_LUT = scanner_tone(np.arange(LUT_SIZE) / (LUT_SIZE - 1)).astype(np.float32)


@kernel()
def _encode(linear, noise, lut, out):
    """8-bit levels of the linear signal through the tone response (a 65,536-entry table:
    within 0.05 levels of scanner_tone) plus noise, rounded and clipped; all flat."""
    top = lut.shape[0] - 1
    for i in range(linear.shape[0]):
        j = int(min(max(linear[i], 0.0), 1.0) * top + 0.5)
        v = np.rint(lut[j] + noise[i])
        out[i] = 0 if v < 0 else (255 if v > 255 else np.uint8(v))


class Scanner:
    """The scan of one job (docs/physical.md, "The scan")."""

    def __init__(self, path: str, geo: JobGeometry, dpi: float, dot_um: float,
                 faults: Faults, slack_um: float = 0.0, swath_um: float = 20_000.0,
                 media: SpectralMedia | None = None, drop_pl: float = 40.0):
        if not 50 <= dpi <= 9600:
            raise ValueError(f"scan resolution {dpi} dpi: must be 50..9600")
        self.path, self.geo, self.dpi = path, geo, float(dpi)
        self.pix = 25_400.0 / self.dpi
        self.margin_px = int(round(faults.scan_margin * 1000.0 / self.pix))
        self.margin_um = self.margin_px * self.pix
        # skewed paper turns the print and a longer feed stretches it: the field grows so
        # that the sheet's whole print is on the glass (docs/physical.md, "Skew")
        sk = abs(math.sin(getattr(geo, "skew_rad", 0.0)))
        w_um, h_um = geo.width * geo.col_um, geo.height * geo.row_um
        self.pad_x_um = math.ceil(h_um * sk / self.pix) * self.pix if geo.skew_rad < 0 else 0.0
        self.width = int(math.ceil(w_um / self.pix)) + 2 * self.margin_px + int(math.ceil(h_um * sk / self.pix))
        self.height = int(math.ceil((h_um * (1 + max(faults.feed_error_fraction, 0.0)) + w_um * sk) / self.pix)) \
            + 2 * self.margin_px
        self.grey = faults.scan_mode == "grey"
        self.seed = faults.seed
        self.noise = float(faults.scan_noise)
        self.slack_um = slack_um
        self.dot_um = dot_um
        self.kernel = disc_kernel(dot_um / self.pix)
        self.media = media if media is not None else SpectralMedia.load()
        self.lut = sensor_lut(self.media)
        self.white = np.ascontiguousarray(self.lut[0, 0, 0, 0])        # the paper's signal
        # ink beyond the media's limit (docs/physical.md): its volume, smoothed, per pixel
        self.unit = drop_pl * 1000.0 / (float(self.kernel.sum()) * self.pix ** 2)
        self.bleed_px = self.media.bleed_um / self.pix
        self.rk = self.kernel.shape[0] // 2
        self.rv = int(math.ceil(3 * self.bleed_px)) if self.bleed_px > 0 else 0
        self.sigma = faults.scan_blur.um(geo.col_um, geo.row_um) / self.pix
        self.rb = int(math.ceil(3 * self.sigma)) + 1 if self.sigma > 0 else 0
        # geometry: scan pixel q = A (p - c) + c + o, p the sheet's pixel
        th = math.radians(faults.scan_rotation)
        s = faults.scan_scale
        self.A = s * np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        self.Ainv = np.linalg.inv(self.A)
        self.c = np.array([(self.width - 1) / 2.0, (self.height - 1) / 2.0])
        self.o = np.array(faults.scan_offset, np.float64) * 1000.0 / self.pix
        self._acc = np.zeros((int((swath_um + slack_um) / self.pix) + 2 * (self.rk + self.rv) + 8,
                              self.width, 4), np.float32)
        self._a_base = -self.rk - 1            # sheet pixel row of accumulator row 0
        # the drops' dot size errors (a machine with drop volume spreads), splatted beside
        # the drops and spread by the ring; made at the first drop that has one
        self._dacc: np.ndarray | None = None
        self._refl: list[np.ndarray] = []      # rendered rows [r_base, r_next)
        self._r_base = self._r_next = 0
        self._v_next = 0
        self.drops = 0
        self.late = 0
        self.closed = False
        # the TIFF's header and contiguous pixel data, written in place row by row
        shape = (self.height, self.width) if self.grey else (self.height, self.width, 3)
        out = tifffile.memmap(path, shape=shape, dtype=np.uint8,
                              photometric="minisblack" if self.grey else "rgb",
                              resolution=(self.dpi, self.dpi), resolutionunit="INCH",
                              description="wideprint emulator scan")
        self._data_offset, self._row_bytes = out.offset, out[0].nbytes
        del out
        self._out = open(path, "r+b")

    # -- coordinates -----------------------------------------------------------------------
    def sheet_px(self, x_um, y_um) -> tuple[np.ndarray, np.ndarray]:
        """Image-frame micrometres -> the sheet's pixel coordinates (before the scanner's
        geometry; pixel centres on integers)."""
        return ((np.asarray(x_um) + self.margin_um + self.pad_x_um) / self.pix - 0.5,
                (np.asarray(y_um) + self.margin_um) / self.pix - 0.5)

    def paper_to_scan(self, x_um, y_um) -> tuple[np.ndarray, np.ndarray]:
        """Image-frame micrometres -> fractional scan pixel coordinates (u, v)."""
        px, py = self.sheet_px(x_um, y_um)
        dx, dy = px - self.c[0], py - self.c[1]
        u = self.A[0, 0] * dx + self.A[0, 1] * dy + self.c[0] + self.o[0]
        v = self.A[1, 0] * dx + self.A[1, 1] * dy + self.c[1] + self.o[1]
        return u, v

    # -- drops -----------------------------------------------------------------------------
    def splat(self, channel: int, x_um: np.ndarray, y_um: np.ndarray,
              size: np.ndarray | None = None) -> None:
        """Drops of one ink at image-frame positions; `size` each one's relative dot
        diameter error (None: all nominal)."""
        if x_um.size == 0:
            return
        px, py = self.sheet_px(x_um, y_um)
        top = int(math.floor(float(py.max()))) + 2 - self._a_base
        if top > self._acc.shape[0]:
            grow = np.zeros((top - self._acc.shape[0] + 64, self.width, 4), np.float32)
            self._acc = np.concatenate([self._acc, grow])
            if self._dacc is not None:
                self._dacc = np.concatenate([self._dacc, np.zeros_like(grow)])
        self.late += _splat(self._acc, self._a_base, channel, px, py)
        if size is not None:
            self._splat_sizes(channel, px, py, np.asarray(size, np.float32))
        self.drops += x_um.size

    def _splat_sizes(self, channel: int, px: np.ndarray, py: np.ndarray, size: np.ndarray) -> None:
        """The size errors, bilinear like the drops (numpy: only a machine with volume
        spreads pays for it)."""
        if self._dacc is None:
            self._dacc = np.zeros_like(self._acc)
            self.ring = ring_kernel(self.dot_um / self.pix, self.rk)
        j0, i0 = np.floor(py).astype(np.int64), np.floor(px).astype(np.int64)
        fy, fx = (py - j0).astype(np.float32), (px - i0).astype(np.float32)
        plane = self._dacc[:, :, channel]
        for dj, wy in ((0, 1 - fy), (1, fy)):
            r = j0 + dj - self._a_base
            for di, wx in ((0, 1 - fx), (1, fx)):
                c = i0 + di
                ok = (r >= 0) & (r < plane.shape[0]) & (c >= 0) & (c < plane.shape[1])
                np.add.at(plane, (r[ok], c[ok]), (size * wy * wx)[ok])

    def flush_below(self, y_um: float) -> None:
        """No drop will land above image-frame y (the paper has carried it past the heads)."""
        done = int(math.floor((y_um - self.slack_um + self.margin_um) / self.pix - 0.5))
        self._render(min(done, self.height))

    def close(self) -> None:
        if self.closed:
            return
        try:
            self._render(self.height + self.rk + self.rv + 1)
        finally:
            self._out.close()
        self._acc, self._refl = np.zeros((0, 0, 4), np.float32), []      # the geometry stays
        self.closed = True

    # -- rendering ---------------------------------------------------------------------------
    def _render(self, done: int) -> None:
        """Sheet rows < done receive no more drops: render what they complete, then write
        the scan rows that can be made."""
        upto = min(done - self.rk - self.rv, self.height)
        if upto > self._r_next:
            self._reflectance(self._r_next, upto)
        while self._v_next < self.height:
            v0, v1 = self._v_next, min(self._v_next + STRIP, self.height)
            lo, hi = self._source_rows(v0, v1)
            if hi > self._r_next and self._r_next < self.height:
                break
            self._write_strip(v0, v1, lo, hi)
            self._v_next = v1
        if self._v_next < self.height:                       # rows no scan row needs any more
            lo, _ = self._source_rows(self._v_next, min(self._v_next + STRIP, self.height))
            self._drop_reflectance(lo)

    def _reflectance(self, r0: int, r1: int) -> None:
        """Render sheet rows [r0, r1) from the accumulator: dots, coverage, ink limit, the
        media's spectra through the sensor."""
        from .coverage import coverage_rows
        h = self.rk + self.rv
        refl = np.empty((r1 - r0, self.width, 3), np.float32)
        for c0 in range(r0, r1, STRIP):                 # in strips: small temporaries
            c1 = min(c0 + STRIP, r1)
            a0, a1 = c0 - h, c1 + h
            src = np.zeros((a1 - a0, self.width, 4), np.float32)
            s0, s1 = max(a0, self._a_base), min(a1, self._a_base + self._acc.shape[0])
            if s1 > s0:
                src[s0 - a0:s1 - a0] = self._acc[s0 - self._a_base:s1 - self._a_base]
            ink = cv2.filter2D(src, -1, self.kernel, borderType=cv2.BORDER_CONSTANT)
            if self._dacc is not None:                  # dots larger or smaller than nominal
                dsrc = np.zeros_like(src)
                if s1 > s0:
                    dsrc[s0 - a0:s1 - a0] = self._dacc[s0 - self._a_base:s1 - self._a_base]
                ink = ink + cv2.filter2D(dsrc, -1, self.ring, borderType=cv2.BORDER_CONSTANT)
            cov = coverage_rows(ink, self.media, self.unit, self.bleed_px)
            _sense(cov[h:h + c1 - c0], self.lut, self.white, refl[c0 - r0:c1 - r0])
        self._refl.append(refl)
        self._r_next = r1
        # accumulator rows the next rendering no longer needs
        drop = (r1 - h) - self._a_base
        if drop > 0:
            keep = self._acc[drop:]
            self._acc = np.concatenate([keep, np.zeros((drop, self.width, 4), np.float32)])
            if self._dacc is not None:
                self._dacc = np.concatenate([self._dacc[drop:], np.zeros((drop, self.width, 4),
                                                                         np.float32)])
            self._a_base += drop

    def _source_rows(self, v0: int, v1: int) -> tuple[int, int]:
        """Sheet rows [lo, hi) that scan rows [v0, v1) sample (with the blur's reach)."""
        corners = np.array([[0, v0], [self.width - 1, v0], [0, v1 - 1], [self.width - 1, v1 - 1]],
                           np.float64)
        p = (corners - self.c - self.o) @ self.Ainv.T + self.c
        lo = int(math.floor(p[:, 1].min())) - 1 - self.rb
        hi = int(math.ceil(p[:, 1].max())) + 2 + self.rb
        return max(lo, 0), min(max(hi, 0), self.height)

    def _rows(self, lo: int, hi: int) -> np.ndarray:
        if not self._refl:
            return np.broadcast_to(self.white, (max(hi - lo, 1), self.width, 3)).copy()
        buf = np.concatenate(self._refl) if len(self._refl) > 1 else self._refl[0]
        self._refl = [buf]
        lo, hi = max(lo, self._r_base), min(hi, self._r_next)
        return buf[lo - self._r_base:hi - self._r_base] if hi > lo else \
            np.broadcast_to(self.white, (1, self.width, 3)).copy()

    def _drop_reflectance(self, lo: int) -> None:
        if lo <= self._r_base or not self._refl:
            return
        buf = np.concatenate(self._refl) if len(self._refl) > 1 else self._refl[0]
        n = min(lo - self._r_base, buf.shape[0])
        self._refl = [buf[n:]] if n < buf.shape[0] else []
        self._r_base += n

    def _write_strip(self, v0: int, v1: int, lo: int, hi: int) -> None:
        lo = max(lo, self._r_base)
        sheet = self._rows(lo, hi)
        if self.sigma > 0:
            sheet = cv2.GaussianBlur(sheet, (0, 0), self.sigma, borderType=cv2.BORDER_REPLICATE)
        # dst (u, v - v0) -> src (sheet pixel - (0, lo))
        m = np.zeros((2, 3))
        m[:, :2] = self.Ainv
        m[:, 2] = self.Ainv @ (np.array([0.0, v0]) - self.c - self.o) + self.c - np.array([0.0, lo])
        white = tuple(float(w) for w in self.white)
        scan = cv2.warpAffine(np.ascontiguousarray(sheet), m, (self.width, v1 - v0),
                              flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=white)
        if self.grey:
            scan = scan @ LUMA
        scan = scan.reshape(-1)
        if self.noise > 0:
            rng = np.random.default_rng((self.seed, v0))
            noise = np.float32(self.noise) * rng.standard_normal(scan.shape, dtype=np.float32)
        else:
            noise = np.zeros(scan.shape, np.float32)
        out = np.empty(scan.shape, np.uint8)
        _encode(scan, noise, _TONE_LUT, out)
        self._out.seek(self._data_offset + v0 * self._row_bytes)
        self._out.write(out.tobytes())
