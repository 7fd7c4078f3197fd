"""JPEG's header, walked up to the frame header before libvips sees the file (rip/load/vips.py
decodes it): the dimensions checked first, the resolution (JFIF), the Adobe marker that says
a CMYK file's samples are inverted, and what the RIP cannot print (lossless, 12-bit)."""

from __future__ import annotations

import struct

from .source import ImageError, _Hdr


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


def _check_jpeg(path: str, hdr: _Hdr) -> None:
    e = hdr.extra
    if e["sof"] in (0xC3, 0xC7, 0xCB, 0xCF):
        raise ImageError(path, "unsupported JPEG: lossless JPEG")
    if e["precision"] != 8:
        raise ImageError(path, f"unsupported bit depth: {e['precision']}-bit JPEG (need 8-bit)")
    if e["components"] not in (1, 3, 4):
        raise ImageError(path, f"unsupported colour space: JPEG with {e['components']} components")
