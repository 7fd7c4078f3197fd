"""A test contour cutter with a camera (docs/cut.md, "Cut meets print").

It does what a camera cutter (Summa OPOS, Graphtec ARMS) does with a printed sheet and its
cut file: finds the registration marks on the sheet (here the emulator's `--scan-out`
scan, OpenCV), matches them to the marks the cut file names, fits one projective transform
per section between two pairs of marks along the length (four marks: the section's scale,
rotation, shear and the feed's error there are all measured), and maps every point of the
cut path through its section's transform onto the sheet.  `measure_on_print` then says how
far the corrected path is from the contour really printed, found on the same scan.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import tifffile


@dataclass
class Found:
    centres_px: np.ndarray       # (n, 2) scan pixels (u, v), in the cut file's mark order
    nominal_mm: np.ndarray       # (n, 2) the cut file's mark centres
    pix_mm: float                # one scan pixel on the paper, mm


def load_scan(path: str) -> tuple[np.ndarray, float]:
    """The scan's darkness (0 paper .. 1 solid K, float32) and its pixel size in mm."""
    with tifffile.TiffFile(path) as tf:
        img = tf.asarray()
        tag = tf.pages[0].tags.get("XResolution")
        num, den = tag.value if tag is not None else (1200, 1)
    grey = img.mean(axis=2) if img.ndim == 3 else img.astype(np.float32)
    paper = float(np.percentile(grey, 90))
    dark = np.clip((paper - grey) / max(paper - 40.0, 1.0), 0, 1).astype(np.float32)
    return dark, 25.4 / (num / den)


def find_marks(dark: np.ndarray, pix_mm: float, marks: list, mark_mm: float) -> Found:
    """The cut file's marks [(place, x mm, y mm)] on the scan: solid squares of `mark_mm`,
    each found by its size and fill, its centre the darkness-weighted centroid.  The found
    squares are matched to the file's by order: rows of pairs down the sheet, left then
    right (the cutter's own search pattern).  AssertionError when the count differs."""
    # a little blur first: a mark printed at 150 dpi is a grid of dots with paper between
    smooth = cv2.GaussianBlur(dark, (0, 0), max(0.1 / pix_mm, 0.5))
    binary = (smooth > 0.4).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    side = mark_mm / pix_mm
    found = []
    for i in range(1, n):
        x, y, w, h, area = stats[i]
        if not (0.75 * side <= w <= 1.35 * side and 0.75 * side <= h <= 1.35 * side):
            continue
        if area < 0.7 * side * side:
            continue
        pad = 3
        y0, y1 = max(y - pad, 0), min(y + h + pad, dark.shape[0])
        x0, x1 = max(x - pad, 0), min(x + w + pad, dark.shape[1])
        win = dark[y0:y1, x0:x1].astype(np.float64)
        vv, uu = np.mgrid[y0:y1, x0:x1]
        found.append(((win * uu).sum() / win.sum(), (win * vv).sum() / win.sum()))
    nominal = np.array([(x, y) for _, x, y in marks], np.float64)
    assert len(found) == len(nominal), f"found {len(found)} marks on the scan, the cut file has {len(nominal)}"
    got = np.array(sorted(found, key=lambda c: c[1]))
    order = np.lexsort((nominal[:, 0], np.round(nominal[:, 1], 3)))
    # pairs: sort each consecutive two by u (left, right)
    out = np.empty_like(got)
    for k in range(0, len(got), 2):
        pair = got[k:k + 2]
        pair = pair[np.argsort(pair[:, 0])]
        out[order[k:k + 2]] = pair
    return Found(out, nominal, pix_mm)


def correct(points_mm: np.ndarray, found: Found) -> np.ndarray:
    """Cut path points (mm, the cut file's frame) -> scan pixels, through the projective
    transform of the section of marks they lie in (before the first or after the last
    pair: the nearest section's)."""
    nom, px = found.nominal_mm, found.centres_px
    levels = np.unique(np.round(nom[:, 1], 6))
    out = np.empty_like(points_mm, dtype=np.float64)
    sec = np.clip(np.searchsorted(levels, points_mm[:, 1]) - 1, 0, len(levels) - 2)
    for s in np.unique(sec):
        pick = np.isin(np.round(nom[:, 1], 6), levels[s:s + 2])
        h = cv2.getPerspectiveTransform(nom[pick].astype(np.float32), px[pick].astype(np.float32))
        sel = sec == s
        out[sel] = cv2.perspectiveTransform(points_mm[sel][None].astype(np.float64), h)[0]
    return out


def resample(points: np.ndarray, step: float) -> np.ndarray:
    """A polyline with a point at least every `step` along it."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / step)))
        t = (np.arange(1, n + 1) / n)[:, None]
        out.append(a + (b - a) * t)
    return np.vstack(out)


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """img sampled at (u, v), 0 outside (cv2.remap stops at 32,767 rows: a 3 m scan is longer)."""
    u0, v0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    fu, fv = u - u0, v - v0
    h, w = img.shape

    def at(a, b):
        ok = (a >= 0) & (a < w) & (b >= 0) & (b < h)
        return np.where(ok, img[np.clip(b, 0, h - 1), np.clip(a, 0, w - 1)], 0.0)
    return ((1 - fu) * (1 - fv) * at(u0, v0) + fu * (1 - fv) * at(u0 + 1, v0)
            + (1 - fu) * fv * at(u0, v0 + 1) + fu * fv * at(u0 + 1, v0 + 1))


def measure_on_print(dark: np.ndarray, path_px: np.ndarray, pix_mm: float,
                     reach_mm: float = 1.0) -> np.ndarray:
    """For each point of a path on the scan, the distance (mm) to the printed line there:
    the darkness-weighted centre of the line along the path's normal within `reach_mm`.
    NaN where no line is within reach."""
    d = np.gradient(path_px, axis=0)
    normal = np.stack([-d[:, 1], d[:, 0]], axis=1)
    normal /= np.maximum(np.hypot(normal[:, 0], normal[:, 1]), 1e-12)[:, None]
    reach = reach_mm / pix_mm
    s = np.linspace(-reach, reach, int(2 * reach * 8) + 1)
    u = (path_px[:, 0:1] + normal[:, 0:1] * s[None]).astype(np.float32)
    v = (path_px[:, 1:2] + normal[:, 1:2] * s[None]).astype(np.float32)
    prof = _bilinear(dark, u, v)
    prof = np.clip(prof - 0.1, 0, None)                     # paper noise away
    mass = prof.sum(axis=1)
    centre = (prof * s[None]).sum(axis=1) / np.where(mass > 0, mass, 1)
    out = np.abs(centre) * pix_mm
    out[mass < 1.0] = np.nan
    return out
