"""Planes and media TIFFs (docs/formats.md): 4 channels C, M, Y, K, uint8, one value
per dot (0 = no drop, n = n drops), device resolution, tiled and deflate-compressed,
written band by band so memory is bounded by the band, never by the image length."""

from __future__ import annotations

import queue
import threading
from pathlib import Path

import numpy as np
import tifffile

TILE = (64, 1024)


class PlanesWriter:
    """Append rows top to bottom; the file is complete after close()."""

    def __init__(self, path: str | Path, width: int, height: int, dpi_x: float, dpi_y: float,
                 description: str = "wideprint planes"):
        self.path, self.width, self.height = str(path), width, height
        self._pending: list[np.ndarray] = []
        self._pending_rows = 0
        self._rows = 0
        self._q: queue.Queue = queue.Queue(maxsize=8)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(dpi_x, dpi_y, description),
                                        name="planes-writer", daemon=True)
        self._thread.start()

    def _tiles(self):
        while True:
            band = self._q.get()
            if band is None:
                return
            for x in range(0, self.width, TILE[1]):
                yield band[:, x:x + TILE[1]]

    def _run(self, dpi_x, dpi_y, description):
        try:
            tifffile.imwrite(self.path, data=self._tiles(), shape=(self.height, self.width, 4),
                             dtype=np.uint8, photometric="separated", tile=TILE,
                             compression="zlib", resolution=(dpi_x, dpi_y),
                             resolutionunit="INCH", description=description)
        except BaseException as exc:  # reported by write()/close()
            self._error = exc
            while self._q.get() is not None:   # drain so producers never block
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
        if self._rows != self.height and not self._error:
            # pad with blank rows so the file is valid; the caller decided it is complete
            self.write(np.zeros((self.height - self._rows, self.width, 4), np.uint8))
        self._q.put(None)
        self._thread.join()
        if self._error:
            raise self._error

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


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
    if not cv2.imwrite(str(png_path), rgb[:, :, ::-1]):
        raise OSError(f"{png_path}: cannot write the preview")
