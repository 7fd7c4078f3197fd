"""BMP, read by our own parser (pyvips-binary has no BMP loader; docs/rip.md "Input back
ends"): uncompressed rows straight from the file with numpy (bottom-up or top-down),
RLE4/RLE8 decoded by a small numba kernel into an index plane (one byte per pixel).  Not
OpenCV: ``cv2.imread`` has no banded read and decodes the whole image into memory, which a
banner cannot afford."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from ..compiled import kernel
from .source import ImageError, ImageSource, _check_dims, _fmt_px

#: largest RLE-compressed BMP we decode (the index plane is held in memory: 1 byte / px)
RLE_MAX_PIXELS = 1 << 31


_BI_NAMES = {0: "none", 1: "RLE8", 2: "RLE4", 3: "bitfields", 4: "embedded JPEG", 5: "embedded PNG",
             6: "alpha bitfields", 11: "CMYK", 12: "CMYK RLE8", 13: "CMYK RLE4"}


@dataclass
class _BmpInfo:
    width: int
    height: int
    top_down: bool
    bpp: int
    compression: int
    offset: int
    stride: int
    palette: np.ndarray | None  # (256, 3) RGB uint8 for bpp <= 8
    grey: bool
    masks: tuple[int, int, int, int] | None  # r, g, b, a for 16/32-bit
    xres: float | None
    yres: float | None
    icc: bytes | None
    data_size: int
    colors: int = 0  # palette entries in the file (bpp <= 8)


def _bmp_header(path: str, f, size: int) -> _BmpInfo:
    f.seek(0)
    head = f.read(14 + 124)
    if len(head) < 26:
        raise ImageError(path, "truncated BMP: the file ends inside the header")
    off_bits = struct.unpack_from("<I", head, 10)[0]
    hsize = struct.unpack_from("<I", head, 14)[0]
    if hsize == 12:
        w, h, planes, bpp = struct.unpack_from("<HHHH", head, 18)
        compression, sizeimage, xppm, yppm, clrused = 0, 0, 0, 0, 0
        pal_entry = 3
    elif 16 <= hsize <= 64 or hsize in (108, 124):
        if len(head) < 14 + hsize:
            raise ImageError(path, "truncated BMP: the file ends inside the header")
        w, h, planes, bpp = struct.unpack_from("<iiHH", head, 18)
        compression = sizeimage = xppm = yppm = clrused = 0
        if hsize >= 40:
            compression, sizeimage, xppm, yppm, clrused = struct.unpack_from("<IIiiI", head, 30)
        if hsize == 64 and compression in (3, 4):  # OS/2 2.x: Huffman 1D / RLE24
            raise ImageError(path, f"unsupported BMP compression (OS/2 {'Huffman' if compression == 3 else 'RLE24'})")
        pal_entry = 4
    else:
        raise ImageError(path, f"corrupt BMP: unknown header size {hsize}")
    top_down = h < 0
    h = abs(h)
    if planes != 1:
        raise ImageError(path, f"corrupt BMP: {planes} colour planes (must be 1)")
    if bpp not in (1, 2, 4, 8, 16, 24, 32):
        raise ImageError(path, f"unsupported bit depth: {bpp}-bit BMP")
    if compression in (4, 5) or compression not in (0, 1, 2, 3, 6):
        raise ImageError(path, f"unsupported BMP compression {_BI_NAMES.get(compression, compression)}")
    if (compression == 1 and bpp != 8) or (compression == 2 and bpp != 4) or \
            (compression in (3, 6) and bpp not in (16, 32)):
        raise ImageError(path, f"corrupt BMP: compression {_BI_NAMES[compression]} with {bpp} bits per pixel")
    masks = None
    after = 14 + hsize
    if bpp in (16, 32):
        if compression in (3, 6):
            if hsize >= 52:
                r, g, b = struct.unpack_from("<III", head, 54)
                a = struct.unpack_from("<I", head, 66)[0] if hsize >= 56 else 0
            else:
                f.seek(after)
                extra = f.read(16 if compression == 6 else 12)
                if len(extra) < (16 if compression == 6 else 12):
                    raise ImageError(path, "truncated BMP: the file ends inside the colour masks")
                r, g, b = struct.unpack_from("<III", extra, 0)
                a = struct.unpack_from("<I", extra, 12)[0] if compression == 6 else 0
                after += len(extra)
            if compression == 3 and hsize < 56:
                a = 0
            masks = (r, g, b, a)
        elif bpp == 16:
            masks = (0x7C00, 0x03E0, 0x001F, 0)
        else:
            masks = (0x00FF0000, 0x0000FF00, 0x000000FF, 0)  # BI_RGB: 4th byte unused
        for m in masks[:3]:
            if m == 0:
                raise ImageError(path, "corrupt BMP: a colour mask is zero")
    palette = None
    grey = False
    if bpp <= 8:
        n = clrused if 0 < clrused <= (1 << bpp) else (1 << bpp)
        room = (off_bits - after) // pal_entry
        if 0 < room < n:  # the pixel data starts sooner: the palette is shorter than 2^bpp
            n = room
        f.seek(after)
        raw = f.read(n * pal_entry)
        n = len(raw) // pal_entry
        if n == 0:
            raise ImageError(path, "corrupt BMP: missing colour palette")
        p = np.frombuffer(raw[: n * pal_entry], np.uint8).reshape(n, pal_entry)[:, 2::-1]
        palette = np.zeros((256, 3), np.uint8)  # indices past the palette are refused (_BmpReader)
        palette[:n] = p
        grey = bool(np.all(p[:, 0] == p[:, 1]) and np.all(p[:, 1] == p[:, 2]))
    if compression in (1, 2) and top_down:
        raise ImageError(path, "corrupt BMP: RLE-compressed bitmaps cannot be top-down")
    stride = ((w * bpp + 31) // 32) * 4 if w > 0 else 0
    icc = None
    if hsize >= 124:
        cstype, pdata, psize = struct.unpack_from("<I", head, 70)[0], *struct.unpack_from("<II", head, 126)
        if cstype == 0x4D424544 and psize > 0 and 14 + pdata + psize <= size:  # 'MBED'
            f.seek(14 + pdata)
            icc = f.read(psize)
    xres = xppm * 0.0254 if xppm > 0 else None
    yres = yppm * 0.0254 if yppm > 0 else None
    if xres is None or yres is None:
        xres = yres = None
    return _BmpInfo(w, h, top_down, bpp, compression, off_bits, stride, palette, grey, masks, xres, yres, icc,
                    sizeimage, 0 if palette is None else n)


def _mask_shift_bits(m: int) -> tuple[int, int]:
    if m == 0:
        return 0, 0
    shift = (m & -m).bit_length() - 1
    bits = bin(m).count("1")
    return shift, bits


@kernel()
def _rle_decode(data, width, padded, height, rle4, colors, out, where):
    """RLE8/RLE4 into ``out`` (height, width) uint8, rows in file order (bottom-up).
    A run may cover the row's padding (`padded` pixels: encoders such as ImageMagick
    encode it), never more.  Returns 0 ok, 1 data ends early, 2 bad delta / position
    outside the image, 3 a run overruns its row, 4 a colour index past the palette;
    `where` gets (byte of the code in `data`, x, y, count or index) of the problem."""
    n = data.shape[0]
    x = 0
    y = 0
    i = 0
    while True:
        if y >= height:
            return 0
        if i + 1 >= n:
            where[0], where[1], where[2], where[3] = i, x, y, 0
            return 1
        count = data[i]
        val = data[i + 1]
        at = i
        i += 2
        if count > 0:  # encoded run
            where[0], where[1], where[2], where[3] = at, x, y, count
            if x + count > padded:
                return 3
            for t in range(count):
                v = ((val >> 4) if (t & 1) == 0 else (val & 15)) if rle4 else val
                if x < width:               # not the padding
                    if v >= colors:
                        where[1], where[3] = x, v
                        return 4
                    out[y, x] = v
                x += 1
        elif val == 0:  # end of line
            x = 0
            y += 1
        elif val == 1:  # end of bitmap
            return 0
        elif val == 2:  # delta
            if i + 1 >= n:
                where[0], where[1], where[2], where[3] = at, x, y, 0
                return 1
            x += data[i]
            y += data[i + 1]
            i += 2
            if x > padded or y > height or (y == height and x > 0):
                where[0], where[1], where[2], where[3] = at, x, y, 0
                return 2
        else:  # absolute run of `val` pixels
            cnt = val
            nbytes = (cnt + 1) // 2 if rle4 else cnt
            where[0], where[1], where[2], where[3] = at, x, y, cnt
            if i + nbytes > n:
                return 1
            if x + cnt > padded:
                return 3
            for t in range(cnt):
                if rle4:
                    b = data[i + (t >> 1)]
                    v = (b >> 4) if (t & 1) == 0 else (b & 15)
                else:
                    v = data[i + t]
                if x < width:               # not the padding
                    if v >= colors:
                        where[0], where[1], where[3] = i + ((t >> 1) if rle4 else t), x, v
                        return 4
                    out[y, x] = v
                x += 1
            i += nbytes + (nbytes & 1)  # padded to 16 bits



class _BmpReader:
    def __init__(self, path: str, info: _BmpInfo):
        self.path = path
        self.info = info
        self._plane: np.ndarray | None = None

    def _decode_rle(self) -> np.ndarray:
        info = self.info
        with open(self.path, "rb") as f:
            f.seek(info.offset)
            data = np.frombuffer(f.read(), np.uint8)
        plane = np.zeros((info.height, info.width), np.uint8)
        where = np.zeros(4, np.int64)
        padded = info.stride * 8 // info.bpp          # pixels in a row with its padding
        status = _rle_decode(data, info.width, padded, info.height, info.compression == 2, info.colors,
                                plane, where)
        at, x, y, val = (int(v) for v in where)
        at += info.offset                  # a byte offset in the file
        row = info.height - 1 - y          # rows are stored bottom-up; say them from the top
        if status == 1:
            raise ImageError(self.path, f"truncated BMP: the RLE data ends before the end of the image "
                                        f"(at byte {at}, row {row} of {info.height})")
        if status == 2:
            edge = "right edge" if x > info.width else "top"
            raise ImageError(self.path, f"corrupt BMP: RLE data moves outside the image (the delta at byte {at} "
                                        f"moves past the {edge} of the {info.width} x {info.height} image)")
        if status == 3:
            raise ImageError(self.path, f"corrupt BMP: the RLE run of {val} pixels at byte {at} overruns row {row} "
                                        f"(it starts at column {x}, the image is {info.width} wide, "
                                        f"{padded} with the row's padding)")
        if status == 4:
            raise ImageError(self.path, f"corrupt BMP: colour index {val} at byte {at} (row {row}, column {x}) "
                                        f"is outside the palette of {info.colors} colours")
        return plane

    def _pixels(self, idx_or_raw: np.ndarray) -> np.ndarray:
        info = self.info
        if info.bpp <= 8:
            palette = info.palette
            assert palette is not None          # _bmp_header refuses a file without one
            if info.grey:
                return palette[:, 0][idx_or_raw][..., None]
            return palette[idx_or_raw]
        return idx_or_raw

    def _check_indices(self, idx: np.ndarray, y0: int) -> None:
        """Refuse a colour index past the palette (a corrupt file, not black ink)."""
        info = self.info
        if info.colors >= (1 << info.bpp) or int(idx.max(initial=0)) < info.colors:
            return
        r, x = (int(v) for v in np.argwhere(idx >= info.colors)[0])
        row = y0 + r
        frow = row if info.top_down else info.height - 1 - row
        at = info.offset + frow * info.stride + x * info.bpp // 8
        raise ImageError(self.path, f"corrupt BMP: colour index {int(idx[r, x])} at byte {at} (row {row}, column {x}) "
                                    f"is outside the palette of {info.colors} colours")

    def _decode_rows(self, raw: np.ndarray, y0: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
        """raw (n, stride) uint8 in top-to-bottom order (image row y0 first) -> (pixels (n, w, c) uint8,
        alpha (n, w) or None)."""
        info = self.info
        w = info.width
        n = raw.shape[0]
        bpp = info.bpp
        if bpp == 8:
            self._check_indices(raw[:, :w], y0)
            return self._pixels(raw[:, :w]), None
        if bpp in (1, 2, 4):
            if bpp == 1:
                idx = np.unpackbits(raw, axis=1)[:, :w]
            elif bpp == 4:
                packed = raw[:, : (w + 1) // 2]
                idx = np.empty((n, packed.shape[1] * 2), np.uint8)
                idx[:, 0::2] = packed >> 4
                idx[:, 1::2] = packed & 15
                idx = idx[:, :w]
            else:
                packed = raw[:, : (w + 3) // 4]
                idx = np.empty((n, packed.shape[1] * 4), np.uint8)
                for k in range(4):
                    idx[:, k::4] = (packed >> (6 - 2 * k)) & 3
                idx = idx[:, :w]
            self._check_indices(idx, y0)
            return self._pixels(idx), None
        if bpp == 24:
            return np.ascontiguousarray(raw[:, : w * 3].reshape(n, w, 3)[..., ::-1]), None
        assert info.masks is not None           # 16 and 32 bits always have masks
        r, g, b, a = info.masks
        if bpp == 32 and (r, g, b) == (0x00FF0000, 0x0000FF00, 0x000000FF):
            px = raw[:, : w * 4].reshape(n, w, 4)
            rgb = np.ascontiguousarray(px[..., 2::-1])
            alpha = px[..., 3] if a == 0xFF000000 else None
            if a not in (0, 0xFF000000):
                alpha = self._channel(px.copy().view("<u4")[..., 0], a)
            return rgb, alpha
        v = raw[:, : w * (bpp // 8)].copy().view("<u2" if bpp == 16 else "<u4").astype(np.uint32)
        rgb = np.empty((n, w, 3), np.uint8)
        for c, m in enumerate((r, g, b)):
            rgb[..., c] = self._channel(v, m)
        alpha = self._channel(v, a) if a else None
        return rgb, alpha

    @staticmethod
    def _channel(v: np.ndarray, mask: int) -> np.ndarray:
        shift, bits = _mask_shift_bits(mask)
        x = (v & np.uint32(mask)) >> np.uint32(shift)
        if bits == 8:
            return x.astype(np.uint8)
        mx = (1 << bits) - 1
        return ((x.astype(np.uint64) * 255 + mx // 2) // mx).astype(np.uint8)

    def bands(self, rows: int) -> Iterator[np.ndarray]:
        info = self.info
        h, w = info.height, info.width
        if info.compression in (1, 2):
            if self._plane is None:
                self._plane = self._decode_rle()
            plane = self._plane
            for y in range(0, h, rows):
                n = min(rows, h - y)
                idx = plane[h - y - n: h - y][::-1]
                yield np.ascontiguousarray(self._pixels(idx))
            return
        stride = info.stride
        try:
            f = open(self.path, "rb")
        except OSError as e:
            raise ImageError(self.path, f"cannot read file: {e.strerror or e}") from None
        with f:
            for y in range(0, h, rows):
                n = min(rows, h - y)
                fr0 = y if info.top_down else h - y - n
                f.seek(info.offset + fr0 * stride)
                buf = f.read(n * stride)
                if len(buf) < n * stride:
                    # the last row may lack its padding; anything shorter is truncation
                    need = (n - 1) * stride + (w * info.bpp + 7) // 8
                    if len(buf) < need:
                        raise ImageError(self.path, "truncated BMP: the pixel data ends before the end of the image")
                    buf = buf + b"\x00" * (n * stride - len(buf))
                raw = np.frombuffer(buf, np.uint8).reshape(n, stride)
                if not info.top_down:
                    raw = raw[::-1]
                px, alpha = self._decode_rows(raw, y)
                if alpha is not None:
                    px = _composite_white_u8(px, alpha)
                yield np.ascontiguousarray(px)


def _composite_white_u8(px: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    a = alpha.astype(np.uint32)[..., None]
    out = (px.astype(np.uint32) * a + 255 * (255 - a) + 127) // 255
    return out.astype(np.uint8)


def _open_bmp(path: str, info: _BmpInfo, size: int, max_pixels: int, max_side: int) -> ImageSource:
    _check_dims(path, info.width, info.height, max_pixels, max_side)
    if info.offset >= size:
        raise ImageError(path, f"truncated BMP: pixel data should start at byte {info.offset} but the file has "
                               f"only {size} bytes")
    if info.compression in (1, 2):
        if info.width * info.height > RLE_MAX_PIXELS:
            raise ImageError(path, f"image too large: {info.width} x {info.height} px exceeds the limit of "
                                   f"{_fmt_px(RLE_MAX_PIXELS)} for RLE-compressed BMP")
    else:
        need = info.offset + (info.height - 1) * info.stride + (info.width * info.bpp + 7) // 8
        if need > size:
            raise ImageError(path, f"truncated BMP: pixel data needs {need} bytes but the file has only {size}")
    grey = info.bpp <= 8 and info.grey
    return ImageSource(path=path, width=info.width, height=info.height, channels=1 if grey else 3,
                       colorspace="grey" if grey else "rgb", depth=8, xres=info.xres, yres=info.yres,
                       icc=info.icc, format="bmp", _reader=_BmpReader(path, info))
