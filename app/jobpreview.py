"""Job previews and estimates (no Qt here): the print server makes them for its clients
(GET /v1/jobs/ID/preview, docs/server.md), the GUI shows them.

The preview is the RIP's real halftone of a downsampled image: the file is reduced with
libvips (the loader's own pipeline, so alpha, CMYK JPEG inversion and band layout are
exactly what the RIP reads), rotated/mirrored like the placement, separated with the
RIP's Separator (same ICC, intent, ink limit, curves) and halftoned with the RIP's
Halftoner; render_rgb then paints the enabled separations.  When the placed image is no
larger than the preview and is not resampled by the placement (1 pixel = 1 dot, or a
physical size equal to the pixel size), nothing is resampled and the preview halftone IS
the halftone the RIP will print, dot for dot (rotation and mirror included).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..rip.color import Separator
from ..rip.halftone import Halftoner
from ..rip.load import ImageSource, open_image
from ..rip.pipeline import RipJob, profile_curves
from ..rip.planes import render_rgb
from .estimate import Estimate, estimate

PREVIEW_MAX_PX = 1600


@dataclass
class PreviewData:
    path: str
    width_dots: int
    height_rows: int
    width_mm: float
    height_mm: float
    dpi: int
    total_strokes: int
    dots: np.ndarray                      # (ph, pw, 4) uint8 0/1: the preview halftone
    estimate: Estimate
    source_desc: str = ""                 # "3000 x 2000 px CMYK 8-bit TIFF"
    exact: bool = False                   # dots are the RIP's halftone, dot for dot
    seconds: float = 0.0
    warnings: list = field(default_factory=list)
    out_of_gamut: float | None = None     # share of the image the media cannot print (softproof.py)
    spots: list = field(default_factory=list)   # a document's spot colours as resolved (docs/spot.md)


def _vips_reduce(src: ImageSource, tw: int, th: int) -> np.ndarray | None:
    reader = getattr(src, "_reader", None)
    if reader is None or not (hasattr(reader, "open") and hasattr(reader, "pipeline")):
        return None
    img = reader.pipeline(reader.open())
    if (tw, th) != (img.width, img.height):
        img = img.resize(tw / img.width, vscale=th / img.height, kernel="linear")
    a = img.numpy()
    if a.ndim == 2:
        a = a[:, :, None]
    # resize may round a side by one pixel: crop or pad to the exact size
    if a.shape[0] != th or a.shape[1] != tw:
        out = np.zeros((th, tw, a.shape[2]), a.dtype)
        h, w = min(th, a.shape[0]), min(tw, a.shape[1])
        out[:h, :w] = a[:h, :w]
        if h < th:
            out[h:] = out[h - 1:h]
        if w < tw:
            out[:, w:] = out[:, w - 1:w]
        a = out
    return np.ascontiguousarray(a)


def _band_reduce(src: ImageSource, tw: int, th: int) -> np.ndarray:
    """Any source (BMP has no libvips pipeline): stream bands, resize each across with
    OpenCV, then average the rows that fall on each output row (or, when the output has
    more rows than the source, which is then small, interpolate them)."""
    import cv2
    C = src.channels
    across = cv2.INTER_AREA if tw <= src.width else cv2.INTER_LINEAR

    def hresize(b: np.ndarray) -> np.ndarray:
        r = cv2.resize(np.ascontiguousarray(b), (tw, b.shape[0]), interpolation=across)
        return r.reshape(b.shape[0], tw, C)

    if th >= src.height:
        a = np.concatenate([hresize(b) for b in src.bands(256)])
        if th == src.height:
            return a
        return cv2.resize(a, (tw, th), interpolation=cv2.INTER_LINEAR).reshape(th, tw, C)
    sums = np.zeros((th, tw, C), np.float64)
    counts = np.zeros(th, np.int64)
    y = 0
    for b in src.bands(256):
        n = b.shape[0]
        idx = np.minimum(np.arange(y, y + n) * th // src.height, th - 1)     # sorted
        starts = np.flatnonzero(np.diff(idx, prepend=-1))
        sums[idx[starts]] += np.add.reduceat(hresize(b).astype(np.float64), starts, axis=0)
        counts += np.bincount(idx, minlength=th)
        y += n
    out = sums / np.maximum(counts, 1)[:, None, None]
    return np.rint(out).astype(src.dtype)


def reduce_image(src: ImageSource, tw: int, th: int) -> np.ndarray:
    """The whole image reduced to (th, tw, channels), same dtype and value conventions as
    src.bands() (identity when the size is already right)."""
    if (tw, th) == (src.width, src.height):
        return np.ascontiguousarray(np.concatenate(list(src.bands(1024)), axis=0))
    a = _vips_reduce(src, tw, th)
    return a if a is not None else _band_reduce(src, tw, th)


def place_array(a: np.ndarray, rotate: int, mirror: bool) -> np.ndarray:
    """Clockwise rotation, then a horizontal mirror (rip.place's order)."""
    if rotate:
        a = np.rot90(a, k=-(rotate // 90))
    if mirror:
        a = a[:, ::-1]
    return np.ascontiguousarray(a)


def preview_size(width_mm: float, height_mm: float, width_dots: int, height_rows: int,
                 max_px: int = PREVIEW_MAX_PX) -> tuple[int, int]:
    """Preview pixels across and along: the same density per mm both ways, at most
    max_px on the longer side, never more than the job's dots (then it is exact)."""
    s = max_px / max(width_mm, height_mm, 1e-9)
    pw = max(1, min(width_dots, int(round(width_mm * s))))
    ph = max(1, min(height_rows, int(round(height_mm * s))))
    return pw, ph


def compute_preview(path: str, rs, profile, copies: int = 1, max_px: int = PREVIEW_MAX_PX,
                    cancelled=lambda: False) -> PreviewData:
    """Open, place, separate and halftone a reduced copy of the image (RipSettings `rs`,
    Profile `profile`); estimate the job.  Raises ImageError / ValueError (the job's own
    problem, shown in its row)."""
    t0 = time.monotonic()
    job = RipJob(path, rs, profile)
    try:
        from ..rip.spot_render import job_spots
        spots = job_spots(job)
        W, H = job.width, job.height
        planner = job.planner()
        total = planner.total_strokes
        k = profile.k(rs.dpi)
        width_mm = W * k / profile.counts_per_inch * 25.4
        height_mm = H * profile.row_um / 1000.0
        pw, ph = preview_size(width_mm, height_mm, W, H, max_px)
        rotate = int(rs.placement.rotate)
        mirror = bool(rs.placement.mirror)
        quarter = rotate in (90, 270)
        from ..rip.inputs import sniff_input
        gamut = None
        if job.layout is not None:
            dots, desc, warnings, resampled = _layout_preview(job, pw, ph, copies, max_px, cancelled)
        elif sniff_input(path) != "image":
            dots, desc, warnings, resampled = _document_preview(job, pw, ph, cancelled)
        else:
            src = open_image(path)
            try:
                tw, th = (ph, pw) if quarter else (pw, ph)
                if cancelled():
                    raise InterruptedError
                small = reduce_image(src, tw, th)
                small = place_array(small, rotate, mirror)
                sep = Separator(src.colorspace, src.depth, embedded_icc=src.icc,
                                input_icc=rs.input_icc, output_icc=rs.output_icc, intent=rs.intent,
                                ink_limit=job.ink_limit, curves=profile_curves(profile))
                if cancelled():
                    raise InterruptedError
                ink = sep.convert(small)
                dots = Halftoner(rs.dither, pw, channels=4).process(np.ascontiguousarray(ink))
                from .softproof import proof_image      # the estimate's out-of-gamut share
                gamut = proof_image(small, src.colorspace, src.depth, embedded_icc=src.icc,
                                    input_icc=rs.input_icc, output_icc=rs.output_icc,
                                    intent=rs.intent, ink_limit=job.ink_limit).share
                desc = (f"{src.width} × {src.height} px {src.colorspace.upper() if src.colorspace != 'grey' else 'grey'} "
                        f"{src.depth}-bit {(src.format or '').upper()}").strip()
                warnings = list(getattr(sep, "warnings", []))
                resampled = (tw, th) != (src.width, src.height)
            finally:
                src.close()
        drops = dots.reshape(-1, 4).sum(axis=0, dtype=np.int64)
        est = estimate(profile, W, H, rs.dpi, rs.passes, rs.bidir, total, copies,
                       preview_drops=drops, preview_dots=pw * ph)
        # no resampling: the halftoner saw exactly the placed image the RIP will see
        exact = (pw, ph) == (W, H) and not resampled
        return PreviewData(path=path, width_dots=W, height_rows=H, width_mm=width_mm,
                           height_mm=height_mm, dpi=rs.dpi, total_strokes=total, dots=dots,
                           estimate=est, source_desc=desc, exact=exact,
                           seconds=time.monotonic() - t0, warnings=warnings,
                           out_of_gamut=gamut, spots=spots)
    finally:
        job.close()


DOCUMENT_PREVIEW_MAX_DOTS = 40_000_000


def _document_preview(job, pw: int, ph: int, cancelled):
    """PDF, PostScript, EPS and RTL: the job's own source, already on the device grid,
    reduced band by band (Ghostscript renders it, or the RTL decoder runs, once); above
    DOCUMENT_PREVIEW_MAX_DOTS the picture is left blank rather than render a banner for a
    thumbnail (the estimate's size and time stand, its ink is then unknown)."""
    W, H = job.width, job.height
    src = job.source
    desc = f"{(getattr(src, 'format', '') or 'document').upper()} on the device grid"
    if W * H > DOCUMENT_PREVIEW_MAX_DOTS:
        return np.zeros((ph, pw, 4), np.uint8), desc + " (too large to preview)", [], True
    if cancelled():
        raise InterruptedError
    if getattr(src, "prescreened", False):
        small = _band_reduce(src, pw, ph)
        return (small > 0).astype(np.uint8), desc, [], (pw, ph) != (W, H)
    small = _band_reduce(src, pw, ph)
    sep = job._separator()
    ink = sep.convert(small)
    dots = Halftoner(job.settings.dither, pw, channels=4).process(np.ascontiguousarray(ink))
    return dots, desc, list(getattr(sep, "warnings", [])), (pw, ph) != (W, H)


def _layout_preview(job, pw: int, ph: int, copies: int, max_px: int, cancelled):
    """A layout (docs/layout.md): each distinct item previewed once (the same code, at the
    sheet preview's scale), pasted where the plan puts its slots (a tile: its crop of the
    item), and the marks and label drawn from their own masks, reduced; so the operator sees
    items, gaps, marks and tile seams before printing, in memory bounded by the preview."""
    import cv2
    from ..rip.layout import item_settings
    plan = job.layout.plan
    sx, sy = pw / plan.width, ph / plan.height
    canvas = np.zeros((ph, pw, 4), np.uint8)
    cache: dict = {}
    warnings: list = []
    for slot in plan.slots:
        if cancelled():
            raise InterruptedError
        it = slot.item
        key = (it.path, it.turn)
        if key not in cache:
            rs = item_settings(job.settings, it.turn)
            # the whole placed item, at the sheet's preview scale (a tile's item is its whole
            # image: only then is the file opened to learn that size)
            if it.crop is None:
                iw, ih = it.width, it.height
            else:
                probe = RipJob(it.path, rs, job.profile)
                try:
                    iw, ih = probe.width, probe.height
                finally:
                    probe.close()
            side = max(1, int(round(max(iw * sx, ih * sy))))
            sub = compute_preview(it.path, rs, job.profile, 1, max_px=max(8, min(max_px, side)))
            cache[key] = (sub, iw, ih)
            warnings.extend(w for w in sub.warnings if w not in warnings)
        sub, iw, ih = cache[key]
        d = sub.dots
        if it.crop is not None:                          # a tile: its part of the item
            x0, y0, x1, y1 = it.crop
            fy, fx = d.shape[0] / ih, d.shape[1] / iw
            d = d[int(y0 * fy):max(int(y0 * fy) + 1, int(round(y1 * fy))),
                  int(x0 * fx):max(int(x0 * fx) + 1, int(round(x1 * fx)))]
        x, y = int(round(slot.x * sx)), int(round(slot.y * sy))
        w = max(1, int(round(it.width * sx)))
        h = max(1, int(round(it.height * sy)))
        w, h = min(w, pw - x), min(h, ph - y)
        if w <= 0 or h <= 0:
            continue
        if d.shape[:2] != (h, w):
            d = cv2.resize(d, (w, h), interpolation=cv2.INTER_NEAREST).reshape(h, w, 4)
        canvas[y:y + h, x:x + w] = np.maximum(canvas[y:y + h, x:x + w], d)
    for m in plan.marks():
        x, y = int(m.x * sx), int(m.y * sy)
        w = max(1, int(round(m.w * sx)))
        h = max(1, int(round(m.h * sy)))
        w, h = min(w, pw - x), min(h, ph - y)
        if w <= 0 or h <= 0:
            continue
        mask = m.mask()
        if mask is None:
            on = np.ones((h, w), bool)
        else:
            on = cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.2
        for c in m.inks:
            canvas[y:y + h, x:x + w, c] |= on
    n = len(plan.slots)
    desc = f"layout ({plan.mode}): {n} item{'s' if n != 1 else ''} on {plan.width_mm:,.0f} × " \
           f"{plan.height_mm:,.0f} mm"
    return canvas, desc, warnings, True


def render_separations(dots: np.ndarray, enabled) -> np.ndarray:
    """(h, w, 3) uint8 sRGB of the enabled separations (C, M, Y, K flags)."""
    mask = np.array([1 if e else 0 for e in enabled], np.uint8)
    if mask.all():
        return render_rgb(dots)
    return render_rgb(dots * mask)


def proof_job(path: str, rs, profile, max_px: int = 2000):
    """The soft proof (app/softproof.py) of a whole job (RipSettings `rs`, its media already
    resolved into the settings and the profile), at most `max_px` on its longer side, placed
    as it prints."""
    from ..rip.inputs import sniff_input
    from .softproof import proof_cmyk, proof_image
    job = RipJob(path, rs, profile)
    try:
        k = profile.k(rs.dpi)
        width_mm = job.width * k / profile.counts_per_inch * 25.4
        height_mm = job.height * profile.row_um / 1000.0
        pw, ph = preview_size(width_mm, height_mm, job.width, job.height, max_px)
        if job.layout is not None:
            raise ValueError("soft proof: layouts (nest, step and repeat, tiles) are proofed "
                             "item by item: proof each file")
        if sniff_input(path) != "image":
            small = _band_reduce(job.source, pw, ph)
            if getattr(job.source, "prescreened", False):
                raise ValueError("soft proof: an RTL file's dots are already halftoned")
            ink = Separator("cmyk", 8, ink_limit=job.ink_limit).convert(   # the RIP's limit
                np.ascontiguousarray(small[..., :4]))
            return proof_cmyk(ink, rs.output_icc)
        src = open_image(path)
        try:
            quarter = int(rs.placement.rotate) in (90, 270)
            small = reduce_image(src, *((ph, pw) if quarter else (pw, ph)))
            small = place_array(small, int(rs.placement.rotate), bool(rs.placement.mirror))
            return proof_image(small, src.colorspace, src.depth, embedded_icc=src.icc,
                               input_icc=rs.input_icc, output_icc=rs.output_icc,
                               intent=rs.intent, ink_limit=job.ink_limit)
        finally:
            src.close()
    finally:
        job.close()
