"""A scan of a print against the physical model's prediction (docs/acceptance.md, "A scan
against the prediction"): how an acceptance test checks a real printer whose media cannot
be read back.

The prediction is the emulator's scan of the same job on a perfect machine without sensor
noise (device_sim/physical.py + scanner.py).  The supplied scan is registered onto it
(OpenCV's ECC, an affine map: the sheet's rotation, offset and the scanner's scale), then
compared where the print is, in three ways, each with a stated tolerance:
- ink density: block means of each band's darkness (R ~ cyan, G ~ magenta, B ~ yellow,
  black in all) over blocks of `block_mm`;
- rows: the darkness of every scan row across the print (a dead or weak nozzle leaves a
  light line along the carriage travel in every stroke; a feed error, lines at the seams);
- dot positions: the sideways shift of each band of `band_mm` of rows against the
  prediction (a bidirectional error moves every reverse stroke's dots).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

BANDS = "RGB"


@dataclass(frozen=True)
class ScanTolerances:
    """What a good print may differ from the prediction by (docs/acceptance.md)."""
    density: float = 0.08        # block mean darkness, fraction of paper white
    block_mm: float = 2.0
    row: float = 0.055           # a scan row's mean darkness over the print, fraction of white
    edge_mm: float = 0.25        # rows this near the print's top and bottom edge: not row-checked
    shift_um: float = 25.0       # sideways shift of a band of rows
    band_mm: float = 1.0
    max_rotation_deg: float = 5.0
    max_scale_error: float = 0.02
    min_correlation: float = 0.9  # of the registered scan with the prediction


@dataclass
class ScanComparison:
    ok: bool = False
    dpi: float = 0.0
    rotation_deg: float = 0.0
    scale: float = 1.0
    offset_mm: tuple = (0.0, 0.0)
    correlation: float = 0.0
    density_worst: list = field(default_factory=lambda: [0.0] * 3)   # per band R, G, B (or grey)
    density_where_mm: list = field(default_factory=lambda: [(0.0, 0.0)] * 3)
    row_worst: float = 0.0
    row_where_mm: float = 0.0
    shift_worst_um: float = 0.0
    shift_where_mm: float = 0.0
    problems: list = field(default_factory=list)
    tolerances: ScanTolerances = field(default_factory=ScanTolerances)

    def explain(self) -> str:
        t = self.tolerances
        head = (f"scan {'matches' if self.ok else 'does not match'} the prediction "
                f"(registered: rotation {self.rotation_deg:.3f}°, scale {self.scale:.4f}, offset "
                f"{self.offset_mm[0]:.2f}, {self.offset_mm[1]:.2f} mm, correlation {self.correlation:.3f})")
        lines = [head]
        lines += [f"  {p}" for p in self.problems]
        bands = BANDS if len(self.density_worst) == 3 else ["grey"]
        lines.append("  worst: density " + ", ".join(
            f"{b} {d:+.3f}" for b, d in zip(bands, self.density_worst))
            + f" (tolerance {t.density}); row {self.row_worst:+.3f} at {self.row_where_mm:.2f} mm "
            f"(tolerance {t.row}); shift {self.shift_worst_um:+.1f} um at {self.shift_where_mm:.2f} mm "
            f"(tolerance {t.shift_um} um)")
        return "\n".join(lines)


def scan_format(path) -> tuple[float, bool]:
    """(dpi, grey) of a scan TIFF: what its prediction must be made at."""
    import tifffile
    from .calibrate import CalibrationError
    with tifffile.TiffFile(str(path)) as tif:
        page = tif.pages[0]
        res, unit = page.tags.get("XResolution"), page.tags.get("ResolutionUnit")
        if res is None:
            raise CalibrationError(f"{path}: no resolution tags: the scan's dpi is unknown")
        num, den = res.value
        dpi = num / den * (2.54 if unit is not None and int(unit.value) == 3 else 1.0)
        return float(dpi), len(page.shape) == 2 or page.shape[-1] == 1


def _darkness(path) -> tuple[np.ndarray, float]:
    """(darkness (H, W, bands) as a fraction of paper white, dpi)."""
    from .calibrate import read_scan_white
    dark, white, dpi = read_scan_white(str(path))
    dark = dark / np.maximum(white, 1.0)[None, None, :]
    return dark.astype(np.float32), dpi


def _register(pred: np.ndarray, scan: np.ndarray) -> tuple[np.ndarray, float]:
    """The affine map of prediction pixels to scan pixels (2 x 3) and the ECC correlation:
    first at <= 1000 px (a translation from phase correlation to start), then at full size."""
    import cv2
    gp, gs = pred.mean(axis=2), scan.mean(axis=2)
    f = max(1, int(np.ceil(max(gp.shape) / 1000)))
    small = [cv2.resize(g, (g.shape[1] // f, g.shape[0] // f), interpolation=cv2.INTER_AREA)
             for g in (gp, gs)]
    h, w = max(small[0].shape[0], small[1].shape[0]), max(small[0].shape[1], small[1].shape[1])
    pads = [np.pad(s, ((0, h - s.shape[0]), (0, w - s.shape[1]))) for s in small]
    (dx, dy), _ = cv2.phaseCorrelate(pads[0].astype(np.float64), pads[1].astype(np.float64))
    M = np.array([[1, 0, dx], [0, 1, dy]], np.float32)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
    try:
        _, M = cv2.findTransformECC(small[0], small[1], M, cv2.MOTION_AFFINE, crit, None, 5)
        M[:, 2] *= f
        rho, M = cv2.findTransformECC(gp, gs, M, cv2.MOTION_AFFINE,
                                      (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-7),
                                      None, 3)
    except cv2.error as exc:
        why = getattr(exc, "err", None) or str(exc).strip().splitlines()[-1]
        raise ValueError(f"registration: the scan could not be registered onto the prediction "
                         f"({why}): it does not show this job") from None
    return M, float(rho)


def _block_means(a: np.ndarray, step: int) -> np.ndarray:
    h, w = a.shape[0] // step * step, a.shape[1] // step * step
    return a[:h, :w].reshape(h // step, step, w // step, step, *a.shape[2:]).mean(axis=(1, 3))


def compare_scan(scan, predicted, tolerances: ScanTolerances | None = None) -> ScanComparison:
    """Compare a scan (a TIFF with its resolution) with the predicted scan of the same job."""
    import cv2
    t = tolerances or ScanTolerances()
    pred, dpi = _darkness(predicted)
    got, sdpi = _darkness(scan)
    if abs(sdpi / dpi - 1) > 0.01:           # the finer of the two brought to the coarser's dpi
        fine, f = (pred, sdpi / dpi) if sdpi < dpi else (got, dpi / sdpi)
        fine = cv2.resize(fine, (round(fine.shape[1] * f), round(fine.shape[0] * f)),
                          interpolation=cv2.INTER_AREA).reshape(-1, round(fine.shape[1] * f), fine.shape[2])
        pred, got = (fine, got) if sdpi < dpi else (pred, fine)
        dpi = min(dpi, sdpi)
    if pred.shape[2] != got.shape[2]:        # a grey scan: the prediction's bands averaged
        pred, got = (pred.mean(axis=2, keepdims=True) if pred.shape[2] > 1 else pred,
                     got.mean(axis=2, keepdims=True) if got.shape[2] > 1 else got)
    res = ScanComparison(dpi=dpi, tolerances=t)
    res.density_worst = [0.0] * pred.shape[2]
    res.density_where_mm = [(0.0, 0.0)] * pred.shape[2]
    try:
        M, res.correlation = _register(pred, got)
    except ValueError as exc:
        res.problems.append(str(exc))
        return res
    A = M[:, :2].astype(np.float64)
    res.scale = float(np.sqrt(abs(np.linalg.det(A))))
    res.rotation_deg = float(np.degrees(np.arctan2(A[1, 0], A[0, 0])))
    pix_mm = 25.4 / dpi
    res.offset_mm = (float(M[0, 2] * pix_mm), float(M[1, 2] * pix_mm))
    if abs(res.rotation_deg) > t.max_rotation_deg or abs(res.scale - 1) > t.max_scale_error:
        res.problems.append(f"registration: the scan lies at {res.rotation_deg:.2f}° and scale "
                            f"{res.scale:.4f} against the prediction (limits {t.max_rotation_deg}°, "
                            f"{t.max_scale_error}): another job or a wrong resolution?")
    if res.correlation < t.min_correlation:
        res.problems.append(f"registration: correlation {res.correlation:.3f} with the prediction "
                            f"(at least {t.min_correlation}): the scan does not show this job")
    h, w = pred.shape[:2]
    warped = cv2.warpAffine(got, M, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0).reshape(h, w, -1)
    # where the print is: the prediction's inked area, with a margin of one block
    ink = pred.max(axis=2) > 0.02
    rows_in, cols_in = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    if rows_in.size == 0:
        res.problems.append("the prediction is blank: nothing to compare")
        return res
    r0, r1, c0, c1 = rows_in[0], rows_in[-1] + 1, cols_in[0], cols_in[-1] + 1
    diff = warped[r0:r1, c0:c1] - pred[r0:r1, c0:c1]
    # 1. density, block by block, per band
    step = max(1, int(round(t.block_mm / pix_mm)))
    blocks = _block_means(diff, step)
    bands = BANDS if pred.shape[2] == 3 else ["grey"]
    for b in range(pred.shape[2]):
        d = blocks[..., b]
        i = np.unravel_index(np.argmax(np.abs(d)), d.shape) if d.size else (0, 0)
        res.density_worst[b] = float(d[i]) if d.size else 0.0
        res.density_where_mm[b] = ((c0 + (i[1] + 0.5) * step) * pix_mm,
                                   (r0 + (i[0] + 0.5) * step) * pix_mm)
        if abs(res.density_worst[b]) > t.density:
            x, y = res.density_where_mm[b]
            res.problems.append(f"density: band {bands[b]} {res.density_worst[b]:+.3f} of white "
                                f"against the prediction in the {t.block_mm} mm block at "
                                f"{x:.1f}, {y:.1f} mm (tolerance {t.density})")
    # 2. rows across the print
    rows = diff.max(axis=2).mean(axis=1) if diff.shape[1] else np.zeros(0)
    rows_min = diff.min(axis=2).mean(axis=1) if diff.shape[1] else np.zeros(0)
    prof = np.where(np.abs(rows_min) > np.abs(rows), rows_min, rows)
    # a sub-pixel registration error where the print's rows change (its top and bottom, a
    # horizontal edge in the image) would look like a row error: those rows are left out
    edge = int(round(t.edge_mm / pix_mm))
    pm = pred[r0:r1, c0:c1].max(axis=2).mean(axis=1)
    steep = np.abs(np.gradient(pm)) > 0.03 if pm.size > 1 else np.zeros(pm.size, bool)
    steep[:edge], steep[pm.size - edge:] = True, True
    near = np.convolve(steep.astype(float), np.ones(2 * edge + 1), "same") > 0
    prof = np.where(near, 0.0, prof)
    if prof.size:
        i = int(np.argmax(np.abs(prof)))
        res.row_worst, res.row_where_mm = float(prof[i]), (r0 + i) * pix_mm
        if abs(res.row_worst) > t.row:
            res.problems.append(
                f"rows: the scan row at {res.row_where_mm:.2f} mm is {abs(res.row_worst):.3f} of "
                f"white {'lighter' if res.row_worst < 0 else 'darker'} across the print than "
                f"predicted (tolerance {t.row}): a nozzle that does not fire (or fires where it "
                f"should not), or a feed error")
    # 3. dot positions: each band of rows' sideways shift
    band = max(4, int(round(t.band_mm / pix_mm)))
    pg, wg = pred[r0:r1, c0:c1].mean(axis=2), warped[r0:r1, c0:c1].mean(axis=2)
    win = cv2.createHanningWindow((pg.shape[1], band), cv2.CV_64F) if pg.shape[1] > 1 else None
    for y in range(0, pg.shape[0] - band + 1, band):
        a, b = pg[y:y + band], wg[y:y + band]
        if a.std() < 0.02:                    # no detail in this band to measure by
            continue
        (dx, _), resp = cv2.phaseCorrelate(a.astype(np.float64), b.astype(np.float64), win)
        if resp < 0.1:
            continue
        um = dx * pix_mm * 1000
        if abs(um) > abs(res.shift_worst_um):
            res.shift_worst_um, res.shift_where_mm = um, (r0 + y + band / 2) * pix_mm
    if abs(res.shift_worst_um) > t.shift_um:
        res.problems.append(f"dot positions: the rows at {res.shift_where_mm:.2f} mm lie "
                            f"{res.shift_worst_um:+.1f} um sideways of the prediction (tolerance "
                            f"{t.shift_um} um): a bidirectional or head alignment error")
    res.ok = not res.problems
    return res
