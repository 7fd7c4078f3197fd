"""What every image reader of rip/load/ hands over (docs/rip.md "Input back ends"): the
opened image (`ImageSource`, whose `bands(rows)` yields it top to bottom with memory
bounded by the band), the error every problem with a file is raised as (`ImageError`), the
header the sniffers read (`_Hdr`), the band layout libvips and the strip reader agree on
(`_VipsPlan`), the decompression-bomb check (`_check_dims`), and `_reband`, which re-cuts
any stream of rows into bands of a given height (the readers, rip/place.py, the layout)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np


class ImageError(Exception):
    """A file that cannot be printed.  ``str(e) == f"{path}: {problem}"``."""

    def __init__(self, path: Any, problem: str):
        self.path = os.fspath(path) if not isinstance(path, str) else path
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")

    def __reduce__(self):  # picklable across processes
        return (type(self), (self.path, self.problem))


def _fmt_px(n: int) -> str:
    if n >= 1_000_000_000:
        return f"{n / 1e9:.1f} Gpx"
    if n >= 1_000_000:
        return f"{n / 1e6:.1f} Mpx"
    return f"{n} px"


def _check_dims(path: str, w: int, h: int, max_pixels: int, max_side: int) -> None:
    if w <= 0 or h <= 0:
        raise ImageError(path, f"invalid image dimensions {w} x {h} px")
    if w * h > max_pixels:
        raise ImageError(path, f"image too large: {w} x {h} px exceeds the limit of {_fmt_px(max_pixels)}")
    if w > max_side or h > max_side:
        raise ImageError(path, f"image too large: {w} x {h} px exceeds the limit of {max_side} px per side")


@dataclass
class _Hdr:
    width: int = 0
    height: int = 0
    xres: float | None = None
    yres: float | None = None
    extra: dict = field(default_factory=dict)


@dataclass
class _VipsPlan:
    colour: int  # number of colour bands at the start of the image
    alpha: int | None  # band index of alpha, or None
    colorspace: str
    depth: int
    invert: bool = False  # CMYK JPEG that libvips hands over inverted


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


@dataclass
class ImageSource:
    path: str
    width: int
    height: int
    channels: int  # 1 (grey), 3 (rgb) or 4 (cmyk) after alpha is removed
    colorspace: str  # 'grey' | 'rgb' | 'cmyk'
    depth: int  # 8 or 16 (dtype of the bands: uint8 / uint16)
    xres: float | None  # pixels per inch, None if the file has none
    yres: float | None
    icc: bytes | None  # embedded ICC profile
    format: str = ""  # 'tiff' | 'jpeg' | 'png' | 'bmp'
    _reader: Any = field(default=None, repr=False, compare=False)

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint16 if self.depth == 16 else np.uint8)

    def bands(self, rows: int = 256) -> Iterator[np.ndarray]:
        """Yield the image top to bottom as (h, width, channels) uint8/uint16 arrays, h == rows except the
        last.  CMYK values are ink amounts (0 = none).  Alpha is composited onto white paper.  Memory is
        bounded by the band.  Decoding problems are raised as :class:`ImageError`.  May be called again
        to re-read the image from the top."""
        if self._reader is None:
            raise ValueError(f"{self.path}: image source is closed")
        rows = int(rows)
        if rows < 1:
            raise ValueError("rows must be >= 1")
        return self._bands(self._reader, rows)

    def _bands(self, reader, rows: int) -> Iterator[np.ndarray]:
        try:
            yield from reader.bands(rows)
        except ImageError:
            raise
        except MemoryError:
            raise ImageError(self.path, "not enough memory to decode the image") from None
        except OSError as e:
            raise ImageError(self.path, f"cannot read file: {e.strerror or e}") from None

    def close(self) -> None:
        self._reader = None

    def __enter__(self) -> "ImageSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
