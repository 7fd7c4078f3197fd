"""Test-file writers: hand-made BMPs (every depth, RLE), minimal TIFF/JPEG/PNG headers, and the hostile
corpus (malformed, truncated, absurd files).  Everything is written at test time into a tmp dir; no binary
test files are committed."""

from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# --------------------------------------------------------------------------------------------------
# BMP writer


def _pack_rows(rows: list[bytes], top_down: bool) -> bytes:
    out = []
    for r in rows:
        pad = (-len(r)) % 4
        out.append(r + b"\x00" * pad)
    if not top_down:
        out = out[::-1]
    return b"".join(out)


def pack_indices(idx: np.ndarray, bpp: int) -> list[bytes]:
    rows = []
    for row in np.asarray(idx, np.uint8):
        if bpp == 8:
            rows.append(row.tobytes())
        elif bpp == 1:
            rows.append(np.packbits(row.astype(bool)).tobytes())
        else:
            per = 8 // bpp
            n = (len(row) + per - 1) // per
            r = np.zeros(n * per, np.uint8)
            r[: len(row)] = row
            r = r.reshape(n, per)
            b = np.zeros(n, np.uint8)
            for k in range(per):
                b |= (r[:, k] << (8 - bpp * (k + 1))).astype(np.uint8)
            rows.append(b.tobytes())
    return rows


def bmp_bytes(*, width: int, height: int, bpp: int, pixel_data: bytes, palette: np.ndarray | None = None,
              compression: int = 0, top_down: bool = False, header_size: int = 40,
              masks: tuple[int, int, int, int] | None = None, ppm: tuple[int, int] = (0, 0),
              icc: bytes | None = None, planes: int = 1) -> bytes:
    """Assemble a BMP.  ``pixel_data`` is the already laid out (padded, ordered) pixel array."""
    pal = b""
    if palette is not None:
        p = np.asarray(palette, np.uint8)
        if header_size == 12:
            pal = p[:, ::-1].tobytes()
        else:
            pal = np.concatenate([p[:, ::-1], np.zeros((len(p), 1), np.uint8)], 1).tobytes()
    extra_masks = b""
    if header_size == 12:
        info = struct.pack("<IHHHH", 12, width, height, planes, bpp)
    else:
        h = -height if top_down else height
        info = struct.pack("<IiiHHIIiiII", header_size, width, h, planes, bpp, compression, len(pixel_data),
                           ppm[0], ppm[1], len(palette) if palette is not None else 0, 0)
        if header_size >= 52:
            m = masks or (0, 0, 0, 0)
            info += struct.pack("<III", *m[:3])
            if header_size >= 56:
                info += struct.pack("<I", m[3])
        elif masks is not None and compression in (3, 6):
            extra_masks = struct.pack("<III", *masks[:3]) + (struct.pack("<I", masks[3]) if compression == 6 else b"")
        if header_size >= 108:
            info += struct.pack("<I", 0x73524742 if icc is None else 0x4D424544)  # 'sRGB' / 'MBED'
            info += b"\x00" * 36 + b"\x00" * 12  # endpoints, gamma
            if header_size >= 124:
                info += struct.pack("<I", 4)  # intent
                # profile data offset (from the start of the info header) patched below
                info += struct.pack("<III", 0, len(icc) if icc else 0, 0)
        info = info.ljust(header_size, b"\x00")[:header_size]
    off = 14 + len(info) + len(extra_masks) + len(pal)
    icc_part = b""
    if icc is not None and header_size >= 124:
        prof_off = off + len(pixel_data) - 14
        info = info[:112] + struct.pack("<I", prof_off) + info[116:]
        icc_part = icc
    fh = b"BM" + struct.pack("<IHHI", off + len(pixel_data) + len(icc_part), 0, 0, off)
    return fh + info + extra_masks + pal + pixel_data + icc_part


def bmp_indexed(idx: np.ndarray, palette: np.ndarray, bpp: int, *, top_down=False, header_size=40, **kw) -> bytes:
    h, w = idx.shape
    data = _pack_rows(pack_indices(idx, bpp), top_down)
    return bmp_bytes(width=w, height=h, bpp=bpp, pixel_data=data, palette=palette, top_down=top_down,
                     header_size=header_size, **kw)


def bmp_rgb24(rgb: np.ndarray, *, top_down=False, **kw) -> bytes:
    h, w, _ = rgb.shape
    rows = [np.ascontiguousarray(r[:, ::-1]).tobytes() for r in np.asarray(rgb, np.uint8)]
    return bmp_bytes(width=w, height=h, bpp=24, pixel_data=_pack_rows(rows, top_down), top_down=top_down, **kw)


def bmp_packed(values: np.ndarray, bpp: int, *, masks=None, compression=0, top_down=False, **kw) -> bytes:
    """16- or 32-bit BMP from raw pixel words ``values`` (h, w) uint16/uint32."""
    h, w = values.shape
    dt = "<u2" if bpp == 16 else "<u4"
    rows = [np.asarray(r).astype(dt).tobytes() for r in values]
    return bmp_bytes(width=w, height=h, bpp=bpp, pixel_data=_pack_rows(rows, top_down), compression=compression,
                     masks=masks, top_down=top_down, **kw)


def rle_encode(idx: np.ndarray, rle4: bool) -> bytes:
    """RLE8 / RLE4 encoder (bottom-up rows) using encoded runs and absolute runs."""
    out = bytearray()
    h, w = idx.shape
    for yi, row in enumerate(np.asarray(idx, np.uint8)[::-1]):
        x = 0
        while x < w:
            run = 1
            while x + run < w and run < 255 and row[x + run] == row[x]:
                run += 1
            if run >= 2:
                v = int(row[x])
                out += bytes([run, (v << 4 | v) if rle4 else v])
                x += run
                continue
            # literal: until the next repeat
            end = x + 1
            while end < w and end - x < 255 and not (end + 1 < w and row[end] == row[end + 1]):
                end += 1
            lit = row[x:end]
            if len(lit) < 3:
                for v in lit:
                    out += bytes([1, (int(v) << 4) if rle4 else int(v)])
            else:
                out += bytes([0, len(lit)])
                if rle4:
                    data = pack_indices(lit[None, :], 4)[0]
                else:
                    data = lit.tobytes()
                out += data + (b"\x00" if len(data) % 2 else b"")
            x = end
        out += b"\x00\x01" if yi == h - 1 else b"\x00\x00"
    return bytes(out)


def bmp_rle(idx: np.ndarray, palette: np.ndarray, rle4: bool, *, data: bytes | None = None, **kw) -> bytes:
    h, w = idx.shape
    enc = rle_encode(idx, rle4) if data is None else data
    return bmp_bytes(width=w, height=h, bpp=4 if rle4 else 8, pixel_data=enc, palette=palette,
                     compression=2 if rle4 else 1, **kw)


# --------------------------------------------------------------------------------------------------
# minimal hand-made TIFF / PNG / JPEG pieces


def tiff_minimal(width: int, height: int, *, bps: int = 8, spp: int = 1, photometric: int = 1, data: bytes = b"",
                 sampleformat: int = 1, extra_tags: list[tuple[int, int, int, int]] = ()) -> bytes:
    """A little-endian single-strip TIFF written by hand (for headers tifffile will not write)."""
    entries: list[tuple[int, int, int, int]] = []
    n_tags = 10 + len(extra_tags)
    ifd_off = 8
    data_off = ifd_off + 2 + n_tags * 12 + 4
    bps_val = bps
    entries += [(256, 4, 1, width), (257, 4, 1, height), (258, 3, 1, bps_val), (259, 3, 1, 1),
                (262, 3, 1, photometric), (273, 4, 1, data_off), (277, 3, 1, spp), (278, 4, 1, height),
                (279, 4, 1, len(data)), (339, 3, 1, sampleformat)]
    entries += list(extra_tags)
    entries.sort()
    ifd = struct.pack("<H", len(entries))
    for tag, typ, count, value in entries:
        if typ == 3:
            ifd += struct.pack("<HHIHH", tag, typ, count, value, 0)
        else:
            ifd += struct.pack("<HHII", tag, typ, count, value)
    ifd += struct.pack("<I", 0)
    return b"II*\x00" + struct.pack("<I", ifd_off) + ifd + data


def png_chunk(ctype: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + ctype + data + struct.pack(">I", zlib.crc32(ctype + data) & 0xFFFFFFFF)


def png_header_only(width: int, height: int) -> bytes:
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    idat = zlib.compress(b"\x00" + b"\x00" * 3 * 16)
    return b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", idat) + png_chunk(b"IEND", b"")


def jpeg_sof_only(width: int, height: int, precision: int = 8, components: int = 3) -> bytes:
    sof = struct.pack(">BHHB", precision, height, width, components)
    for c in range(components):
        sof += bytes([c + 1, 0x11, 0])
    app0 = b"JFIF\x00\x01\x01\x01\x01\x2c\x01\x2c\x00\x00"
    return (b"\xff\xd8" + b"\xff\xe0" + struct.pack(">H", len(app0) + 2) + app0 + b"\xff\xc0"
            + struct.pack(">H", len(sof) + 2) + sof + b"\xff\xd9")


def strip_app14(jpeg: bytes) -> bytes:
    """Remove the Adobe APP14 segment from a JPEG."""
    out = bytearray(jpeg[:2])
    pos = 2
    while pos < len(jpeg):
        marker = jpeg[pos + 1]
        if marker == 0xDA:
            out += jpeg[pos:]
            break
        (length,) = struct.unpack(">H", jpeg[pos + 2: pos + 4])
        if not (marker == 0xEE and jpeg[pos + 4: pos + 9] == b"Adobe"):
            out += jpeg[pos: pos + 2 + length]
        pos += 2 + length
    return bytes(out)


def set_jpeg_precision(jpeg: bytes, precision: int) -> bytes:
    pos = 2
    b = bytearray(jpeg)
    while pos < len(b):
        marker = b[pos + 1]
        (length,) = struct.unpack(">H", b[pos + 2: pos + 4])
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            b[pos + 4] = precision
            return bytes(b)
        pos += 2 + length
    raise ValueError("no SOF")


# --------------------------------------------------------------------------------------------------
# sample images


def gradient_rgb(h: int, w: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    img = np.stack([(xx * 255) // max(w - 1, 1), (yy * 255) // max(h - 1, 1), ((xx + yy) * 3) % 256], -1)
    img = img + rng.integers(0, 12, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def _damage(data: bytes, start: int, length: int, step: int = 3) -> bytes:
    b = bytearray(data)
    for i in range(start, min(start + length, len(b)), step):
        b[i] = (b[i] * 31 + 17) & 0xFF
    return bytes(b)


# --------------------------------------------------------------------------------------------------
# hostile corpus


@dataclass
class Case:
    name: str
    path: str
    phrase: str  # must appear in the ImageError message


def write_corpus(d) -> list[Case]:
    import pyvips
    import tifffile

    d = Path(d)
    cases: list[Case] = []

    def add(name: str, data: bytes | None, phrase: str, path: Path | None = None):
        p = path or d / name
        if data is not None:
            p.write_bytes(data)
        cases.append(Case(name, str(p), phrase))

    img = gradient_rgb(256, 200)
    # --- not images ---
    add("empty.tif", b"", "empty file (0 bytes)")
    add("text.jpg", b"hello, this is not an image\n" * 10, "not an image file (unknown format)")
    add("random.png", np.random.default_rng(3).integers(0, 256, 4096, dtype=np.uint8).tobytes(),
        "not an image file (unknown format)")
    add("really_a_gif.tif", b"GIF89a" + b"\x00" * 100, "unsupported file format GIF")
    add("really_a_pdf.jpg", b"%PDF-1.4\n" + b"x" * 100, "unsupported file format PDF")
    add("missing.tif", None, "file not found")
    (d / "a_directory.tif").mkdir(exist_ok=True)
    add("a_directory.tif", None, "is a directory")

    # --- TIFF ---
    tmp = d / "_src_lzw.tif"
    tifffile.imwrite(tmp, img, photometric="rgb", compression="lzw", rowsperstrip=8)
    lzw = tmp.read_bytes()
    add("truncated_lzw.tif", lzw[: len(lzw) * 6 // 10], "truncated TIFF: strip")
    add("truncated_tiff_header.tif", lzw[:40], "TIFF")
    add("corrupt_lzw.tif", _damage(lzw, len(lzw) // 2, 3000), "corrupt TIFF data")
    tifffile.imwrite(tmp, img, photometric="rgb", compression="deflate", rowsperstrip=8)
    dfl = tmp.read_bytes()
    add("corrupt_deflate.tif", _damage(dfl, len(dfl) // 2, 3000), "corrupt TIFF data")
    tifffile.imwrite(tmp, img, photometric="rgb", compression="zlib", tile=(64, 64))
    tiled = tmp.read_bytes()
    add("truncated_tiled.tif", tiled[: len(tiled) // 2], "truncated TIFF: tile")
    add("tiff_bad_ifd_offset.tif", b"II*\x00" + struct.pack("<I", 10_000_000) + b"\x00" * 64, "TIFF")
    add("bomb.tif", tiff_minimal(2_000_000, 2_000_000, data=b"\x00" * 64),
        "image too large: 2000000 x 2000000 px exceeds the limit of 4.0 Gpx")
    add("too_wide.tif", tiff_minimal(5_000_000, 1, data=b"\x00" * 64),
        "image too large: 5000000 x 1 px exceeds the limit of 1000000 px per side")
    add("zero_width.tif", tiff_minimal(0, 10, data=b"\x00" * 64), "invalid image dimensions 0 x 10")
    add("gray12.tif", tiff_minimal(16, 4, bps=12, data=b"\x00" * 96), "unsupported bit depth: 12 bits per sample")
    tifffile.imwrite(tmp, np.zeros((8, 8, 3), np.float32), photometric="rgb")
    add("float32.tif", tmp.read_bytes(), "unsupported bit depth: 32-bit floating point")
    tifffile.imwrite(tmp, np.zeros((8, 8), np.int16), photometric="minisblack")
    add("int16.tif", tmp.read_bytes(), "unsupported bit depth: 16-bit signed")
    tifffile.imwrite(tmp, np.zeros((8, 8, 3), np.uint8), photometric="cielab")
    add("lab.tif", tmp.read_bytes(), "unsupported colour space LAB")
    tifffile.imwrite(tmp, np.zeros((8, 8, 6), np.uint8), photometric="separated", extrasamples=[0, 0])
    add("six_ink.tif", tmp.read_bytes(), "unsupported colour space: 6-channel separation")
    tifffile.imwrite(tmp, np.zeros((8, 8, 4), np.uint8), photometric="separated", extratags=[(332, "H", 1, 2, True)])
    add("not_cmyk_inks.tif", tmp.read_bytes(), "not CMYK")
    tmp.unlink()

    # --- JPEG ---
    pyvips.Image.new_from_array(img).copy(interpretation="srgb").jpegsave(str(d / "_src.jpg"), Q=90)
    jpg = (d / "_src.jpg").read_bytes()
    (d / "_src.jpg").unlink()
    add("truncated.jpg", jpg[: len(jpg) * 6 // 10], "truncated JPEG")
    add("corrupt.jpg", _damage(jpg, len(jpg) // 2, 300, 7), "corrupt JPEG data")
    add("jpeg_headers_only.jpg", jpg[:20], "truncated JPEG")
    add("bomb.jpg", jpeg_sof_only(65535, 65535), "image too large: 65535 x 65535 px exceeds the limit of 4.0 Gpx")
    add("jpeg12.jpg", set_jpeg_precision(jpg, 12), "unsupported bit depth: 12-bit JPEG")
    add("jpeg_no_frame.jpg", b"\xff\xd8\xff\xd9", "no image")

    # --- PNG ---
    pyvips.Image.new_from_array(img).copy(interpretation="srgb").pngsave(str(d / "_src.png"), compression=1)
    png = (d / "_src.png").read_bytes()
    (d / "_src.png").unlink()
    add("truncated.png", png[: len(png) * 6 // 10], "truncated PNG")
    add("corrupt.png", _damage(png, len(png) // 2, 200), "corrupt or truncated PNG data")
    add("bomb.png", png_header_only(100_000, 100_000),
        "image too large: 100000 x 100000 px exceeds the limit of 4.0 Gpx")

    # --- BMP ---
    good = bmp_rgb24(img[:50, :60])
    add("truncated.bmp", good[: len(good) // 2], "truncated BMP")
    add("bmp_header_only.bmp", good[:20], "truncated BMP")
    add("bomb.bmp", bmp_bytes(width=60_000, height=80_000, bpp=24, pixel_data=b"\x00" * 64),
        "image too large: 60000 x 80000 px exceeds the limit of 4.0 Gpx")
    add("bmp_jpeg.bmp", bmp_bytes(width=8, height=8, bpp=24, pixel_data=b"\xff\xd8" + b"\x00" * 62, compression=4),
        "unsupported BMP compression embedded JPEG")
    add("bmp64.bmp", bmp_bytes(width=8, height=8, bpp=64, pixel_data=b"\x00" * 512),
        "unsupported bit depth: 64-bit BMP")
    bad_hdr = bytearray(good)
    bad_hdr[14:18] = struct.pack("<I", 77)
    add("bmp_bad_header.bmp", bytes(bad_hdr), "corrupt BMP: unknown header size 77")
    pal = np.stack([np.arange(256)] * 3, 1).astype(np.uint8)
    idx = (np.arange(40 * 30).reshape(30, 40) % 7).astype(np.uint8)
    rle = rle_encode(idx, False)
    add("rle_truncated.bmp", bmp_rle(idx, pal, False, data=rle[: len(rle) // 2]), "truncated BMP: the RLE data ends")
    add("rle_outside.bmp", bmp_rle(idx, pal, False, data=b"\x02\x05\x00\x02\x00\x7f\x00\x01"),
        "corrupt BMP: RLE data moves outside the image")
    add("bmp_bad_planes.bmp", bmp_bytes(width=8, height=8, bpp=24, pixel_data=b"\x00" * 192, planes=3),
        "corrupt BMP")

    # --- BMP: RLE runs that do not fit their row, colour indices past the palette (a
    # decoder that clips or paints them black prints a wrong image with exit 0) ---
    # 6 x 4, rows bottom-up in the file, 8 pixels a row with the padding (runs may cover
    # it); the pixel data starts after 14 + 40 + 4 * len(palette) bytes
    six = np.zeros((4, 6), np.uint8)
    add("rle8_run_overruns_row.bmp", bmp_rle(six, pal, False, data=bytes([4, 1, 5, 2, 0, 0, 0, 1])),
        "corrupt BMP: the RLE run of 5 pixels at byte 1080 overruns row 3 (it starts at column 4, "
        "the image is 6 wide, 8 with the row's padding)")
    add("rle8_absolute_overruns_row.bmp",
        bmp_rle(six, pal, False, data=bytes([0, 10, *range(1, 11), 0, 1])),
        "corrupt BMP: the RLE run of 10 pixels at byte 1078 overruns row 3")
    pal16 = pal[:16]
    add("rle4_run_overruns_row.bmp", bmp_rle(six, pal16, True, data=bytes([9, 0x12, 0, 1])),
        "corrupt BMP: the RLE run of 9 pixels at byte 118 overruns row 3")
    add("rle8_no_end_of_line.bmp",                 # a full row, then the next run without EOL
        bmp_rle(six, pal, False, data=bytes([6, 1, 3, 2, 0, 0, 0, 1])),
        "overruns row 3 (it starts at column 6")
    add("rle8_delta_past_right_edge.bmp", bmp_rle(six, pal, False, data=bytes([2, 1, 0, 2, 9, 0, 0, 1])),
        "corrupt BMP: RLE data moves outside the image (the delta at byte 1080 moves past the right edge")
    add("rle8_index_past_palette.bmp", bmp_rle(six, pal[:4], False, data=bytes([2, 1, 3, 9, 0, 1])),
        "corrupt BMP: colour index 9 at byte 72 (row 3, column 2) is outside the palette of 4 colours")
    add("rle4_index_past_palette.bmp",
        bmp_rle(six, pal[:3], True, data=bytes([0, 4, 0x12, 0x0F, 0, 1])),
        "corrupt BMP: colour index 15 at byte 69 (row 3, column 3) is outside the palette of 3 colours")
    idx8 = np.zeros((5, 7), np.uint8)
    idx8[1, 4] = 200                               # image row 1 is file row 3 (bottom-up)
    add("bmp8_index_past_palette.bmp", bmp_indexed(idx8, pal[:16], 8),
        "corrupt BMP: colour index 200 at byte 146 (row 1, column 4) is outside the palette of 16 colours")
    idx4 = np.zeros((3, 5), np.uint8)
    idx4[2, 1] = 5
    add("bmp4_index_past_palette.bmp", bmp_indexed(idx4, pal[:2], 4, top_down=True),
        "corrupt BMP: colour index 5 at byte 70 (row 2, column 1) is outside the palette of 2 colours")

    # --- not regular files: a FIFO or a device is no image (and must not hang the reader) ---
    fifo = d / "a_fifo.tif"
    if not fifo.exists():
        os.mkfifo(fifo)
    add("a_fifo.tif", None, "not a regular file (a FIFO)")
    link = d / "link_to_fifo.jpg"
    if not link.is_symlink():
        link.symlink_to(fifo.name)
    add("link_to_fifo.jpg", None, "not a regular file (a FIFO)")
    add("dev_zero", None, "not a regular file (a character device)", path=Path("/dev/zero"))
    add("dev_null", None, "not a regular file (a character device)", path=Path("/dev/null"))

    # --- names: longer than NAME_MAX / PATH_MAX; not UTF-8 ---
    add("name_max", None, "cannot read file: File name too long", path=d / ("n" * 300 + ".tif"))
    add("path_max", None, "cannot read file: File name too long",
        path=d.joinpath(*["p" * 200] * 25, "deep.tif"))
    add("non_utf8_truncated.jpg", jpg[: len(jpg) * 6 // 10], "truncated JPEG",
        path=d / os.fsdecode(b"caf\xe9-\xff.jpg"))

    # --- a header claiming a huge image (under the pixel cap) with a few KB of data ---
    add("jpeg_claims_huge.jpg", set_jpeg_size(jpg, 30000, 20000), "corrupt JPEG data")
    return cases


def set_jpeg_size(jpeg: bytes, width: int, height: int) -> bytes:
    """The same JPEG data under a frame header claiming another size."""
    pos = 2
    b = bytearray(jpeg)
    while pos < len(b):
        marker = b[pos + 1]
        (length,) = struct.unpack(">H", b[pos + 2: pos + 4])
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            struct.pack_into(">HH", b, pos + 5, height, width)
            return bytes(b)
        pos += 2 + length
    raise ValueError("no SOF")


def mutations(data: bytes, n: int, seed: int) -> list[bytes]:
    """Deterministic fuzz: byte flips, truncations and splices of a valid file."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        b = bytearray(data)
        kind = i % 3
        if kind == 0:
            for _ in range(int(rng.integers(1, 8))):
                b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
        elif kind == 1:
            b = b[: int(rng.integers(1, len(b)))]
        else:
            p = int(rng.integers(0, len(b)))
            b[p: p + 16] = rng.integers(0, 256, 16, dtype=np.uint8).tobytes()
        out.append(bytes(b))
    return out


if __name__ == "__main__":  # write the corpus somewhere to look at it
    import sys
    import tempfile

    target = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="wideprint-corpus-")
    os.makedirs(target, exist_ok=True)
    for c in write_corpus(target):
        print(f"{c.name:32s} {c.phrase}")
    print(target)


def fuzz_failures(samples: dict, tmp_path: Path, n: int, opener, suffix: str = "") -> list[str]:
    """Open `n` mutations of every valid sample with `opener` (path -> an image source) and
    read all its bands: each must decode or raise ImageError naming the file with a
    problem, within 5 s.  Returns what did neither, one line each."""
    import time

    from wideprint.rip.load import ImageError
    bad = []
    for kind, data in samples.items():
        for i, m in enumerate(mutations(data, n, seed=zlib.crc32(kind.encode()))):
            p = tmp_path / f"fuzz_{kind}_{i}{suffix}"
            p.write_bytes(m)
            t0 = time.perf_counter()
            try:
                src = opener(p)
                for b in src.bands(16):
                    assert b.shape[1:] == (src.width, src.channels)
            except ImageError as e:
                assert str(p) in str(e) and e.problem
            except Exception as e:  # noqa: BLE001 - reported by the caller
                bad.append(f"{kind} #{i}: {type(e).__name__}: {e}")
            assert time.perf_counter() - t0 < 5
    return bad
