"""Planes and media TIFFs (docs/formats.md "Planes and media TIFFs"): 4 channels C, M, Y,
K, one value per dot (0 = no drop, n = n drops), device resolution, deflate-compressed,
written band by band so memory is bounded by the band, never by the image length.

Two encodings of the same content, and every reader here accepts both:
- "8bit" (the default, and always for media): 8 bits per sample, tiled 64 x 1024.  What any
  TIFF reader opens (tifffile, PIL, libvips); the only one that can hold a doubled dot (2).
- "packed": 1 bit per sample (each dot's C, M, Y, K in one nibble), strips of 64 rows; 0/1
  only (the RIP's planes).  8x less to compress and store; tifffile and wideprint read it,
  PIL and libvips do not (docs/formats.md says why it is not the default).

Segments are deflated on worker threads, which release the GIL, while the caller makes the
next band: 8-bit tiles of 0/1 samples by the dot coder (rip/dotdeflate.py), the rest by
ISA-L (python-isal; imagecodecs or zlib without it)."""

from __future__ import annotations

import contextlib
import os
import queue
import secrets
import shutil
import stat
import sys
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Callable, Iterator, cast

import numpy as np
import tifffile

from .compiled import kernel
from .dotdeflate import deflate_dot_tile
from .parallel import WORKERS

TILE = (64, 1024)          # the 8-bit encoding's tiles
STRIP_ROWS = 64            # the packed encoding's strips
FORMATS = ("8bit", "packed")
DEFLATE_LEVEL = 1          # level 6 gives files ~25 % smaller at 3-5x the CPU time
_ABORT = object()
_NIBBLE_MASKS = (0x88, 0x44, 0x22, 0x11)      # C, M, Y, K of the two dots in a packed byte
# A dot's 4 inks are 4 bytes side by side: seen as one uint32 per dot, ink c is the byte at
# bit INK_SHIFT[c] (rip/swath.py packs 8 dots' inks in one word; the emulator's media lands
# drops of one ink with a shift).
INK_SHIFT = (0, 8, 16, 24) if sys.byteorder == "little" else (24, 16, 8, 0)


def _spread_table() -> np.ndarray:
    """byte b (8 dots of one ink, x = 0 in bit 7) -> uint32 with dot i at bit 31 - 4 i: one
    ink's bits in the packed encoding's nibbles (C at the nibble's top bit, K at its bottom)."""
    b = np.arange(256, dtype=np.uint32)
    out = np.zeros(256, np.uint32)
    for i in range(8):
        out |= ((b >> np.uint32(7 - i)) & np.uint32(1)) << np.uint32(31 - 4 * i)
    return out


_SPREAD = _spread_table()


def _deflate(quick: bool = False) -> Callable[[Any], bytes]:
    """A deflate (zlib stream) encoder for the file's tiles and strips: ISA-L's level 1
    (python-isal; it releases the GIL).  Measured on a print's media, one core: a 256 KB
    8-bit tile of 0/1 samples 0.55 ms to 13 % of its size, against zlib-ng's `deflate_quick`
    0.77 ms to 23 % and libdeflate level 1 1.34 ms to 10 %; a 1.2 MB strip of the packed
    encoding 4.2 ms against libdeflate level 1's 15.9 ms, both to 59 %.  Without isal:
    zlib-ng's level 1 for the 8-bit tiles (`quick`), libdeflate's for the packed strips,
    then zlib.  Any inflate reads them all."""
    try:
        from isal import isal_zlib

        def isal(data: Any) -> bytes:
            if isinstance(data, np.ndarray) and not data.flags.c_contiguous:
                data = np.ascontiguousarray(data)       # it takes contiguous buffers only
            return isal_zlib.compress(data, 1)
        return isal
    except ImportError:            # pragma: no cover - isal is a dependency
        pass
    try:
        import imagecodecs
        if quick and imagecodecs.ZLIBNG.available:
            return lambda data: imagecodecs.zlibng_encode(data, level=1)  # type: ignore[return-value]
        return lambda data: imagecodecs.deflate_encode(data, level=DEFLATE_LEVEL)  # type: ignore[return-value]
    except ImportError:            # pragma: no cover - imagecodecs is a dependency
        import zlib
        return lambda data: zlib.compress(data, DEFLATE_LEVEL)


def _nibble_dots(band: np.ndarray) -> np.ndarray:
    """Dots per colour in packed-encoding rows: each colour's bits counted 8 bytes at a
    time (a mask per colour, the CPU's popcount)."""
    flat = np.ascontiguousarray(band).reshape(-1)
    whole = flat.size - flat.size % 8
    words, tail = flat[:whole].view(np.uint64), flat[whole:]
    return np.array([np.bitwise_count(words & np.uint64(int.from_bytes(bytes([m]) * 8, "little")))
                     .sum(dtype=np.int64) + np.bitwise_count(tail & np.uint8(m)).sum(dtype=np.int64)
                     for m in _NIBBLE_MASKS], np.int64)


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


@kernel()
def _nibble_rows(bits: np.ndarray, spread: np.ndarray, out: np.ndarray) -> None:
    """bits (h, 4, wb) -> out (h, n) bytes of the packed encoding, n <= 4 wb: the 8 dots of
    plane byte xb are the 4 bytes from 4 xb, dot 0 in the high nibble (big-endian order).
    A compiled loop: numpy's four table look-ups over the band took ~9x as long (1.0 ms
    against 0.11 ms for 64 rows 12,000 dots wide: fancy indexing and the casts between
    uint8 and the table's uint32)."""
    n = out.shape[1]
    wb = bits.shape[2]
    for i in range(bits.shape[0]):
        for xb in range(wb):
            w = (spread[bits[i, 0, xb]] | (spread[bits[i, 1, xb]] >> np.uint32(1))
                 | (spread[bits[i, 2, xb]] >> np.uint32(2)) | (spread[bits[i, 3, xb]] >> np.uint32(3)))
            o = 4 * xb
            if o + 4 <= n:
                out[i, o] = w >> np.uint32(24)
                out[i, o + 1] = (w >> np.uint32(16)) & np.uint32(0xFF)
                out[i, o + 2] = (w >> np.uint32(8)) & np.uint32(0xFF)
                out[i, o + 3] = w & np.uint32(0xFF)
            else:                                   # the row's last, partial word
                for j in range(n - o):
                    out[i, o + j] = (w >> np.uint32(24 - 8 * j)) & np.uint32(0xFF)


def _bits_to_nibbles(bits: np.ndarray, width: int) -> np.ndarray:
    """(h, 4, ceil(W / 8)) plane bits -> (h, ceil(W / 2)) bytes of the packed encoding (each
    dot a nibble C M Y K, x = 0 in the first byte's high nibble)."""
    out = np.empty((bits.shape[0], -(-width // 2)), np.uint8)
    _nibble_rows(np.ascontiguousarray(bits), _SPREAD, out)
    return out


class PlanesWriter:
    """Append rows top to bottom (`write`: dots (n, W, 4); `write_bits`: the RIP's packed
    bands (n, 4, ceil(W / 8)); one kind per file); the file is complete after close().
    `dots` holds the drops per colour written.  Leaving a `with` block by an exception
    aborts instead: the unfinished file is removed, not padded."""

    def __init__(self, path: str | Path, width: int, height: int, dpi_x: float, dpi_y: float,
                 description: str = "wideprint planes", planes_format: str = "8bit",
                 workers: int | None = None):
        if planes_format not in FORMATS:
            raise ValueError(f"planes format must be one of {', '.join(FORMATS)}, not {planes_format!r}")
        self.path, self.width, self.height = str(path), width, height
        self.packed = planes_format == "packed"
        self.rows_per_segment = STRIP_ROWS if self.packed else TILE[0]
        description = _ascii(description)      # a TIFF string is 7-bit ASCII; file names are not
        self.dots = np.zeros(4, np.int64)
        self._kind: str | None = None           # "dots" or "bits": what write*() was given
        self._pending: list[tuple[str, np.ndarray]] = []     # (kind, rows)
        self._pending_rows = 0
        self._rows = 0
        workers = workers or WORKERS            # the RIP's count (rip/parallel.py)
        self._deflate = _deflate(quick=not self.packed)
        self._blank: bytes | None = None        # a deflated tile of blank paper
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="planes-deflate")
        # futures of encoded bands in file order; bounded: memory is a few bands
        self._q: queue.Queue[Any] = queue.Queue(maxsize=workers + 1)
        self._error: BaseException | None = None
        self._opened = False
        self._thread = threading.Thread(target=self._run, args=(dpi_x, dpi_y, description),
                                        name="planes-writer", daemon=True)
        self._thread.start()

    # -- the file (writer thread) ---------------------------------------------------------
    def _segments(self) -> Iterator[bytes]:
        while True:
            item = self._q.get()
            if item is None:
                return
            if item is _ABORT:
                raise _Aborted
            segments, dots = item.result()
            self.dots += dots
            yield from segments

    def _run(self, dpi_x: float, dpi_y: float, description: str) -> None:
        layout = dict(rowsperstrip=STRIP_ROWS) if self.packed else dict(tile=TILE)
        try:
            with open(self.path, "wb") as fh:
                self._opened = True             # from now on an abort removes what we wrote
                # the segments come deflated: tifffile writes them as they are
                tifffile.imwrite(fh, data=self._segments(), shape=(self.height, self.width, 4),
                                 dtype=bool if self.packed else np.uint8, photometric="separated",
                                 compression="zlib", resolution=(dpi_x, dpi_y),
                                 resolutionunit="INCH", description=description, metadata=None,
                                 **layout)
        except BaseException as exc:  # reported by write()/close()
            self._error = exc
            if not isinstance(exc, _Aborted):
                while self._q.get() not in (None, _ABORT):   # drain so producers never block
                    pass

    # -- encoding (worker threads) --------------------------------------------------------
    def _encode(self, kind: str, band: np.ndarray) -> tuple[list[bytes], np.ndarray]:
        """One band of the file, deflated: kind "nibbles" (the packed encoding's rows),
        "bits" (the RIP's packed bands) or "dots" (8-bit values, some above 1)."""
        n = band.shape[0]
        if kind == "bits":
            dots = np.bitwise_count(band).sum(axis=(0, 2), dtype=np.int64)
            if self.packed:
                band, kind = _bits_to_nibbles(band, self.width), "nibbles"
        elif kind == "nibbles":
            dots = _nibble_dots(band)
        else:
            dots = band.reshape(-1, 4).sum(axis=0, dtype=np.int64)
        if self.packed:
            return [self._deflate(band)], dots
        if kind == "bits":
            band, kind = _bits_to_nibbles(band, self.width), "nibbles"
        th, tw = TILE
        # 0/1 samples go to the dot coder as the packed rows they are (docs/formats.md)
        tile = np.zeros((th, tw // 2) if kind == "nibbles" else (th, tw, 4), np.uint8)
        out = []
        for x in range(0, self.width, tw):       # a tile at a time: memory is a tile
            ww = min(tw, self.width - x)
            part = band[:, x // 2:(x + ww + 1) // 2] if kind == "nibbles" else band[:, x:x + ww]
            if not part.any():                    # blank paper: the same bytes every time
                out.append(self._blank_tile())
                continue
            if n < th or ww < tw:
                tile[:] = 0
            tile[:n, :part.shape[1]] = part       # tiles are 1024 wide: x // 2 is exact
            out.append(deflate_dot_tile(tile) if kind == "nibbles" else self._deflate(tile))
        return out, dots

    def _blank_tile(self) -> bytes:
        if self._blank is None:
            self._blank = self._deflate(np.zeros(TILE + (4,), np.uint8))
        return self._blank

    # -- the caller's side ----------------------------------------------------------------
    def write(self, rows: np.ndarray) -> None:
        """Dots (n, W, 4), one value per dot."""
        rows = np.asarray(rows, dtype=np.uint8)
        if rows.ndim != 3 or rows.shape[1:] != (self.width, 4):
            raise ValueError(f"rows must be (n, {self.width}, 4), got {rows.shape}")
        self._append("dots", rows)

    def write_bits(self, bits: np.ndarray) -> None:
        """The RIP's packed bands (n, 4, ceil(W / 8)) uint8, x = 0 in bit 7 of byte 0, the
        bits beyond the width 0 (rip/swath.py pack_dots)."""
        bits = np.asarray(bits, dtype=np.uint8)
        if bits.ndim != 3 or bits.shape[1:] != (4, -(-self.width // 8)):
            raise ValueError(f"bits must be (n, 4, {-(-self.width // 8)}), got {bits.shape}")
        self._append("bits", bits)

    def _append(self, kind: str, rows: np.ndarray) -> None:
        if self._error:
            raise self._error
        if self._kind not in (None, kind):
            raise ValueError(f"this file is written from {self._kind}; cannot add {kind}")
        self._kind = kind
        if self._rows + rows.shape[0] > self.height:
            raise ValueError("more rows than the declared height")
        self._rows += rows.shape[0]
        if kind == "dots":
            # 0/1 dots wait for their band as the packed encoding's rows, 1/8 of the bytes
            # (np.packbits is ~10x faster than deflate), and the caller's array is free to
            # be reused at once (the emulator's media window is)
            if rows.size and int(rows.max()) > 1:
                if self.packed:
                    raise ValueError(f"the packed planes format holds 0 or 1 drop per dot, "
                                     f"not {int(rows.max())}")
                item = ("dots", rows.copy())
            else:
                item = ("nibbles", np.packbits(rows.reshape(rows.shape[0], -1), axis=1))
        else:
            item = (kind, rows)
        self._pending.append(item)
        self._pending_rows += item[1].shape[0]
        seg = self.rows_per_segment
        while self._pending_rows >= seg or (self._rows == self.height and self._pending_rows):
            self._flush_band()

    def _flush_band(self) -> None:
        kinds = {k for k, _ in self._pending}
        if len(kinds) > 1:                   # a doubled dot among 0/1 rows: all as dots
            w = self.width
            parts = [a if k == "dots" else
                     np.unpackbits(a, axis=1, count=w * 4).reshape(a.shape[0], w, 4)
                     for k, a in self._pending]
            kind = "dots"
        else:
            parts, kind = [a for _, a in self._pending], kinds.pop()
        allrows = np.concatenate(parts) if len(parts) > 1 else parts[0]
        n = min(self.rows_per_segment, allrows.shape[0])
        band = np.ascontiguousarray(allrows[:n])
        rest = allrows[n:]
        if kind == "dots" and rest.size and int(rest.max()) <= 1:     # past the doubled dot
            rest, kind_rest = np.packbits(rest.reshape(rest.shape[0], -1), axis=1), "nibbles"
        else:
            kind_rest = kind
        self._pending = [(kind_rest, rest)] if rest.shape[0] else []
        self._pending_rows = rest.shape[0]
        future = self._pool.submit(self._encode, kind, band)
        while True:                 # never block forever on a writer that has failed
            if self._error:
                future.cancel()
                raise self._error
            try:
                self._q.put(future, timeout=0.1)
                return
            except queue.Full:
                continue

    def close(self) -> None:
        # pad with blank rows so the file is valid (the caller decided it is complete), a
        # band at a time: the missing rows may be far more than memory holds
        while self._rows != self.height and not self._error:
            n = min(self.rows_per_segment, self.height - self._rows)
            if self._kind == "bits":
                self.write_bits(np.zeros((n, 4, -(-self.width // 8)), np.uint8))
            else:
                self.write(np.zeros((n, self.width, 4), np.uint8))
        self._q.put(None)
        self._thread.join()
        self._pool.shutdown(wait=True)
        if self._error:
            raise self._error

    def abort(self) -> None:
        """Stop writing and remove the unfinished file."""
        if self._thread.is_alive():
            self._q.put(_ABORT)
            self._thread.join()
        self._pool.shutdown(wait=True, cancel_futures=True)
        with contextlib.suppress(OSError):
            if self._opened and stat.S_ISREG(os.stat(self.path).st_mode):
                os.unlink(self.path)

    def __enter__(self) -> PlanesWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


@contextlib.contextmanager
def output_file(path: str | Path) -> Iterator[str]:
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
    """The whole planes/media TIFF, either encoding, as (rows, cols, 4) uint8 (tests and
    small jobs)."""
    with tifffile.TiffFile(str(path)) as tf:
        page = cast(tifffile.TiffPage, tf.pages[0])       # the first page: never a frame
        if (page.is_tiled and page.compression == 8 and page.predictor == 1 and page.planarconfig == 1
                and page.bitspersample == 8 and page.shape[2:] == (4,) and len(page.shape) == 3):
            return _read_tiles(tf.filehandle, page)
    data = tifffile.imread(str(path))
    if data.ndim != 3 or data.shape[2] != 4:
        raise ValueError(f"{path}: not a 4-channel CMYK planes file (shape {data.shape})")
    return data.view(np.uint8) if data.dtype == np.bool_ else data


def _read_tiles(fh: Any, page: Any) -> np.ndarray:
    """An 8bit file's tiles inflated by ISA-L on two threads (twice zlib's speed: reading a
    full-width print's media back is a good part of an acceptance test's time)."""
    from isal import isal_zlib
    h, w = page.shape[:2]
    th, tw = page.tilelength, page.tilewidth
    across = -(-w // tw)
    out = np.empty((h, w, 4), np.uint8)

    def inflate(k: int, data: bytes) -> None:
        y, x = (k // across) * th, (k % across) * tw
        hh, ww = min(th, h - y), min(tw, w - x)
        if not data:                                 # a tile never written: blank, as in tifffile
            out[y:y + hh, x:x + ww] = 0
            return
        try:
            tile = np.frombuffer(isal_zlib.decompress(data, bufsize=th * tw * 4), np.uint8)
        except isal_zlib.error as exc:  # type: ignore[misc]  # isal's stub types it as a function
            raise ValueError(f"{fh.name}: tile {k} does not inflate: {exc}") from None
        if tile.size != th * tw * 4:
            raise ValueError(f"{fh.name}: tile {k} holds {tile.size} bytes, not {th * tw * 4}")
        out[y:y + hh, x:x + ww] = tile.reshape(th, tw, 4)[:hh, :ww]

    with ThreadPoolExecutor(2, thread_name_prefix="planes-inflate") as pool:
        done = [pool.submit(inflate, k, data)
                for data, k in fh.read_segments(page.dataoffsets, page.databytecounts, sort=True)]
        for f in done:
            f.result()
    return out


def planes_format(path: str | Path) -> str:
    """"8bit" or "packed": which encoding a planes/media TIFF uses (docs/formats.md)."""
    with tifffile.TiffFile(str(path)) as tf:
        return "packed" if cast(tifffile.TiffPage, tf.pages[0]).bitspersample == 1 else "8bit"


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


READ_BUFFER = 1 << 20      # bytes of a planes file read at once (iter_planes)


def iter_planes(path: str | Path) -> Iterator[np.ndarray]:
    """The planes/media TIFF (either encoding) top to bottom as (rows, width, 4) uint8
    bands, one strip or tile row at a time: memory is one band, whatever the print's length."""
    with tifffile.TiffFile(str(path)) as tf:
        page = tf.pages[0]
        if len(page.shape) != 3 or page.shape[2] != 4:
            raise ValueError(f"{path}: not a 4-channel CMYK planes file (shape {page.shape})")
        h, w = page.shape[:2]
        band: np.ndarray | None = None
        y0, bh = -1, 0
        # one tile at a time, read from the file 1 MB at a time (tifffile reads up to
        # 256 MB of compressed tiles in one go by default: all of a 0.25 m2 media file)
        for seg, idx, _shape in page.segments(maxworkers=1, buffersize=READ_BUFFER):
            y, x = idx[-3], idx[-2]
            arr = cast(np.ndarray, seg)                # every segment is in the file
            seg = cast(np.ndarray, arr.reshape(arr.shape[-3:]))
            if band is None or y != y0:
                if band is not None:
                    yield band[:min(bh, h - y0)]
                y0, bh = y, seg.shape[0]
                band = np.zeros((bh, w, 4), np.uint8)
            hh, ww = min(seg.shape[0], h - y), min(seg.shape[1], w - x)
            band[:hh, x:x + ww] = seg[:hh, :ww]
        if band is not None:
            yield band[:h - y0]


def _resolution(page: Any, tag: str, default: float) -> float:
    t = page.tags.get(tag)
    try:
        num, den = t.value
        return num / den if num and den else default
    except (AttributeError, TypeError, ValueError):
        return default


@kernel()
def _box_sums(band: np.ndarray, y0: int, by: int, bx: int, lut: np.ndarray,
              sums: np.ndarray) -> None:
    """Add the ink colour of every dot of `band` (rows from y0) into its by x bx box."""
    for r in range(band.shape[0]):
        yy = (y0 + r) // by
        for c in range(band.shape[1]):
            i = (band[r, c, 0] > 0) | (band[r, c, 1] > 0) << 1 | \
                (band[r, c, 2] > 0) << 2 | (band[r, c, 3] > 0) << 3
            xx = c // bx
            sums[yy, xx, 0] += lut[i, 0]
            sums[yy, xx, 1] += lut[i, 1]
            sums[yy, xx, 2] += lut[i, 2]


def _ink_lut() -> np.ndarray:
    """sRGB of every combination of inks on one dot (index: C | M<<1 | Y<<2 | K<<3)."""
    lut = np.ones((16, 3), np.float32)
    for combo in range(16):
        for c in range(4):
            if combo >> c & 1:
                lut[combo] *= INK_RGB[c]
    return (lut * 255 + 0.5).astype(np.uint8)


_LUT = _ink_lut()


def _reflect101(i: int, n: int) -> int:
    """An index outside [0, n) mirrored about the edge samples (OpenCV's BORDER_REFLECT_101)."""
    if n == 1:
        return 0
    while not 0 <= i < n:
        i = -i if i < 0 else 2 * n - 2 - i
    return i


def _axis_taps(n: int, m: int, sigma: float, area: bool) -> tuple[np.ndarray, np.ndarray]:
    """One axis of the preview's low-pass and resampling, n samples to m, as taps: output j
    is sum_t weight[j, t] * input[index[j, t]].  A Gaussian of `sigma` samples (OpenCV's
    GaussianBlur: 8 sigma + 1 taps, mirrored edges), then cv2.resize's INTER_AREA: with
    `area` (both axes shrink) each output the mean of the inputs its cell covers, in part at
    its ends; else (the picture finer than the dots on an axis) its blend of neighbours."""
    k = max(1, int(round(sigma * 8 + 1)) | 1)
    x = np.arange(k) - (k - 1) / 2
    g = np.exp(-x * x / (2 * sigma * sigma))
    g /= g.sum()
    rows: list[dict[int, float]] = []
    scale = n / m
    for d in range(m):
        taps: list[tuple[int, float]] = []
        if area:                                       # INTER_AREA's table
            f1 = d * scale
            f2 = f1 + scale
            cell = min(scale, n - f1)
            s1, s2 = int(np.ceil(f1)), int(np.floor(f2))
            s2 = min(s2, n - 1)
            s1 = min(s1, s2)
            if s1 - f1 > 1e-3:
                taps.append((s1 - 1, (s1 - f1) / cell))
            taps += [(i, 1.0 / cell) for i in range(s1, s2)]
            if f2 - s2 > 1e-3:
                taps.append((s2, min(f2 - s2, 1.0, cell) / cell))
        else:                                          # INTER_AREA not shrinking
            i0 = int(np.floor(d * scale))
            f = (d + 1) - (i0 + 1) * m / n
            f = 0.0 if f <= 0 else f - np.floor(f)
            if i0 >= n - 1:
                i0, f = n - 1, 0.0
            taps = [(i0, 1.0 - f), (min(i0 + 1, n - 1), f)]
        w: dict[int, float] = {}
        for i, a in taps:
            for t in range(k):
                j = _reflect101(i + t - (k - 1) // 2, n)
                w[j] = w.get(j, 0.0) + a * g[t]
        rows.append(w)
    width = max(max(w) - min(w) + 1 for w in rows)
    index = np.zeros((m, width), np.intp)
    weight = np.zeros((m, width), np.float32)
    for d, w in enumerate(rows):
        lo = min(w)
        index[d] = np.minimum(lo + np.arange(width), n - 1)
        for i, a in w.items():
            weight[d, i - lo] += a
    return index, weight


def _dense(index: np.ndarray, weight: np.ndarray, n: int) -> np.ndarray:
    """Taps (outputs, taps) as a dense (outputs, n) matrix."""
    m = np.zeros((index.shape[0], n), np.float32)
    np.add.at(m, (np.arange(index.shape[0])[:, None], index), weight)
    return m


def preview_image(planes_path: str | Path, max_side: int = 2000) -> np.ndarray:
    """An sRGB picture (rows, cols, 3) of a planes/media TIFF at its true physical aspect
    (the device grid is 300 x 370.5 dots per inch: a square prints square), low-passed
    as the eye sees a print from a distance (area sums, then a Gaussian of about 0.7 of a
    picture pixel: no aliasing, no beat between dot patterns and pixels), at most `max_side`
    pixels a side and never finer than the finer dot pitch.

    Streamed: each band of dots is summed into whole-dot boxes, the finished rows of boxes
    are filtered and resampled across (`_axis_taps`), and each picture row is made down the
    page as soon as the box rows it needs are in.  Memory is a band, a few rows of boxes and
    the picture itself (12 MB at 2000 x 2000), whatever the print's size: holding every box
    of a 0.25 m2 print, as it once did, took ~200 MB."""
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
    inter_w, inter_h = -(-w // bx), -(-h // by)
    cols = np.full(inter_w, float(bx), np.float32)           # dots in each box: whole
    cols[-1] = w - (inter_w - 1) * bx                         # boxes but the last column
    last_rows = h - (inter_h - 1) * by                        # and the last row of boxes
    area = inter_w >= out_w and inter_h >= out_h
    xi, xw = _axis_taps(inter_w, out_w, 0.7 * max(inter_w / out_w, 1.0), area)
    yi, yw = _axis_taps(inter_h, out_h, 0.7 * max(inter_h / out_h, 1.0), area)
    need = yi.max(axis=1)                                     # the last box row each picture row needs
    xblocks = []                                              # the taps across as small matrices
    for c0 in range(0, out_w, 256):
        c1 = min(out_w, c0 + 256)
        lo, hi = int(xi[c0:c1].min()), int(xi[c0:c1].max()) + 1
        xblocks.append((c0, c1, lo, hi, _dense(xi[c0:c1] - lo, xw[c0:c1], hi - lo).T.copy()))
    out = np.empty((out_h, out_w, 3), np.uint8)
    across: list[np.ndarray] = []                             # box rows filtered across, from `base`
    base, done = 0, 0

    def box_rows(sums: np.ndarray, r0: int) -> None:
        """Finished box rows r0.. in: across, then every picture row they complete."""
        nonlocal base, done
        n = sums.shape[0]
        counts = np.full(n, float(by), np.float32)
        if r0 + n == inter_h:
            counts[-1] = last_rows
        mean = np.divide(sums, (counts[:, None, None] * cols[None, :, None]), dtype=np.float32)
        mean = np.ascontiguousarray(mean.transpose(0, 2, 1)).reshape(n * 3, inter_w)
        acc = np.empty((n * 3, out_w), np.float32)       # rows of (3, out_w): one BLAS call
        for c0, c1, lo, hi, m in xblocks:                 # a block: (rows x 3, inputs) @ (inputs, outputs)
            acc[:, c0:c1] = mean[:, lo:hi] @ m
        across.append(acc.reshape(n, 3, out_w))
        have = base + sum(a.shape[0] for a in across)
        last = done
        while last < out_h and need[last] < have:
            last += 1
        if last == done:
            return
        rows = np.concatenate(across) if len(across) > 1 else across[0]
        down = _dense(yi[done:last] - base, yw[done:last], rows.shape[0])
        part = (down @ rows.reshape(rows.shape[0], -1)).reshape(last - done, 3, out_w)
        out[done:last] = np.clip(part.transpose(0, 2, 1) + 0.5, 0, 255).astype(np.uint8)
        done = last
        keep = int(yi[done:, 0].min()) if done < out_h else have
        across[:] = [rows[keep - base:]]
        base = keep

    y = 0
    carry: tuple[int, np.ndarray] | None = None                # a box row the band left unfinished
    for band in iter_planes(planes_path):
        y1 = y + band.shape[0]
        r0, r1 = y // by, (y1 - 1) // by + 1
        sums = np.zeros((r1 - r0, inter_w, 3), np.uint32)
        if carry is not None and carry[0] == r0:
            sums[0] = carry[1]
        _box_sums(band, y - r0 * by, by, bx, _LUT, sums)
        finished = r1 if y1 >= h else y1 // by
        if finished > r0:
            box_rows(sums[:finished - r0], r0)
        carry = (finished, sums[finished - r0].copy()) if finished < r1 else None
        y = y1
    return out


def png_bytes(rgb: np.ndarray) -> bytes:
    """An (h, w, 3) uint8 sRGB picture as a PNG file's bytes: zlib and the "Up" filter, a
    few hundred rows at a time (no image library: cv2's import alone is ~37 MB of memory)."""
    import struct
    import zlib
    h, w = rgb.shape[:2]

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + \
            struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    z = zlib.compressobj(1)          # fast, as cv2's PNG default; the picture is small anyway
    flat = rgb.reshape(h, w * 3)
    parts = []
    for y0 in range(0, h, 256):
        y1 = min(h, y0 + 256)
        rows = np.empty((y1 - y0, 1 + w * 3), np.uint8)
        rows[:, 0] = 2                                      # filter "Up": the row above subtracted
        rows[:, 1:] = flat[y0:y1]
        rows[1:, 1:] -= flat[y0:y1 - 1]
        if y0:
            rows[0, 1:] -= flat[y0 - 1]
        parts.append(z.compress(rows.tobytes()))
    parts.append(z.flush())
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", b"".join(parts)) + chunk(b"IEND", b""))


def write_preview(planes_path: str | Path, png_path: str | Path, max_side: int = 2000) -> None:
    """A PNG preview of a planes/media TIFF: true physical aspect, area-averaged, built in
    bands (preview_image)."""
    png = png_bytes(preview_image(planes_path, max_side))
    with open(png_path, "wb") as f:
        f.write(png)
