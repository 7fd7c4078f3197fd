"""The emulated spectrophotometer (docs/physical.md, "The spectrophotometer"): the print's
colorimetric truth, CIELAB (D50, 2°, M0) one pixel per `dpi`, from the drops the physical
model lands (physical.py) and the media's spectral model (spectral.py).

    --spectro-out LAB.tif [--spectro-dpi 50]

Drops are counted as they land into a rolling accumulator on a fine grid (a whole number
`sub` of fine cells per measuring pixel, each at most dot/2.4 wide) and never kept: each
drop spreads into its disc (dot gain), each ink's coverage is min(1, its amount), ink
beyond what the media takes bleeds (the coverages scaled down where the smoothed ink
volume exceeds the media's limit), each fine cell's Demichel weights are summed over its
measuring pixel, and the pixel's spectrum is the Yule-Nielsen modified spectral
Neugebauer mixture of the 16 primaries with those weights.  Rows are measured once the
paper has carried them past the heads.  Memory: the job's width times the swath, at
4 bytes a fine cell (the counts), never its length.

Patches: `measure_patches` reads the Lab file and averages each patch in XYZ (the
instrument's aperture sees the mean reflectance); `write_ti3` writes them as ArgyllCMS's
chartread does (CGATS CTI3, CMYK_XYZ with LAB fields too).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Iterable, Sequence

import cv2
import numpy as np
import tifffile

from ..rip.compiled import kernel
from .coverage import coverage_rows
from .physical import JobGeometry
from .scanner import STRIP, disc_kernel
from .spectral import SpectralMedia, lab_to_xyz, xyz_to_lab

TILE = 128                  # measuring pixels across a tile of the rendering
FINE_PER_DOT = 3.0          # fine cells across a dot's diameter, at least
SPECTRO_DPI = (10, 300)     # the resolutions --spectro-dpi takes
DESCRIPTION = "wideprint emulator spectrophotometer: CIELAB D50 2deg M0, float32 L a b"


@kernel()
def _count(acc, base, xoff, channel, fx, fy):
    """One drop per (fx, fy) (fine cells, image frame) into acc[row - base, col + xoff];
    returns the drops that fell on rows already measured."""
    rows, width = acc.shape[0], acc.shape[1]
    late = 0
    for i in range(fx.shape[0]):
        r = fy[i] - base
        c = fx[i] + xoff
        if r < 0:
            late += 1
        elif r < rows and 0 <= c < width:
            v = acc[r, c, channel]
            if v < 255:
                acc[r, c, channel] = v + 1
    return late


@kernel()
def _weights(cov, sub, out):
    """Sum the Demichel weights of every fine cell's coverages (rows, cols, 4) into its
    measuring pixel out[r // sub, c // sub, 16]."""
    cm = np.empty(4, np.float32)
    yk = np.empty(4, np.float32)
    for r in range(cov.shape[0]):
        v = r // sub
        for c in range(cov.shape[1]):
            u = c // sub
            c0 = cov[r, c, 0]
            c1 = cov[r, c, 1]
            c2 = cov[r, c, 2]
            c3 = cov[r, c, 3]
            if c0 == 0.0 and c1 == 0.0 and c2 == 0.0 and c3 == 0.0:
                out[v, u, 0] += 1.0
                continue
            cm[0] = (1 - c0) * (1 - c1)
            cm[1] = c0 * (1 - c1)
            cm[2] = (1 - c0) * c1
            cm[3] = c0 * c1
            yk[0] = (1 - c2) * (1 - c3)
            yk[1] = c2 * (1 - c3)
            yk[2] = (1 - c2) * c3
            yk[3] = c2 * c3
            for j in range(16):
                out[v, u, j] += cm[j & 3] * yk[j >> 2]


class Spectrophotometer:
    """The colorimetric truth of one job: a float32 CIELAB TIFF, one pixel per `dpi`,
    covering the image area exactly (pixel (u, v) measures [u P, (u+1) P) x [v P, (v+1) P)
    of the image frame, P = 25.4 mm / dpi)."""

    event = "spectro"

    def __init__(self, path: str, geo: JobGeometry, dpi: float, dot_um: float,
                 media: SpectralMedia, drop_pl: float, slack_um: float = 0.0,
                 swath_um: float = 20_000.0):
        if not SPECTRO_DPI[0] <= dpi <= SPECTRO_DPI[1]:
            raise ValueError(f"spectro resolution {dpi} dpi: must be "
                             f"{SPECTRO_DPI[0]}..{SPECTRO_DPI[1]}")
        self.path, self.geo, self.dpi, self.media = path, geo, float(dpi), media
        self.pitch = 25_400.0 / self.dpi
        self.sub = max(1, math.ceil(self.pitch * FINE_PER_DOT / dot_um))
        self.fine = self.pitch / self.sub
        self.width = max(1, math.ceil(geo.width * geo.col_um / self.pitch - 1e-9))
        self.height = max(1, math.ceil(geo.height * geo.row_um / self.pitch - 1e-9))
        self.dot_um, self.slack_um = dot_um, slack_um
        self.kernel = disc_kernel(dot_um / self.fine)
        self.rk = self.kernel.shape[0] // 2
        # ml/m² of ink per unit of amount: a drop's volume spread over its disc's cells
        self.unit = drop_pl * 1000.0 / (float(self.kernel.sum()) * self.fine ** 2)
        self.bleed_px = media.bleed_um / self.fine
        self.rv = int(math.ceil(3 * self.bleed_px)) if self.bleed_px > 0 else 0
        self.halo = self.rk + self.rv
        self.xoff = self.halo                                 # fine columns left of x = 0
        self.fine_width = self.width * self.sub + 2 * self.halo
        self._acc = np.zeros((int(swath_um + slack_um) // int(self.fine) + 2 * self.halo + 8,
                              self.fine_width, 4), np.uint8)
        self._a_base = -self.halo                             # fine row of accumulator row 0
        self._v_next = 0                                      # next measuring row to write
        self.drops = self.late = 0
        self.seconds = 0.0                                    # spent measuring (rendering)
        self.closed = False
        out = tifffile.memmap(path, shape=(self.height, self.width, 3), dtype=np.float32,
                              photometric="minisblack", planarconfig="contig",
                              resolution=(self.dpi, self.dpi), resolutionunit="INCH",
                              description=DESCRIPTION, metadata=None)
        self._data_offset, self._row_bytes = out.offset, out[0].nbytes
        del out
        self._out = open(path, "r+b")

    # -- drops -----------------------------------------------------------------------------
    def splat(self, channel: int, x_um: np.ndarray, y_um: np.ndarray, size=None) -> None:
        # a drop is counted, not sized: drop volume spreads are the scanner's alone
        # (docs/physical.md "The machine")
        if x_um.size == 0:
            return
        fx = np.floor(np.asarray(x_um) / self.fine).astype(np.int64)
        fy = np.floor(np.asarray(y_um) / self.fine).astype(np.int64)
        top = int(fy.max()) + 1 - self._a_base
        if top > self._acc.shape[0]:
            grow = np.zeros((top - self._acc.shape[0] + 64, self.fine_width, 4), np.uint8)
            self._acc = np.concatenate([self._acc, grow])
        self.late += _count(self._acc, self._a_base, self.xoff, channel, fx, fy)
        self.drops += x_um.size

    def flush_below(self, y_um: float) -> None:
        """No drop will land above image-frame y: measure the rows that completes."""
        done = int(math.floor((y_um - self.slack_um) / self.fine))
        self._measure(min((done - self.halo) // self.sub, self.height))

    def close(self) -> None:
        if self.closed:
            return
        try:
            self._measure(self.height)
        finally:
            self._out.close()
        self._acc = np.zeros((0, 0, 4), np.uint8)
        self.closed = True

    # -- measuring -------------------------------------------------------------------------
    def _measure(self, upto: int) -> None:
        t0 = time.perf_counter()
        while self._v_next < upto:
            v0 = self._v_next
            v1 = min(upto, v0 + max(1, STRIP // self.sub))
            self._write(v0, self.lab_rows(v0, v1))
            self._v_next = v1
        self._drop_rows(self._v_next * self.sub - self.halo)
        self.seconds += time.perf_counter() - t0

    def lab_rows(self, v0: int, v1: int) -> np.ndarray:
        """Measuring rows [v0, v1) (their drops all landed) as Lab (rows, width, 3), made
        in tiles of TILE measuring pixels (small temporaries, whatever the width)."""
        s, h = self.sub, self.halo
        f0, f1 = v0 * s - h, v1 * s + h                      # fine rows with the halo
        a0, a1 = max(f0, self._a_base), min(f1, self._a_base + self._acc.shape[0])
        sums = np.zeros((v1 - v0, self.width, 16), np.float32)
        for u0 in range(0, self.width, TILE):
            u1 = min(u0 + TILE, self.width)
            x0, x1 = u0 * s, u1 * s + 2 * h                  # fine columns with the halo
            counts = self._acc[a0 - self._a_base:a1 - self._a_base, x0:x1]
            if a1 <= a0 or not counts.any():                 # paper
                sums[:, u0:u1, 0] = s * s
                continue
            src = np.zeros((f1 - f0, x1 - x0, 4), np.float32)
            src[a0 - f0:a1 - f0] = counts
            amounts = cv2.filter2D(src, -1, self.kernel, borderType=cv2.BORDER_CONSTANT)
            cov = coverage_rows(amounts, self.media, self.unit, self.bleed_px)
            tile = np.zeros((v1 - v0, u1 - u0, 16), np.float32)
            _weights(np.ascontiguousarray(cov[h:h + (v1 - v0) * s, h:h + (u1 - u0) * s]), s, tile)
            sums[:, u0:u1] = tile
        return self.media.lab(sums / np.float32(s * s)).astype(np.float32)

    def _drop_rows(self, keep_from: int) -> None:
        drop = keep_from - self._a_base
        if drop > 0:
            drop = min(drop, self._acc.shape[0])
            keep = self._acc[drop:]
            self._acc = np.concatenate([keep, np.zeros((drop, self.fine_width, 4), np.uint8)])
            self._a_base += drop

    def _write(self, v0: int, lab: np.ndarray) -> None:
        self._out.seek(self._data_offset + v0 * self._row_bytes)
        self._out.write(np.ascontiguousarray(lab, np.float32).tobytes())


class Instruments:
    """A scanner and a spectrophotometer on one job: every drop goes to both."""

    def __init__(self, *instruments):
        self.instruments = instruments
        self.scanner = instruments[0]          # what tests read (paper_to_scan, pix, ...)

    def __getattr__(self, name):
        return getattr(self.scanner, name)

    def splat(self, channel, x_um, y_um, size=None) -> None:
        for i in self.instruments:
            i.splat(channel, x_um, y_um, size)

    def flush_below(self, y_um: float) -> None:
        for i in self.instruments:
            i.flush_below(y_um)

    def close(self) -> None:
        for i in self.instruments:
            i.close()


def open_instruments(profile, faults, geo: JobGeometry, dot_um: float,
                     scan: tuple[str, float] | None, spectro: tuple[str, float] | None,
                     slack_um: float, swath_um: float):
    """The instruments a job is measured with (device_sim/printer.py): None, a Scanner, a
    Spectrophotometer, or both as Instruments."""
    from .scanner import Scanner
    media = SpectralMedia.from_profile(profile)
    out = []
    if scan:
        out.append(Scanner(scan[0], geo, scan[1], dot_um, faults, slack_um=slack_um,
                           swath_um=swath_um, media=media, drop_pl=profile.drop_volume_pl))
    if spectro:
        out.append(Spectrophotometer(spectro[0], geo, spectro[1], dot_um, media,
                                     profile.drop_volume_pl, slack_um=slack_um,
                                     swath_um=swath_um))
    if not out:
        return None
    return out[0] if len(out) == 1 else Instruments(*out)


# -- patches ----------------------------------------------------------------------------------
def read_lab(path: str | Path) -> tuple[np.ndarray, float]:
    """A --spectro-out file: Lab (rows, cols, 3) float32 and its resolution (dpi)."""
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        lab = page.asarray()
        num, den = page.tags["XResolution"].value
    return lab, num / den


def measure_patches(lab: np.ndarray | str | Path, patches: Iterable[Sequence[float]],
                    dpi: float | None = None, inset_mm: float = 0.0) -> np.ndarray:
    """Lab (n, 3) of each patch: rectangles (x0, y0, x1, y1) in mm of the image frame (x
    along the sweep from image column 0's left edge, y along the feed from image row 0's
    top edge), each shrunk by `inset_mm` on every side; the measuring pixels wholly inside
    are averaged in XYZ, as an instrument's aperture averages the light.  `lab` is a
    --spectro-out file or its array (then `dpi` is its resolution)."""
    if not isinstance(lab, np.ndarray):
        lab, dpi = read_lab(lab)
    if dpi is None:
        raise ValueError("measure_patches: the Lab array's resolution (dpi) is needed")
    pitch = 25.4 / dpi
    out = []
    for k, (x0, y0, x1, y1) in enumerate(patches):
        u0 = math.ceil((x0 + inset_mm) / pitch - 1e-6)
        v0 = math.ceil((y0 + inset_mm) / pitch - 1e-6)
        u1 = math.floor((x1 - inset_mm) / pitch + 1e-6)
        v1 = math.floor((y1 - inset_mm) / pitch + 1e-6)
        u0, v0 = max(u0, 0), max(v0, 0)
        u1, v1 = min(u1, lab.shape[1]), min(v1, lab.shape[0])
        if u1 <= u0 or v1 <= v0:
            raise ValueError(f"patch {k} ({x0}, {y0}, {x1}, {y1}) mm holds no whole "
                             f"measuring pixel at {dpi:g} dpi")
        xyz = lab_to_xyz(lab[v0:v1, u0:u1].reshape(-1, 3)).mean(axis=0)
        out.append(xyz_to_lab(xyz))
    return np.array(out).reshape(-1, 3)


def write_ti3(path: str | Path, device: np.ndarray, lab: np.ndarray,
              ids: Sequence | None = None, originator: str = "wideprint spectro",
              total_ink_limit: float | None = None) -> None:
    """A CGATS .ti3 as ArgyllCMS's chartread writes for a CMYK printer: device values in
    percent (0..100) and the measurement as XYZ (0..100, D50) with its LAB too."""
    device = np.asarray(device, np.float64).reshape(-1, 4)
    lab = np.asarray(lab, np.float64).reshape(-1, 3)
    if device.shape[0] != lab.shape[0]:
        raise ValueError(f"{device.shape[0]} device values, {lab.shape[0]} measurements")
    xyz = lab_to_xyz(lab) * 100.0
    ids = list(ids) if ids is not None else list(range(1, device.shape[0] + 1))
    lines = ["CTI3   ", "",
             'DESCRIPTOR "Argyll Calibration Target chart information 3"',
             f'ORIGINATOR "{originator}"',
             f'CREATED "{time.strftime("%a %b %d %H:%M:%S %Y")}"',
             'DEVICE_CLASS "OUTPUT"', 'COLOR_REP "CMYK_XYZ"']
    if total_ink_limit is not None:
        lines.append(f'TOTAL_INK_LIMIT "{total_ink_limit:g}"')
    fields = ["SAMPLE_ID", "CMYK_C", "CMYK_M", "CMYK_Y", "CMYK_K", "XYZ_X", "XYZ_Y", "XYZ_Z",
              "LAB_L", "LAB_A", "LAB_B"]
    lines += ["", f"NUMBER_OF_FIELDS {len(fields)}", "BEGIN_DATA_FORMAT", " ".join(fields) + " ",
              "END_DATA_FORMAT", "", f"NUMBER_OF_SETS {device.shape[0]}", "BEGIN_DATA"]
    for i, d, x, l in zip(ids, device, xyz, lab):
        vals = [f"{v:.5f}" for v in d] + [f"{v:.6g}" for v in x] + [f"{v:.5f}" for v in l]
        lines.append(f"{i} " + " ".join(vals) + " ")
    lines.append("END_DATA")
    Path(path).write_text("\n".join(lines) + "\n")
