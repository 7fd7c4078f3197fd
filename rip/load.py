"""Streaming image loaders for the RIP.

``open_image(path)`` reads only the file header, checks it (format by magic bytes,
dimensions against decompression-bomb limits, bit depth, colour space, truncation
that can be seen from the header) and returns an :class:`ImageSource`.
``ImageSource.bands(rows)`` then decodes the image top to bottom, one band at a time,
with memory bounded by the band (never by the image height).

Back ends
---------
* TIFF, JPEG, PNG: libvips (pyvips) with ``access='sequential'``.  Pixels are pulled with
  :class:`pyvips.Region` so libvips only keeps a small line cache.  TIFF and PNG use
  ``fail_on='error'``, JPEG ``fail_on='warning'`` (libjpeg reports corrupt entropy-coded
  data only as a *warning* and would otherwise fill the image with grey - printing that on
  3.4 m of media is worse than refusing the file).
* BMP (pyvips-binary has no BMP loader): our own header parser; uncompressed rows are read
  straight from the file with numpy (bottom-up or top-down), RLE4/RLE8 is decoded by a small
  numba decoder into an index plane (one byte per pixel).  Not OpenCV: ``cv2.imread`` has no
  banded read and decodes the whole image into memory, which a banner cannot afford
  (docs/rip.md).

Every problem with a file is raised as :class:`ImageError` (``str(e) == f"{path}: {problem}"``).
"""

from __future__ import annotations

import math
import os
import stat
import struct
from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np

from .compiled import kernel

__all__ = ["ImageError", "ImageSource", "open_image"]

#: largest RLE-compressed BMP we decode (the index plane is held in memory: 1 byte / px)
RLE_MAX_PIXELS = 1 << 31


class ImageError(Exception):
    """A file that cannot be printed.  ``str(e) == f"{path}: {problem}"``."""

    def __init__(self, path: Any, problem: str):
        self.path = os.fspath(path) if not isinstance(path, str) else path
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")

    def __reduce__(self):  # picklable across processes
        return (type(self), (self.path, self.problem))


# --------------------------------------------------------------------------------------
# helpers


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


def _vips():
    import pyvips  # imported lazily: BMP-only use does not need libvips

    # libvips' operation cache keeps every pipeline's decoded regions (up to ~150 MB of
    # RSS) although the RIP streams each file once per read; a file read again (layout
    # copies, docs/layout.md "Measured") or many files in one process made memory grow
    # with the number of reads, and the cache saved no time (measured)
    pyvips.cache_set_max(0)
    return pyvips


def _clean_vips_message(msg: str, path: str) -> list[str]:
    out: list[str] = []
    base = os.path.basename(path)
    for line in str(msg).splitlines():
        line = line.strip()
        if not line:
            continue
        low = line.lower()
        if low.startswith(("unable to call", "unable to fetch from region", "unable to write to memory")):
            continue
        for prefix in (path + ":", base + ":"):
            if line.startswith(prefix):
                line = line[len(prefix):].strip()
        for prefix in ("VipsJpeg:", "tiff2vips:", "vipspng:", "VipsForeignLoad", "spngload:", "pngload:",
                       "VipsImage:", "vips_image_get:", "TIFFReadDirectory:", "TIFFFillStrip:", "TIFFFillTile:",
                       "LZWDecode:", "ZIPDecode:", "JPEGLib:", "TIFFReadEncodedStrip:", "TIFFReadEncodedTile:"):
            if line.startswith(prefix):
                line = line[len(prefix):].strip()
        if line and line not in out:
            out.append(line)
    return out


def _vips_problem(fmt: str, msg: str, path: str) -> str:
    """Turn a libvips error message into a plain-words problem."""
    lines = _clean_vips_message(msg, path)
    text = " ".join(lines).lower()
    first = lines[0] if lines else ""
    if len(first) > 160:
        first = first[:157] + "..."
    if fmt == "jpeg":
        if "premature end of jpeg" in text or "premature end of input" in text or "truncated" in text:
            return "truncated JPEG: the file ends before the image data is complete"
        if "corrupt jpeg data" in text:
            detail = next((ln for ln in lines if "corrupt jpeg data" in ln.lower()), first)
            detail = detail.split(":", 1)[1].strip() if ":" in detail else detail
            return f"corrupt JPEG data: {detail}" if detail else "corrupt JPEG data"
        if "arithmetic" in text:
            return f"unsupported JPEG coding: {first}"
        return f"corrupt JPEG: {first}" if first else "corrupt JPEG (decoder failed)"
    if fmt == "tiff":
        if "read error at scanline" in text or "seek error" in text or "bad seek" in text or "unexpected end" in text:
            return f"truncated TIFF: {first}" if first else "truncated TIFF"
        if "compression" in text and ("not implemented" in text or "not configured" in text or "not supported" in text):
            return f"unsupported TIFF compression: {first}"
        return f"corrupt TIFF data: {first}" if first else "corrupt TIFF data (decoder failed)"
    if fmt == "png":
        return f"corrupt or truncated PNG data: {first}" if first else "corrupt or truncated PNG data"
    return f"cannot decode image: {first}" if first else "cannot decode image"


# --------------------------------------------------------------------------------------
# header sniffers (dimensions are checked with these BEFORE libvips sees the file)


@dataclass
class _Hdr:
    width: int = 0
    height: int = 0
    xres: float | None = None
    yres: float | None = None
    extra: dict = field(default_factory=dict)


def _jpeg_header(path: str, f, size: int) -> _Hdr:
    """Walk JPEG markers up to the frame header (SOFn)."""
    hdr = _Hdr()
    pos = 2
    f.seek(2)
    exif = False
    while True:
        b = f.read(2)
        if len(b) < 2:
            raise ImageError(path, "truncated JPEG: the file ends before the frame header")
        if b[0] != 0xFF:
            raise ImageError(path, f"corrupt JPEG: expected a marker at byte {pos}")
        marker = b[1]
        pos += 2
        if marker == 0xFF:  # fill byte
            f.seek(pos - 1)
            pos -= 1
            continue
        if marker in (0x01,) or 0xD0 <= marker <= 0xD7:
            continue
        if marker == 0xD9:
            raise ImageError(path, "corrupt JPEG: no image in the file (end marker before the frame header)")
        if marker == 0xDA:
            raise ImageError(path, "corrupt JPEG: image data before the frame header")
        lb = f.read(2)
        if len(lb) < 2:
            raise ImageError(path, "truncated JPEG: the file ends inside the header")
        (length,) = struct.unpack(">H", lb)
        if length < 2:
            raise ImageError(path, f"corrupt JPEG: bad marker segment length at byte {pos}")
        if pos + length > size:
            raise ImageError(path, "truncated JPEG: the file ends inside the header")
        if marker == 0xE0:
            seg = f.read(min(length - 2, 14))
            if seg[:5] == b"JFIF\x00" and len(seg) >= 12:
                units = seg[7]
                xd, yd = struct.unpack(">HH", seg[8:12])
                if units in (1, 2) and xd > 0 and yd > 0:
                    k = 1.0 if units == 1 else 2.54
                    hdr.xres, hdr.yres = xd * k, yd * k
        elif marker == 0xE1:
            seg = f.read(min(length - 2, 6))
            exif = exif or seg[:4] == b"Exif"
        elif marker == 0xEE:
            seg = f.read(min(length - 2, 12))
            if seg[:5] == b"Adobe" and len(seg) >= 12:
                hdr.extra["adobe_transform"] = seg[11]
        elif 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            seg = f.read(6)
            if len(seg) < 6:
                raise ImageError(path, "truncated JPEG: the file ends inside the frame header")
            precision, h, w, nc = struct.unpack(">BHHB", seg)
            hdr.width, hdr.height = w, h
            hdr.extra.update(precision=precision, components=nc, sof=marker, exif=exif)
            return hdr
        pos += length
        f.seek(pos)


def _png_header(path: str, f, size: int) -> _Hdr:
    hdr = _Hdr()
    f.seek(8)
    pos = 8
    seen_idat = False
    first = True
    while True:
        b = f.read(8)
        if len(b) < 8:
            if first:
                raise ImageError(path, "truncated PNG: the file ends before the image header")
            raise ImageError(path, "truncated PNG: the file ends before the end of the image (no IEND chunk)")
        length, ctype = struct.unpack(">I4s", b)
        if first:
            if ctype != b"IHDR" or length < 13:
                raise ImageError(path, "corrupt PNG: the first chunk is not IHDR")
            d = f.read(13)
            if len(d) < 13:
                raise ImageError(path, "truncated PNG: the file ends inside the image header")
            w, h, bitdepth, colortype, _c, _fl, interlace = struct.unpack(">IIBBBBB", d)
            hdr.width, hdr.height = w, h
            hdr.extra.update(bitdepth=bitdepth, colortype=colortype, interlace=interlace)
            first = False
        elif ctype == b"pHYs" and length >= 9:
            d = f.read(9)
            if len(d) == 9:
                xp, yp, unit = struct.unpack(">IIB", d)
                if unit == 1 and xp > 0 and yp > 0:
                    hdr.xres, hdr.yres = xp * 0.0254, yp * 0.0254
        elif ctype == b"IDAT":
            seen_idat = True
        if pos + 12 + length > size:
            raise ImageError(path, f"truncated PNG: chunk {ctype.decode('latin-1')!r} at byte {pos} runs past the end of the file")
        if ctype == b"IEND":
            if not seen_idat:
                raise ImageError(path, "corrupt PNG: no image data (IDAT) in the file")
            return hdr
        pos += 12 + length
        f.seek(pos)


_PHOTOMETRIC_NAMES = {4: "transparency mask", 8: "LAB", 9: "LAB", 10: "LAB", 32803: "colour filter array (raw)",
                      32844: "LogL", 32845: "LogLuv", 34892: "linear raw"}


def _tiff_header(path: str, size: int, max_pixels: int, max_side: int) -> _Hdr:
    import tifffile

    hdr = _Hdr()
    try:
        with tifffile.TiffFile(path) as tf:
            if len(tf.pages) == 0:
                raise ImageError(path, "corrupt TIFF header: no image directory (IFD) found")
            page = tf.pages.first if hasattr(tf.pages, "first") else tf.pages[0]
            tags = page.tags
            w, h = int(page.imagewidth), int(page.imagelength)
            _check_dims(path, w, h, max_pixels, max_side)  # before anything else is read
            spp = int(page.samplesperpixel)
            bps = page.bitspersample
            bps = int(bps[0]) if isinstance(bps, tuple) else int(bps)
            sfmt = page.sampleformat
            sfmt = int(sfmt[0]) if isinstance(sfmt, tuple) else int(sfmt)
            photometric = int(page.photometric)
            extrasamples = tuple(int(e) for e in (page.extrasamples or ()))
            inkset = tags.get("InkSet")
            inkset = int(inkset.value) if inkset is not None else None
            offsets = np.asarray(page.dataoffsets, dtype=np.int64)
            counts = np.asarray(page.databytecounts, dtype=np.int64)
            tiled = bool(page.is_tiled)
            compression = int(page.compression)
            orientation = tags.get("Orientation")
            layout = dict(planar=int(page.planarconfig), fillorder=int(page.fillorder),
                          orientation=int(orientation.value) if orientation is not None else 1,
                          rowsperstrip=int(page.rowsperstrip))
            xr, yr, unit = tags.get("XResolution"), tags.get("YResolution"), tags.get("ResolutionUnit")
            xres = yres = None
            ru = int(unit.value) if unit is not None else 2
            if xr is not None and yr is not None and ru in (2, 3):
                def rat(v):
                    if isinstance(v, tuple):
                        return v[0] / v[1] if v[1] else 0.0
                    return float(v)
                xres, yres = rat(xr.value), rat(yr.value)
                if ru == 3:
                    xres, yres = xres * 2.54, yres * 2.54
                if not (xres > 0 and yres > 0 and math.isfinite(xres) and math.isfinite(yres)):
                    xres = yres = None
    except ImageError:
        raise
    except Exception as e:  # tifffile raises many kinds on hostile files
        msg = str(e).strip() or type(e).__name__
        if len(msg) > 160:
            msg = msg[:157] + "..."
        low = msg.lower()
        if "eof" in low or "end of file" in low or "truncat" in low or "unexpected end" in low:
            raise ImageError(path, f"truncated TIFF: the header is incomplete ({msg})") from None
        raise ImageError(path, f"corrupt TIFF header: {msg}") from None
    hdr.width, hdr.height, hdr.xres, hdr.yres = w, h, xres, yres
    hdr.extra.update(spp=spp, bps=bps, sampleformat=sfmt, photometric=photometric, extrasamples=extrasamples,
                     inkset=inkset, offsets=offsets, counts=counts, tiled=tiled, compression=compression,
                     **layout)
    return hdr


def _check_tiff(path: str, hdr: _Hdr, size: int) -> None:
    e = hdr.extra
    if e["sampleformat"] == 3:
        raise ImageError(path, f"unsupported bit depth: {e['bps']}-bit floating point samples (need 8 or 16-bit integer)")
    if e["sampleformat"] == 2:
        raise ImageError(path, f"unsupported bit depth: {e['bps']}-bit signed integer samples (need 8 or 16-bit unsigned)")
    if e["sampleformat"] not in (1, 4):
        raise ImageError(path, f"unsupported sample format {e['sampleformat']}")
    if e["bps"] not in (1, 2, 4, 8, 16):
        raise ImageError(path, f"unsupported bit depth: {e['bps']} bits per sample (need 1, 2, 4, 8 or 16)")
    ph = e["photometric"]
    if ph in _PHOTOMETRIC_NAMES:
        raise ImageError(path, f"unsupported colour space {_PHOTOMETRIC_NAMES[ph]}")
    if ph not in (0, 1, 2, 3, 5, 6):
        raise ImageError(path, f"unsupported colour space (TIFF photometric {ph})")
    if ph == 5:
        n_alpha = sum(1 for x in e["extrasamples"] if x in (1, 2))
        inks = e["spp"] - n_alpha
        if e["inkset"] not in (None, 1):
            raise ImageError(path, f"unsupported colour space: {inks}-ink separation that is not CMYK (InkSet {e['inkset']})")
        if inks != 4:
            more = inks - 4
            if more > 0:
                raise ImageError(path, f"unsupported colour space: {inks}-channel separation (CMYK + {more} extra "
                                       f"channel{'s' if more > 1 else ''} of unknown meaning, e.g. spot colours)")
            raise ImageError(path, f"unsupported colour space: {inks}-channel separation (need CMYK)")
    offsets, counts = e["offsets"], e["counts"]
    n = len(offsets)
    if n == 0:
        raise ImageError(path, "corrupt TIFF: no image data (no strip or tile offsets)")
    if len(counts) == n:
        end = offsets + counts
        bad = np.nonzero((end > size) | (offsets < 0))[0]
        if len(bad):
            i = int(bad[0])
            what = "tile" if e["tiled"] else "strip"
            if offsets[i] >= size:
                raise ImageError(path, f"truncated TIFF: {what} {i + 1} of {n} is missing "
                                       f"(the file ends at byte {size})")
            raise ImageError(path, f"truncated TIFF: {what} {i + 1} of {n} is cut short "
                                   f"(needs bytes up to {int(end[i])}, the file has {size})")


def _check_jpeg(path: str, hdr: _Hdr) -> None:
    e = hdr.extra
    if e["sof"] in (0xC3, 0xC7, 0xCB, 0xCF):
        raise ImageError(path, "unsupported JPEG: lossless JPEG")
    if e["precision"] != 8:
        raise ImageError(path, f"unsupported bit depth: {e['precision']}-bit JPEG (need 8-bit)")
    if e["components"] not in (1, 3, 4):
        raise ImageError(path, f"unsupported colour space: JPEG with {e['components']} components")


# --------------------------------------------------------------------------------------
# BMP


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
    if (compression == 1 and bpp != 8) or (compression == 2 and bpp != 4) or (compression in (3, 6) and bpp not in (16, 32)):
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
            if info.grey:
                return info.palette[:, 0][idx_or_raw][..., None]
            return info.palette[idx_or_raw]
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
                b = raw[:, : (w + 1) // 2]
                idx = np.empty((n, b.shape[1] * 2), np.uint8)
                idx[:, 0::2] = b >> 4
                idx[:, 1::2] = b & 15
                idx = idx[:, :w]
            else:
                b = raw[:, : (w + 3) // 4]
                idx = np.empty((n, b.shape[1] * 4), np.uint8)
                for k in range(4):
                    idx[:, k::4] = (b >> (6 - 2 * k)) & 3
                idx = idx[:, :w]
            self._check_indices(idx, y0)
            return self._pixels(idx), None
        if bpp == 24:
            return np.ascontiguousarray(raw[:, : w * 3].reshape(n, w, 3)[..., ::-1]), None
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


# --------------------------------------------------------------------------------------
# libvips back end (TIFF, JPEG, PNG)


_FORMAT_NAMES = {"char": "8-bit signed integer", "short": "16-bit signed integer", "uint": "32-bit integer",
                 "int": "32-bit signed integer", "float": "32-bit floating point", "double": "64-bit floating point",
                 "complex": "complex", "dpcomplex": "complex"}
_UNSUPPORTED_INTERP = {"lab": "LAB", "labq": "LAB", "labs": "LAB", "lch": "LCh", "cmc": "CMC", "xyz": "XYZ",
                       "yxy": "Yxy", "hsv": "HSV", "scrgb": "scRGB (linear float)", "fourier": "Fourier",
                       "histogram": "histogram", "matrix": "matrix"}


@dataclass
class _VipsPlan:
    colour: int  # number of colour bands at the start of the image
    alpha: int | None  # band index of alpha, or None
    colorspace: str
    depth: int
    invert: bool = False  # CMYK JPEG that libvips hands over inverted


def _strip_app14(data: bytes) -> bytes:
    out = bytearray(data[:2])
    pos = 2
    while pos + 4 <= len(data):
        marker = data[pos + 1]
        if marker == 0xDA:
            break
        (length,) = struct.unpack(">H", data[pos + 2: pos + 4])
        if not (marker == 0xEE and data[pos + 4: pos + 9] == b"Adobe"):
            out += data[pos: pos + 2 + length]
        pos += 2 + length
    out += data[pos:]
    return bytes(out)


_JPEG_CMYK_PROBE: tuple[bool, bool] | None = None


def _libvips_cmyk_jpeg_inversion() -> tuple[bool, bool]:
    """(inverts when the Adobe marker is present, inverts when it is absent), probed once.

    Convention: a CMYK JPEG with an Adobe APP14 marker stores inverted samples (Photoshop), one without
    stores ink values.  libvips versions differ in what they undo, so we look instead of assuming."""
    global _JPEG_CMYK_PROBE
    if _JPEG_CMYK_PROBE is None:
        pv = _vips()
        ink = np.zeros((8, 8, 4), np.uint8)
        ink[..., 0] = 30
        ink[..., 3] = 200
        import imagecodecs

        data = pv.Image.new_from_array(ink).copy(interpretation="cmyk").jpegsave_buffer(Q=100)
        stored = float(imagecodecs.jpeg8_decode(data)[..., 0].mean())  # raw samples, as in the file
        res = []
        for variant in (data, _strip_app14(data)):
            got = float(pv.Image.new_from_buffer(variant, "").numpy()[..., 0].mean())
            res.append(abs(got - (255 - stored)) < abs(got - stored))  # libvips inverted the samples
        _JPEG_CMYK_PROBE = (res[0], res[1])
    return _JPEG_CMYK_PROBE


def _utf8(path: str) -> bool:
    try:
        path.encode("utf-8")
        return True
    except UnicodeEncodeError:      # surrogate-escaped bytes of a non-UTF-8 name
        return False


class _VipsReader:
    def __init__(self, path: str, fmt: str, plan: _VipsPlan):
        self.path = path
        self.fmt = fmt
        self.plan = plan

    def open(self, *, revalidate: bool = True):
        pv = _vips()
        fail_on = "warning" if self.fmt == "jpeg" else "error"
        kw: dict[str, Any] = dict(access="sequential", fail_on=fail_on)
        if revalidate:
            kw["revalidate"] = True
        if _utf8(self.path):
            return pv.Image.new_from_file(self.path, **kw)
        # libvips takes UTF-8 file names only: a name with other bytes is opened here and
        # handed over as a descriptor (the source keeps its own copy of it)
        fd = os.open(self.path, os.O_RDONLY | os.O_CLOEXEC)
        try:
            source = pv.Source.new_from_descriptor(fd)
        finally:
            os.close(fd)
        return pv.Image.new_from_source(source, "", **kw)

    def pipeline(self, img):
        p = self.plan
        mx = 65535 if p.depth == 16 else 255
        if p.invert:
            img = img.invert()
        if p.alpha is None:
            if img.bands != p.colour:
                img = img.extract_band(0, n=p.colour)
            return img
        colour = img.extract_band(0, n=p.colour) if p.colour > 1 else img.extract_band(0)
        alpha = img.extract_band(p.alpha)
        if p.colorspace == "cmyk":
            # paper is "no ink": ink * alpha
            out = colour * alpha / mx
        else:
            # paper is white: c * a + white * (1 - a)
            out = (colour * alpha + (mx - alpha) * mx) / mx
        return (out + 0.5).cast("ushort" if p.depth == 16 else "uchar")

    def bands(self, rows: int) -> Iterator[np.ndarray]:
        pv = _vips()
        p = self.plan
        dtype = np.uint16 if p.depth == 16 else np.uint8
        try:
            img = self.pipeline(self.open())
            region = pv.Region.new(img)
            w, h = img.width, img.height
        except pv.Error as e:
            raise ImageError(self.path, _vips_problem(self.fmt, str(e), self.path)) from None
        y = 0
        while y < h:
            n = min(rows, h - y)
            band = np.empty((n, w, p.colour), dtype)
            # libvips is asked for a few rows at a time (fetch_rows)
            step = fetch_rows(w * p.colour * band.itemsize)
            for yy in range(0, n, step):
                m = min(step, n - yy)
                try:
                    buf = region.fetch(0, y + yy, w, m)
                except pv.Error as e:
                    raise ImageError(self.path, _vips_problem(self.fmt, str(e), self.path)) from None
                arr = np.frombuffer(buf, dtype=dtype)
                if arr.size != m * w * p.colour:
                    raise ImageError(self.path, f"cannot decode image: got {arr.size} samples "
                                                f"for rows {y + yy}..{y + yy + m}")
                band[yy:yy + m] = arr.reshape(m, w, p.colour)
            yield band
            y += n


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


class _StripReader:
    """Plain strip TIFFs (the common print-shop file: uncompressed, LZW, deflate or PackBits, 8 or 16-bit
    grey, RGB or CMYK, no alpha, top-left orientation) read strip by strip with tifffile.
    libvips' sequential TIFF reader keeps ~70 MB of caches for a 40,000 px wide RGB file
    (bench/README.md, issue 17); this holds a band and one compressed strip decoded, or
    ~1 MB of an uncompressed one.  The samples are the
    file's own, as libvips hands them over for these files (tests/test_load.py compares
    the two).  A damaged strip fails here at least as often as there (300 single-byte
    damages each: deflate 300 failures against libvips' 287 - its checksum -, LZW the same
    outcomes, PackBits 5 against 2; neither LZW nor PackBits can see every damage)."""

    COMPRESSIONS = (1, 5, 8, 32773, 32946)    # none, LZW, Adobe deflate, PackBits, deflate
    MAX_STRIP_BYTES = 16 << 20            # a compressed strip decoded whole: bigger ones stay with libvips

    def __init__(self, path: str, plan: _VipsPlan, hdr: _Hdr, vips: _VipsReader):
        self.path, self.plan, self.hdr = path, plan, hdr
        # resampling and previews take the image through libvips (rip/place.py): the same
        # pixels, from the libvips reader's own pipeline
        self.open, self.pipeline = vips.open, vips.pipeline

    @classmethod
    def fits(cls, hdr: _Hdr, plan: _VipsPlan) -> bool:
        e = hdr.extra
        photometric = {1: "grey", 2: "rgb", 5: "cmyk"}.get(e["photometric"])
        return (not e["tiled"] and e["compression"] in cls.COMPRESSIONS
                and photometric == plan.colorspace and e["spp"] == plan.colour
                and plan.alpha is None and not plan.invert and not e["extrasamples"]
                and e["bps"] == plan.depth and e["sampleformat"] == 1
                and (e["planar"] == 1 or e["spp"] == 1) and e["fillorder"] == 1
                and e["orientation"] == 1 and e["inkset"] in (None, 1)
                and 0 < e["rowsperstrip"] and len(e["offsets"]) == len(e["counts"])
                and (e["compression"] == 1 or min(e["rowsperstrip"], hdr.height) * hdr.width
                     * e["spp"] * e["bps"] // 8 <= cls.MAX_STRIP_BYTES))

    def _strips(self, rows: int) -> Iterator[np.ndarray]:
        """The image as chunks of rows: a strip decoded, or, uncompressed, whole bands of
        `rows` rows (`_plain_bands`)."""
        import tifffile
        with tifffile.TiffFile(self.path) as tf:
            page = tf.pages.first if hasattr(tf.pages, "first") else tf.pages[0]
            fh, n = tf.filehandle, len(page.dataoffsets)
            w, c, h = self.hdr.width, self.plan.colour, self.hdr.height
            native = np.dtype(np.uint16 if self.plan.depth == 16 else np.uint8)
            sample = native.newbyteorder(tf.byteorder)
            if page.compression == 1:
                yield from self._plain_bands(fh, page, rows, sample, native)
                return
            rows_done = 0
            for i, (offset, count) in enumerate(zip(page.dataoffsets, page.databytecounts)):
                if rows_done >= h:
                    return
                fh.seek(offset)
                data = fh.read(count)
                if len(data) != count:
                    raise ImageError(self.path, f"truncated TIFF: strip {i + 1} of {n} is cut short")
                try:
                    strip = page.decode(data, i)[0]
                except Exception as exc:       # imagecodecs' and tifffile's many kinds
                    msg = str(exc).strip() or type(exc).__name__
                    raise ImageError(self.path, f"corrupt TIFF data: strip {i + 1} of {n}: "
                                                f"{msg[:120]}") from None
                if strip is None or strip.ndim != 4 or strip.shape[2:] != (w, c):
                    raise ImageError(self.path, f"corrupt TIFF data: strip {i + 1} of {n} has the "
                                                f"wrong size")
                strip = strip[0, :h - rows_done].astype(native, copy=False)
                rows_done += strip.shape[0]
                yield strip
            if rows_done < h:
                raise ImageError(self.path, f"truncated TIFF: {rows_done} of {h} rows in the strips")

    def _plain_bands(self, fh, page, rows: int, sample: np.dtype, native: np.dtype):
        """Uncompressed: band by band, each read from the file straight into its array,
        from as many strips as it spans.  Nothing is copied to re-cut strips into bands (a
        64-row strip against 43-row bands cost a concatenation of every band: ~0.05 CPU-s
        of a 144 MB file)."""
        w, c, h = self.hdr.width, self.plan.colour, self.hdr.height
        offsets, counts = page.dataoffsets, page.databytecounts
        n, rps = len(offsets), self.hdr.extra["rowsperstrip"]
        row_bytes = w * c * sample.itemsize
        step = max(1, rows)
        for y0 in range(0, h, step):
            k = min(step, h - y0)
            chunk = np.empty((k, w, c), sample)
            flat = chunk.reshape(-1).view(np.uint8)
            y = y0
            while y < y0 + k:
                i = y // rps                         # the strip holding row y
                if i >= n:
                    raise ImageError(self.path, f"truncated TIFF: {i * rps} of {h} rows in the strips")
                rows_in = min(rps, h - i * rps)
                if counts[i] < rows_in * row_bytes:
                    raise ImageError(self.path, f"corrupt TIFF data: strip {i + 1} of {n} has "
                                                f"{counts[i]} bytes for {rows_in} rows of {row_bytes}")
                m = min(i * rps + rows_in, y0 + k) - y
                fh.seek(offsets[i] + (y - i * rps) * row_bytes)
                at = (y - y0) * row_bytes
                if fh.readinto(flat[at:at + m * row_bytes]) != m * row_bytes:
                    raise ImageError(self.path, f"truncated TIFF: strip {i + 1} of {n} is cut short")
                y += m
            yield chunk.astype(native, copy=False)

    def bands(self, rows: int) -> Iterator[np.ndarray]:
        return _reband(self._strips(rows), rows)


FETCH_BYTES = 512 << 10    # bytes per libvips fetch, at most
FETCH_ROWS = 16            # rows per libvips fetch, at most


def fetch_rows(row_bytes: int) -> int:
    """Rows to pull from libvips per fetch.  libvips' sequential caches grow with the
    largest request: reading a 40,000 px wide RGB TIFF cost +93 MB with 4-row fetches,
    +146 MB with 16 and +370 MB with 64 (bench/README.md), so a fetch stays under
    FETCH_BYTES; narrower images take up to FETCH_ROWS rows, fewer calls."""
    return max(1, min(FETCH_ROWS, FETCH_BYTES // max(1, row_bytes)))


def _vips_plan(path: str, fmt: str, img, hdr: _Hdr) -> _VipsPlan:
    if img.coding != "none":
        raise ImageError(path, "unsupported colour space LAB")
    vfmt = img.format
    if vfmt == "uchar":
        depth = 8
    elif vfmt == "ushort":
        depth = 16
    else:
        raise ImageError(path, f"unsupported bit depth: {_FORMAT_NAMES.get(vfmt, vfmt)} samples (need 8 or 16-bit)")
    interp = img.interpretation
    if interp in _UNSUPPORTED_INTERP:
        raise ImageError(path, f"unsupported colour space {_UNSUPPORTED_INTERP[interp]}")
    bands = img.bands
    extras: tuple[int, ...] | None = hdr.extra.get("extrasamples") if fmt == "tiff" else None
    if fmt == "tiff" and hdr.extra.get("photometric") == 3:
        extras = None  # palette images are expanded by libvips; alpha (if any) is libvips' own
    if interp == "cmyk" or (fmt == "jpeg" and bands == 4):
        colour, cs = 4, "cmyk"
    elif interp in ("b-w", "grey16") or (interp == "multiband" and bands in (1, 2)):
        colour, cs = 1, "grey"
    elif interp in ("srgb", "rgb", "rgb16") or (interp == "multiband" and bands in (3, 4)):
        colour, cs = 3, "rgb"
    else:
        raise ImageError(path, f"unsupported colour space {interp} with {bands} channels")
    if bands < colour:
        raise ImageError(path, f"unsupported colour space: {bands} channels for {cs}")
    alpha = None
    if bands > colour:
        if extras is not None and len(extras) == bands - colour:
            kinds = list(extras)
        else:
            kinds = [2] + [0] * (bands - colour - 1)  # libvips' view: first extra band is alpha
        if cs == "cmyk" and any(k == 0 for k in kinds):
            n = sum(1 for k in kinds if k == 0)
            raise ImageError(path, f"unsupported colour space: {4 + n}-channel separation (CMYK + {n} extra "
                                   f"channel{'s' if n > 1 else ''} of unknown meaning, e.g. spot colours)")
        for i, k in enumerate(kinds):
            if k in (1, 2):
                alpha = colour + i
                break
        # unspecified extra channels of grey/RGB images (saved selections, masks) carry no colour: dropped
    invert = False
    if fmt == "jpeg" and cs == "cmyk":
        adobe = "adobe_transform" in hdr.extra
        inv_adobe, inv_plain = _libvips_cmyk_jpeg_inversion()
        # wanted: the samples are inverted exactly when the Adobe marker is there
        invert = (not inv_adobe) if adobe else inv_plain
    return _VipsPlan(colour, alpha, cs, depth, invert)


# --------------------------------------------------------------------------------------
# public API


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
        _check_dims(path, hdr.width, hdr.height, max_pixels, max_side)
        if fmt == "jpeg":
            _check_jpeg(path, hdr)
        if fmt == "png" and hdr.extra.get("bitdepth") not in (1, 2, 4, 8, 16):
            raise ImageError(path, f"unsupported bit depth: {hdr.extra.get('bitdepth')}-bit PNG")
    return _open_vips(path, fmt, hdr, max_pixels, max_side)


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


def _open_vips(path: str, fmt: str, hdr: _Hdr, max_pixels: int, max_side: int) -> ImageSource:
    pv = _vips()
    reader = _VipsReader(path, fmt, _VipsPlan(0, None, "", 8))
    try:
        img = reader.open()
    except pv.Error as e:
        raise ImageError(path, _vips_problem(fmt, str(e), path)) from None
    except OSError as e:
        raise ImageError(path, f"cannot read file: {e.strerror or e}") from None
    # libvips' own view of the size must agree with the limits too (e.g. multi-page quirks)
    _check_dims(path, img.width, img.height, max_pixels, max_side)
    plan = _vips_plan(path, fmt, img, hdr)
    reader.plan = plan
    try:
        reader.pipeline(img)  # builds (lazily) only: catches impossible band layouts early
    except pv.Error as e:
        raise ImageError(path, _vips_problem(fmt, str(e), path)) from None
    if fmt == "tiff" and _StripReader.fits(hdr, plan):
        reader = _StripReader(path, plan, hdr, reader)
    icc = None
    if img.get_typeof("icc-profile-data") != 0:
        try:
            icc = bytes(img.get("icc-profile-data"))
        except Exception:
            icc = None
    xres, yres = hdr.xres, hdr.yres
    if xres is None and fmt == "jpeg" and hdr.extra.get("exif") and img.get_typeof("resolution-unit") != 0:
        try:
            xr, yr = img.xres * 25.4, img.yres * 25.4
            if xr > 0 and yr > 0:
                xres, yres = xr, yr
        except Exception:
            pass
    return ImageSource(path=path, width=img.width, height=img.height, channels=plan.colour,
                       colorspace=plan.colorspace, depth=plan.depth, xres=xres, yres=yres, icc=icc, format=fmt,
                       _reader=reader)
