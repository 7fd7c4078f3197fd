"""`wideprint calibrate nozzles|bidir|heads|feed|wedge|banding --scan SCAN.tif`: calibration
from a scan of a test print (docs/calibration.md; the wedge: docs/color.md "Linearisation";
the banding chart, measured and not written: docs/quality.md).

The pattern is rebuilt from the profile, dpi and width it was printed with
(`rip.testprints.scan_layout`), so every mark's model position is known. In the scan the
two K frame bars are found (OpenCV connected components), the scanner's similarity
transform is estimated from them (cv2.estimateAffinePartial2D), and every mark's
darkness-weighted centroid or ink is read through it. What was measured is reported, and
with --write stored in the printer profile (rip.profile.save_calibration).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..rip.profile import FINE_STEPS, Profile, ProfileError, load_profile, save_calibration
from ..rip.testpatterns import CALIBRATION_KINDS as KINDS

if TYPE_CHECKING:      # the patterns import the RIP's kernels: not for `wideprint --help`
    from ..rip.testprints import Mark, ScanLayout

EXIT_OK, EXIT_USAGE, EXIT_NOT_FOUND = 0, 2, 3
BAND = (0, 1, 2, 1)          # the scan band each ink darkens most: C red, M green, Y blue, K
NOISE_LEVELS = 6.0           # darkness below this is paper (four σ of a 1.5-level noise)
DEAD_FRACTION = 0.35         # a dash with less ink than this of its head's median is dead
MARK_MARGIN_UM = 250.0       # around an x or y mark's cells: the dot, the blur, the error
REFERENCE_HEAD = "K1"
TRIM_NOISE_UM = 1.0          # head trims below this are not written (the measurement's noise)


class CalibrationError(Exception):
    """The pattern was not found in the scan, or could not be measured."""


# -- the scan -----------------------------------------------------------------------------------
def read_scan(path: str, scan_dpi: float | None = None) -> tuple[np.ndarray, float]:
    """(darkness per band (H, W, bands) float32, scan dpi).  Darkness is paper white less
    the value, in 8-bit levels; the white is each band's 90th percentile."""
    dark, _, dpi = read_scan_white(path, scan_dpi)
    return dark, dpi


def read_scan_white(path: str, scan_dpi: float | None = None):
    """read_scan's darkness, the paper white per band (levels) and the scan dpi."""
    import tifffile
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        img = page.asarray()
        if scan_dpi is None:
            tags = page.tags
            res = tags.get("XResolution")
            unit = tags.get("ResolutionUnit")
            if res is None:
                raise CalibrationError(f"{path}: no resolution tags; give --scan-dpi")
            num, den = res.value
            scan_dpi = num / den * (2.54 if unit is not None and int(unit.value) == 3 else 1.0)
    if img.dtype != np.uint8:
        img = (img / (np.iinfo(img.dtype).max / 255.0) if img.dtype.kind == "u"
               else img).astype(np.float32)
    img = img.astype(np.float32)
    if img.ndim == 2:
        img = img[:, :, None]
    img = img[:, :, :3]
    white = np.percentile(img[::4, ::4].reshape(-1, img.shape[2]), 90, axis=0)
    return np.clip(white[None, None, :] - img, 0, None), white, float(scan_dpi)


@dataclass
class Registration:
    """The scanner's similarity transform: model µm (image frame) -> scan pixels."""
    M: np.ndarray            # 2 x 3
    pix: float               # nominal µm per scan pixel

    @property
    def rotation_deg(self) -> float:
        return math.degrees(math.atan2(self.M[1, 0], self.M[0, 0]))

    @property
    def scale(self) -> float:
        """The scanner's true resolution / its nominal one."""
        return math.hypot(self.M[0, 0], self.M[1, 0]) * self.pix

    def to_scan(self, x_um, y_um):
        M = self.M
        return M[0, 0] * x_um + M[0, 1] * y_um + M[0, 2], M[1, 0] * x_um + M[1, 1] * y_um + M[1, 2]

    def to_model(self, u, v):
        A = np.linalg.inv(self.M[:, :2])
        du, dv = u - self.M[0, 2], v - self.M[1, 2]
        return A[0, 0] * du + A[0, 1] * dv, A[1, 0] * du + A[1, 1] * dv


@dataclass
class Measured:
    """One mark measured: its model and measured centroids (µm) and its ink."""
    mark: Mark
    model: tuple[float, float]
    got: tuple[float, float] | None      # None: no ink
    ink: float

    @property
    def dx(self) -> float:
        return self.got[0] - self.model[0]

    @property
    def dy(self) -> float:
        return self.got[1] - self.model[1]


class Scan:
    """A scan of a pattern, registered: marks are measured in the image frame."""

    def __init__(self, dark: np.ndarray, scan_dpi: float, layout: ScanLayout, profile: Profile,
                 dpi: int, white: np.ndarray | None = None):
        self.dark, self.layout, self.profile = dark, layout, profile
        self.white = np.full(dark.shape[2], 255.0) if white is None else np.asarray(white)
        self.pix = 25_400.0 / scan_dpi
        self.col_um = profile.k(dpi) * 25_400.0 / profile.counts_per_inch
        self.row_um = profile.row_um
        self.grey = dark.shape[2] == 1
        self.reg = self._register()
        self.passes: int | None = None  # the weave of a banding chart (its periods)
        self.path = "the scan"          # its file, for messages (calibrate sets it)

    def band(self, channel: int) -> np.ndarray:
        return self.dark[:, :, 0 if self.grey else BAND[channel]]

    def model_centroid(self, m: Mark) -> tuple[float, float]:
        """Mean cell centre of the mark's dots (µm, image frame)."""
        rr, cc = np.nonzero(self.layout.planes[m.r0:m.r1, m.c0:m.c1, m.channel])
        if m.kind == "bar":
            rr, cc = np.nonzero(self.layout.planes[m.r0:m.r1, m.c0:m.c1].any(axis=2))
        return (float((cc + m.c0 + 0.5).mean() * self.col_um),
                float((rr + m.r0 + 0.5).mean() * self.row_um))

    def window(self, m: Mark, margin_x: float, margin_y: float, img: np.ndarray,
               reg: Registration | None = None):
        """(weights, model x, model y) of the scan pixels whose model position lies in the
        mark's cells widened by the margins (µm)."""
        reg = reg or self.reg
        x0, x1 = m.c0 * self.col_um - margin_x, m.c1 * self.col_um + margin_x
        y0, y1 = m.r0 * self.row_um - margin_y, m.r1 * self.row_um + margin_y
        u, v = reg.to_scan(np.array([x0, x1, x0, x1]), np.array([y0, y0, y1, y1]))
        h, w = img.shape[:2]
        u0, u1 = max(0, int(math.floor(u.min()))), min(w, int(math.ceil(u.max())) + 1)
        v0, v1 = max(0, int(math.floor(v.min()))), min(h, int(math.ceil(v.max())) + 1)
        if u1 <= u0 or v1 <= v0:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        vv, uu = np.mgrid[v0:v1, u0:u1].astype(np.float64)
        mx, my = reg.to_model(uu, vv)
        inside = (mx >= x0) & (mx < x1) & (my >= y0) & (my < y1)
        wgt = np.clip(img[v0:v1, u0:u1].astype(np.float64) - NOISE_LEVELS, 0, None) * inside
        return wgt, mx, my

    def _register(self) -> Registration:
        import cv2
        allink = self.dark.max(axis=2)
        top = float(np.percentile(allink, 99.9))
        if top < 4 * NOISE_LEVELS:
            raise CalibrationError("the scan is blank: no pattern found")
        binary = (allink > max(2 * NOISE_LEVELS, 0.4 * top)).astype(np.uint8)
        close = max(3, int(round(250.0 / self.pix)) | 1)          # the bar's rows merge
        binary = cv2.morphologyEx(binary, cv2.MORPH_CLOSE, np.ones((close, close), np.uint8))
        n, labels, stats, cents = cv2.connectedComponentsWithStats(binary, connectivity=8)
        if n < 3:
            raise CalibrationError("the pattern's frame bars were not found in the scan")
        order = np.argsort(stats[1:, cv2.CC_STAT_AREA])[::-1][:2] + 1
        bars = self.layout.bars
        want = [(b.c1 - b.c0) * self.col_um * (b.r1 - b.r0) * self.row_um / self.pix ** 2
                for b in bars]
        # the bars are the two objects of a bar's size farthest left and right: a chart of
        # dark tints (the banding chart) has larger objects between them
        areas = stats[1:, cv2.CC_STAT_AREA]
        fits = np.flatnonzero((areas >= 0.4 * min(want)) & (areas <= 2.5 * max(want))) + 1
        if len(fits) >= 2:
            order = np.array([fits[np.argmin(cents[fits, 0])], fits[np.argmax(cents[fits, 0])]])
        for i in order:
            area = stats[i, cv2.CC_STAT_AREA]
            if not 0.4 * min(want) <= area <= 2.5 * max(want):
                raise CalibrationError(
                    f"the pattern's frame bars were not found in the scan (the largest dark "
                    f"object is {area * self.pix ** 2 / 1e6:.1f} mm², a bar "
                    f"{want[0] * self.pix ** 2 / 1e6:.1f} mm²): is it the right pattern, dpi and width?")
        found = sorted((cents[i] for i in order), key=lambda c: c[0])     # left, right
        model = np.array([self.model_centroid(b) for b in bars])
        src, dst = model.astype(np.float32), np.array(found, np.float32)
        coarse = Registration(self._similarity(src, dst), self.pix)
        # the bars' darkness-weighted centroids, each in its own window
        fine = []
        for b in bars:
            wgt, mx, my = self.window(b, 150.0, 150.0, allink, coarse)
            if wgt.sum() <= 0:
                raise CalibrationError("a frame bar lies outside the scan")
            u, v = coarse.to_scan((wgt * mx).sum() / wgt.sum(), (wgt * my).sum() / wgt.sum())
            fine.append((u, v))
        reg = Registration(self._similarity(src, np.array(fine, np.float32)), self.pix)
        if abs(reg.rotation_deg) > 10 or not 0.9 < reg.scale < 1.1:
            raise CalibrationError(f"the pattern lies at {reg.rotation_deg:.1f}° and scale "
                                   f"{reg.scale:.3f} on the scan: not this pattern?")
        return reg

    @staticmethod
    def _similarity(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
        import cv2
        M, _ = cv2.estimateAffinePartial2D(src.reshape(-1, 1, 2), dst.reshape(-1, 1, 2),
                                           method=cv2.LMEDS)
        if M is None:
            raise CalibrationError("the frame bars give no transform")
        return M

    def reflectance(self, m: Mark, inset: float = 0.2) -> float:
        """The mean linear reflectance (sRGB decoded, 0..1) in the ink's band over the mark's
        cells less `inset` of its size on every side, sampled on a model grid at the scan's
        pixel pitch through the registration."""
        x0, x1 = m.c0 * self.col_um, m.c1 * self.col_um
        y0, y1 = m.r0 * self.row_um, m.r1 * self.row_um
        dx, dy = inset * (x1 - x0), inset * (y1 - y0)
        xs = np.arange(x0 + dx, x1 - dx, self.pix)
        ys = np.arange(y0 + dy, y1 - dy, self.pix)
        mx, my = np.meshgrid(xs, ys)
        u, v = self.reg.to_scan(mx, my)
        band = 0 if self.grey else BAND[m.channel]
        img = self.dark[:, :, band]
        h, w = img.shape
        ok = (u >= 0) & (u < w - 1) & (v >= 0) & (v < h - 1)
        if not ok.any():
            raise CalibrationError(f"a {m.head} patch lies outside the scan")
        level = self.white[band] - img[v[ok].round().astype(int), u[ok].round().astype(int)]
        x = np.clip(level / 255.0, 0, 1)
        return float(np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).mean())

    def measure(self, m: Mark) -> Measured:
        model = self.model_centroid(m)
        if m.kind == "dash":          # neighbours are a column and two rows away
            wgt, mx, my = self.window(m, -0.0, 0.5 * self.row_um, self.band(m.channel))
        else:
            wgt, mx, my = self.window(m, MARK_MARGIN_UM, MARK_MARGIN_UM, self.band(m.channel))
        ink = float(wgt.sum()) * self.pix ** 2
        if ink <= 0:
            return Measured(m, model, None, 0.0)
        return Measured(m, model, (float((wgt * mx).sum() / wgt.sum()),
                                   float((wgt * my).sum() / wgt.sum())), ink)


# -- the calibrations ---------------------------------------------------------------------------
@dataclass
class Result:
    kind: str
    dpi: int
    text: list[str] = field(default_factory=list)
    found: dict = field(default_factory=dict)          # for --json and tests
    write: dict = field(default_factory=dict)          # save_calibration keyword arguments


def _mean_std(v) -> tuple[float, float]:
    v = np.asarray(v, np.float64)
    return float(v.mean()), float(v.std())


def calibrate_nozzles(scan: Scan, res: Result) -> None:
    prof = scan.profile
    dead, weak = [], {}
    ms = [scan.measure(m) for m in scan.layout.marks]
    for h in prof.heads:
        mine = [m for m in ms if m.mark.head == h.name]
        ink = np.array([m.ink for m in mine])
        med = float(np.median(ink))
        if med <= 0:
            raise CalibrationError(f"head {h.name}: no ink found in its block")
        for m, v in zip(mine, ink):
            if v < DEAD_FRACTION * med:
                dead.append((h.name, m.mark.nozzle))
                weak[f"{h.name}:{m.mark.nozzle}"] = round(v / med, 3)
    names = [f"{h}:{z}" for h, z in dead]
    res.found = dict(dead=names, ink_fraction=weak, dashes=len(ms))
    res.text.append(f"nozzles: {len(ms)} dashes measured; "
                    + (f"{len(dead)} dead: {', '.join(names)}" if dead else "no dead nozzle"))
    res.write = dict(dead_nozzles=dead)
    nozzle_errors(scan, res, set(dead))


def nozzle_errors(scan: Scan, res: Result, dead: set[tuple[str, int]]) -> None:
    """Every nozzle's landing error and volume (app/nozzles.py), from a scan fine enough;
    the dead nozzles are the ones just found, stored as no drop, so the list and the
    measurement written together agree."""
    from datetime import datetime, timezone

    from .nozzles import MIN_SCAN_DPI, measure_nozzle_errors, summary
    scan_dpi = 25_400.0 / scan.pix
    if scan_dpi < MIN_SCAN_DPI - 0.5:
        why = (f"{scan.path}: a {scan_dpi:g} dpi scan is too coarse to measure the nozzles' "
               f"landing errors and drop volumes (needs {MIN_SCAN_DPI:g} dpi: print the nozzle "
               f"check with --scan-dpi {MIN_SCAN_DPI:g} or scan it at {MIN_SCAN_DPI:g} dpi); "
               "dead nozzles only")
        res.found["errors"] = None
        res.found["errors_refused"] = why
        res.text.append(why)
        return
    dy, volume = measure_nozzle_errors(scan, dead)
    when = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    heads = scan.profile.heads
    dy_um = {h.name: [round(float(v), 2) for v in dy[h.index]] for h in heads}
    pct = {h.name: [round(float(v), 2) for v in (volume[h.index] - 1.0) * 100.0] for h in heads}
    spread = summary(dy, volume)
    res.found["errors"] = dict(measured=when, dy_um=dy_um, volume_pct=pct, **spread)
    res.text.append(f"nozzle errors ({spread['nozzles']} nozzles, {scan_dpi:g} dpi): landing "
                    f"along the feed spread {spread['dy_spread_um']:.2f} µm, drop volume spread "
                    f"{spread['volume_spread_pct']:.2f} %; --pass-mask hiding plans with them")
    res.write["nozzle_errors"] = (dy_um, pct, when)


def _by_head(ms: list[Measured], stroke: int | None = None, kind: str = "x") -> dict:
    out: dict[str, list[Measured]] = {}
    for m in ms:
        if m.got is not None and m.mark.kind == kind and (stroke is None or m.mark.stroke == stroke):
            out.setdefault(m.mark.head, []).append(m)
    return out


def calibrate_bidir(scan: Scan, res: Result) -> None:
    prof, dpi, col = scan.profile, res.dpi, scan.col_um
    ms = [scan.measure(m) for m in scan.layout.marks]
    fwd, rev = _by_head(ms, 0), _by_head(ms, 1)
    per_head = {h: float(np.mean([m.dx for m in rev[h]]) - np.mean([m.dx for m in fwd[h]]))
                for h in fwd if h in rev}
    if not per_head:
        raise CalibrationError("no head printed segments in both strokes")
    d, sd = _mean_std(list(per_head.values()))
    old = prof.bidir_shift_columns(dpi)
    new = old - d / col
    steps = int(round(new * FINE_STEPS))
    whole, fine = int(round(steps / FINE_STEPS)), 0
    fine = steps - whole * FINE_STEPS
    res.found = dict(offset_um=round(d, 2), offset_columns=round(d / col, 4), spread_um=round(sd, 2),
                     per_head_um={h: round(v, 2) for h, v in per_head.items()},
                     correction_columns=round(steps / FINE_STEPS, 4),
                     bidir_offset_columns=whole, bidir_fine_steps=fine)
    res.text.append(f"bidir at {dpi} dpi: reverse strokes land {d:+.1f} µm ({d / col:+.3f} columns) "
                    f"from forward ones ({len(per_head)} heads, spread {sd:.1f} µm)")
    res.text.append(f"  correction: reverse strokes {steps / FINE_STEPS:+.4f} columns "
                    f"(bidir_offset_columns {whole}, bidir_fine_steps {fine}/{FINE_STEPS}; "
                    f"was {old:+.4f})")
    offs, fines = dict(prof.bidir_offset_columns), dict(prof.layout.bidir_fine_steps)
    offs[dpi], fines[dpi] = whole, fine
    res.write = dict(bidir_offset_columns=offs, bidir_fine_steps=fines)


def calibrate_heads(scan: Scan, res: Result) -> None:
    prof = scan.profile
    ms = [scan.measure(m) for m in scan.layout.marks]
    xs, ys = _by_head(ms, kind="x"), _by_head(ms, kind="y")
    ref = REFERENCE_HEAD if REFERENCE_HEAD in xs else prof.heads_of("K")[0].name
    if ref not in xs or ref not in ys:
        raise CalibrationError(f"the reference head {ref} printed nothing measurable")
    rx, ry = np.mean([m.dx for m in xs[ref]]), np.mean([m.dy for m in ys[ref]])
    pitch = prof.nozzle_pitch_um
    x_um, y_um = dict(prof.layout.head_x_um), {}
    y_rows, found = {}, {}
    res.text.append(f"heads (relative to {ref}; right and down the paper are +):")
    for h in prof.heads:
        if h.name not in xs or h.name not in ys:
            raise CalibrationError(f"head {h.name}: no marks measured")
        dx = float(np.mean([m.dx for m in xs[h.name]]) - rx)
        dy = float(np.mean([m.dy for m in ys[h.name]]) - ry)
        sx, sy = np.std([m.dx for m in xs[h.name]]), np.std([m.dy for m in ys[h.name]])
        found[h.name] = dict(x_um=round(dx, 2), y_um=round(dy, 2))
        new_x = x_um.get(h.name, 0.0) + dx       # the x trim is applied: dx is what is left
        pitches = int(round(dy / pitch)) if abs(dy) >= pitch / 2 else 0
        new_y = dy - pitches * pitch            # the y trim is not applied: dy is all of it
        line = f"  {h.name}: x {dx:+6.1f} µm (±{sx:.1f}), y {dy:+6.1f} µm (±{sy:.1f})"
        if pitches:
            y_rows[h.name] = h.y_rows + prof.heads_per_color * pitches
            line += f"; y_rows {h.y_rows} -> {y_rows[h.name]}"
        if abs(new_y) > 5.0:
            line += f"; adjust the head {-new_y:+.0f} µm along the feed (mechanically)"
        res.text.append(line)
        if h.name != ref and abs(dx) >= TRIM_NOISE_UM:      # below: measurement noise
            x_um[h.name] = round(new_x, 2)
        if abs(new_y) >= TRIM_NOISE_UM:
            y_um[h.name] = round(new_y, 2)
    res.found = dict(reference=ref, heads=found)
    res.write = dict(head_x_um={k: v for k, v in x_um.items() if abs(v) >= 0.005},
                     head_y_um=y_um)
    if y_rows:
        res.write["head_y_rows"] = y_rows


def feed_offsets(scan: Scan, res_strokes: int | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Per stroke of the feed pattern: the mean y displacement of its dashes (µm, stroke 0
    = 0), what the driver's whole-step feeds put there (the same), and the steps of one
    feed."""
    prof = scan.profile
    ms = [scan.measure(m) for m in scan.layout.marks]
    a = scan.layout.rows_per_stroke
    strokes = sorted({m.mark.stroke for m in ms})
    dy = np.array([np.mean([m.dy for m in ms if m.mark.stroke == s and m.got is not None])
                   for s in strokes])
    steps = np.array([prof.feed_steps_for_rows(s * a) for s in strokes])
    rounding = steps * prof.feed_um_per_step - np.array(strokes) * a * prof.row_um
    return dy - dy[0], rounding - rounding[0], int(round((steps[-1] - steps[0]) / (len(strokes) - 1)))


def calibrate_feed(scan: Scan, res: Result) -> None:
    prof = scan.profile
    dy, rounding, steps = feed_offsets(scan)
    i = np.arange(len(dy))
    place = float(np.polyfit(i, dy, 1)[0])                 # where each stroke lands
    extra = float(np.polyfit(i, dy - rounding, 1)[0])      # beyond what the steps say
    ppm = extra / (steps * prof.feed_um_per_step) * 1e6
    res.found = dict(placement_um_per_feed=round(place, 2), travel_error_um_per_feed=round(extra, 2),
                     steps_per_feed=steps, travel_error_ppm=round(ppm, 2),
                     stroke_offsets_um=[round(float(v), 2) for v in dy])
    res.text.append(f"feed: each stroke lands {place:+.1f} µm from where it should (strokes at "
                    + ", ".join(f"{v:+.1f}" for v in dy) + " µm)")
    res.text.append(f"  the paper travels {extra:+.1f} µm further than its {steps} steps "
                    f"per feed: {ppm:+.0f} ppm (profile: {prof.feed.travel_error_ppm:+.0f} ppm)")
    res.write = dict(travel_error_ppm=ppm)


def wedge_curve(old, steps, tone) -> list[tuple[float, float]]:
    """The curve that makes the measured wedge linear (docs/color.md "Linearisation"):
    the wedge was printed through `old` ([in, out] points), input v gave `tone[i]` at
    `steps[i]`; the new curve sends v to old(u), u the input whose tone was v / 255."""
    steps = np.asarray(steps, np.float64)
    t = np.maximum.accumulate(np.asarray(tone, np.float64))
    if not t[-1] > t[0]:
        raise CalibrationError("the wedge shows no tone: is it this pattern and ink?")
    t = (t - t[0]) / (t[-1] - t[0]) + np.arange(len(t)) * 1e-9    # strictly increasing
    u = np.interp(steps / 255.0, t, steps)
    u[0], u[-1] = steps[0], steps[-1]        # paper stays paper, the solid stays the solid
    old = np.asarray(old, np.float64)
    out = np.clip(np.interp(u, old[:, 0], old[:, 1]), 0, 255)
    return [(float(v), round(float(o), 2)) for v, o in zip(steps, out)]


def wedge_result(res: Result, profile: Profile, steps, tones: dict[str, list[float]]) -> None:
    """Per ink its tones (0..1 from paper to solid) -> the curves to write."""
    steps = list(steps)
    curves, found = {}, {}
    for ink, tone in tones.items():
        t = np.asarray(tone, np.float64)
        t = (t - t[0]) / (t[-1] - t[0]) if t[-1] != t[0] else t
        err = t - np.asarray(steps) / 255.0
        curves[ink] = wedge_curve(getattr(profile.curves, ink), steps, tone)
        found[ink] = dict(tone=[round(float(x), 4) for x in t],
                          max_error=round(float(np.abs(err).max()), 4))
        worst = int(np.abs(err).argmax())
        res.text.append(f"wedge {ink}: tone at " + ", ".join(
            f"{v}:{x * 100:.0f}%" for v, x in zip(steps, t)) + f"; worst {err[worst] * 100:+.1f} "
            f"points at {steps[worst]}")
        res.text.append(f"  curve {ink} = " + str([list(p) for p in curves[ink]]))
    res.found.update(steps=steps, inks=found)
    res.write = dict(curves=curves)


def calibrate_wedge(scan: Scan, res: Result) -> None:
    """Each patch's reflectance in its ink's band; its tone is the Murray-Davies dot area
    (paper - R) / (paper - solid), paper and solid the wedge's own 0 and 255 steps."""
    from ..rip.profile import COLORS
    from ..rip.testprints import WEDGE_STEPS
    tones = {}
    for ch, ink in enumerate(COLORS):
        refl = {m.nozzle: scan.reflectance(m) for m in scan.layout.marks
                if m.kind == "patch" and m.channel == ch}
        r = np.array([refl[v] for v in WEDGE_STEPS])
        tones[ink] = list((r[0] - r) / (r[0] - r[-1]) if r[0] > r[-1] else np.zeros_like(r))
    wedge_result(res, scan.profile, WEDGE_STEPS, tones)


def parse_values(items: list[str]) -> dict[str, list[float]]:
    """--values INK=T0,T1,... (one a WEDGE_STEPS amount): typed-in wedge measurements."""
    from ..rip.profile import COLORS
    from ..rip.testprints import WEDGE_STEPS
    out = {}
    for item in items:
        ink, sep, rest = item.partition("=")
        if not sep or ink not in COLORS:
            raise ValueError(f"--values {item!r}: must be INK=T0,T1,... with INK one of C, M, Y, K")
        try:
            vals = [float(x) for x in rest.split(",")]
        except ValueError:
            raise ValueError(f"--values {item!r}: the tones must be numbers") from None
        if len(vals) != len(WEDGE_STEPS):
            raise ValueError(f"--values {ink}: {len(vals)} tones given, the wedge has "
                             f"{len(WEDGE_STEPS)} steps ({', '.join(map(str, WEDGE_STEPS))})")
        if not vals[-1] > vals[0]:
            raise ValueError(f"--values {ink}: the last (solid) tone must exceed the first (paper)")
        out[ink] = vals
    return out


def calibrate_banding(scan: Scan, res: Result) -> None:
    """The banding chart's tints where the registration puts them: banding, graininess and
    mottle (app/quality.py, docs/quality.md); nothing to write."""
    from .quality import lightness_from_levels, measure_registered, weave_periods
    light = lightness_from_levels(scan.white[None, None, :] - scan.dark, scan.white)
    patches = [(m.head, m.c0 * scan.col_um, m.r0 * scan.row_um, m.c1 * scan.col_um,
                m.r1 * scan.row_um) for m in scan.layout.marks]
    periods = weave_periods(scan.passes, scan.profile) if scan.passes else None
    tints = measure_registered(light, scan.reg.M, scan.pix, patches, periods=periods)
    res.found["tints"] = {q.name: dict(banding=q.banding, period_mm=q.period_mm,
                                       graininess=q.graininess, mottle=q.mottle,
                                       lightness=q.lightness) for q in tints}
    for q in tints:
        res.text.append(f"{q.name:<10} L* {q.lightness:5.1f}  banding {q.banding:.3f} ΔL*"
                        + (f" (period {q.period_mm:.3f} mm)" if q.period_mm else "")
                        + f"  graininess {q.graininess:.3f}  mottle {q.mottle:.3f}")


CALIBRATIONS = {"nozzles": calibrate_nozzles, "bidir": calibrate_bidir,
                "heads": calibrate_heads, "feed": calibrate_feed, "wedge": calibrate_wedge,
                "banding": calibrate_banding}


def calibrate(kind: str, scan_path: str, profile: Profile, dpi: int = 150, width_mm: float = 100.0,
              scan_dpi: float | None = None, passes: int | None = None) -> Result:
    """Measure a scan of the `kind` pattern printed with `profile` at `dpi`, `width_mm`."""
    from ..rip.testprints import scan_layout
    k = profile.k(dpi)
    width = int(round(width_mm / 25.4 * profile.counts_per_inch / k))
    layout = scan_layout(KINDS[kind], profile, width, dpi)
    dark, white, sdpi = read_scan_white(scan_path, scan_dpi)
    scan = Scan(dark, sdpi, layout, profile, dpi, white)
    scan.passes = passes                # the banding chart's weave (its periods)
    scan.path = scan_path
    res = Result(kind, dpi)
    res.text.append(f"{scan_path}: {KINDS[kind]} at {dpi} dpi found on a {sdpi:g} dpi scan, "
                    f"rotated {scan.reg.rotation_deg:+.2f}°, scale {scan.reg.scale:.4f}")
    res.found["registration"] = dict(rotation_deg=round(scan.reg.rotation_deg, 4),
                                     scale=round(scan.reg.scale, 6))
    found = res.found
    CALIBRATIONS[kind](scan, res)
    res.found = {**found, **res.found}
    return res


# -- the command --------------------------------------------------------------------------------
def cmd_calibrate(args) -> int:
    try:
        profile = load_profile(args.profile)
        if args.write and not args.profile:
            raise ValueError("--write needs --profile: the printer profile to update "
                             "(a copy of the built-in one)")
        if args.values:
            if args.kind != "wedge" or args.scan:
                raise ValueError("--values is for `calibrate wedge`, instead of --scan")
            from ..rip.testprints import WEDGE_STEPS
            res = Result("wedge", args.dpi, ["wedge: typed-in tones"])
            wedge_result(res, profile, WEDGE_STEPS, parse_values(args.values))
        elif not args.scan:
            raise ValueError("--scan SCAN.tif is required" + (" (or --values)" if args.kind == "wedge" else ""))
        else:
            res = calibrate(args.kind, args.scan, profile, args.dpi, args.width_mm, args.scan_dpi,
                            getattr(args, "passes", None))
    except (ValueError, ProfileError, OSError, CalibrationError) as exc:
        from .quality import scan_failure
        return scan_failure(exc, "calibrate", f"calibrate {args.kind}")
    written = None
    if args.write:
        try:
            save_calibration(args.profile, **res.write)
            written = args.profile
        except ProfileError as exc:
            print(f"wideprint calibrate: {exc}", file=sys.stderr)
            return EXIT_USAGE
    if args.json:
        print(json.dumps(dict(kind=res.kind, dpi=res.dpi, found=res.found, written=written),
                         ensure_ascii=False))
    else:
        print("\n".join(res.text))
        print(f"written to {written}" if written else "(not written: --write stores it in --profile)")
    return EXIT_OK
