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


def write_preview(planes_path: str | Path, png_path: str | Path, max_side: int = 4000) -> None:
    """A PNG preview of a planes/media TIFF (reduced by whole-dot sampling if large)."""
    import cv2
    planes = read_planes(planes_path)
    step = max(1, -(-max(planes.shape[:2]) // max_side))
    rgb = render_rgb(planes[::step, ::step])
    ok, png = cv2.imencode(".png", rgb[:, :, ::-1])
    if not ok:
        raise OSError(f"{png_path}: cannot encode the preview")
    with open(png_path, "wb") as f:     # (Python's open takes any file name; cv2's not)
        f.write(png.tobytes())
