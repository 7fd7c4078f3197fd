"""`wideprint quality SCAN.tif`: banding, graininess and mottle of flat tints on a scan
(docs/quality.md).  Any scan: the emulator's `--scan-out` or a real scanner's TIFF.

The scan is read as lightness L* relative to its paper white (docs/quality.md "Lightness":
no scanner profile, so the scan's RGB is taken as gamma 2.2 and its paper as the white).
The flat tints are found by themselves: strips of ink running along the feed, split by
paper (the banding chart, `wideprint test-print banding-scan`, is ten such strips between
two K bars).  Per strip, on its inner area:

- banding: the lightness profile along the feed (row means) of GROUPS column groups of the
  strip; the cross-spectra of groups apart keep what they share - variation across the
  whole width, the banding - and average out the grain, which they do not share;
  weighted by the eye's contrast sensitivity (Dooley-Shaw's visual transfer function at the
  viewing distance) and summed: an RMS ΔL* the eye sees.  Also the amplitude at the feed's
  advance and the swath period and their harmonics, when the weave is known;
- graininess and mottle (ISO/IEC TS 24790, ISO 15311-1): the 2-D lightness spectrum weighted
  by the same eye, above 0.4 cycles/mm (graininess) and from 0.1 to 0.4 (mottle), the lines
  of banding (along x constant) and of streaks (along y constant) left out.

Everything is numpy FFTs on a few hundred thousand pixels a strip: no hand-written loops.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import asdict, dataclass, field

import numpy as np

EXIT_OK, EXIT_USAGE, EXIT_NOT_FOUND = 0, 2, 3
VIEWING_MM = 500.0          # default viewing distance (docs/quality.md "The eye")
GRAIN_CUT = 0.4             # cycles/mm: graininess above, mottle below (ISO 13660, TS 24790)
MOTTLE_LOW = 0.1            # cycles/mm: mottle's lowest frequency (a 10 mm wavelength)
INSET_MM = 0.5              # the strip's edges left out (the scanner's blur, a slight rotation)
GAP_MM = 2.0                # paper across a strip shorter than this is a defect, not its end
DETECT_BLUR_MM = 0.2        # the lightness smoothed this much (sigma) to find the strips
MIN_STRIP_MM = 3.0          # a run of ink narrower than this is not a strip
MIN_LENGTH_MM = 8.0         # ... or shorter along the feed
INK_DL = 4.0                # a pixel this much darker than paper (L*) holds ink
HARMONICS = 4               # of the advance and the swath frequency, reported
GROUPS = 5                  # column groups of a strip whose shared variation is the banding
PAIR_GAP = 2                # ... of which only groups this far apart are compared: the
                            # halftone's own texture reaches ~2 mm across (docs/quality.md)
PERIOD_MIN_MM, PERIOD_MAX_MM = 1.0, 40.0    # banding periods searched
PERIOD_SMOOTH_MM = 0.1      # the profile smoothed (Gaussian sigma) before its period is found
PERIOD_MIN_CORR = 0.2       # a period explains at least this share of the profile's variance
GAMMA = 2.2                 # the scan's encoding (docs/quality.md "Lightness")
LUMA = np.array([0.2126, 0.7152, 0.0722])


class QualityError(Exception):
    """No flat tint found in the scan, or the scan cannot be read."""


# -- the eye ------------------------------------------------------------------------------
def vtf(f_cyc_mm: np.ndarray, viewing_mm: float = VIEWING_MM) -> np.ndarray:
    """Dooley and Shaw's visual transfer function (1979), as ISO 13660's successors and the
    banding literature use it, at `viewing_mm`; normalised to a peak of 1 (docs/quality.md)."""
    u = np.pi * viewing_mm * np.abs(np.asarray(f_cyc_mm, np.float64)) / 180.0   # cycles/degree
    v = 5.05 * np.exp(-0.138 * u) * (1.0 - np.exp(-0.1 * u))
    return v / _VTF_PEAK


def _vtf_peak() -> float:
    u = np.linspace(0.01, 60, 60_000)
    return float((5.05 * np.exp(-0.138 * u) * (1.0 - np.exp(-0.1 * u))).max())


_VTF_PEAK = _vtf_peak()


# -- the scan -----------------------------------------------------------------------------
def read_lightness(path: str, scan_dpi: float | None = None) -> tuple[np.ndarray, float]:
    """(L* relative to the scan's paper white (H, W) float32, scan dpi): 8 or 16 bits, RGB
    or grey, the paper each band's 90th percentile as `calibrate` takes it."""
    import tifffile
    with tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        img = page.asarray()
        if scan_dpi is None:
            res, unit = page.tags.get("XResolution"), page.tags.get("ResolutionUnit")
            if res is None:
                raise QualityError(f"{path}: no resolution tags; give --scan-dpi")
            scan_dpi = res.value[0] / res.value[1] * (2.54 if unit is not None and int(unit.value) == 3 else 1.0)
    if img.dtype.kind not in "uf":
        raise QualityError(f"{path}: {img.dtype} samples: not a scan")
    levels = img.astype(np.float32) * np.float32(255.0 / (np.iinfo(img.dtype).max if img.dtype.kind == "u" else 1.0))
    levels = levels[:, :, :3] if levels.ndim == 3 else levels[:, :, None]
    white = np.percentile(levels[::4, ::4].reshape(-1, levels.shape[2]), 90, axis=0)
    return lightness_from_levels(np.minimum(levels, white), white).astype(np.float32), float(scan_dpi)


def _luminance(lstar: np.ndarray) -> np.ndarray:
    """L* -> Y / Y_paper (the inverse of _lstar)."""
    f = (np.asarray(lstar, np.float64) + 16.0) / 116.0
    d = 6 / 29
    return np.where(f > d, f ** 3, 3 * d * d * (f - 4 / 29))


def _lstar_slope(y: float) -> float:
    """dL*/dY at Y (relative to paper)."""
    d = 6 / 29
    return 116.0 / 3.0 * y ** (-2.0 / 3.0) if y > d ** 3 else 116.0 / (3 * d * d)


def _lstar(y: np.ndarray) -> np.ndarray:
    y = np.asarray(y, np.float32)
    d = np.float32(6 / 29)
    f = np.where(y > d ** 3, np.cbrt(np.maximum(y, 0)), y / (3 * d * d) + np.float32(4 / 29))
    return (116 * f - 16).astype(np.float32)


@dataclass
class Strip:
    """One flat tint found in the scan: scan pixels [x0, x1) x [y0, y1), its inner area."""
    name: str
    x0: int
    x1: int
    y0: int
    y1: int


def find_strips(lightness: np.ndarray, pix_mm: float) -> list[Strip]:
    """Runs of ink columns at least MIN_STRIP_MM wide, split by paper, each with the
    longest run of inked rows down its middle; the edges inset by INSET_MM."""
    import cv2
    # a tint's dots and the paper between them, smoothed to its mean: a light tint at a
    # fine scan is mostly paper pixels
    smooth = cv2.GaussianBlur(lightness.astype(np.float32), (0, 0), DETECT_BLUR_MM / pix_mm)
    ink = smooth < (100.0 - INK_DL)
    rows_inked = ink.mean(axis=1) > 0.02
    if not rows_inked.any():
        raise QualityError("no ink in the scan")
    cols = ink[rows_inked].mean(axis=0) > 0.5
    inset = int(round((INSET_MM + DETECT_BLUR_MM) / pix_mm))     # the blur widens the runs
    strips: list[Strip] = []
    for a, b in _runs(cols):
        if (b - a) * pix_mm < MIN_STRIP_MM:
            continue
        mid = ink[:, a + (b - a) // 4:b - (b - a) // 4].mean(axis=1) > 0.5
        runs = _merge(_runs(mid), int(round(GAP_MM / pix_mm)))   # a banding gap is not an end
        y0, y1 = max(runs, key=lambda r: r[1] - r[0])
        if (y1 - y0) * pix_mm < MIN_LENGTH_MM:
            continue
        strips.append(Strip(f"strip {len(strips) + 1}", a + inset, b - inset, y0 + inset, y1 - inset))
    if not strips:
        raise QualityError(f"no flat tint of at least {MIN_STRIP_MM:g} x {MIN_LENGTH_MM:g} mm in the scan")
    return strips


def _merge(runs: list[tuple[int, int]], gap: int) -> list[tuple[int, int]]:
    """Runs joined across gaps of at most `gap`."""
    out: list[tuple[int, int]] = []
    for a, b in runs:
        if out and a - out[-1][1] <= gap:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


# -- the measures -------------------------------------------------------------------------
@dataclass
class Component:
    """A periodic banding component: its period and amplitude (ΔL*, peak)."""
    what: str
    period_mm: float
    amplitude: float


@dataclass
class TintQuality:
    name: str
    lightness: float              # mean L*
    banding: float                # visual banding, RMS ΔL* (eye-weighted, coherent across x)
    banding_raw: float            # the same without the eye's weighting, 0.05-5 cycles/mm
    period_mm: float              # the fundamental period of the periodic banding (0: none)
    peak_period_mm: float         # where the eye sees most of it (strongest weighted bin)
    graininess: float             # RMS ΔL*, eye-weighted, above GRAIN_CUT
    mottle: float                 # RMS ΔL*, eye-weighted, MOTTLE_LOW .. GRAIN_CUT
    width_mm: float
    length_mm: float
    components: list[Component] = field(default_factory=list)


def _hann(n: int) -> np.ndarray:
    return np.hanning(n + 2)[1:-1]


def banding_spectrum(area: np.ndarray, pix_mm: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(frequencies cycles/mm, coherent power per bin, window norm): the mean cross-spectrum
    of the pairs of GROUPS column groups' row-mean profiles at least PAIR_GAP groups apart,
    Hann-windowed, linear trend removed.  Power per bin sums to the variance the groups
    share (the banding); the grain, which no two distant groups share, averages out of it
    instead of adding to it.  Neighbouring groups are not compared: error diffusion's
    texture is correlated over ~2 mm across the sweep (positively at mid-tones, its worms;
    negatively in light tints, its blue noise), which read as banding on a perfect printer
    (docs/quality.md "The floor")."""
    h, w = area.shape
    edges = np.linspace(0, w, GROUPS + 1).astype(int)
    y = np.arange(h, dtype=np.float64)
    win = _hann(h)
    spectra = []
    for a, b in zip(edges[:-1], edges[1:]):
        p = area[:, a:b].mean(axis=1).astype(np.float64)
        p = p - np.polyval(np.polyfit(y, p, 1), y)
        spectra.append(np.fft.rfft(p * win))
    norm = float(h * np.sum(win ** 2))
    f = np.array(spectra)
    pairs = [(i, j) for i in range(GROUPS) for j in range(i + PAIR_GAP, GROUPS)]
    cross = sum((f[i] * np.conj(f[j])).real for i, j in pairs) / len(pairs)
    cross[1:-1] *= 2.0                      # rfft: the negative frequencies too
    if h % 2 == 1:
        cross[-1] *= 2.0
    return np.fft.rfftfreq(h, pix_mm), cross / norm, float(win.sum())


def grain_mottle(area: np.ndarray, pix_mm: float, viewing_mm: float) -> tuple[float, float]:
    """Eye-weighted RMS ΔL* above GRAIN_CUT (graininess) and from MOTTLE_LOW to it (mottle),
    the fx = 0 and fy = 0 lines (banding, streaks) left out; 2-D Hann window."""
    h, w = area.shape
    win = np.outer(_hann(h), _hann(w))
    z = area.astype(np.float64) - area.mean()
    power = np.abs(np.fft.fft2(z * win)) ** 2 / (h * w * np.sum(win ** 2))
    fy, fx = np.fft.fftfreq(h, pix_mm), np.fft.fftfreq(w, pix_mm)
    f = np.hypot(fy[:, None], fx[None, :])
    weighted = power * vtf(f, viewing_mm) ** 2
    keep = (fy[:, None] != 0) & (fx[None, :] != 0)
    grain = float(weighted[keep & (f >= GRAIN_CUT)].sum())
    mottle = float(weighted[keep & (f >= MOTTLE_LOW) & (f < GRAIN_CUT)].sum())
    return math.sqrt(grain), math.sqrt(mottle)


def measure_area(name: str, area: np.ndarray, pix_mm: float, viewing_mm: float = VIEWING_MM,
                 periods: dict[str, float] | None = None) -> TintQuality:
    """All the figures of one flat tint's L* area (rows along the feed)."""
    h, w = area.shape
    # the banding in light, not lightness: row means of L* would move with the grain's
    # variance wherever it changes (a rotated scan's resampling), the mean light does not;
    # then to ΔL* by the slope of L* at the tint's light (small variations: docs/quality.md)
    y = _luminance(area)
    slope = _lstar_slope(float(y.mean()))
    freqs, cross, wsum = banding_spectrum(y, pix_mm)
    cross = cross * slope ** 2
    eye = vtf(freqs, viewing_mm) ** 2
    coherent = np.maximum(cross, 0.0)            # a negative bin is noise that did not cancel
    banding = math.sqrt(max(0.0, float((eye * cross).sum())))
    raw_band = (freqs >= 0.05) & (freqs <= 5.0)
    banding_raw = math.sqrt(max(0.0, float(cross[raw_band].sum())))
    weighted = eye * coherent
    weighted[freqs < 2.0 / (h * pix_mm)] = 0.0   # under two cycles in the strip: not a period
    k = int(np.argmax(weighted))
    peak = 1.0 / freqs[k] if freqs[k] > 0 else float("inf")
    period = banding_period(y, pix_mm)
    comps = []
    for what, p_mm in (periods or {}).items():
        for n in range(1, HARMONICS + 1):
            f0 = n / p_mm
            if f0 > freqs[-1] or f0 < 2.0 / (h * pix_mm):
                break
            comps.append(Component(f"{what} x{n}" if n > 1 else what, round(p_mm / n, 4),
                                   round(_amplitude(freqs, coherent, f0), 4)))
    grain, mottle = grain_mottle(area, pix_mm, viewing_mm)
    return TintQuality(name, round(float(area.mean()), 3), round(banding, 4), round(banding_raw, 4),
                       round(period, 3), round(peak, 3), round(grain, 4), round(mottle, 4),
                       round(w * pix_mm, 2), round(h * pix_mm, 2), comps)


def banding_period(area: np.ndarray, pix_mm: float) -> float:
    """The fundamental period (mm) of the periodic banding: the lag at which the strip's
    lightness profile along the feed (row means, trend removed, smoothed below 1/3 mm)
    best matches itself, per overlapping row, searched from PERIOD_MIN_MM to a third of the
    strip; a period's multiples match too, so the shortest lag within 10 % of the best is
    taken, refined by a parabola through its neighbours.  0 when nothing periodic stands out."""
    import cv2
    h = area.shape[0]
    y = np.arange(h, dtype=np.float64)
    p = area.mean(axis=1).astype(np.float64)
    p = p - np.polyval(np.polyfit(y, p, 1), y)
    p = cv2.GaussianBlur(p[:, None], (1, 0), sigmaX=0.1, sigmaY=PERIOD_SMOOTH_MM / pix_mm)[:, 0]
    n = 1 << int(math.ceil(math.log2(2 * h)))
    f = np.fft.rfft(p, n)
    ac = np.fft.irfft(np.abs(f) ** 2, n)[:h] / (h - np.arange(h))      # per overlapping row
    lo, hi = int(math.ceil(PERIOD_MIN_MM / pix_mm)), int(min(PERIOD_MAX_MM, h * pix_mm / 3) / pix_mm)
    if hi <= lo + 2 or ac[0] <= 0:
        return 0.0
    seg = ac[lo:hi]
    best = seg.max()
    if best < PERIOD_MIN_CORR * ac[0]:
        return 0.0
    peaks = [i for i in range(1, len(seg) - 1) if seg[i] >= seg[i - 1] and seg[i] >= seg[i + 1]
             and seg[i] >= 0.9 * best]
    i = peaks[0] if peaks else int(np.argmax(seg))
    lag = float(lo + i)
    if 0 < i < len(seg) - 1:                     # a parabola through the peak and its neighbours
        a, b, c = seg[i - 1], seg[i], seg[i + 1]
        if a - 2 * b + c < 0:
            lag += 0.5 * (a - c) / (a - 2 * b + c)
    return float(lag * pix_mm)


def _amplitude(freqs: np.ndarray, power: np.ndarray, f0: float) -> float:
    """The peak amplitude (ΔL*) of a sinusoid at f0: the power of the Hann window's main lobe
    around it (± 2 bins), a sinusoid of amplitude a having a variance of a² / 2."""
    df = freqs[1] - freqs[0]
    near = np.abs(freqs - f0) <= 2.0 * df
    return math.sqrt(2.0 * float(power[near].sum()))


# -- a scan -------------------------------------------------------------------------------
@dataclass
class QualityReport:
    scan: str
    scan_dpi: float
    viewing_mm: float
    tints: list[TintQuality]
    periods: dict[str, float]

    def summary(self) -> dict:
        """The figures over the chart's tints (the K frame bars left out): mean visual
        banding, graininess and mottle, and the worst tint's banding."""
        t = [q for q in self.tints if not q.name.startswith("bar")] or self.tints
        return dict(banding=round(float(np.mean([q.banding for q in t])), 4),
                    banding_max=round(float(max(q.banding for q in t)), 4),
                    graininess=round(float(np.mean([q.graininess for q in t])), 4),
                    mottle=round(float(np.mean([q.mottle for q in t])), 4))

    def as_dict(self) -> dict:
        return dict(scan=self.scan, scan_dpi=self.scan_dpi, viewing_distance_mm=self.viewing_mm,
                    periods_mm=self.periods, summary=self.summary(),
                    tints=[asdict(q) for q in self.tints])

    def text(self) -> str:
        out = [f"{self.scan}: {len(self.tints)} flat tints at {self.scan_dpi:g} dpi, viewed from "
               f"{self.viewing_mm:g} mm (docs/quality.md)"]
        if self.periods:
            out.append("weave periods: " + ", ".join(f"{k} {v:.3f} mm" for k, v in self.periods.items()))
        out.append(f"{'tint':<12} {'L*':>6} {'banding':>8} {'period':>8} {'grain':>7} {'mottle':>7}")
        for q in self.tints:
            out.append(f"{q.name:<12} {q.lightness:6.1f} {q.banding:8.3f} {q.period_mm:7.2f}mm "
                       f"{q.graininess:7.3f} {q.mottle:7.3f}")
        s = self.summary()
        out.append(f"mean: banding {s['banding']:.3f} ΔL* (worst {s['banding_max']:.3f}), "
                   f"graininess {s['graininess']:.3f}, mottle {s['mottle']:.3f}")
        return "\n".join(out)


def weave_periods(passes: int, profile=None) -> dict[str, float]:
    """The periods along the feed a weave of `passes` prints with (mm): the advance (one
    feed: every row's nozzles repeat) and the swath (the head's whole run, passes x advance)."""
    from ..rip.profile import load_profile
    profile = profile if profile is not None else load_profile()
    s0, s1 = profile.usable_slots()
    advance = (s1 - s0) // passes
    return {"advance": round(advance * profile.row_um / 1000.0, 4),
            "swath": round(passes * advance * profile.row_um / 1000.0, 4)}


def chart_names(n: int) -> list[str] | None:
    """The banding chart's strip names when the scan shows its strips and two bars."""
    from ..rip.testprints import BANDING_TINTS
    names = [t[0] for t in BANDING_TINTS]
    if n == len(BANDING_TINTS) + 2:            # the K bars wide enough to be strips
        return ["bar left"] + names + ["bar right"]
    return names if n == len(BANDING_TINTS) else None


def measure_scan(path: str, scan_dpi: float | None = None, viewing_mm: float = VIEWING_MM,
                 passes: int | None = None, profile=None) -> QualityReport:
    """Find the flat tints of a scan and measure each (docs/quality.md)."""
    light, dpi = read_lightness(path, scan_dpi)
    pix = 25.4 / dpi
    strips = find_strips(light, pix)
    names = chart_names(len(strips))
    periods = weave_periods(passes, profile) if passes else {}
    tints = []
    for i, s in enumerate(strips):
        area = light[s.y0:s.y1, s.x0:s.x1]
        tints.append(measure_area(names[i] if names else s.name, area, pix, viewing_mm, periods))
    return QualityReport(path, dpi, viewing_mm, tints, periods)


def lightness_from_levels(levels: np.ndarray, white: np.ndarray) -> np.ndarray:
    """Scan levels (H, W, bands) 0..255 and the paper's per band -> L* relative to paper
    (docs/quality.md "Lightness")."""
    v = (np.clip(levels, 0, 255) / 255.0) ** GAMMA
    w = (np.asarray(white, np.float64) / 255.0) ** GAMMA
    if v.shape[2] >= 3:
        y, yw = v[:, :, :3] @ LUMA, float(w[:3] @ LUMA)
    else:
        y, yw = v[:, :, 0], float(w[0])
    return _lstar(y / max(yw, 1e-6))


def measure_registered(light: np.ndarray, to_scan: np.ndarray, pix_um: float,
                       patches: list[tuple[str, float, float, float, float]],
                       viewing_mm: float = VIEWING_MM, periods: dict[str, float] | None = None
                       ) -> list[TintQuality]:
    """The chart's tints where a registration puts them: `to_scan` the 2 x 3 map from the
    image frame (µm) to scan pixels, each patch (name, x0, y0, x1, y1) in µm.  Each patch is
    resampled onto the image frame at the scan's pitch (rows along the feed, straight
    whatever the scan's rotation), less INSET_MM at every edge, and measured."""
    import cv2
    inset = INSET_MM * 1000.0
    light_y = _luminance(light).astype(np.float32)
    out = []
    for name, x0, y0, x1, y1 in patches:
        x0, y0, x1, y1 = x0 + inset, y0 + inset, x1 - inset, y1 - inset
        w, h = int((x1 - x0) / pix_um), int((y1 - y0) / pix_um)
        if w < 8 or h < 8:
            raise QualityError(f"{name}: the patch is too small to measure")
        frame = np.array([[pix_um, 0.0, x0 + pix_um / 2], [0.0, pix_um, y0 + pix_um / 2], [0, 0, 1]])
        m = np.asarray(to_scan, np.float64) @ frame                 # patch pixel -> scan pixel
        # resampled in light: interpolating lightness would bias its mean by the grain
        area = cv2.warpAffine(light_y, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)
        out.append(measure_area(name, _lstar(area), pix_um / 1000.0, viewing_mm, periods))
    return out


# -- the command --------------------------------------------------------------------------
def scan_failure(exc: Exception, command: str, where: str) -> int:
    """Why a command that measures a scan (`quality`, `calibrate`) failed, said on stderr,
    and its exit status: bad input (an argument, the profile, a file that cannot be read:
    ValueError, ProfileError, OSError) is a usage error, 2, said as `wideprint COMMAND: ...`;
    anything else the command raised (what it looked for not found on the scan) is 3, said
    with `where` (the scan, the pattern measured)."""
    if isinstance(exc, (ValueError, OSError)):      # ProfileError is a ValueError
        print(f"wideprint {command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print(f"wideprint {where}: {exc}", file=sys.stderr)
    return EXIT_NOT_FOUND


def cmd_quality(args) -> int:
    from ..rip.profile import ProfileError, load_profile
    try:
        profile = load_profile(args.profile) if args.profile else None
        rep = measure_scan(args.scan, args.scan_dpi, args.viewing_distance_mm, args.passes, profile)
    except (ValueError, ProfileError, OSError, QualityError) as exc:
        return scan_failure(exc, "quality", f"quality: {args.scan}")
    print(json.dumps(rep.as_dict(), ensure_ascii=False) if args.json else rep.text())
    return EXIT_OK
