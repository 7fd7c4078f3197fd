"""Planes and media TIFFs (docs/formats.md): 4 channels C, M, Y, K, uint8, one value
per dot (0 = no drop, n = n drops), device resolution, tiled and deflate-compressed,
written band by band so memory is bounded by the band, never by the image length."""

from __future__ import annotations

import contextlib
import os
import queue
import secrets
import shutil
import stat
import tempfile
import threading
from pathlib import Path

import numpy as np
import tifffile

TILE = (64, 1024)
_ABORT = object()


class _Aborted(Exception):
    pass


def _ascii(text: str) -> str:
    """Printable ASCII, the rest as escapes (\\xNN for a byte of a non-UTF-8 name)."""
    out = []
    for ch in text:
        o = ord(ch)
        if 32 <= o < 127:
            out.append(ch)
        elif o < 32 or o == 127:
            out.append(f"\\x{o:02x}")
        elif 0xDC80 <= o <= 0xDCFF:
            out.append(f"\\x{o - 0xDC00:02x}")
        else:
            out.append(ch.encode("ascii", "backslashreplace").decode())
    return "".join(out)


class PlanesWriter:
    """Append rows top to bottom; the file is complete after close().  Leaving a `with`
    block by an exception aborts instead: the unfinished file is removed, not padded."""

    def __init__(self, path: str | Path, width: int, height: int, dpi_x: float, dpi_y: float,
                 description: str = "wideprint planes"):
        self.path, self.width, self.height = str(path), width, height
        description = _ascii(description)      # a TIFF string is 7-bit ASCII; file names are not
        self._pending: list[np.ndarray] = []
        self._pending_rows = 0
        self._rows = 0
        self._q: queue.Queue = queue.Queue(maxsize=8)
        self._error: BaseException | None = None
        self._opened = False
        self._thread = threading.Thread(target=self._run, args=(dpi_x, dpi_y, description),
                                        name="planes-writer", daemon=True)
        self._thread.start()

    def _tiles(self):
        while True:
            band = self._q.get()
            if band is None:
                return
            if band is _ABORT:
                raise _Aborted
            for x in range(0, self.width, TILE[1]):
                yield band[:, x:x + TILE[1]]

    def _run(self, dpi_x, dpi_y, description):
        try:
            with open(self.path, "wb") as fh:
                self._opened = True             # from now on an abort removes what we wrote
                tifffile.imwrite(fh, data=self._tiles(), shape=(self.height, self.width, 4),
                                 dtype=np.uint8, photometric="separated", tile=TILE,
                                 compression="zlib", resolution=(dpi_x, dpi_y),
                                 resolutionunit="INCH", description=description)
        except BaseException as exc:  # reported by write()/close()
            self._error = exc
            if not isinstance(exc, _Aborted):
                while self._q.get() not in (None, _ABORT):   # drain so producers never block
                    pass

    def write(self, rows: np.ndarray) -> None:
        if self._error:
            raise self._error
        rows = np.asarray(rows, dtype=np.uint8)
        if rows.ndim != 3 or rows.shape[1:] != (self.width, 4):
            raise ValueError(f"rows must be (n, {self.width}, 4), got {rows.shape}")
        if self._rows + rows.shape[0] > self.height:
            raise ValueError("more rows than the declared height")
        self._rows += rows.shape[0]
        self._pending.append(rows)
        self._pending_rows += rows.shape[0]
        while self._pending_rows >= TILE[0] or (self._rows == self.height and self._pending_rows):
            self._flush_band()

    def _flush_band(self) -> None:
        allrows = np.concatenate(self._pending) if len(self._pending) > 1 else self._pending[0]
        n = min(TILE[0], allrows.shape[0])
        self._q.put(np.ascontiguousarray(allrows[:n]))
        rest = allrows[n:]
        self._pending = [rest] if rest.shape[0] else []
        self._pending_rows = rest.shape[0]

    def close(self) -> None:
        # pad with blank rows so the file is valid (the caller decided it is complete), a
        # band at a time: the missing rows may be far more than memory holds
        while self._rows != self.height and not self._error:
            self.write(np.zeros((min(TILE[0], self.height - self._rows), self.width, 4), np.uint8))
        self._q.put(None)
        self._thread.join()
        if self._error:
            raise self._error

    def abort(self) -> None:
        """Stop writing and remove the unfinished file."""
        if self._thread.is_alive():
            self._q.put(_ABORT)
            self._thread.join()
        with contextlib.suppress(OSError):
            if self._opened and stat.S_ISREG(os.stat(self.path).st_mode):
                os.unlink(self.path)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()


@contextlib.contextmanager
def output_file(path: str | Path):
    """Yield a temporary name to write `path` under: in its folder, renamed to `path` when
    the block succeeds and removed when it fails, so `path` is never left half written.
    Any other target - a symlink (a rename would replace the link, not write through it),
    /dev/stdout, a FIFO (a TIFF being written needs seeking) - gets the finished file
    copied into it."""
    path = os.fspath(path)
    try:
        special = not stat.S_ISREG(os.lstat(path).st_mode)
    except FileNotFoundError:
        special = False
    folder, name = os.path.split(path)
    if special:
        folder = tempfile.gettempdir()
    short = os.fsdecode(os.fsencode(name)[:200])          # names are at most 255 bytes
    tmp = os.path.join(folder, f".{short}.{secrets.token_hex(4)}.part")
    try:
        # made here (O_EXCL, mode 0666 less the umask, as the final file would be)
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666))
    except OSError as exc:
        raise OSError(f"{path}: cannot write: {exc.strerror or exc}") from None
    try:
        yield tmp
        if special:
            with open(tmp, "rb") as src, open(path, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
            os.unlink(tmp)
        else:
            os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def read_planes(path: str | Path) -> np.ndarray:
    """The whole planes/media TIFF as (rows, cols, 4) uint8 (tests and small jobs)."""
    data = tifffile.imread(str(path))
    if data.ndim != 3 or data.shape[2] != 4:
        raise ValueError(f"{path}: not a 4-channel CMYK planes file (shape {data.shape})")
    return data


# Ink colours on white paper (sRGB), for previews of planes and media.
INK_RGB = np.array([[0, 174, 239], [236, 0, 140], [255, 242, 0], [35, 31, 32]], np.float32) / 255


def render_rgb(planes: np.ndarray) -> np.ndarray:
    """(h, w, 4) drops -> (h, w, 3) uint8 sRGB: each ink multiplies the paper white by its
    colour (a subtractive approximation good enough to see dots, bands and gaps)."""
    out = np.ones(planes.shape[:2] + (3,), np.float32)
    for c in range(4):
        on = planes[:, :, c] > 0
        out[on] *= INK_RGB[c]
    return (out * 255 + 0.5).astype(np.uint8)


def iter_planes(path: str | Path):
    """The planes/media TIFF top to bottom as (rows, width, 4) bands, one strip or tile
    row at a time: memory is one band, whatever the print's length."""
    with tifffile.TiffFile(str(path)) as tf:
        page = tf.pages[0]
        if len(page.shape) != 3 or page.shape[2] != 4:
            raise ValueError(f"{path}: not a 4-channel CMYK planes file (shape {page.shape})")
        h, w = page.shape[:2]
        band, y0, bh = None, None, 0
        for seg, idx, _shape in page.segments(maxworkers=1):   # one tile at a time
            y, x = idx[-3], idx[-2]
            seg = seg.reshape(seg.shape[-3:])
            if y != y0:
                if band is not None:
                    yield band[:min(bh, h - y0)]
                y0, bh = y, seg.shape[0]
                band = np.zeros((bh, w, 4), np.uint8)
            hh, ww = min(seg.shape[0], h - y), min(seg.shape[1], w - x)
            band[:hh, x:x + ww] = seg[:hh, :ww]
        if band is not None:
            yield band[:h - y0]


def _resolution(page, tag: str, default: float) -> float:
    t = page.tags.get(tag)
    try:
        num, den = t.value
        return num / den if num and den else default
    except (AttributeError, TypeError, ValueError):
        return default


def _box_sums(band, y0, by, bx, lut, sums):
    """Add the ink colour of every dot of `band` (rows from y0) into its by x bx box."""
    from numba import njit                 # compiled once, cached; here, so the seam loads light

    global _box_sums_kernel
    if _box_sums_kernel is None:
        @njit(cache=True, nogil=True)
        def kernel(band, y0, by, bx, lut, sums):
            for r in range(band.shape[0]):
                yy = (y0 + r) // by
                for c in range(band.shape[1]):
                    i = (band[r, c, 0] > 0) | (band[r, c, 1] > 0) << 1 | \
                        (band[r, c, 2] > 0) << 2 | (band[r, c, 3] > 0) << 3
                    xx = c // bx
                    sums[yy, xx, 0] += lut[i, 0]
                    sums[yy, xx, 1] += lut[i, 1]
                    sums[yy, xx, 2] += lut[i, 2]
        _box_sums_kernel = kernel
    _box_sums_kernel(band, y0, by, bx, lut, sums)


_box_sums_kernel = None


def _ink_lut() -> np.ndarray:
    """sRGB of every combination of inks on one dot (index: C | M<<1 | Y<<2 | K<<3)."""
    lut = np.ones((16, 3), np.float32)
    for combo in range(16):
        for c in range(4):
            if combo >> c & 1:
                lut[combo] *= INK_RGB[c]
    return (lut * 255 + 0.5).astype(np.uint8)


_LUT = _ink_lut()


def preview_image(planes_path: str | Path, max_side: int = 2000) -> np.ndarray:
    """An sRGB picture (rows, cols, 3) of a planes/media TIFF at its true physical aspect
    (the device grid is 300 x 370.5 dots per inch: a square prints square), low-passed
    as the eye sees a print from a distance (area sums, then a Gaussian of half a picture
    pixel: no aliasing, no beat between dot patterns and pixels), at most `max_side` pixels a
    side and never finer than the finer dot pitch.  Built band by band: memory is a band plus
    the picture, whatever the print's length."""
    import cv2
    with tifffile.TiffFile(str(planes_path)) as tf:
        page = tf.pages[0]
        h, w = page.shape[:2]
        xres, yres = _resolution(page, "XResolution", 300.0), _resolution(page, "YResolution", 300.0)
    width_in, height_in = w / xres, h / yres
    scale = min(max_side / max(width_in, height_in), max(xres, yres))     # pixels per inch
    out_w, out_h = max(1, round(width_in * scale)), max(1, round(height_in * scale))
    # whole-dot boxes at about the picture's resolution first (integer sums of the ink
    # colours of every dot), then the exact physical size
    bx, by = max(1, w // out_w), max(1, h // out_h)
    inter_w, pad = -(-w // bx), (-w) % bx
    inter_h = -(-h // by)
    sums = np.zeros((inter_h, inter_w, 3), np.uint32)        # small: ~ twice the picture
    y = 0
    for band in iter_planes(planes_path):
        _box_sums(band, y, by, bx, _LUT, sums)
        y += band.shape[0]
    cols = np.full(inter_w, float(bx), np.float32)           # dots in each box: whole
    cols[-1] = bx - pad                                       # boxes but the last column
    rows = np.full(inter_h, float(by), np.float32)            # and the last row of boxes
    rows[-1] = h - (inter_h - 1) * by
    inter = np.divide(sums, (rows[:, None] * cols[None, :])[..., None], dtype=np.float32)
    del sums
    # a gentle low-pass of about a picture pixel (as the eye sees a print from a distance):
    # no beat between a dot pattern and the pixel grid survives it
    sx, sy = inter.shape[1] / out_w, inter.shape[0] / out_h
    inter = cv2.GaussianBlur(inter, (0, 0), sigmaX=0.7 * max(sx, 1.0), sigmaY=0.7 * max(sy, 1.0))
    out = cv2.resize(inter, (out_w, out_h), interpolation=cv2.INTER_AREA)
    del inter
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def write_preview(planes_path: str | Path, png_path: str | Path, max_side: int = 2000) -> None:
    """A PNG preview of a planes/media TIFF: true physical aspect, area-averaged, built in
    bands (preview_image)."""
    import cv2
    rgb = preview_image(planes_path, max_side)
    ok, png = cv2.imencode(".png", rgb[:, :, ::-1])
    if not ok:
        raise OSError(f"{png_path}: cannot encode the preview")
    with open(png_path, "wb") as f:     # (Python's open takes any file name; cv2's not)
        f.write(png.tobytes())
