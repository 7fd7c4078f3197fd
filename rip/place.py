"""Placement: the source image -> the job's image area on the device grid.

Sits between loading (:mod:`.load`) and colour separation.  ``place(source, placement,
dpi, row_um)`` returns something with the :class:`~.load.ImageSource` duck type whose
``bands(rows)`` are already on the device grid: columns at the dpi mode, rows at the
profile's row pitch (68.55 um, 370.53 rows per inch) - an anisotropic grid, so a square
image pixel generally becomes a non-square block of dots.  docs/placement.md explains the
options and the arithmetic.

Streaming, memory bounded by bands (never by the image height):

* Resampling is done by libvips, which is demand driven.  For TIFF/JPEG/PNG the file is
  re-opened through the loader's own libvips pipeline (``ImageSource._reader.open()`` /
  ``.pipeline()``: the very same alpha compositing, band extraction and CMYK JPEG
  un-inversion that ``ImageSource.bands()`` applies), ``resize(hscale, vscale=...)`` is
  applied and the result is pulled top to bottom with a :class:`pyvips.Region`.  Sources
  without a libvips pipeline (BMP, which pyvips-binary cannot load, or any other duck
  type) are first spooled band by band into an uncompressed striped TIFF in a temporary
  directory, which libvips then reads sequentially.
* mirror is a per-band column flip.  rotate 180/90/270 cannot stream from a striped
  source (the first output row needs the last input row): the placed-but-unrotated image
  is streamed once into a disk-backed tile spool (``SPOOL_TILE`` x ``SPOOL_TILE`` tiles,
  raw, in a temporary directory) and read back rotated, one tile row (180) or one tile
  column (90/270) at a time.  The spool is kept for further ``bands()`` calls and
  deleted by ``close()``.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import weakref
from dataclasses import replace
from typing import Iterator

import numpy as np

from .load import ImageError, ImageSource
from .load.source import _reband  # noqa: F401 (_reband: document, layout)
from .load.vips import fetch_rows
# the Placement settings object is declared with the settings schema (rip/settings.py)
from .settings import (DEFAULT_PPI, FILTERS, MAX_SIDE, MM_PER_INCH, ROTATIONS,  # noqa: F401
                       Placement)

__all__ = ["Placement", "PlacedSource", "place", "FILTERS", "ROTATIONS", "MAX_SIDE", "DEFAULT_PPI"]

#: side of the square tiles of the rotation spool, pixels
SPOOL_TILE = 128
#: free space left on the temporary file system after a spool is written
DISK_RESERVE = 64 << 20


# --------------------------------------------------------------------------------------
# helpers


def _need_disk(path: str, directory: str, nbytes: int, what: str) -> None:
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        return
    if free < nbytes + DISK_RESERVE:
        raise ImageError(path, f"not enough disk space for {what}: needs {nbytes / 1e9:.2f} GB in "
                               f"{directory}, {free / 1e9:.2f} GB free (set TMPDIR to a larger disk)")


class _TileSpool:
    """A disk-backed (h, w, c) image stored as raw tiles of t x t pixels, tile rows top to
    bottom, tiles left to right in a row, each tile row-major and padded to t x t.  Written
    one tile row at a time, read back as tile rows or tile columns with ``os.pread``."""

    def __init__(self, path: str, w: int, h: int, c: int, dtype: np.dtype, t: int):
        self.path, self.w, self.h, self.c, self.dtype, self.t = path, w, h, c, np.dtype(dtype), t
        self.ntx, self.nty = -(-w // t), -(-h // t)
        self.tile_bytes = t * t * c * self.dtype.itemsize
        self.nbytes = self.ntx * self.nty * self.tile_bytes
        self.complete = False

    def write(self, bands: Iterator[np.ndarray]) -> None:
        """`bands` must be exactly t rows each (the last may be shorter)."""
        t, ntx = self.t, self.ntx
        self.complete = False
        rows = 0
        with open(self.path, "wb") as f:
            for band in bands:
                n = band.shape[0]
                if n > t or band.shape[1] != self.w:
                    raise AssertionError("spool band of the wrong shape")
                tile_row = np.zeros((t, ntx * t, self.c), self.dtype)
                tile_row[:n, : self.w] = band
                f.write(tile_row.reshape(t, ntx, t, self.c).transpose(1, 0, 2, 3).tobytes())
                rows += n
        if rows != self.h:
            raise AssertionError(f"spool got {rows} rows, expected {self.h}")
        self.complete = True

    def tile_row(self, fd: int, i: int) -> np.ndarray:
        """Rows [i t, i t + t) cropped to the image: (th, w, c)."""
        t, ntx = self.t, self.ntx
        buf = os.pread(fd, ntx * self.tile_bytes, i * ntx * self.tile_bytes)
        if len(buf) != ntx * self.tile_bytes:
            raise OSError(f"{self.path}: short read")
        a = np.frombuffer(buf, self.dtype).reshape(ntx, t, t, self.c).transpose(1, 0, 2, 3).reshape(t, ntx * t, self.c)
        return a[: min(t, self.h - i * t), : self.w]

    def tile(self, fd: int, i: int, j: int) -> np.ndarray:
        t = self.t
        off = (i * self.ntx + j) * self.tile_bytes
        buf = os.pread(fd, self.tile_bytes, off)
        if len(buf) != self.tile_bytes:
            raise OSError(f"{self.path}: short read")
        a = np.frombuffer(buf, self.dtype).reshape(t, t, self.c)
        return a[: min(t, self.h - i * t), : min(t, self.w - j * t)]


# --------------------------------------------------------------------------------------
# the placed source


class PlacedSource:
    """Same duck type as ImageSource for what RipJob uses: path, width, height, channels,
    colorspace, depth, icc, bands(rows) -> Iterator[np.ndarray], close().  ``xres``/``yres``
    are the device grid's (dpi, 25400 / row_um)."""

    def __init__(self, source: ImageSource, placement: Placement, dpi: int, row_um: float,
                 width: int, height: int, tmp_dir: str | None = None):
        self.source = source
        self.placement = replace(placement)  # a copy: later edits by the caller change nothing
        self.dpi = int(dpi)
        self.row_um = float(row_um)
        self.path = source.path
        self.width, self.height = int(width), int(height)
        self.channels = source.channels
        self.colorspace = source.colorspace
        self.depth = source.depth
        self.icc = source.icc
        self.format = getattr(source, "format", "")
        self.xres = float(dpi)
        self.yres = MM_PER_INCH * 1000.0 / self.row_um
        # size of the resampled, not yet rotated image
        self.scaled_width, self.scaled_height = ((self.height, self.width) if placement.quarter_turn
                                                 else (self.width, self.height))
        self.resample = (self.scaled_width, self.scaled_height) != (source.width, source.height)
        self.tmp_dir = tmp_dir
        self._tmp: tempfile.TemporaryDirectory | None = None
        self._finalizer = None
        self._spool: _TileSpool | None = None
        self._input_spool: str | None = None  # TIFF copy of a source libvips cannot read
        self._closed = False

    # -- ImageSource duck type ----------------------------------------------------------
    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint16 if self.depth == 16 else np.uint8)

    @property
    def rotate(self) -> int:
        return self.placement.rotate

    @property
    def spool_bytes(self) -> int:
        """Disk the rotation spool needs (0 without rotation)."""
        if self.rotate == 0:
            return 0
        t = SPOOL_TILE
        return (-(-self.scaled_width // t)) * (-(-self.scaled_height // t)) * t * t * self.channels \
            * self.dtype.itemsize

    def bands(self, rows: int = 256) -> Iterator[np.ndarray]:
        """The placed image top to bottom as (h, width, channels) bands, h == rows except the
        last; same value conventions as ImageSource.bands().  May be called again."""
        if self._closed:
            raise ValueError(f"{self.path}: placed image source is closed")
        rows = int(rows)
        if rows < 1:
            raise ValueError("rows must be >= 1")
        return self._bands(rows)

    def close(self) -> None:
        self._closed = True
        self._spool = None
        self._input_spool = None
        if self._finalizer is not None:
            self._finalizer()  # removes the temporary directory
            self._finalizer = None
        self._tmp = None
        self.source.close()

    def __enter__(self) -> "PlacedSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        p = self.placement
        return (f"PlacedSource({self.path!r}, {self.source.width} x {self.source.height} px -> "
                f"{self.width} x {self.height} dots at {self.dpi} x {self.yres:.2f} dpi, "
                f"rotate={p.rotate}, mirror={p.mirror}, filter={p.filter!r})")

    # -- internals ----------------------------------------------------------------------
    def _tmpdir(self) -> str:
        if self._tmp is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="wideprint-place-", dir=self.tmp_dir)
            self._finalizer = weakref.finalize(self, self._tmp.cleanup)
        return self._tmp.name

    def _bands(self, rows: int) -> Iterator[np.ndarray]:
        mirror = self.placement.mirror
        if self.rotate == 0:
            chunks = self._scaled(rows)
            if mirror:
                chunks = (b[:, ::-1] for b in chunks)
            yield from _reband(chunks, rows)
            return
        spool = self._rotation_spool()
        yield from _reband(self._rotated(spool), rows)

    def _rotation_spool(self) -> _TileSpool:
        if self._spool is not None and self._spool.complete:
            return self._spool
        d = self._tmpdir()
        spool = _TileSpool(os.path.join(d, "rotate.raw"), self.scaled_width, self.scaled_height,
                           self.channels, self.dtype, SPOOL_TILE)
        _need_disk(self.path, d, spool.nbytes, f"rotating the image by {self.rotate} degrees")
        try:
            spool.write(self._scaled(spool.t))
        except OSError as e:
            raise ImageError(self.path, f"cannot write the rotation spool in {d}: {e.strerror or e}") from None
        self._spool = spool
        return spool

    def _rotated(self, spool: _TileSpool) -> Iterator[np.ndarray]:
        mirror, rot = self.placement.mirror, self.rotate
        t, w, h = spool.t, spool.w, spool.h
        try:
            fd = os.open(spool.path, os.O_RDONLY)
        except OSError as e:
            raise ImageError(self.path, f"cannot read the rotation spool: {e.strerror or e}") from None
        try:
            if rot == 180:
                for i in reversed(range(spool.nty)):
                    a = spool.tile_row(fd, i)
                    yield a[::-1, :] if mirror else a[::-1, ::-1]
                return
            # 90 clockwise: out[y, x] = in[h-1-x, y]; 270: out[y, x] = in[x, w-1-y]
            cw = rot == 90
            reverse_x = cw != mirror  # tile row i lands at output columns counted from the right
            order = range(spool.ntx) if cw else reversed(range(spool.ntx))
            for j in order:
                tw = min(t, w - j * t)
                out = np.empty((tw, h, self.channels), self.dtype)
                for i in range(spool.nty):
                    tile = spool.tile(fd, i, j)
                    th = tile.shape[0]
                    r = np.rot90(tile, -1 if cw else 1)  # (tw, th, c)
                    if mirror:
                        r = r[:, ::-1]
                    x0 = h - i * t - th if reverse_x else i * t
                    out[:, x0: x0 + th] = r
                yield out
        finally:
            os.close(fd)

    # -- resampling (unrotated frame) -----------------------------------------------------
    def _scaled(self, rows: int) -> Iterator[np.ndarray]:
        """The resampled (not rotated, not mirrored) image in bands of `rows` rows."""
        if not self.resample:
            yield from self.source.bands(rows)      # the loader fetches in small pieces
        else:
            yield from _reband(self._resampled(), rows)

    def _resampled(self) -> Iterator[np.ndarray]:
        """The resampled image in chunks of `fetch_rows` rows, pulled top to bottom."""
        import pyvips

        src = self.source
        fmt = getattr(src, "format", "")
        try:
            img = self._vips_input(pyvips)
            sw, sh = self.scaled_width, self.scaled_height
            hscale = 1.0 if sw == src.width else sw / src.width
            vscale = 1.0 if sh == src.height else sh / src.height
            out = img.resize(hscale, vscale=vscale, kernel=self.placement.filter)
            if out.width > sw or out.height > sh:  # libvips rounds; make the size exact
                out = out.crop(0, 0, min(sw, out.width), min(sh, out.height))
            if out.width < sw or out.height < sh:
                out = out.embed(0, 0, sw, sh, extend="copy")
            region = pyvips.Region.new(out)
        except pyvips.Error as e:
            raise ImageError(self.path, _vips_problem(fmt, str(e), self.path)) from None
        dtype = self.dtype
        c = self.channels
        step = fetch_rows(sw * c * np.dtype(dtype).itemsize)
        y = 0
        while y < sh:
            n = min(step, sh - y)
            try:
                buf = region.fetch(0, y, sw, n)
            except pyvips.Error as e:
                raise ImageError(self.path, _vips_problem(fmt, str(e), self.path)) from None
            a = np.frombuffer(buf, dtype)
            if a.size != n * sw * c:
                raise ImageError(self.path, f"resampling failed: got {a.size} samples for rows {y}..{y + n}")
            yield a.reshape(n, sw, c)
            y += n

    def _vips_input(self, pyvips):
        """A libvips image with exactly the pixels ImageSource.bands() yields."""
        src = self.source
        want_fmt = "ushort" if src.depth == 16 else "uchar"
        reader = getattr(src, "_reader", None)
        if reader is not None and hasattr(reader, "open") and hasattr(reader, "pipeline"):
            img = reader.pipeline(reader.open())
            if (img.width, img.height, img.bands, img.format) == (src.width, src.height, src.channels, want_fmt):
                return img
        return pyvips.Image.new_from_file(self._tiff_copy(), access="sequential", fail_on="error")

    def _tiff_copy(self) -> str:
        """Spool the source's bands into an uncompressed striped TIFF libvips can stream."""
        if self._input_spool is not None:
            return self._input_spool
        import tifffile

        src = self.source
        d = self._tmpdir()
        path = os.path.join(d, "source.tif")
        nbytes = src.width * src.height * src.channels * self.dtype.itemsize
        _need_disk(self.path, d, nbytes, "resampling this file")
        photometric = {"grey": "minisblack", "rgb": "rgb", "cmyk": "separated"}[src.colorspace]
        strip = max(1, min(src.height, (4 << 20) // max(1, src.width * src.channels * self.dtype.itemsize)))
        shape = (src.height, src.width, src.channels) if src.channels > 1 else (src.height, src.width)

        def strips():
            for b in src.bands(strip):
                yield b if src.channels > 1 else b[..., 0]
        try:
            tifffile.imwrite(path, strips(), shape=shape, dtype=self.dtype, photometric=photometric,
                             rowsperstrip=strip, metadata=None)
        except OSError as e:
            raise ImageError(self.path, f"cannot write the resampling spool in {d}: {e.strerror or e}") from None
        self._input_spool = path
        return path


def _vips_problem(fmt: str, msg: str, path: str) -> str:
    from .load.vips import _vips_problem as problem

    return problem(fmt, msg, path)


def place(source: ImageSource, placement: Placement | None, dpi: int, row_um: float, *,
          tmp_dir: str | None = None) -> ImageSource | PlacedSource:
    """The job's image area on the device grid.  Returns `source` itself when nothing changes
    (the placed size equals the pixel size and there is no rotation or mirror), so that path
    stays bit-exact and zero-cost.  Raises ValueError for bad options or absurd sizes.
    Temporary files (rotation, BMP resampling) go to `tmp_dir` (default: $TMPDIR)."""
    placement = placement or Placement()
    w, h = placement.target_size(source.width, source.height, getattr(source, "xres", None),
                                 getattr(source, "yres", None), dpi, row_um)
    same = (w, h) == ((source.height, source.width) if placement.quarter_turn else (source.width, source.height))
    if placement.rotate == 0 and not placement.mirror and same:
        return source
    return PlacedSource(source, placement, dpi, row_um, w, h, tmp_dir=tmp_dir)
