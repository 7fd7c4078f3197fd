"""Which reader a file needs, by its content (not its name), and the job's image area.

``open_source(path, settings, profile)`` is what RipJob opens a file with:

* PDF (``%PDF-`` in the first KiB), PostScript (``%!``), EPS (``%!PS-Adobe-x.x EPSF``, or
  the DOS EPS binary header): Ghostscript renders the pages straight onto the device grid
  (rip/document.py, rip/ghostscript.py; docs/documents.md);
* HP-GL/2 RTL (first escape sequence ESC E, ESC%-12345X, ESC*, ESC&, ESC%): our own
  decoder (rip/rtl.py; docs/rtl.md); 1-bit raster prints dot for dot, contone raster
  goes through the normal RIP;
* anything else: rip/load/'s image loaders (TIFF, JPEG, PNG, BMP), placed by
  rip/place.py.

The result has the ImageSource duck type (docs/placement.md), already on the device grid.
Two flags tell the RIP what it holds (rip/pipeline.py):
``separated`` — CMYK already in the output space (documents: no second ICC conversion),
``prescreened`` — 0/1 dots already (1-bit RTL: no separation, no halftone).
"""

from __future__ import annotations

import os
from typing import Iterator

import numpy as np

__all__ = ["sniff_input", "open_source", "prescreened_packed", "DOCUMENT_SUFFIXES", "RTL_SUFFIXES"]

#: file name suffixes of the formats this module adds (detection is by content; these are
#: for file dialogs, hot folders and the server's spool names)
DOCUMENT_SUFFIXES = (".pdf", ".ps", ".eps", ".epsf", ".ai")
RTL_SUFFIXES = (".rtl", ".prn", ".plt", ".hpgl", ".pcl")


def sniff_input(path) -> str:
    """'pdf', 'ps', 'eps', 'rtl' or 'image' (the image loaders decide what kind, or refuse)."""
    from .ghostscript import sniff_document
    from .rtl import sniff_rtl
    try:
        with open(path, "rb") as f:
            head = f.read(1024)
    except OSError:
        return "image"                   # open_image names the problem
    return sniff_document(head) or ("rtl" if sniff_rtl(head) else "image")


def open_source(path, settings, profile):
    """The file opened and placed on the device grid for RipJob (ValueError for placement
    problems, ImageError for the file's)."""
    path = os.fspath(path)
    kind = sniff_input(path) if os.path.isfile(path) else "image"
    if kind in ("pdf", "ps", "eps"):
        from .document import open_document
        return open_document(path, kind, settings, profile)
    if kind == "rtl":
        from .rtl import open_rtl
        return open_rtl(path, settings, profile)
    from .load import open_image
    from .place import place
    loaded = open_image(path)
    try:
        # the image area on the device grid: physical size, scaled, rotated, mirrored
        return place(loaded, settings.placement, settings.dpi, profile.row_um)
    except ValueError as exc:
        loaded.close()
        raise ValueError(f"{path}: {exc}") from None


def prescreened_packed(source, rows: int) -> Iterator[np.ndarray]:
    """The dots of a prescreened source as packed bits (h, 4, ceil(W / 8)): straight from
    the decoder when it can, else packed from its 0/1 bands (a turned or mirrored one)."""
    if hasattr(source, "packed_bands"):
        yield from source.packed_bands(rows)
        return
    from .swath import pack_dots
    for band in source.bands(rows):
        yield pack_dots(band)
