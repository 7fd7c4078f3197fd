"""PNG's chunks, walked before libvips sees the file (rip/load/vips.py decodes it): the
dimensions checked first, the resolution (pHYs), and truncation seen from the chunk
lengths."""

from __future__ import annotations

import struct

from .source import ImageError, _Hdr


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
            raise ImageError(path, f"truncated PNG: chunk {ctype.decode('latin-1')!r} at byte {pos} "
                                   f"runs past the end of the file")
        if ctype == b"IEND":
            if not seen_idat:
                raise ImageError(path, "corrupt PNG: no image data (IDAT) in the file")
            return hdr
        pos += 12 + length
        f.seek(pos)
