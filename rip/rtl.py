"""HP RTL (Raster Transfer Language) input: the raster subset that other RIPs send to
wide-format plotters (docs/rtl.md lists the commands).

``RtlSource(path)`` reads the file twice, never holding more than a band:

1. on opening, the whole command stream is parsed and every row decoded (compression
   modes 0, 1, 2, 3 and 5), which checks the file and gives its size; any problem is an
   :class:`~.load.ImageError` that names the byte offset;
2. ``bands(rows)`` / ``packed_bands(rows)`` parse and decode it again, band by band.

1-bit raster (simple colour ESC*r#U, or configure image data ESC*v#W with one bit per
plane) is already halftoned: the source is ``prescreened`` and the RIP prints its dots as
they are (no separation, no ink limit, no screen), one bit per device dot.  Contone raster
(ESC*v#W direct by pixel, 8 bits per component, RGB or CMY) is an ordinary image source that
goes through the normal RIP.

The commands are parsed in Python, one escape sequence at a time (a few per row); rows
are decoded by compiled kernels (numba), never pixel by pixel in Python.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, replace
from typing import Iterator

import numpy as np
from .compiled import kernel

from .load import ImageError
from .settings import MAX_SIDE

__all__ = ["RtlSource", "open_rtl", "sniff_rtl", "SIMPLE_COLOURS"]

ESC = 0x1B
CHUNK = 1 << 20
MAX_DATA = 64 << 20          # one transfer command's data, at most
MAX_WARNINGS = 20

# output channel of each plane and whether a set bit means "no ink" (RGB planes)
C, M, Y, K = 0, 1, 2, 3
SIMPLE_COLOURS = {
    1: ("K (ESC*r1U)", ((K, False),)),
    3: ("RGB (ESC*r3U)", ((C, True), (M, True), (Y, True))),
    -3: ("CMY (ESC*r-3U)", ((C, False), (M, False), (Y, False))),
    -4: ("KCMY (ESC*r-4U)", ((K, False), (C, False), (M, False), (Y, False))),
}
MODES = (0, 1, 2, 3, 5)


def sniff_rtl(head: bytes) -> bool:
    """Does the file start like RTL/PCL: ESC E (reset), ESC%-12345X (UEL), ESC%#B (HP-GL/2),
    ESC* or ESC& (raster, job control)?"""
    h = head.lstrip(b"\r\n\t \x00")
    return len(h) >= 2 and h[0] == ESC and h[1:2] in (b"E", b"%", b"*", b"&")


@dataclass(frozen=True)
class _Config:
    kind: str                 # "bits" | "contone"
    name: str                 # for messages
    planes: tuple = ()        # bits: ((channel, inverted), ...) per plane
    space: str = ""           # contone: "rgb" | "cmy"

    @property
    def nplanes(self) -> int:
        return len(self.planes) if self.kind == "bits" else 1

    def row_bytes(self, width: int) -> int:
        return (width + 7) // 8 if self.kind == "bits" else width * 3


DEFAULT = _Config("bits", SIMPLE_COLOURS[1][0], SIMPLE_COLOURS[1][1])


# --------------------------------------------------------------------------------------
# row decoders (compiled)

OK, TRUNCATED, TOO_LONG, ODD_RLE = 0, 1, 2, 3


@kernel(inline="always")
def _fill(dst, o, cnt, v) -> bool:
    """A run of `cnt` bytes `v` into dst from `o`; False if it passes the row's end with a
    non-zero byte (a zero run past the width is padding)."""
    cap = dst.shape[0]
    end = o + cnt
    if end > cap:
        if v != 0:
            return False
        end = cap
    for k in range(o, end):
        dst[k] = v
    return True


@kernel(inline="always")
def _literal(src, i, cnt, dst, o) -> int:
    """Copy src[i:i+cnt] into dst from `o`; the index in src of a non-zero byte past the
    row's end, or -1."""
    cap = dst.shape[0]
    for k in range(cnt):
        v = src[i + k]
        if o + k < cap:
            dst[o + k] = v
        elif v != 0:
            return i + k
    return -1


@kernel()
def _decode_row(mode, src, dst):
    """Decode one row `src` in compression `mode` (0, 1, 2, 3) into `dst` (one plane row of the
    source width).  Modes 0-2 overwrite dst and zero-fill what the row does not reach; mode 3
    (delta row) changes dst, the seed row, in place.  Bytes past the width must be zero.
    Returns (status, index in src): OK, TRUNCATED, TOO_LONG (a non-zero byte past the
    width) or ODD_RLE."""
    n = src.shape[0]
    cap = dst.shape[0]
    if mode == 0:
        m = min(n, cap)
        dst[:m] = src[:m]
        dst[m:] = 0
        for i in range(m, n):
            if src[i] != 0:
                return TOO_LONG, i
        return OK, n
    if mode == 1:
        if n & 1:
            return ODD_RLE, n - 1
        o = 0
        for i in range(0, n, 2):
            cnt = np.int64(src[i]) + 1
            if not _fill(dst, o, cnt, src[i + 1]):
                return TOO_LONG, i
            o += cnt
        if o < cap:
            dst[o:] = 0
        return OK, n
    if mode == 2:
        o = 0
        i = 0
        while i < n:
            c = np.int64(src[i])
            i += 1
            if c < 128:                       # c + 1 literal bytes
                cnt = c + 1
                if i + cnt > n:
                    return TRUNCATED, i - 1
                bad = _literal(src, i, cnt, dst, o)
                if bad >= 0:
                    return TOO_LONG, bad
                o += cnt
                i += cnt
            elif c > 128:                     # the next byte 257 - c times
                cnt = 257 - c
                if i >= n:
                    return TRUNCATED, i - 1
                if not _fill(dst, o, cnt, src[i]):
                    return TOO_LONG, i - 1
                i += 1
                o += cnt
            # c == 128: no operation
        if o < cap:
            dst[o:] = 0
        return OK, n
    # mode 3: delta row against the seed row in dst
    o = 0
    i = 0
    while i < n:
        c = np.int64(src[i])
        start = i
        i += 1
        cnt = (c >> 5) + 1
        off = c & 31
        if off == 31:
            while True:
                if i >= n:
                    return TRUNCATED, start
                b = np.int64(src[i])
                i += 1
                off += b
                if b != 255:
                    break
        o += off
        if i + cnt > n:
            return TRUNCATED, start
        bad = _literal(src, i, cnt, dst, o)
        if bad >= 0:
            return TOO_LONG, bad
        o += cnt
        i += cnt
    return OK, n


# --------------------------------------------------------------------------------------
# the command stream

_PARAM = re.compile(rb"([+-]?[0-9]*(?:\.[0-9]*)?)([\x40-\x7e])")
_HPGL_END = re.compile(rb"\x1b(?:%[+-]?[0-9]*A|E|%-12345X)")
_LANG = re.compile(rb"ENTER\s+LANGUAGE\s*=\s*([A-Za-z0-9_]+)", re.I)


class _Stream:
    """A file read in chunks, with the position as a file offset."""

    def __init__(self, f, size: int):
        self.f, self.size = f, size
        self.buf = b""
        self.pos = 0
        self.base = 0
        self.eof = False

    @property
    def offset(self) -> int:
        return self.base + self.pos

    def fill(self, n: int) -> int:
        """At least n bytes from pos in the buffer (fewer only at the end of the file)."""
        while len(self.buf) - self.pos < n and not self.eof:
            more = self.f.read(max(CHUNK, n))
            if not more:
                self.eof = True
                break
            self.buf = self.buf[self.pos:] + more
            self.base += self.pos
            self.pos = 0
        return len(self.buf) - self.pos

    def skip_to_esc(self) -> int:
        """Move to the next ESC (or the end); the number of bytes skipped."""
        skipped = 0
        while True:
            i = self.buf.find(b"\x1b", self.pos)
            if i >= 0:
                skipped += i - self.pos
                self.pos = i
                return skipped
            skipped += len(self.buf) - self.pos
            self.pos = len(self.buf)
            if not self.fill(1):
                return skipped

    def take(self, n: int) -> bytes:
        """n bytes (fewer at the end of the file); n is at most MAX_DATA."""
        self.fill(n)
        out = self.buf[self.pos: self.pos + n]
        self.pos += len(out)
        return out


class _Parser:
    """Parses an RTL stream; `events()` yields ("row", count) when the planes in `seeds`
    form the next row (count times), ("blank", count) for rows that print nothing, and
    ("block", None) when a raster block starts (cfg and width are then current)."""

    def __init__(self, path: str):
        self.path = path
        self.warnings: list[str] = []
        self.resolution: int | None = None
        self.modes_used: set[int] = set()
        self.hpgl_bytes = 0
        self.stray_bytes = 0
        self.language: str | None = None
        self.row = 0

    def fail(self, offset: int, problem: str) -> ImageError:
        return ImageError(self.path, f"RTL: {problem} (byte {offset})")

    def warn(self, text: str) -> None:
        if text not in self.warnings and len(self.warnings) < MAX_WARNINGS:
            self.warnings.append(text)

    # -- the state machine ---------------------------------------------------------------
    def _reset(self) -> None:
        self.cfg = DEFAULT
        self.src_width: int | None = None
        self.mode = 0
        self.in_raster = False
        self.plane = 0
        self.width = 0
        self.seeds = np.zeros((1, 0), np.uint8)

    def _start(self, offset: int) -> Iterator[tuple]:
        if self.src_width is None:
            raise self.fail(offset, "raster data before the source raster width (ESC*r#S)")
        self.width = self.src_width
        self.seeds = np.zeros((self.cfg.nplanes, self.cfg.row_bytes(self.width)), np.uint8)
        self.in_raster = True
        self.plane = 0
        yield ("block", None)

    def _end_row(self) -> Iterator[tuple]:
        if self.plane:
            self.seeds[self.plane:] = 0       # planes not sent are zero
            self.plane = 0
            yield ("row", 1)

    def _end(self) -> Iterator[tuple]:
        if self.in_raster:
            yield from self._end_row()
        self.in_raster = False

    def _decode(self, data: bytes, plane: int, offset: int, cmd: str) -> None:
        src = np.frombuffer(data, np.uint8)
        status, at = _decode_row(self.mode, src, self.seeds[plane])
        if status == OK:
            return
        where = offset + int(at)
        what = f"row {self.row + 1}, plane {plane + 1}: {cmd}"
        if status == TOO_LONG:
            rb = self.seeds.shape[1]
            raise self.fail(where, f"{what}: the row is wider than the source raster width of "
                                   f"{self.width} px ({rb} bytes per plane)")
        if status == ODD_RLE:
            raise self.fail(where, f"{what}: run-length data (mode 1) of odd length {len(data)}")
        raise self.fail(where, f"{what}: the compressed row (mode {self.mode}) ends inside a "
                               f"{'replacement' if self.mode == 3 else 'run'}")

    def _adaptive(self, data: bytes, offset: int) -> Iterator[tuple]:
        """Mode 5: a block of rows, each with a 3-byte header (docs/rtl.md)."""
        if self.cfg.nplanes != 1:
            raise self.fail(offset, f"adaptive compression (mode 5) with {self.cfg.nplanes} planes: only "
                                    f"single-plane raster can use it")
        i, n = 0, len(data)
        seed = self.seeds[0]
        while i < n:
            if i + 3 > n:
                raise self.fail(offset + i, "adaptive compression: a row header is cut short")
            cmd = data[i]
            count = (data[i + 1] << 8) | data[i + 2]
            i += 3
            if cmd == 4:                        # empty rows
                seed[:] = 0
                if count:
                    yield ("blank", count)
            elif cmd == 5:                      # the previous row again
                if count:
                    yield ("row", count)
            elif cmd <= 3:
                if i + count > n:
                    raise self.fail(offset + i - 3, f"adaptive compression: a row of {count} bytes runs past "
                                                    f"the end of the block")
                chunk = data[i: i + count]
                save, self.mode = self.mode, cmd
                try:
                    self._decode(chunk, 0, offset + i, f"adaptive row (method {cmd})")
                finally:
                    self.mode = save
                i += count
                yield ("row", 1)
            else:
                raise self.fail(offset + i - 3, f"adaptive compression: unknown row command {cmd}")

    def _cid(self, data: bytes, offset: int) -> _Config:
        if len(data) < 6:
            raise self.fail(offset, f"configure image data (ESC*v{len(data)}W) needs 6 bytes")
        space, pem, bpi, b1, b2, b3 = data[:6]
        names = {0: "RGB", 1: "CMY"}
        if space not in names:
            other = {2: "colorimetric RGB", 3: "CIE L*a*b*", 4: "luminance-chrominance"}.get(space, str(space))
            raise self.fail(offset, f"configure image data: colour space {other} is not supported "
                                    f"(supported: 0 = RGB, 1 = CMY)")
        sname = names[space]
        inv = space == 0
        if pem == 0:                                   # indexed by plane, the default palette
            if bpi == 1:
                return _Config("bits", f"1 plane K (ESC*v6W {space} 0 1)", ((K, False),))
            if bpi == 3:
                return _Config("bits", f"3 planes {sname} (ESC*v6W {space} 0 3)",
                               ((C, inv), (M, inv), (Y, inv)))
            if bpi == 4 and space == 1:
                return _Config("bits", "4 planes KCMY (ESC*v6W 1 0 4)", SIMPLE_COLOURS[-4][1])
            raise self.fail(offset, f"configure image data: {bpi} bits per index by plane in {sname} is "
                                    f"not supported (1 = K, 3 = {sname} planes, 4 = KCMY with CMY)")
        if pem == 2:                                   # direct by plane, one bit per primary
            if (b1, b2, b3) != (1, 1, 1):
                raise self.fail(offset, f"configure image data: direct by plane needs 1 bit per "
                                        f"primary, not {b1}/{b2}/{b3}")
            return _Config("bits", f"3 planes {sname} direct (ESC*v6W {space} 2)", ((C, inv), (M, inv), (Y, inv)))
        if pem == 3:                                   # direct by pixel
            if (b1, b2, b3) != (8, 8, 8):
                raise self.fail(offset, f"configure image data: direct by pixel needs 8 bits per "
                                        f"primary, not {b1}/{b2}/{b3}")
            return _Config("contone", f"{sname} 8 bits per component (ESC*v6W {space} 3)", (), sname.lower())
        raise self.fail(offset, f"configure image data: pixel encoding mode {pem} "
                                f"({'indexed by pixel' if pem == 1 else 'unknown'}) is not supported "
                                f"(0 = indexed by plane, 2 = direct by plane, 3 = direct by pixel)")

    def events(self, f, size: int) -> Iterator[tuple]:
        self.row = 0                                    # rows yielded so far
        for ev in self._events(f, size):
            yield ev
            if ev[0] != "block":
                self.row += ev[1]

    def _events(self, f, size: int) -> Iterator[tuple]:
        s = _Stream(f, size)
        self._reset()
        while True:
            skipped = s.skip_to_esc()
            if skipped:
                self.stray_bytes += skipped
            if s.fill(2) == 0:
                break
            start = s.offset
            if s.fill(2) < 2:
                raise self.fail(start, "the file ends inside an escape sequence")
            c1 = s.buf[s.pos + 1]
            if 0x30 <= c1 <= 0x7E:                      # two-character command
                s.pos += 2
                if c1 == ord("E"):                      # reset
                    yield from self._end()
                    self._reset()
                continue
            if not 0x21 <= c1 <= 0x2F:
                raise self.fail(start, f"not an escape sequence: ESC followed by byte {c1:#04x}")
            if c1 == ord("%"):
                group, i = "%", s.pos + 2
            else:
                if s.fill(3) < 3:
                    raise self.fail(start, "the file ends inside an escape sequence")
                c2 = s.buf[s.pos + 2]
                if not 0x60 <= c2 <= 0x7E:
                    raise self.fail(start, f"not an escape sequence: ESC {chr(c1)} followed by byte {c2:#04x}")
                group, i = chr(c1) + chr(c2), s.pos + 3
            s.pos = i
            while True:                                 # the parameters of a (combined) command
                s.fill(64)
                m = _PARAM.match(s.buf, s.pos)
                if m is None:
                    bad = s.buf[s.pos: s.pos + 1]
                    raise self.fail(s.offset, f"malformed escape sequence ESC{group}... (unexpected "
                                              f"{'end of file' if not bad else repr(bad)[1:]})")
                vtext, term = m.group(1), m.group(2)[0]
                s.pos = m.end()
                try:
                    value = float(vtext) if vtext.strip(b"+-.") else 0.0
                except ValueError:
                    raise self.fail(start, f"malformed number {vtext!r} in an escape sequence") from None
                letter = chr(term).upper()
                final = term < 0x60
                yield from self._command(s, group, letter, value, start)
                if final:
                    break
        yield from self._end()

    def _data(self, s: _Stream, value: float, start: int, cmd: str) -> tuple[bytes, int]:
        n = int(value)
        if n < 0 or n > MAX_DATA:
            raise self.fail(start, f"{cmd} announces {n} bytes of data")
        at = s.offset
        data = s.take(n)
        if len(data) != n:
            raise self.fail(start, f"{cmd} announces {n} bytes but the file ends after {len(data)}: "
                                   f"a truncated file")
        return data, at

    def _command(self, s: _Stream, group: str, letter: str, value: float, start: int) -> Iterator[tuple]:
        v = int(value)
        if group == "%":
            if letter == "X":                          # UEL: PJL lines follow, up to the next escape
                yield from self._end()
                s.fill(4096)
                pjl = s.buf[s.pos: s.pos + 4096].split(b"\x1b", 1)[0]
                m = _LANG.search(pjl)
                if m:
                    self.language = m.group(1).decode("ascii", "replace").upper()
                    if self.language not in ("RTL", "PCL", "HPGL2", "HPGL", "PCL3GUI"):
                        raise self.fail(start, f"the PJL header switches to {self.language}, not RTL "
                                               f"(send PostScript or PDF without the PJL header)")
                s.skip_to_esc()                        # the PJL lines are not stray bytes
            elif letter == "B":                        # HP-GL/2: skipped up to ESC%#A, ESC E or UEL
                yield from self._end()
                skipped = 0
                while True:
                    s.fill(64)
                    m = _HPGL_END.search(s.buf, s.pos)
                    if m is not None:
                        skipped += m.start() - s.pos
                        s.pos = m.start()
                        if s.buf[s.pos + 1: s.pos + 2] == b"%" and s.buf[m.end() - 1:m.end()] == b"A":
                            s.pos = m.end()
                        break
                    keep = max(s.pos, len(s.buf) - 16)     # an end sequence may straddle the chunks
                    skipped += keep - s.pos
                    s.pos = keep
                    before = len(s.buf) - s.pos
                    if s.fill(before + 1) <= before:
                        skipped += len(s.buf) - s.pos
                        s.pos = len(s.buf)
                        break
                self.hpgl_bytes += skipped
                self.warn(f"HP-GL/2 vector data was skipped (byte {start}): only the raster is printed")
            # ESC%#A (enter PCL) and others: nothing to do
            return
        if letter == "W" or (group == "&p" and letter == "X"):
            cmd = f"ESC{group}{v}{letter}"
            data, at = self._data(s, value, start, cmd)
            if group == "*b":
                yield from self._transfer(data, at, start, last=True)
            elif group == "*v":
                self._configure(self._cid(data, start), start)
            return
        if group == "*b":
            if letter == "V":
                cmd = f"ESC*b{v}V"
                data, at = self._data(s, value, start, cmd)
                yield from self._transfer(data, at, start, last=False)
            elif letter == "M":
                if v not in MODES:
                    extra = " (9 = replacement delta row)" if v == 9 else ""
                    raise self.fail(start, f"compression method {v}{extra} is not supported "
                                           f"(supported: 0, 1, 2, 3, 5)")
                self.mode = v
                self.modes_used.add(v)
            elif letter == "Y":
                if v < 0:
                    raise self.fail(start, f"negative y offset ESC*b{v}Y")
                if not self.in_raster:
                    yield from self._start(start)
                yield from self._end_row()
                self.seeds[:] = 0
                if v:
                    yield ("blank", v)
            return
        if group == "*r":
            if letter == "S":
                if not 1 <= v <= MAX_SIDE:
                    raise self.fail(start, f"source raster width {v} px is out of range (1..{MAX_SIDE:,})")
                self.src_width = v
            elif letter == "A":
                yield from self._end()
                yield from self._start(start)
            elif letter in ("B", "C"):
                yield from self._end()
            elif letter == "U":
                if v not in SIMPLE_COLOURS:
                    raise self.fail(start, f"simple colour ESC*r{v}U is not supported "
                                           f"(1 = K, 3 = RGB, -3 = CMY, -4 = KCMY)")
                name, planes = SIMPLE_COLOURS[v]
                self._configure(_Config("bits", name, planes), start)
            # T (source height), F (orientation), ...: nothing to do
            return
        if group == "*t" and letter == "R":
            if v <= 0 or v > 10_000:
                raise self.fail(start, f"raster resolution {v} dpi is out of range")
            if self.resolution is not None and v != self.resolution:
                raise self.fail(start, f"the raster resolution changes from {self.resolution} to {v} dpi")
            self.resolution = v
            return
        if group == "*v" and letter == "I":
            raise self.fail(start, "palette entries (ESC*v#I) are not supported: only the default palettes "
                                   "of simple colour and configure image data are")
        if group == "*p" and letter in ("X", "Y"):
            self.warn(f"cursor positioning ESC*p{v}{letter} is ignored (byte {start}): raster blocks are "
                      f"printed one below the other")

    def _configure(self, cfg: _Config, start: int) -> None:
        if self.in_raster:
            # the colour set-up changes only between raster blocks
            raise self.fail(start, "the colour configuration changes inside a raster block (before ESC*rC)")
        self.cfg = cfg

    def _transfer(self, data: bytes, at: int, start: int, last: bool) -> Iterator[tuple]:
        if not self.in_raster:
            yield from self._start(start)                # implicit start of raster graphics
        cmd = f"ESC*b{len(data)}{'W' if last else 'V'}"
        if self.mode == 5:
            if not last or self.plane:
                raise self.fail(start, "adaptive compression (mode 5) with plane-by-plane transfer (ESC*b#V)")
            yield from self._adaptive(data, at)
            return
        if self.plane >= self.cfg.nplanes:
            raise self.fail(start, f"{cmd}: more planes in a row than the {self.cfg.nplanes} of "
                                   f"{self.cfg.name}")
        self._decode(data, self.plane, at, cmd)
        self.plane += 1
        if last:
            yield from self._end_row()


# --------------------------------------------------------------------------------------
# the image source


def _bit_mask(width: int) -> int:
    r = width % 8
    return 0xFF if r == 0 else (0xFF << (8 - r)) & 0xFF


class RtlSource:
    """An RTL file as the ImageSource duck type (docs/placement.md).

    1-bit raster: ``prescreened`` is True, ``bands()`` are (h, W, 4) 0/1 dots (C, M, Y, K)
    and ``packed_bands()`` the same as packed bits (h, 4, ceil(W / 8)), the planner's layout.
    Contone raster: ``bands()`` are (h, W, 3) RGB or (h, W, 4) CMYK (CMY with K = 0) uint8.
    Rows that print nothing (y offsets, empty rows, the right of narrower blocks) are
    blank: no ink."""

    def __init__(self, path):
        self.path = os.fspath(path)
        try:
            self.size = os.path.getsize(self.path)
        except OSError as e:
            raise ImageError(self.path, f"cannot read file: {e.strerror or e}") from None
        p = _Parser(self.path)
        width = rows = blocks = 0
        kinds: set[str] = set()
        spaces: set[str] = set()
        with self._open() as f:
            for ev, n in p.events(f, self.size):
                if ev == "block":
                    blocks += 1
                    kinds.add(p.cfg.kind)
                    if p.cfg.kind == "contone":
                        spaces.add(p.cfg.space)
                    width = max(width, p.width)
                else:
                    rows += n
                    if rows > MAX_SIDE:
                        raise ImageError(self.path, f"RTL: more than {MAX_SIDE:,} rows")
        if not blocks or not rows:
            why = ""
            if p.hpgl_bytes:
                why = " (it holds HP-GL/2 vector data, which is not printed: send raster RTL)"
            elif p.stray_bytes:
                why = f" ({p.stray_bytes} bytes outside escape sequences)"
            raise ImageError(self.path, f"RTL: no raster data in the file{why}")
        if len(kinds) > 1:
            raise ImageError(self.path, "RTL: the file mixes 1-bit and contone raster blocks")
        if len(spaces) > 1:
            raise ImageError(self.path, "RTL: the file mixes RGB and CMY contone raster blocks")
        if p.stray_bytes:
            p.warn(f"{p.stray_bytes} bytes outside escape sequences were ignored")
        self.width, self.height = width, rows
        self.blocks = blocks
        self.prescreened = kinds == {"bits"}
        space = next(iter(spaces)) if spaces else ""
        self.contone_space = space
        self.colorspace = "cmyk" if self.prescreened or space == "cmy" else "rgb"
        self.channels = 4 if self.colorspace == "cmyk" else 3
        self.depth = 8
        self.icc = None
        self.format = "rtl"
        self.resolution = p.resolution
        self.xres = self.yres = float(p.resolution) if p.resolution else None
        self.modes = sorted(p.modes_used)
        self.warnings = p.warnings
        self._closed = False

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8)

    def _open(self):
        try:
            return open(self.path, "rb")
        except OSError as e:
            raise ImageError(self.path, f"cannot read file: {e.strerror or e}") from None

    def _check(self, rows: int) -> int:
        if self._closed:
            raise ValueError(f"{self.path}: RTL source is closed")
        rows = int(rows)
        if rows < 1:
            raise ValueError("rows must be >= 1")
        return rows

    # -- rows -----------------------------------------------------------------------------
    def _rows(self) -> Iterator[tuple]:
        """(row, count): row is the next row in the output layout (packed (4, RB) for 1-bit,
        (W, channels) pixels for contone) or None for blank rows."""
        p = _Parser(self.path)
        W = self.width
        if self.prescreened:
            out = np.zeros((4, (W + 7) // 8), np.uint8)
        else:
            out = np.zeros((W, self.channels), np.uint8)
        with self._open() as f:
            for ev, n in p.events(f, self.size):
                if ev == "block":
                    continue
                if ev == "blank":
                    yield None, n
                    continue
                if self.prescreened:
                    out[:] = 0
                    rb = p.seeds.shape[1]
                    mask = _bit_mask(p.width)
                    for plane, (ch, inv) in enumerate(p.cfg.planes):
                        row = out[ch, :rb]
                        if inv:
                            np.invert(p.seeds[plane], out=row)
                        else:
                            row[:] = p.seeds[plane]
                        row[rb - 1] &= mask
                else:
                    w = p.width
                    pix = p.seeds[0].reshape(w, 3)
                    if self.channels == 3:
                        out[:w] = pix
                        out[w:] = 255
                    else:
                        out[:w, :3] = pix
                        out[w:] = 0
                yield out, n

    def _banded(self, rows: int, blank_value: int, shape_row: tuple) -> Iterator[np.ndarray]:
        band = np.empty((rows, *shape_row), np.uint8)
        fill = 0
        for row, n in self._rows():
            while n:
                k = min(n, rows - fill)
                if row is None:
                    band[fill: fill + k] = blank_value
                else:
                    band[fill: fill + k] = row
                fill += k
                n -= k
                if fill == rows:
                    yield band
                    band = np.empty((rows, *shape_row), np.uint8)
                    fill = 0
        if fill:
            yield band[:fill]

    def packed_bands(self, rows: int = 256) -> Iterator[np.ndarray]:
        """1-bit raster as packed bits (h, 4, ceil(W / 8)), x = 0 in bit 7 of byte 0."""
        rows = self._check(rows)
        if not self.prescreened:
            raise ValueError(f"{self.path}: contone RTL has no dots")
        return self._banded(rows, 0, (4, (self.width + 7) // 8))

    def bands(self, rows: int = 256) -> Iterator[np.ndarray]:
        rows = self._check(rows)
        if self.prescreened:
            from .swath import unpack_dots
            return (unpack_dots(b, self.width) for b in self.packed_bands(rows))
        blank = 255 if self.channels == 3 else 0
        return self._banded(rows, blank, (self.width, self.channels))

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> "RtlSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        kind = "1-bit" if self.prescreened else f"contone {self.contone_space.upper()}"
        return (f"RtlSource({self.path!r}, {self.width} x {self.height} px, {kind}, "
                f"{self.resolution or '?'} dpi, modes {self.modes})")


def open_rtl(path, settings, profile):
    """The RTL file on the device grid: 1-bit raster dot for dot (turned or mirrored if asked),
    contone raster placed like an image."""
    from .place import place
    src = RtlSource(path)
    pl = settings.placement
    if not src.prescreened:
        try:
            return place(src, pl, settings.dpi, profile.row_um)
        except ValueError as exc:
            raise ValueError(f"{src.path}: {exc}") from None
    sized = [n for n in ("width_mm", "height_mm", "scale", "fit_width_mm") if getattr(pl, n) is not None]
    if sized:
        raise ImageError(src.path, f"this RTL file is halftoned already (1 bit per dot): it prints dot for "
                                   f"dot and cannot be resized ({', '.join(sized)})")
    if src.resolution and src.resolution != settings.dpi:
        modes = tuple(profile.dpi_modes)
        hint = (f"print it with --dpi {src.resolution}" if src.resolution in modes else
                f"the printer's modes are {', '.join(map(str, modes))} dpi")
        raise ImageError(src.path, f"this RTL file is halftoned at {src.resolution} dpi and prints dot for "
                                   f"dot, but the job is at {settings.dpi} dpi: {hint}")
    try:
        placed = place(src, replace(pl, size="pixels"), settings.dpi, profile.row_um)
    except ValueError as exc:
        raise ValueError(f"{src.path}: {exc}") from None
    if placed is not src:
        placed.prescreened = True        # turned or mirrored 0/1 dots are still dots
    return placed
