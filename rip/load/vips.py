"""TIFF, JPEG and PNG through libvips (pyvips) with ``access='sequential'`` (docs/rip.md
"Input back ends").  Pixels are pulled with :class:`pyvips.Region` so libvips only keeps a
small line cache.  TIFF and PNG use ``fail_on='error'``, JPEG ``fail_on='warning'``
(libjpeg reports corrupt entropy-coded data only as a *warning* and would otherwise fill
the image with grey - printing that on 3.4 m of media is worse than refusing the file).
Plain strip TIFFs are handed on to rip/load/tiff.py's strip reader."""

from __future__ import annotations

import os
import struct
from typing import Any, Iterator

import numpy as np

from .source import ImageError, ImageSource, _check_dims, _Hdr, _VipsPlan
from .tiff import _StripReader


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



_FORMAT_NAMES = {"char": "8-bit signed integer", "short": "16-bit signed integer", "uint": "32-bit integer",
                 "int": "32-bit signed integer", "float": "32-bit floating point", "double": "64-bit floating point",
                 "complex": "complex", "dpcomplex": "complex"}
_UNSUPPORTED_INTERP = {"lab": "LAB", "labq": "LAB", "labs": "LAB", "lch": "LCh", "cmc": "CMC", "xyz": "XYZ",
                       "yxy": "Yxy", "hsv": "HSV", "scrgb": "scRGB (linear float)", "fourier": "Fourier",
                       "histogram": "histogram", "matrix": "matrix"}



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



def _open_vips(path: str, fmt: str, hdr: _Hdr, max_pixels: int, max_side: int) -> ImageSource:
    pv = _vips()
    vips_reader = _VipsReader(path, fmt, _VipsPlan(0, None, "", 8))
    reader: _VipsReader | _StripReader = vips_reader
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
        reader = _StripReader(path, plan, hdr, vips_reader)
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
