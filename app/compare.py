"""Compare two planes/media TIFFs dot for dot (`wideprint compare A B`, also
`python -m wideprint.app.compare`).  Exit 0 when equal, 1 when they differ, 2 when a file
cannot be read (the message names it: missing, truncated, not a planes file).  Either file may use either
encoding (8-bit or packed, docs/formats.md); both are read band by band, so memory is a
band of each, whatever the print's length."""

from __future__ import annotations

import sys

import numpy as np

from ..rip.planes import iter_planes

COLORS = "CMYK"


class CompareError(Exception):
    """A file that cannot be compared (missing, truncated, not a planes file): the message
    names it."""


def _reading(path: str, what):
    """what() with any failure to read `path` turned into CompareError naming the file."""
    try:
        return what()
    except CompareError:
        raise
    except MemoryError:
        raise CompareError(f"{path}: too large to read") from None
    except OSError as exc:
        raise CompareError(f"{path}: {exc.strerror or exc}") from None
    except Exception as exc:  # noqa: BLE001 - a damaged file breaks the reader anywhere
        raise CompareError(f"{path}: cannot be read as a planes TIFF (truncated or damaged?): "
                           f"{type(exc).__name__}: {exc}") from None


def _size(path: str) -> tuple[int, int]:
    return _reading(path, lambda: _shape(path))


def _shape(path: str) -> tuple[int, int]:
    import tifffile
    with tifffile.TiffFile(path) as tf:
        shape = tf.pages[0].shape
    if len(shape) != 3 or shape[2] != 4:
        raise CompareError(f"{path}: not a 4-channel CMYK planes file (shape {shape})")
    return shape[0], shape[1]


def _aligned(a_path: str, b_path: str):
    """(first row, a rows, b rows): the two files cut into the same bands."""
    ia = _reading(a_path, lambda: iter_planes(a_path))
    ib = _reading(b_path, lambda: iter_planes(b_path))
    a = b = np.zeros((0, 0, 4), np.uint8)
    y = 0
    while True:
        if not len(a):
            a = _reading(a_path, lambda: next(ia, None))
        if not len(b):
            b = _reading(b_path, lambda: next(ib, None))
        if a is None or b is None:
            return
        n = min(len(a), len(b))
        yield y, a[:n], b[:n]
        y += n
        a, b = a[n:], b[n:]


def compare(a_path: str, b_path: str) -> tuple[bool, str]:
    (ah, aw), (bh, bw) = _size(a_path), _size(b_path)
    if (ah, aw) != (bh, bw):
        return False, f"sizes differ: {a_path} {aw}x{ah}, {b_path} {bw}x{bh}"
    drops = np.zeros(4, np.int64)
    n, first, rows, doubled = 0, None, [None, None], 0
    for y, a, b in _aligned(a_path, b_path):
        drops += a.reshape(-1, 4).sum(axis=0, dtype=np.int64)
        doubled += int((a > 1).sum() + (b > 1).sum())
        diff = a != b
        k = int(np.count_nonzero(diff))
        if k:
            r, c, ch = np.nonzero(diff)
            if first is None:
                first = (y + r[0], c[0], ch[0])
                rows[0] = y + int(r.min())
            rows[1] = y + int(r.max())
            n += k
    if n == 0:
        return True, (f"identical: {aw} x {ah} dots, drops "
                      + " ".join(f"{c} {d}" for c, d in zip(COLORS, drops)))
    return False, (f"{n} dots differ (first at row {first[0]}, column {first[1]}, "
                   f"{COLORS[first[2]]}); rows {rows[0]}..{rows[1]}; doubled dots {doubled}")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: compare A.tif B.tif", file=sys.stderr)
        return 2
    try:
        same, text = compare(*argv)
    except CompareError as exc:
        print(f"compare: {exc}", file=sys.stderr)
        return 2
    print(text)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
