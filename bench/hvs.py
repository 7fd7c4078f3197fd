"""The human-visual-system (HVS) halftone metric of issue 18, shared by bench/quality_bench.py
and the tests.

A halftone h (0/1 dots) of a contone c (ink 0..1) on the device grid (300 dpi across, 370.5
rows per inch along the feed) is compared as the eye would at two viewing distances: both are
blurred by a Gaussian of sigma ``s`` 300-dpi pixels - ``FINE`` = 1.2 px (about 0.1 mm: close
inspection) and ``COARSE`` = 2.5 px (0.21 mm: arm's length) - which is ``s`` columns across
and ``s * 370.5 / 300`` rows along (the same physical size: the grid is anisotropic), then

* ``rmse``: root mean square of blur(h) - blur(c): the visible error (noise plus lost detail);
* ``ssim``: the mean structural similarity (Wang et al. 2004; 7 x 7-ish Gaussian window of
  sigma 1.5 px, C1 = 0.01^2, C2 = 0.03^2 on 0..1) of blur(h) and blur(c) at the fine scale;
* for flat tints, ``lf_share``: the share of the pattern's power (mean removed) below
  0.1 cycles per 300-dpi pixel (1.2 cycles/mm, measured isotropically in physical units):
  low-frequency "grain" and structure; blue noise has almost none.

The images are padded by reflection before blurring, so the borders are not compared with
wrapped-around content.  numpy only.
"""

from __future__ import annotations

import numpy as np

DPI_X = 300.0
DPI_Y = 370.5
ASPECT = DPI_Y / DPI_X      # rows per column of the same physical length
FINE = 1.2
COARSE = 2.5
LF_CUTOFF = 0.1             # cycles per 300-dpi pixel


def blur(img: np.ndarray, sigma: float, aspect: float = ASPECT) -> np.ndarray:
    """Gaussian blur of a 2-D (or (h, w, k)) float image: sigma columns across, sigma *
    aspect rows along; reflective borders; exact (FFT of the padded image)."""
    img = np.asarray(img, np.float64)
    sx, sy = sigma, sigma * aspect
    px, py = int(np.ceil(4 * sx)), int(np.ceil(4 * sy))
    pad = ((py, py), (px, px)) + ((0, 0),) * (img.ndim - 2)
    p = np.pad(img, pad, mode="reflect")
    h, w = p.shape[:2]
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    g = np.exp(-2 * np.pi ** 2 * ((sx * fx) ** 2 + (sy * fy) ** 2))
    if img.ndim == 3:
        g = g[:, :, None]
    out = np.fft.irfftn(np.fft.rfftn(p, axes=(0, 1)) * g, s=(h, w), axes=(0, 1))
    return out[py:py + img.shape[0], px:px + img.shape[1]]


def rmse(h: np.ndarray, c: np.ndarray, sigma: float, margin: int = 0) -> float:
    """RMS of the blurred difference; ``margin`` px (and margin * aspect rows) at each side
    are blurred but not counted (flat tints: the reflected border would pair each dot
    with its own mirror image)."""
    d = blur(np.asarray(h, np.float64) - np.asarray(c, np.float64), sigma)
    if margin:
        my = int(round(margin * ASPECT))
        d = d[my:d.shape[0] - my, margin:d.shape[1] - margin]
    return float(np.sqrt(np.mean(d * d)))


def ssim(h: np.ndarray, c: np.ndarray, sigma: float = FINE, window: float = 1.5) -> float:
    x = blur(np.asarray(h, np.float64), sigma)
    y = blur(np.asarray(c, np.float64), sigma)
    c1, c2 = 0.01 ** 2, 0.03 ** 2

    def w(a):
        return blur(a, window, aspect=1.0)
    mx, my = w(x), w(y)
    vx = w(x * x) - mx * mx
    vy = w(y * y) - my * my
    cxy = w(x * y) - mx * my
    s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
    return float(s.mean())


def lf_share(h: np.ndarray, cutoff: float = LF_CUTOFF, aspect: float = ASPECT) -> float:
    """Share of the AC power of a flat-tint pattern below ``cutoff`` cycles per 300-dpi
    pixel (radial frequency in physical units)."""
    a = np.asarray(h, np.float64)
    a = a - a.mean()
    p = np.abs(np.fft.rfft2(a)) ** 2
    fy = np.fft.fftfreq(a.shape[0])[:, None] * aspect      # cycles per row -> per 300-dpi px
    fx = np.fft.rfftfreq(a.shape[1])[None, :]
    r = np.hypot(fx, fy)
    total = p[r > 0].sum()
    return float(p[(r > 0) & (r < cutoff)].sum() / total) if total > 0 else 0.0


# darkness of the inks for mixed-tint graininess: 1 - L*/L*paper for typical solvent inks
# (C ~55, M ~48, Y ~89, K ~16 against paper ~95), added where dots overlap
DARKNESS = np.array([0.51, 0.59, 0.08, 1.0])


def luminance_noise(dots: np.ndarray, sigma: float = COARSE) -> float:
    """Graininess of a flat mixed tint: RMS of the blurred darkness image (h, w, 4 dots)."""
    d = (np.asarray(dots, np.float64) * DARKNESS[:dots.shape[2]]).sum(axis=2)
    b = blur(d - d.mean(), sigma)
    return float(np.sqrt(np.mean(b * b)))
