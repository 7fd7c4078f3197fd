"""Streaming image loaders for the RIP, one module a reader (docs/rip.md "Input back ends").

``open_image(path)`` reads only the file header, checks it (format by magic bytes,
dimensions against decompression-bomb limits, bit depth, colour space, truncation
that can be seen from the header) and returns an :class:`ImageSource`.
``ImageSource.bands(rows)`` then decodes the image top to bottom, one band at a time,
with memory bounded by the band (never by the image height).

Readers
-------
* source.py: what they all hand over (`ImageSource`, `ImageError`, the header and band
  layout types, `_reband`).
* vips.py: TIFF, JPEG, PNG through libvips, sequential access, pulled with
  :class:`pyvips.Region` (JPEG with ``fail_on='warning'``: corrupt data is refused, not
  printed grey).
* tiff.py: the TIFF header (tifffile) and the strip reader for plain strip TIFFs.
* jpeg.py, png.py: their headers, walked before libvips sees the file.
* bmp.py: our own parser, rows straight from the file; RLE4/RLE8 decoded by a numba
  kernel into an index plane.  Not OpenCV: ``cv2.imread`` has no banded read.

This module only tells the formats apart and hands the file to its reader.  Every problem
with a file is raised as :class:`ImageError` (``str(e) == f"{path}: {problem}"``).
"""

from __future__ import annotations

import os
import stat
import struct

from .bmp import _bmp_header, _open_bmp
from .jpeg import _check_jpeg, _jpeg_header
from .png import _png_header
from .source import ImageError, ImageSource, _check_dims, _Hdr
from .tiff import _check_tiff, _tiff_header
from .vips import _open_vips

__all__ = ["ImageError", "ImageSource", "open_image"]


def _sniff(head: bytes) -> str | None:
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "tiff"
    if head[:3] == b"\xff\xd8\xff":
        return "jpeg"
    if head[:8] == b"\x89PNG\r\n\x1a\n":
        return "png"
    if head[:2] == b"BM":
        return "bmp"
    return None


_OTHER_FORMATS = [
    (b"GIF87a", "GIF"), (b"GIF89a", "GIF"), (b"%PDF", "PDF"), (b"%!PS", "PostScript"),
    (b"8BPS", "Photoshop PSD"), (b"\x00\x00\x00\x0cjP  ", "JPEG 2000"), (b"\xff\x4f\xff\x51", "JPEG 2000"),
    (b"\xff\x0a", "JPEG XL"), (b"\x00\x00\x00\x0cJXL ", "JPEG XL"), (b"PK\x03\x04", "ZIP archive"),
    (b"\x1f\x8b", "gzip archive"), (b"\xc5\xd0\xd3\xc6", "EPS"),
]


def _unknown_format(head: bytes) -> str:
    for magic, name in _OTHER_FORMATS:
        if head.startswith(magic):
            return f"unsupported file format {name} (supported: TIFF, JPEG, PNG, BMP)"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "unsupported file format WebP (supported: TIFF, JPEG, PNG, BMP)"
    if head[4:12] in (b"ftypavif", b"ftypheic", b"ftypmif1", b"ftypheix"):
        return "unsupported file format HEIF/AVIF (supported: TIFF, JPEG, PNG, BMP)"
    return "not an image file (unknown format)"


def _not_regular(mode: int) -> str | None:
    """Why a file that is not a regular file cannot be an image (None for a regular one)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory, not an image file"
    kind = ("a FIFO" if stat.S_ISFIFO(mode) else "a character device" if stat.S_ISCHR(mode)
            else "a block device" if stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "not a file")
    return f"not a regular file ({kind}), not an image file"


def open_image(path, *, max_pixels: int = 4_000_000_000, max_side: int = 1_000_000) -> ImageSource:
    """Read and check the header only; refuse absurd dimensions before decoding anything."""
    path = os.fspath(path)
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    # opened without blocking, then checked on the descriptor: a FIFO must not hang us
    # and the file checked is the file read
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise ImageError(path, "file not found") from None
    except OSError as e:
        raise ImageError(path, f"cannot read file: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        kind = _not_regular(st.st_mode)
        if kind:
            raise ImageError(path, kind)
        os.set_blocking(fd, True)
        f = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    size = st.st_size
    fmt = None
    hdr: _Hdr | None
    try:
        with f:
            if size == 0:
                raise ImageError(path, "empty file (0 bytes)")
            head = f.read(64)
            fmt = _sniff(head)
            if fmt is None:
                raise ImageError(path, _unknown_format(head))
            if fmt == "bmp":
                info = _bmp_header(path, f, size)
                return _open_bmp(path, info, size, max_pixels, max_side)
            if fmt == "jpeg":
                hdr = _jpeg_header(path, f, size)
            elif fmt == "png":
                hdr = _png_header(path, f, size)
            else:
                hdr = None
    except ImageError:
        raise
    except OSError as e:
        raise ImageError(path, f"cannot read file: {e.strerror or e}") from None
    except (struct.error, ValueError, IndexError) as e:
        raise ImageError(path, f"corrupt {fmt.upper() if fmt else 'image'} header: {e}") from None

    if fmt == "tiff":
        if size < 16:
            raise ImageError(path, f"truncated TIFF: the file is only {size} bytes")
        hdr = _tiff_header(path, size, max_pixels, max_side)
        _check_tiff(path, hdr, size)
    else:
        assert hdr is not None          # read above for JPEG and PNG
        _check_dims(path, hdr.width, hdr.height, max_pixels, max_side)
        if fmt == "jpeg":
            _check_jpeg(path, hdr)
        if fmt == "png" and hdr.extra.get("bitdepth") not in (1, 2, 4, 8, 16):
            raise ImageError(path, f"unsupported bit depth: {hdr.extra.get('bitdepth')}-bit PNG")
    return _open_vips(path, fmt, hdr, max_pixels, max_side)
