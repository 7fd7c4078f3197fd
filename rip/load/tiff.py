"""TIFF: the header read with tifffile and checked before libvips sees the file, and the
strip reader that reads plain strip TIFFs without libvips' caches (docs/rip.md "Input back
ends"); every other TIFF is decoded by libvips (rip/load/vips.py)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Iterator, cast

import numpy as np

from .source import ImageError, _check_dims, _Hdr, _reband, _VipsPlan

if TYPE_CHECKING:
    from .vips import _VipsReader


_PHOTOMETRIC_NAMES = {4: "transparency mask", 8: "LAB", 9: "LAB", 10: "LAB", 32803: "colour filter array (raw)",
                      32844: "LogL", 32845: "LogLuv", 34892: "linear raw"}


def _tiff_header(path: str, size: int, max_pixels: int, max_side: int) -> _Hdr:
    import tifffile

    hdr = _Hdr()
    try:
        with tifffile.TiffFile(path) as tf:
            if len(tf.pages) == 0:
                raise ImageError(path, "corrupt TIFF header: no image directory (IFD) found")
            page = cast(tifffile.TiffPage,      # the first page is always a whole page
                        tf.pages.first if hasattr(tf.pages, "first") else tf.pages[0])
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
            ink_tag = tags.get("InkSet")
            inkset = int(ink_tag.value) if ink_tag is not None else None
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
        raise ImageError(path, f"unsupported bit depth: {e['bps']}-bit floating point samples "
                               f"(need 8 or 16-bit integer)")
    if e["sampleformat"] == 2:
        raise ImageError(path, f"unsupported bit depth: {e['bps']}-bit signed integer samples "
                               f"(need 8 or 16-bit unsigned)")
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
            raise ImageError(path, f"unsupported colour space: {inks}-ink separation that is not CMYK "
                                   f"(InkSet {e['inkset']})")
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
