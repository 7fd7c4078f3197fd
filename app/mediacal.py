"""The closed colour loop on a printer (docs/media.md): charts printed and measured,
linearisation, the ink limit, the profile (ArgyllCMS), verification and recalibration.

Every chart is a CMYK (or, for verify, RGB) image of square patches that the RIP prints
like any job (its halftone, its curves) at one device pixel per dot; the emulator's
spectrophotometer (device_sim/spectro.py) measures it and `measure_patches` averages each
patch.  ArgyllCMS programs run as processes on CGATS files (app/argyll.py).
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from . import argyll
from .medialib import IDENTITY, INKS, Media, apply_to_profile

if TYPE_CHECKING:
    from ..rip.profile import Profile

PATCH_MM = 6.0                 # a patch's side: 4 mm measured inside a 1 mm inset
INSET_MM = 1.0
ACROSS = 40                    # patches per chart row (240 mm)
WEDGE_STEPS = tuple(range(0, 101, 5))            # percent, per ink
TAC_STEPS = tuple(range(160, 401, 20))           # percent, the ink-limit chart
SOLVENT_VINYL_MAX_TAC = 300.0                    # the most solvent vinyl takes (percent)
SPECTRO_DPI = 50
SCAN_DPI = 150                 # the flatbed's resolution for charts (patch means)
# a scanned chart's frame (docs/media.md "Measuring with the scanner"): a solid bar each
# side of the patches, found on the scan wherever and at whatever small angle the chart
# lies; 3 mm wide (no patch is narrower than 6 mm, so no cluster of patches looks like
# one), 3 mm of paper between bar and patches
BAR_MM = 3.0
BAR_GAP_MM = 3.0

Progress = Callable[[str], None]


def _quiet(_msg: str) -> None:
    pass


@dataclass
class Printer:
    """Where charts print: the in-process emulator with its spectrophotometer (a real
    printer would print each chart and wait for its measurement file)."""
    profile: Profile                    # the printer profile (rip/profile.py)
    dpi: int = 300
    passes: int = 1
    bidir: bool = False
    dither: str = "vced"
    inject: tuple[str, ...] = ()        # emulator faults (--inject), e.g. a drift
    workdir: Path | None = None
    last_ink_ml_m2: list | None = None  # the last chart's ink per m² of its area, per ink
    device: str = "emulator"            # where the charts print (app/devices.py specs)
    measure_dir: Path | None = None     # an outside instrument: charts and measurements here
    wait_s: float = 24 * 3600.0         # how long to wait for a chart's measurement file
    progress: Progress = _quiet
    scan_dpi: int | None = None         # also scan each chart (last_scan_rgb: patch means)
    scanner_icc: Path | None = None     # measure with the scanner through this input profile
    last_scan_rgb: np.ndarray | None = None
    bars: list = field(default_factory=list)   # the last chart's scan bars (mm), if framed

    def _settings(self, **more):
        from ..rip.settings import Placement, RipSettings
        return RipSettings(dpi=self.dpi, passes=self.passes, bidir=self.bidir,
                           dither=self.dither, placement=Placement(size="pixels"), **more)

    def patch_pixels(self) -> tuple[int, int]:
        """Columns and rows of one patch (PATCH_MM at the mode's dpi and the row pitch)."""
        return (round(PATCH_MM / 25.4 * self.dpi),
                round(PATCH_MM * 1000 / self.profile.row_um))

    def chart(self, values: np.ndarray, channels: int, framed: bool = False) -> tuple[np.ndarray, list]:
        """An image (rows, cols, channels) uint8 of the patches, ACROSS a row, and each
        patch's rectangle in mm of the image frame.  `framed`: with the scan's bars left and
        right (their rectangles in `self.bars`)."""
        pw, ph = self.patch_pixels()
        n = values.shape[0]
        across = min(ACROSS, n)
        down = math.ceil(n / across)
        col_mm, row_mm = 25.4 / self.dpi, self.profile.row_um / 1000
        bar = round(BAR_MM / col_mm) if framed else 0
        x0 = bar + round(BAR_GAP_MM / col_mm) if framed else 0
        img = np.zeros((down * ph, across * pw + 2 * x0, channels), np.uint8)
        if channels == 3:
            img[:] = 255
        self.bars = []
        if framed:
            solid = (0, 0, 0, 255) if channels == 4 else (0, 0, 0)
            for b0 in (0, img.shape[1] - bar):
                img[:, b0:b0 + bar] = solid
                self.bars.append((b0 * col_mm, 0.0, (b0 + bar) * col_mm, img.shape[0] * row_mm))
        rects = []
        for i in range(n):
            r, c = divmod(i, across)
            img[r * ph:(r + 1) * ph, x0 + c * pw:x0 + (c + 1) * pw] = values[i]
            rects.append(((x0 + c * pw) * col_mm, r * ph * row_mm, (x0 + (c + 1) * pw) * col_mm,
                          (r + 1) * ph * row_mm))
        return img, rects

    def measure(self, values: np.ndarray, profile=None, rgb_icc: str | None = None,
                output_icc: str | None = None, ink_limit: float | None = None,
                name: str = "chart") -> np.ndarray:
        """Print these patch values and measure them: Lab (n, 3).  CMYK values (n, 4) in
        0..255 print as they are (through `profile`'s curves); RGB values (n, 3) are
        separated through `rgb_icc` -> `output_icc` like any job."""
        import tifffile
        from ..device_sim.faults import Faults
        from ..device_sim.spectro import measure_patches
        from ..driver.job import PrintJob
        from ..rip.pipeline import RipJob
        from .devices import close_device, open_device
        profile = profile or self.profile
        values = np.asarray(values)
        measure_dir = self.measure_dir
        spectro = measure_dir is None
        # the emulated scanner scans when asked, or when it is the instrument; measured
        # outside, a scanner profile means the shop's own scanner may answer with a scan
        scan_dpi = self.scan_dpi or (SCAN_DPI if self.scanner_icc and spectro else None)
        outside_scan = not spectro and self.scanner_icc is not None
        img, rects = self.chart(values, values.shape[1], framed=bool(scan_dpi) or outside_scan)
        if measure_dir is not None:
            stale = Path(measure_dir) / f"{name}.ti3"
            stale.unlink(missing_ok=True)            # the measurement of an earlier print
        elif self.device != "emulator":
            raise ValueError(f"--device {self.device}: charts on a real printer are measured "
                             f"outside wideprint: give --measure-dir DIR")
        with tempfile.TemporaryDirectory(prefix="wideprint-media-", dir=self.workdir) as tmp:
            src = Path(tmp) / f"{name}.tif"
            tifffile.imwrite(src, img, photometric="separated" if img.shape[2] == 4 else "rgb",
                             resolution=(self.dpi, self.dpi))
            lab_path = str(Path(tmp) / f"{name}-lab.tif")
            settings = self._settings(input_icc=rgb_icc, output_icc=output_icc,
                                      ink_limit=ink_limit)
            job = RipJob(str(src), settings, profile)
            faults = Faults.parse(list(self.inject)) if self.device == "emulator" else None
            opts: dict[str, Any] = dict(spectro_path=lab_path, spectro_dpi=SPECTRO_DPI) \
                if spectro else {}
            scan_path = str(Path(tmp) / f"{name}-scan.tif")
            if scan_dpi:
                opts.update(scan_path=scan_path, scan_dpi=scan_dpi)
            dev = open_device(self.device, profile, faults, **opts)
            try:
                rep = PrintJob(dev, job).run()
                area_m2 = (job.width * 0.0254 / self.dpi) * (job.height * profile.row_um * 1e-6)
                self.last_ink_ml_m2 = [float(v) / area_m2 for v in rep.ink_ml]
            finally:
                close_device(dev)
                job.close()
            if scan_dpi:
                self.last_scan_rgb = scan_patches(scan_path, rects, scan_dpi, self.bars)
                if self.scanner_icc is not None:
                    return xicclu(self.scanner_icc, self.last_scan_rgb / 255.0, "f")[:, :3]
            if measure_dir is None:
                return measure_patches(lab_path, rects, inset_mm=INSET_MM)
            return await_measurements(Path(measure_dir), name, values, img, rects,
                                      self.dpi, self.wait_s, self.progress,
                                      scanner_icc=self.scanner_icc, bars=self.bars)


def find_chart(scan: np.ndarray, bars: list, dpi: float) -> np.ndarray:
    """The similarity transform (2 x 3: chart mm -> scan pixels) of a scanned chart, from
    its two bars wherever they lie (any offset, up to 10° and ±10 % scale): the dark
    objects whose rotated bounding box is a bar's width and length; their centres against
    the model's.  ValueError naming what was not found."""
    import cv2
    pix = 25.4 / dpi
    grey = scan.mean(axis=2) if scan.ndim == 3 else scan.astype(np.float64)
    paper, darkest = np.percentile(grey[::2, ::2], 90), np.percentile(grey[::2, ::2], 0.1)
    if paper - darkest < 40:
        raise ValueError("the scan is blank: no chart found")
    binary = (grey < (paper + darkest) / 2).astype(np.uint8)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    want_w, want_l = BAR_MM / pix, (bars[0][3] - bars[0][1]) / pix
    found = []
    for c in contours:
        if len(c) < 8:
            continue
        (cx, cy), (a, b), _ = cv2.minAreaRect(c)
        w, ln = min(a, b), max(a, b)
        if 0.6 * want_w <= w <= 1.5 * want_w and 0.85 * want_l <= ln <= 1.15 * want_l:
            found.append((cx, cy))
    if len(found) != 2:
        raise ValueError(f"the chart's two bars were not found on the scan ({len(found)} "
                         f"objects {BAR_MM:g} mm wide and {want_l * pix:.0f} mm long): is it "
                         f"this chart, at {dpi:g} dpi?")
    found.sort()                                           # left bar, right bar
    model = np.array([[(x0 + x1) / 2, (y0 + y1) / 2] for x0, y0, x1, y1 in bars], np.float64)
    d_m, d_s = model[1] - model[0], np.subtract(found[1], found[0])
    scale = np.hypot(*d_s) / np.hypot(*d_m)
    angle = math.atan2(d_s[1], d_s[0]) - math.atan2(d_m[1], d_m[0])
    if abs(math.degrees(angle)) > 10 or not 0.9 / pix < scale < 1.1 / pix:
        raise ValueError(f"the chart lies at {math.degrees(angle):.1f}° and scale "
                         f"{scale * pix:.3f} on the scan: not this chart?")
    rot = scale * np.array([[math.cos(angle), -math.sin(angle)],
                            [math.sin(angle), math.cos(angle)]])
    t = np.asarray(found[0]) - rot @ model[0]
    return np.hstack([rot, t[:, None]])


def scan_patches(path: str, rects: list, dpi: float, bars: list | None = None,
                 inset_mm: float = INSET_MM) -> np.ndarray:
    """Each patch's mean 8-bit RGB (n, 3) in a scan of the chart: with `bars`, the chart
    found on the scan wherever it lies (find_chart) and each patch sampled inside its inset
    through that transform; without, at its place in the emulated scanner's image area
    (its margin, no offset or rotation)."""
    import tifffile
    from ..device_sim.scanner import MARGIN_UM
    scan = tifffile.imread(path).astype(np.float64)
    if scan.ndim == 2:
        scan = scan[:, :, None]
    pix = 25.4 / dpi
    if bars:
        M = find_chart(scan, bars, dpi)
        out = []
        for x0, y0, x1, y1 in rects:          # a grid of points one scan pixel apart
            xs = np.arange(x0 + inset_mm, x1 - inset_mm, pix)
            ys = np.arange(y0 + inset_mm, y1 - inset_mm, pix)
            gx, gy = np.meshgrid(xs, ys)
            u = np.rint(M[0, 0] * gx + M[0, 1] * gy + M[0, 2]).astype(int)
            v = np.rint(M[1, 0] * gx + M[1, 1] * gy + M[1, 2]).astype(int)
            if u.min() < 0 or v.min() < 0 or u.max() >= scan.shape[1] or v.max() >= scan.shape[0]:
                raise ValueError("the chart runs off the scan: scan it whole")
            out.append(scan[v, u].reshape(-1, scan.shape[-1]).mean(axis=0))
        return np.array(out)
    margin = round(MARGIN_UM / 1000 / pix) * pix
    out = []
    for x0, y0, x1, y1 in rects:
        u0, v0 = math.ceil((x0 + inset_mm + margin) / pix), math.ceil((y0 + inset_mm + margin) / pix)
        u1, v1 = math.floor((x1 - inset_mm + margin) / pix), math.floor((y1 - inset_mm + margin) / pix)
        out.append(scan[v0:v1, u0:u1].reshape(-1, scan.shape[-1]).mean(axis=0))
    return np.array(out)


def scanner_profile(profile, folder: Path, patches: int = 600, seed: int = 11,
                    progress: Progress = _quiet, where: dict | None = None) -> Path:
    """Characterise the scanner: random CMYK patches printed once, measured by the
    spectrophotometer and scanned; colprof makes an input profile (scanner RGB -> XYZ
    cLUT) of the pairs: DIR/scanner.icc and scanner.ti3."""
    from ..device_sim.spectral import lab_to_xyz
    rng = np.random.default_rng(seed)
    levels = rng.integers(0, 256, (patches, 4)).astype(np.uint8)
    levels[levels.astype(int).sum(axis=1) > 765] //= 2            # keep within ~300 %
    levels[:8] = [[0, 0, 0, 0]] * 2 + [[255, 0, 0, 0], [0, 255, 0, 0], [0, 0, 255, 0],
                                       [0, 0, 0, 255], [255, 255, 0, 0], [0, 0, 0, 0]]
    pr = Printer(profile, scan_dpi=SCAN_DPI, **(where or {}))
    progress(f"scanner characterisation chart: {patches} patches, spectrophotometer and scan")
    lab = pr.measure(levels, profile, name="scanner")
    rgb = pr.last_scan_rgb
    assert rgb is not None
    xyz = lab_to_xyz(lab) * 100
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["CTI3   ", "", 'DESCRIPTOR "Argyll Calibration Target chart information 3"',
             'ORIGINATOR "wideprint media"', 'DEVICE_CLASS "INPUT"', 'COLOR_REP "XYZ_RGB"', "",
             "NUMBER_OF_FIELDS 7", "BEGIN_DATA_FORMAT",
             "SAMPLE_ID RGB_R RGB_G RGB_B XYZ_X XYZ_Y XYZ_Z", "END_DATA_FORMAT", "",
             f"NUMBER_OF_SETS {patches}", "BEGIN_DATA"]
    lines += [f"{i + 1} " + " ".join(f"{v / 2.55:.4f}" for v in c) + " "
              + " ".join(f"{v:.5f}" for v in x) for i, (c, x) in enumerate(zip(rgb, xyz))]
    lines += ["END_DATA", ""]
    (folder / "scanner.ti3").write_text("\n".join(lines))
    progress("colprof: the scanner's input profile")
    argyll.run("colprof", "-v", "-qm", "-ax", "-u", "scanner", cwd=folder)
    return folder / "scanner.icc"


def await_measurements(folder: Path, name: str, values: np.ndarray, img: np.ndarray,
                       rects: list, dpi: int, wait_s: float, progress: Progress = _quiet,
                       poll_s: float = 1.0, scanner_icc: Path | None = None,
                       bars: list | None = None) -> np.ndarray:
    """A chart measured by an outside instrument: the printed chart's image NAME.tif and
    its patches NAME.ti1 (CGATS: SAMPLE_ID, device values in percent, the patch's place in
    mm) go to `folder`; then wait for NAME.ti3 (as Argyll's chartread writes it: LAB_L/A/B
    or XYZ_X/Y/Z per SAMPLE_ID) or, with the scanner's input profile, for a scan of the
    chart NAME-scan.tif (its resolution tag gives the dpi; the chart is found by its bars)
    and return Lab (n, 3) in patch order (docs/media.md "A real printer, another
    instrument")."""
    import tifffile
    from ..device_sim.spectral import xyz_to_lab
    folder.mkdir(parents=True, exist_ok=True)
    tifffile.imwrite(folder / f"{name}.tif", img,
                     photometric="separated" if img.shape[2] == 4 else "rgb",
                     resolution=(dpi, dpi))
    cmyk = values.shape[1] == 4
    fields = (["CMYK_C", "CMYK_M", "CMYK_Y", "CMYK_K"] if cmyk else ["RGB_R", "RGB_G", "RGB_B"])
    fields = ["SAMPLE_ID", *fields, "X0_MM", "Y0_MM", "X1_MM", "Y1_MM"]
    rows = [f"{i + 1} " + " ".join(f"{v / 2.55:.5f}" for v in row) + " "
            + " ".join(f"{v:.3f}" for v in rect) for i, (row, rect) in enumerate(zip(values, rects))]
    (folder / f"{name}.ti1").write_text("\n".join(
        ["CTI1   ", "", 'DESCRIPTOR "wideprint chart: measure each patch, write NAME.ti3"',
         'ORIGINATOR "wideprint media"', f'COLOR_REP "{"CMYK" if cmyk else "RGB"}"', "",
         f"NUMBER_OF_FIELDS {len(fields)}", "BEGIN_DATA_FORMAT", " ".join(fields),
         "END_DATA_FORMAT", "", f"NUMBER_OF_SETS {len(rows)}", "BEGIN_DATA", *rows,
         "END_DATA", ""]))
    ti3 = folder / f"{name}.ti3"
    scans = [folder / f"{name}-scan.{ext}" for ext in ("tif", "tiff")]
    progress(f"    printed: measure {folder / name}.tif ({len(rows)} patches, "
             f"{folder / name}.ti1) and write {ti3}"
             + (f", or scan it whole to {scans[0]}" if scanner_icc is not None else ""))
    deadline = time.monotonic() + wait_s
    last: dict = {}
    found = None
    while found is None:
        for f in (ti3, *scans):
            if f.is_file():
                size = f.stat().st_size
                if size and size == last.get(f):   # written completely
                    found = f
                    break
                last[f] = size
        if found is None:
            if time.monotonic() > deadline:
                raise TimeoutError(f"no measurement {ti3} within {wait_s:g} s")
            time.sleep(poll_s)
    if found != ti3:
        return scan_lab(found, rects, bars, scanner_icc)
    t = argyll.read_cgats(ti3)
    ids = [int(float(v)) for v in (r[t.fields.index("SAMPLE_ID")] for r in t.rows)]
    if "LAB_L" in t.fields:
        lab = t.columns("LAB_L", "LAB_A", "LAB_B")
    else:
        lab = xyz_to_lab(t.columns("XYZ_X", "XYZ_Y", "XYZ_Z") / 100.0)
    by_id = dict(zip(ids, lab))
    missing = [i for i in range(1, len(rows) + 1) if i not in by_id]
    if missing:
        raise ValueError(f"{ti3}: no measurement of patch {missing[0]} "
                         f"({len(missing)} of {len(rows)} missing)")
    return np.array([by_id[i] for i in range(1, len(rows) + 1)])


def scan_lab(path: Path, rects: list, bars: list | None, scanner_icc: Path | None) -> np.ndarray:
    """Lab (n, 3) of a chart's patches read from a scanner's TIFF (8 or 16 bits RGB, its
    resolution in the file) through the scanner's input profile; ValueError naming the
    file for what cannot be read."""
    import tifffile
    if scanner_icc is None:
        raise ValueError(f"{path}: a scan needs the scanner's input profile (--scanner-icc)")
    with tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        res, unit_tag = page.tags.get("XResolution"), page.tags.get("ResolutionUnit")
        samples, dtype = page.samplesperpixel, page.dtype
    unit = int(unit_tag.value) if unit_tag is not None else 2  # TIFF: inch unless said
    dpi = res.value[0] / res.value[1] * (2.54 if unit == 3 else 1.0) if res and unit != 1 else 0
    if not 50 <= dpi <= 9600:           # unit 1 (none), tifffile's default, is no dpi either
        raise ValueError(f"{path}: the scan says no resolution; save it with its dpi")
    if samples < 3 or dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: expected an RGB scan of 8 or 16 bits, not {samples} "
                         f"channel(s) of {dtype}")
    full = 65535.0 if dtype == np.uint16 else 255.0
    try:
        rgb = scan_patches(str(path), rects, dpi, bars)[:, :3] / full
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return xicclu(scanner_icc, rgb, "f")[:, :3]


def pct_to_level(pct) -> np.ndarray:
    return np.clip(np.round(np.asarray(pct, np.float64) * 2.55), 0, 255).astype(np.uint8)


def level_to_pct(level) -> np.ndarray:
    return np.asarray(level, np.float64) / 2.55


# -- linearisation ------------------------------------------------------------------------
def wedge_values(steps=WEDGE_STEPS) -> np.ndarray:
    """Each ink alone at every step (C's steps, then M's, ...): (4 x steps, 4) levels."""
    out = np.zeros((4 * len(steps), 4), np.uint8)
    for i in range(4):
        out[i * len(steps):(i + 1) * len(steps), i] = pct_to_level(steps)
    return out


def delta_e_from_paper(lab: np.ndarray, steps=WEDGE_STEPS) -> dict[str, list[float]]:
    """Each ink's ΔE (CIE76, Euclidean in Lab: additive, as printcal's) from the paper
    along the wedge; the paper is every ink's 0 % step (their mean)."""
    k = len(steps)
    lab = lab.reshape(4, k, 3)
    paper = lab[:, 0].mean(axis=0)
    return {ink: [float(v) for v in np.linalg.norm(lab[i] - paper, axis=-1)]
            for i, ink in enumerate(INKS)}


def linear_reference(response: dict[str, list[float]], steps=WEDGE_STEPS) -> dict:
    """printcal's aim: each ink's ΔE from paper linear in the nominal amount, up to what
    its solid reaches."""
    s = np.asarray(steps, np.float64)
    return {"steps": [float(v) for v in s],
            **{ink: [float(v) for v in s / s[-1] * max(response[ink])] for ink in INKS}}


def curves_for(response: dict[str, list[float]], reference: dict, points: int = 17) -> dict:
    """Per-ink curves [in, out] (0..255) that make the measured response (ΔE from paper
    of each raw step) follow the reference: out(x) = response^-1(reference(x))."""
    s = np.asarray(reference["steps"], np.float64)
    x = np.linspace(0, 100, points)
    out = {}
    for ink in INKS:
        resp = np.maximum.accumulate(np.asarray(response[ink], np.float64))   # monotone
        resp = resp + np.arange(resp.size) * 1e-6                             # strictly
        aim = np.interp(x, s, np.asarray(reference[ink], np.float64))
        aim = np.minimum(aim, resp[-1])
        printed = np.interp(aim, resp, s)
        out[ink] = [[round(float(a) * 2.55, 3), round(float(b) * 2.55, 3)]
                    for a, b in zip(x, printed)]
    return out


# -- ink limit ----------------------------------------------------------------------------
def tac_values(steps=TAC_STEPS) -> np.ndarray:
    """Rich blacks at each total: K solid (from 100 %), C = M = Y share the rest."""
    rows = []
    for t in steps:
        k = min(100.0, t)
        cmy = min(100.0, (t - k) / 3)
        rows.append([cmy, cmy, cmy, k])
    return pct_to_level(np.array(rows))


def choose_ink_limit(lab: np.ndarray, steps=TAC_STEPS, most: float = SOLVENT_VINYL_MAX_TAC,
                     within: float = 0.5) -> float:
    """The rule: the least total whose L* is within `within` of the darkest the media
    reaches (more ink beyond it pools and only costs), at most `most`."""
    L = lab[:, 0]
    ok = np.nonzero(L <= L.min() + within)[0]
    return float(min(steps[int(ok[0])], most))


# -- the profile --------------------------------------------------------------------------
def write_ti3(path: Path, levels: np.ndarray, lab: np.ndarray, ink_limit: float | None) -> None:
    from ..device_sim.spectro import write_ti3 as _write
    _write(path, level_to_pct(levels), lab, total_ink_limit=ink_limit)


def measure_chart(pr: Printer, levels: np.ndarray, profile, path: Path,
                  ink_limit: float | None = None) -> np.ndarray:
    """Print and measure a CMYK chart; its measurements also go to `path` (.ti3)."""
    lab = pr.measure(levels, profile, name=path.stem)
    write_ti3(path, levels, lab, ink_limit)
    return lab


def bradford_relative(lab: np.ndarray, paper_lab: np.ndarray) -> np.ndarray:
    """Measurements relative to the media white (ICC relative colorimetric: the paper
    becomes the D50 white, Bradford adaptation)."""
    from ..device_sim.spectral import lab_to_xyz, xyz_to_lab
    m = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367],
                  [0.0389, -0.0685, 1.0296]])
    d50 = lab_to_xyz(np.array([100.0, 0, 0]))
    src = m @ lab_to_xyz(paper_lab)
    dst = m @ d50
    adapt = np.linalg.inv(m) @ np.diag(dst / src) @ m
    return xyz_to_lab(lab_to_xyz(lab) @ adapt.T)


def xicclu(icc: Path | str, values: np.ndarray, direction: str = "f") -> np.ndarray:
    """Argyll's xicclu on many values: forward (device -> Lab) or backward (Lab ->
    device), relative colorimetric; device values 0..1 in and out."""
    import subprocess
    text = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in values) + "\n"
    cmd = [argyll.tool("xicclu"), "-v0", f"-f{direction}", "-ir", "-pl", str(icc)]
    done = subprocess.run(cmd, input=text, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise argyll.ArgyllError(f"xicclu failed: {done.stderr.strip()[-200:]}")
    out = [list(map(float, line.split())) for line in done.stdout.strip().splitlines()
           if line.strip()]
    return np.array(out)


def _lookup(icc, values: np.ndarray, direction: str, width: int) -> np.ndarray:
    out = xicclu(icc, values, direction)
    return out[:, :width]


def control_chart(media_iccs, count: int = 150, seed: int = 7,
                  gamut_de: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """An independent control chart: random sRGB colours (this seed) that lie in the
    gamut of every profile given (Lab -> the profile's B2A -> A2B returns within
    `gamut_de`): their 8-bit RGB (n, 3) and their Lab (sRGB, D50 relative: what relative
    colorimetric printing aims at)."""
    from ..device_sim.spectral import delta_e2000
    srgb = argyll.REF_DIR / "sRGB.icm"
    if not srgb.is_file():
        raise argyll.ArgyllError(f"{srgb} is missing. {argyll.INSTALL_HINT}")
    rng = np.random.default_rng(seed)
    rgb = rng.integers(0, 256, (count * 100, 3)).astype(np.uint8)   # a small gamut keeps ~1 %
    lab = _lookup(srgb, rgb / 255.0, "f", 3)
    inside = np.ones(len(lab), bool)
    for icc in media_iccs:
        dev = _lookup(icc, lab, "b", 4)
        back = _lookup(icc, np.clip(dev, 0, 1), "f", 3)
        inside &= delta_e2000(lab, back) <= gamut_de
    keep = np.nonzero(inside)[0][:count]
    return rgb[keep], lab[keep]


def stats(de: np.ndarray) -> dict:
    return {"mean": round(float(de.mean()), 3), "p95": round(float(np.percentile(de, 95)), 3),
            "max": round(float(de.max()), 3), "patches": int(de.size)}


# -- the loop -----------------------------------------------------------------------------
def with_budget(profile, dpi: int, budget: float):
    """The printer profile printing `budget` of each ink amount in this dpi mode."""
    color = replace(profile.color, drop_budget={**profile.color.drop_budget, dpi: budget})
    return replace(profile, color=color)


def mode_budget(values: dict, dpi: int) -> float:
    """The budget that lays down the entry's own mode's ink per m² in mode `dpi`."""
    main = int(values["dpi"])
    b = float(values["drop_budget"].get(str(main), 1.0)) * main / dpi
    if b > 1.0 + 1e-9:
        raise ValueError(f"{dpi} dpi cannot lay down the ink of {main} dpi at budget "
                         f"{values['drop_budget'].get(str(main), 1.0)}: make the media with "
                         f"--drop-budget {dpi / main:g} or less")
    return b


def relinearise_modes(values: dict, profile, inject=(), progress: Progress = _quiet,
                      folder: Path | None = None, suffix: str = "",
                      where: dict | None = None) -> dict:
    """Each of the entry's other modes: its budget (equal ink per m²) and curves that
    bring its raw wedge to the entry's reference."""
    out = {}
    steps = values["reference"]["steps"]
    for key in sorted(values["modes"], key=int):
        dpi = int(key)
        b = mode_budget(values, dpi)
        progress(f"    {dpi} dpi: wedge at budget {b:g}")
        pr = printer_for({**values, "dpi": dpi}, profile, inject, where)
        path = (folder or Path(tempfile.gettempdir())) / f"wedge-{dpi}{suffix}.ti3"
        lab = measure_chart(pr, wedge_values([int(v) for v in steps]),
                            with_budget(profile, dpi, b), path)
        out[key] = {**values["modes"][key], "drop_budget": b,
                    "curves": curves_for(delta_e_from_paper(lab, steps), values["reference"])}
    return out


def mode_profile(values: dict, key: str, levels: np.ndarray, profile, folder: Path,
                 tmp: Path, limit: float, quality: str, inject=(),
                 progress: Progress = _quiet, where: dict | None = None) -> dict:
    """A mode's own ICC profile: the profiling chart printed in that mode (its budget and
    curves) and measured, colprof.  The curves make each ink alone match; the overprints
    of a coarser mode do not (150 dpi's dots land on each other's cells), the profile
    takes them as they are."""
    dpi = int(key)
    progress(f"    {dpi} dpi: the profiling chart and its profile")
    media = Media(folder, dict(values))
    pr = printer_for({**values, "dpi": dpi}, profile, inject, where)
    stem = tmp / f"profiling-{dpi}"
    measure_chart(pr, levels, apply_to_profile(media, profile, dpi), stem.with_suffix(".ti3"), limit)
    icc = argyll.colprof(stem, limit, quality, description=f"wideprint {values['name']} {dpi} dpi")
    (folder / f"profile-{dpi}.icc").write_bytes(icc.read_bytes())
    (folder / f"profiling-{dpi}.ti3").write_bytes(stem.with_suffix(".ti3").read_bytes())
    return {"icc": f"profile-{dpi}.icc",
            "profcheck": argyll.profcheck(stem.with_suffix(".ti3"), icc)}


#: the halftone a dpi mode of an entry made in another mode prints with: at 150 dpi `joint`
#: (rip/joint.py), with which 150 dpi lays down about 300 dpi's ink for the same colour
#: (docs/media.md "Every dpi mode the same colour": 23 % more with vced, 6 % with joint)
MODE_DITHER = {150: {"dither": "joint"}}


def printer_for(media_values: dict, profile, inject=(), where: dict | None = None) -> Printer:
    """The printer in the entry's print mode; `where`: device, measure_dir, wait_s,
    progress (Printer's fields) for charts printed elsewhere than the emulator."""
    mode = media_values.get("modes", {}).get(str(int(media_values["dpi"])), {})
    return Printer(profile, dpi=int(media_values["dpi"]), passes=int(media_values["passes"]),
                   bidir=bool(media_values["bidir"]),
                   dither=str(mode.get("dither") or media_values["dither"]),
                   inject=tuple(inject), **(where or {}))


def create(folder: Path, values: dict, profile, patches: int = 1000,
           ink_limit: float | None = None, linearise: bool = True, inject=(),
           quality: str = "m", progress: Progress = _quiet, budget: float = 1.0,
           modes: tuple[int, ...] = (), where: dict | None = None) -> dict:
    """Run the loop and fill `values` (the entry's fields) and `folder` (profile.icc,
    wedge.ti3, tac.ti3, profiling.ti3).  Returns the values."""
    t0 = time.monotonic()
    folder.mkdir(parents=True, exist_ok=True)
    argyll.tool("targen"), argyll.tool("colprof"), argyll.tool("profcheck")   # fail early
    pr = printer_for(values, profile, inject, where)
    timings = {}
    main = int(values["dpi"])
    values["drop_budget"] = {str(main): float(budget)} if budget != 1.0 else {}
    values["modes"] = {str(int(d)): dict(MODE_DITHER.get(int(d), {})) for d in modes
                       if int(d) != main}
    for key in values["modes"]:
        mode_budget(values, int(key))                      # refused before any print
    raw = with_budget(profile, main, budget)

    progress("1/4 linearisation wedge: each ink alone, 0-100 % in 5 % steps")
    t = time.monotonic()
    lab = measure_chart(pr, wedge_values(), raw, folder / "wedge.ti3")
    response = delta_e_from_paper(lab)
    reference = linear_reference(response) if linearise else {
        "steps": [float(s) for s in WEDGE_STEPS], **response}
    values["reference"] = reference
    values["curves"] = curves_for(response, reference) if linearise else \
        {ink: IDENTITY for ink in INKS}
    timings["wedge_s"] = round(time.monotonic() - t, 1)
    media = Media(folder, dict(values))
    prof = apply_to_profile(media, profile)

    progress("2/4 ink limit chart: rich blacks 160-400 %")
    t = time.monotonic()
    lab = measure_chart(pr, tac_values(), prof, folder / "tac.ti3")
    chosen = choose_ink_limit(lab)
    limit = float(ink_limit) if ink_limit is not None else chosen
    values["ink_limit_percent"] = limit
    timings["tac_s"] = round(time.monotonic() - t, 1)
    progress(f"    darkest within 0.5 L* at {chosen:g} %; total ink limit {limit:g} %")

    progress(f"3/4 profiling chart: targen, {patches} patches within {limit:g} %")
    t = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="wideprint-argyll-") as tmp:
        stem = Path(tmp) / "profiling"
        chart = argyll.targen(stem, patches, limit)
        levels = pct_to_level(chart.cmyk)
        timings["targen_s"] = round(time.monotonic() - t, 1)
        t = time.monotonic()
        progress(f"    printing and measuring {len(levels)} patches")
        lab = pr.measure(levels, prof, name="profiling")
        timings["print_measure_s"] = round(time.monotonic() - t, 1)
        write_ti3(stem.with_suffix(".ti3"), levels, lab, limit)
        progress("4/4 colprof (ArgyllCMS): the ICC profile")
        t = time.monotonic()
        icc = argyll.colprof(stem, limit, quality,
                             description=f"wideprint {values['name']} {values['dpi']} dpi")
        timings["colprof_s"] = round(time.monotonic() - t, 1)
        check = argyll.profcheck(stem.with_suffix(".ti3"), icc)
        (folder / "profile.icc").write_bytes(icc.read_bytes())
        (folder / "profiling.ti3").write_bytes(stem.with_suffix(".ti3").read_bytes())
        values["icc"] = "profile.icc"
        values["measurements"] = ["wedge.ti3", "tac.ti3", "profiling.ti3"]
        if values["modes"]:
            progress("    the other dpi modes: " + ", ".join(values["modes"]))
            values["modes"] = relinearise_modes(values, profile, inject, progress, folder,
                                                where=where)
            values["measurements"] += [f"wedge-{k}.ti3" for k in values["modes"]]
            for key in values["modes"]:
                values["modes"][key].update(mode_profile(values, key, levels, profile, folder,
                                                         Path(tmp), limit, quality, inject,
                                                         progress, where))
                values["measurements"].append(f"profiling-{key}.ti3")
    values["build"] = {"patches": int(len(levels)), "profcheck": check,
                       "seconds": round(time.monotonic() - t0, 1), **timings,
                       "injected": list(inject)}
    progress(f"done in {values['build']['seconds']:.0f} s; profcheck ΔE2000 mean "
             f"{check['mean']:.2f}, max {check['max']:.2f}")
    return values


def verify(media: Media, profile, count: int = 150, seed: int = 7, inject=(),
           progress: Progress = _quiet, dpi: int | None = None, keep: dict | None = None,
           where: dict | None = None) -> dict:
    """Print the independent control chart through the media (relative colorimetric,
    the RIP's own path: sRGB -> the media's profile -> 3-D LUT -> curves), measure it and
    compare with what it aims at: ΔE2000 mean, p95, max against the tolerances."""
    from ..device_sim.spectral import delta_e2000
    progress(f"control chart: {count} in-gamut colours (seed {seed})")
    dpi = int(dpi or media.values["dpi"])
    # the same chart in every mode of the entry: colours inside all of their gamuts
    rgb, aim = control_chart(media.all_iccs(), count, seed)
    values = np.concatenate([np.full((1, 3), 255, np.uint8), rgb])   # patch 0: paper
    pr = printer_for({**media.values, "dpi": dpi}, profile, inject, where)
    progress(f"printing and measuring {len(values)} patches at {dpi} dpi")
    lab = pr.measure(values, apply_to_profile(media, profile, dpi),
                     rgb_icc=str(argyll.REF_DIR / "sRGB.icm"), output_icc=str(media.icc_for(dpi)),
                     name="verify")
    rel = bradford_relative(lab[1:], lab[0])
    de = delta_e2000(aim, rel)
    result = stats(de)
    tol = media.values["tolerances"]
    failed = [k for k in ("mean", "p95", "max") if k in tol and result[k] > tol[k]]
    if keep is not None:              # the raw measurements, for comparing modes
        keep.update(lab=lab, ink_ml_m2=pr.last_ink_ml_m2, aim=aim, measured=rel, de=de)
    return {"media": media.name, "version": media.version, "intent": "relative", "dpi": dpi,
            **result, "tolerances": tol, "pass": not failed, "failed": failed,
            "seed": seed, "injected": list(inject), "paper_lab": [round(float(v), 2) for v in lab[0]],
            "worst": [{"rgb": [int(v) for v in rgb[i]], "aim": [round(float(v), 2) for v in aim[i]],
                       "measured": [round(float(v), 2) for v in rel[i]], "de2000": round(float(de[i]), 2)}
                      for i in np.argsort(de)[::-1][:5]]}


def recalibrate(media: Media, profile, inject=(), progress: Progress = _quiet,
                where: dict | None = None) -> dict:
    """One wedge print, new curves that bring each ink's response back to the entry's
    reference (the profile is kept): returns the new values (version + 1)."""
    progress("linearisation wedge: each ink alone, 0-100 % in 5 % steps")
    pr = printer_for(media.values, profile, inject, where)
    steps = media.values["reference"]["steps"]
    version = int(media.values["version"]) + 1
    name = f"wedge-v{version}.ti3"
    raw = with_budget(profile, int(media.values["dpi"]),
                      float(media.values["drop_budget"].get(str(media.values["dpi"]), 1.0)))
    lab = measure_chart(pr, wedge_values([int(s) for s in steps]), raw, media.folder / name)
    response = delta_e_from_paper(lab, steps)
    values = dict(media.values)
    values["curves"] = curves_for(response, media.values["reference"])
    values["version"] = version
    if values["modes"]:
        values["modes"] = relinearise_modes(values, profile, inject, progress, media.folder,
                                            f"-v{version}", where)
    values["measurements"] = [*media.values["measurements"], name]
    shift = {ink: round(float(np.max(np.abs(np.asarray(response[ink]) -
                                            np.asarray(media.values['reference'][ink])))), 2)
             for ink in INKS}
    values["build"] = {**media.values["build"], "recalibrated": {"inject": list(inject),
                                                                 "max_shift_de": shift}}
    return values


def lab_to_srgb8(lab: np.ndarray) -> np.ndarray:
    """D50 Lab -> 8-bit sRGB for a picture (Bradford D50 -> D65, IEC 61966-2-1), clipped."""
    from ..device_sim.spectral import lab_to_xyz
    xyz = lab_to_xyz(lab)
    bradford = np.array([[0.9555766, -0.0230393, 0.0631636], [-0.0282895, 1.0099416, 0.0210077],
                         [0.0122982, -0.0204830, 1.3299098]])          # D50 -> D65
    m = np.array([[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560],
                  [0.0556434, -0.2040259, 1.0572252]])
    rgb = np.clip(xyz @ bradford.T @ m.T, 0, 1)
    rgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * rgb ** (1 / 2.4) - 0.055)
    return np.round(rgb * 255).astype(np.uint8)


def verify_picture(keep: dict, path: Path, cell: int = 48, across: int = 15) -> None:
    """The verify report as a picture: each control patch as a square, its upper half the
    colour aimed at, its lower half the colour measured, a red frame where ΔE2000 > 3."""
    import cv2
    aim, got, de = lab_to_srgb8(keep["aim"]), lab_to_srgb8(keep["measured"]), keep["de"]
    n = len(de)
    down = math.ceil(n / across)
    img = np.full((down * cell, across * cell, 3), 255, np.uint8)
    for i in range(n):
        r, c = divmod(i, across)
        y, x = r * cell, c * cell
        img[y + 2:y + cell // 2, x + 2:x + cell - 2] = aim[i]
        img[y + cell // 2:y + cell - 2, x + 2:x + cell - 2] = got[i]
        if de[i] > 3.0:
            cv2.rectangle(img, (x + 1, y + 1), (x + cell - 2, y + cell - 2), (255, 0, 0), 2)
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
