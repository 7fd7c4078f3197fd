"""PDF, PostScript and EPS as an image source on the device grid (docs/documents.md).

``open_document(path, fmt, settings, profile)`` probes the document with Ghostscript
(rip/ghostscript.py), works out every selected page's size on the device grid from its
page box and the placement (physical size, width/height, scale, fit width), refuses
pages beyond the placement limit before anything is rendered, and returns a
:class:`DocumentSource`: the ImageSource duck type the RIP uses, whose bands are the
pages rendered by Ghostscript at the final resolution (1 rendered pixel = 1 device dot),
one after another along the roll with ``page_gap_mm`` of blank paper between them.

Rotation and mirroring are done per page by rip/place.py (the page is rendered in its
own frame at the resolution that becomes the device grid after the turn, then turned
through the tile spool), so a rotated multi-page document keeps its pages one after
another along the roll.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Iterator

import numpy as np

from .ghostscript import GsPage, colour_args, probe, render_page
from .load import ImageError
from .place import _reband, place
from .settings import MAX_SIDE, MM_PER_INCH, Placement, parse_pages
from .spot_render import SpotPlan
from .spot_render import prepare as prepare_spots

__all__ = ["DocumentSource", "open_document"]


class _PageSource:
    """One page, rendered unrotated (in the page's own frame) at width x height pixels:
    the ImageSource duck type that rip/place.py turns and mirrors."""

    def __init__(self, path: str, fmt: str, page: GsPage, width: int, height: int, xres: float,
                 yres: float, colour: list[str]):
        self.path, self.fmt, self.page = path, fmt, page
        self.width, self.height = int(width), int(height)
        self.xres, self.yres = xres, yres
        self.channels, self.colorspace, self.depth, self.icc = 4, "cmyk", 8, None
        self.format = fmt
        self.colour = colour

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8)

    def bands(self, rows: int = 256) -> Iterator[np.ndarray]:
        return render_page(self.path, self.fmt, self.page, self.width, self.height, self.xres,
                           self.yres, self.colour, int(rows))

    def close(self) -> None:
        pass


class DocumentSource:
    """The selected pages of a document on the device grid, one after another along the
    roll.  ImageSource duck type: path, width, height, channels (4), colorspace ("cmyk":
    ink amounts, 0 = none), depth (8), dtype, icc (None), format, xres/yres (the device
    grid's), bands(rows), close().  ``separated`` tells the RIP that the colours are
    already in the output space (Ghostscript applied the RIP's ICC path, rip/ghostscript.py
    colour_args): ink limit and curves still apply, no second conversion."""

    separated = True

    def __init__(self, path: str, fmt: str, pages: list, gap_rows: int, dpi: int, row_um: float,
                 warnings: list[str], page_count: int):
        self.path, self.format = path, fmt
        self.pages = pages                      # [(GsPage, placed source)]
        self.gap_rows = int(gap_rows)
        self.width = max(src.width for _, src in pages)
        self.height = sum(src.height for _, src in pages) + self.gap_rows * (len(pages) - 1)
        self.channels, self.colorspace, self.depth, self.icc = 4, "cmyk", 8, None
        self.xres = float(dpi)
        self.yres = MM_PER_INCH * 1000.0 / float(row_um)
        self.warnings = list(warnings)
        self.page_count = page_count
        self._closed = False
        self.spots: list[dict] = []             # docs/spot.md "The job's report"
        self.spot_plan: SpotPlan | None = None  # its private rewritten copy, removed on close

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8)

    def describe(self) -> list[dict]:
        """Per printed page: number, box, size in mm and dots (reports, the GUI)."""
        out = []
        for page, src in self.pages:
            out.append(dict(page=page.number, box=page.box, width_pt=page.width_pt, height_pt=page.height_pt,
                            width_dots=src.width, height_rows=src.height))
        return out

    def bands(self, rows: int = 256) -> Iterator[np.ndarray]:
        if self._closed:
            raise ValueError(f"{self.path}: document source is closed")
        rows = int(rows)
        if rows < 1:
            raise ValueError("rows must be >= 1")
        return _reband(self._chunks(rows), rows)

    def _chunks(self, rows: int) -> Iterator[np.ndarray]:
        W = self.width
        for i, (_, src) in enumerate(self.pages):
            if i and self.gap_rows:
                left = self.gap_rows
                while left:
                    n = min(rows, left)
                    yield np.zeros((n, W, 4), np.uint8)
                    left -= n
            for band in src.bands(rows):
                if band.shape[1] != W:
                    out = np.zeros((band.shape[0], W, 4), np.uint8)
                    out[:, : band.shape[1]] = band
                    band = out
                yield band

    def close(self) -> None:
        self._closed = True
        for _, src in self.pages:
            src.close()
        if self.spot_plan is not None:
            self.spot_plan.close()

    def __enter__(self) -> "DocumentSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"DocumentSource({self.path!r}, {self.format}, pages "
                f"{[p.number for p, _ in self.pages]}, {self.width} x {self.height} dots)")


def select_pages(path: str, pages: list[GsPage], selection: str) -> list[GsPage]:
    n = len(pages)
    out: list[GsPage] = []
    for first, last in parse_pages(selection):
        hi = n if last is None else last
        if first > n or hi > n:
            want = f"{first}-{'' if last is None else last}" if last != first else f"{first}"
            raise ImageError(path, f"pages {want}: the document has {n} page{'s' if n != 1 else ''}")
        out += pages[first - 1: hi]
    return out


def _check_icc(settings) -> None:
    """A bad --input-icc/--output-icc fails as it does for images (ValueError naming the file)."""
    if not (settings.input_icc or settings.output_icc):
        return
    from .color import Separator
    from .ghostscript import _icc_space
    cs = "rgb"
    if settings.input_icc:
        cs = {b"CMYK": "cmyk", b"GRAY": "grey"}.get(_icc_space(settings.input_icc), "rgb")
    Separator(cs, 8, input_icc=settings.input_icc, output_icc=settings.output_icc, intent=settings.intent)


def page_geometry(page: GsPage, placement: Placement, dpi: int, row_um: float):
    """(page-frame width, height in pixels, xres, yres) that become the placed size on the
    device grid after the placement's turn: 1 rendered pixel = 1 device dot."""
    w_in, h_in = page.width_pt / 72.0, page.height_pt / 72.0
    cols, rows = placement.target_size_inches(w_in, h_in, dpi, row_um)
    sw, sh = placement.scaled_inches(w_in, h_in)       # across, along the media, inches
    ypi = MM_PER_INCH * 1000.0 / row_um                  # device rows per inch
    if placement.quarter_turn:                           # page x runs along the feed
        return rows, cols, ypi * sh / w_in, dpi * sw / h_in
    return cols, rows, dpi * sw / w_in, ypi * sh / h_in


def open_document(path: str, fmt: str, settings, profile) -> DocumentSource:
    """Probe, check and size a PDF/PostScript/EPS file; nothing is rendered yet."""
    pl: Placement = settings.placement
    dpi, row_um = settings.dpi, profile.row_um
    _check_icc(settings)
    seen: dict[str, str] = {}
    all_pages, warnings = probe(path, fmt, pl.page_box, spots=seen)
    chosen = select_pages(path, all_pages, pl.pages)
    colour = colour_args(settings.input_icc, settings.output_icc, settings.intent)
    # spot colours (docs/spot.md): library colours print their recipes, cut colours never
    # print; a document with neither renders from the original file, as before
    plan = prepare_spots(path, fmt, settings, seen)
    render_path, render_fmt = plan.path, plan.fmt
    turn = replace(pl, size="pixels", width_mm=None, height_mm=None, scale=None, fit_width_mm=None)
    placed = []
    try:
        for page in chosen:
            try:
                pw, ph, xres, yres = page_geometry(page, pl, dpi, row_um)
            except ValueError as exc:
                raise ImageError(path, f"page {page.number} ({page.width_pt / 72 * 25.4:.6g} x "
                                       f"{page.height_pt / 72 * 25.4:.6g} mm): {exc}") from None
            wide = (pw if not pl.quarter_turn else ph) * 25.4 / dpi
            limit = getattr(profile, "print_width_mm", None)
            if limit and wide > limit + 0.5:
                raise ImageError(path, f"page {page.number} would be {wide:.0f} mm wide on the media, more than the "
                                       f"printer's {limit:.0f} mm: scale it (--width-mm, --scale) or turn it "
                                       f"(--rotate 90)")
            rpage = replace(page, flags=()) if render_fmt != fmt else page    # distilled: MediaBox
            src = _PageSource(render_path, render_fmt, rpage, pw, ph, xres, yres, colour)
            placed.append((page, place(src, turn, dpi, row_um)))
        gap = int(round(float(pl.page_gap_mm) * 1000.0 / row_um)) if len(placed) > 1 else 0
        doc = DocumentSource(path, fmt, placed, gap, dpi, row_um, warnings, len(all_pages))
        doc.spots, doc.spot_plan = plan.spots, plan
        doc.warnings += plan.warnings
    except BaseException:
        for _, s in placed:
            s.close()
        plan.close()
        raise
    if doc.height > MAX_SIDE:
        doc.close()
        raise ImageError(path, f"the {len(chosen)} pages are {doc.height:,} rows long together, more than "
                               f"the limit of {MAX_SIDE:,} ({MAX_SIDE * row_um / 1e6:.1f} m); print fewer "
                               f"pages at a time (--pages)")
    return doc
