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

import math
import os
import shutil
import tempfile
import weakref
from dataclasses import dataclass, replace
from typing import Any, Iterator

import numpy as np

from .load import ImageError, ImageSource, fetch_rows

__all__ = ["Placement", "PlacedSource", "place", "FILTERS", "ROTATIONS", "MAX_SIDE", "DEFAULT_PPI"]

#: resampling kernels (libvips names)
FILTERS = ("nearest", "linear", "cubic", "lanczos3")
#: clockwise rotations in degrees
ROTATIONS = (0, 90, 180, 270)
ALIGNS = ("left", "center", "right")
#: largest placed image side, in device columns or rows (3.4 m at 600 dpi is 80,315 columns;
#: 1,000,000 rows is 68.55 m of media)
MAX_SIDE = 1_000_000
#: resolution assumed for files without resolution tags, pixels per inch
DEFAULT_PPI = 300.0
#: side of the square tiles of the rotation spool, pixels
SPOOL_TILE = 128
#: free space left on the temporary file system after a spool is written
DISK_RESERVE = 64 << 20
MM_PER_INCH = 25.4


def _round(x: float) -> int:
    """Nearest integer, halves up (not banker's rounding)."""
    return int(math.floor(x + 0.5))


def _ppi(v: Any) -> float | None:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and v > 0 else None


def _finite(name: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"placement: {name} must be a number, not {v!r}") from None
    if not math.isfinite(f):
        raise ValueError(f"placement: {name} must be a finite number, not {v!r}")
    return f


def _positive(name: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"placement: {name} must be a number, not {v!r}") from None
    if not (math.isfinite(f) and f > 0):
        raise ValueError(f"placement: {name} must be a positive number, not {v!r}")
    return f


@dataclass
class Placement:
    """Where and how large the image goes on the device grid (docs/placement.md)."""

    size: str = "physical"  # "physical": from the file's xres/yres (DEFAULT_PPI when absent)
    #                         "pixels": 1 image pixel = 1 device dot, no resampling
    width_mm: float | None = None  # explicit size; with only one of them the aspect ratio is kept
    height_mm: float | None = None
    scale: float | None = None  # multiplies the physical size
    fit_width_mm: float | None = None  # scale (keeping the aspect ratio) to exactly this width
    rotate: int = 0  # 0, 90, 180, 270 degrees clockwise
    mirror: bool = False  # horizontal mirror on the device (applied after rotation)
    filter: str = "lanczos3"  # nearest | linear | cubic | lanczos3
    # where the image goes on the measured paper (applied by the driver, driver/job.py):
    align: str = "left"  # left | center | right, within the paper minus the side margins
    x_mm: float = 0.0  # then shifted this far to the right (negative: to the left)
    margin_mm: float | None = None  # side margins; None: the printer profile's [paper] margin_mm
    top_mm: float = 0.0  # blank paper fed before the image's first row

    def check(self) -> None:
        """Raise ValueError naming the problem if the options are inconsistent."""
        if self.size not in ("physical", "pixels"):
            raise ValueError(f"placement: size must be 'physical' or 'pixels', not {self.size!r}")
        if self.filter not in FILTERS:
            raise ValueError(f"placement: filter must be one of {', '.join(FILTERS)}, not {self.filter!r}")
        if isinstance(self.rotate, bool) or self.rotate not in ROTATIONS:
            raise ValueError(f"placement: rotate must be 0, 90, 180 or 270 (degrees clockwise), not {self.rotate!r}")
        if self.align not in ALIGNS:
            raise ValueError(f"placement: align must be one of {', '.join(ALIGNS)}, not {self.align!r}")
        _finite("x_mm", self.x_mm)
        for name in ("top_mm", "margin_mm"):
            v = getattr(self, name)
            if v is not None and _finite(name, v) < 0:
                raise ValueError(f"placement: {name} must not be negative, not {v!r}")
        given = {n: getattr(self, n) for n in ("width_mm", "height_mm", "scale", "fit_width_mm")
                 if getattr(self, n) is not None}
        for name, v in given.items():
            _positive(name, v)
        if self.size == "pixels" and given:
            raise ValueError("placement: size='pixels' places 1 image pixel per device dot; it cannot be "
                             f"combined with {', '.join(given)}")
        modes = [m for m, on in (("width_mm/height_mm", "width_mm" in given or "height_mm" in given),
                                 ("scale", "scale" in given), ("fit_width_mm", "fit_width_mm" in given)) if on]
        if len(modes) > 1:
            raise ValueError(f"placement: give only one of {' or '.join(modes)}")

    @property
    def quarter_turn(self) -> bool:
        return self.rotate in (90, 270)

    def target_size(self, src_w: int, src_h: int, xres: float | None, yres: float | None,
                    dpi: int, row_um: float) -> tuple[int, int]:
        """(width in device columns, height in device rows) after rotation."""
        self.check()
        src_w, src_h = int(src_w), int(src_h)
        if src_w < 1 or src_h < 1:
            raise ValueError(f"placement: the source image is {src_w} x {src_h} px")
        dpi = _positive("dpi", dpi)
        row_um = _positive("row_um", row_um)
        if self.size == "pixels":
            w, h = (src_h, src_w) if self.quarter_turn else (src_w, src_h)
            return _check_target(w, h, "")
        xr, yr = _ppi(xres), _ppi(yres)
        if xr is None and yr is None:
            xr = yr = DEFAULT_PPI
        xr, yr = xr or yr, yr or xr  # only one tag: square pixels
        w_in, h_in = src_w / xr, src_h / yr  # physical size of the unrotated image
        if self.quarter_turn:
            w_in, h_in = h_in, w_in
        if self.width_mm is not None and self.height_mm is not None:
            w_in, h_in = float(self.width_mm) / MM_PER_INCH, float(self.height_mm) / MM_PER_INCH
        elif self.width_mm is not None or self.fit_width_mm is not None:
            want = float(self.width_mm if self.width_mm is not None else self.fit_width_mm) / MM_PER_INCH
            w_in, h_in = want, h_in * want / w_in
        elif self.height_mm is not None:
            want = float(self.height_mm) / MM_PER_INCH
            w_in, h_in = w_in * want / h_in, want
        elif self.scale is not None:
            w_in, h_in = w_in * float(self.scale), h_in * float(self.scale)
        wf, hf = w_in * dpi, h_in * MM_PER_INCH * 1000.0 / row_um
        if not (math.isfinite(wf) and math.isfinite(hf)) or wf > 10 * MAX_SIDE or hf > 10 * MAX_SIDE:
            return _check_target(math.inf, math.inf, f" ({w_in * 25.4:.6g} x {h_in * 25.4:.6g} mm)")
        return _check_target(_round(wf), _round(hf), f" ({w_in * 25.4:.6g} x {h_in * 25.4:.6g} mm)")


def _check_target(w, h, what: str) -> tuple[int, int]:
    if not (w >= 1 and h >= 1):
        raise ValueError(f"placement: the placed image would be {w} x {h} dots{what}: nothing to print "
                         f"(0 px); check the size options")
    if w > MAX_SIDE or h > MAX_SIDE:
        ws = "more than 10,000,000" if w == math.inf else f"{w:,}"
        hs = "more than 10,000,000" if h == math.inf else f"{h:,}"
        raise ValueError(f"placement: the placed image would be {ws} columns x {hs} rows{what}, "
                         f"more than the limit of {MAX_SIDE:,} per side; check the size options and "
                         f"the file's resolution")
    return int(w), int(h)


# --------------------------------------------------------------------------------------
# helpers


def _reband(chunks: Iterator[np.ndarray], rows: int) -> Iterator[np.ndarray]:
    """Re-cut a stream of (h_i, w, c) arrays into bands of exactly `rows` rows (the last may be
    shorter).  Holds at most one band plus one chunk."""
    pending: list[np.ndarray] = []
    have = 0
    for chunk in chunks:
        if chunk.shape[0] == 0:
            continue
        if not pending and chunk.shape[0] == rows:
            yield np.ascontiguousarray(chunk)
            continue
        pending.append(chunk)
        have += chunk.shape[0]
        while have >= rows:
            band = np.concatenate(pending, axis=0) if len(pending) > 1 else pending[0]
            yield np.ascontiguousarray(band[:rows])
            rest = band[rows:]
            pending = [rest] if rest.shape[0] else []
            have = rest.shape[0]
    if have:
        yield np.ascontiguousarray(np.concatenate(pending, axis=0) if len(pending) > 1 else pending[0])


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
    from .load import _vips_problem as problem

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
