"""The test suite's own HP RTL writer (docs/rtl.md): planes or contone pixels -> RTL bytes,
in every compression mode the reader supports, with both colour configurations (simple
colour ESC*r#U and configure image data ESC*v#W).  Written from the PCL/RTL descriptions,
independently of rip/rtl.py, so the reader is checked against a second implementation."""

from __future__ import annotations

import numpy as np

ESC = b"\x1b"

# configuration -> (set-up bytes, plane order as (channel, inverted) with C, M, Y, K = 0..3)
CONFIGS = {
    "simple-k": (ESC + b"*r1U", ((3, False),)),
    "simple-rgb": (ESC + b"*r3U", ((0, True), (1, True), (2, True))),
    "simple-cmy": (ESC + b"*r-3U", ((0, False), (1, False), (2, False))),
    "simple-kcmy": (ESC + b"*r-4U", ((3, False), (0, False), (1, False), (2, False))),
    "cid-kcmy": (ESC + b"*v6W" + bytes([1, 0, 4, 1, 1, 1]), ((3, False), (0, False), (1, False), (2, False))),
    "cid-cmy": (ESC + b"*v6W" + bytes([1, 0, 3, 8, 8, 8]), ((0, False), (1, False), (2, False))),
    "cid-rgb-direct": (ESC + b"*v6W" + bytes([0, 2, 1, 1, 1, 1]), ((0, True), (1, True), (2, True))),
    "cid-k": (ESC + b"*v6W" + bytes([0, 0, 1, 1, 1, 1]), ((3, False),)),
}


def rle(row: bytes) -> bytes:
    """Mode 1: (count - 1, byte) pairs."""
    out = bytearray()
    i, n = 0, len(row)
    while i < n:
        j = i
        while j < n and j - i < 256 and row[j] == row[i]:
            j += 1
        out += bytes([j - i - 1, row[i]])
        i = j
    return bytes(out)


def packbits(row: bytes) -> bytes:
    """Mode 2: TIFF PackBits."""
    out = bytearray()
    i, n = 0, len(row)
    while i < n:
        j = i
        while j < n and j - i < 128 and row[j] == row[i]:
            j += 1
        if j - i >= 3:
            out += bytes([257 - (j - i), row[i]])
            i = j
            continue
        k = i
        while k < n and k - i < 128:
            if k + 2 < n and row[k] == row[k + 1] == row[k + 2]:
                break
            k += 1
        out += bytes([k - i - 1]) + row[i:k]
        i = k
    return bytes(out)


def delta(row: bytes, seed: bytes) -> bytes:
    """Mode 3: replacements of up to 8 bytes against the seed row, offsets relative to the
    byte after the previous replacement (31 and more: extension bytes)."""
    out = bytearray()
    pos = 0
    i, n = 0, len(row)
    while i < n:
        if row[i] == seed[i]:
            i += 1
            continue
        j = i
        while j < n and j - i < 8 and row[j] != seed[j]:
            j += 1
        off, cnt = i - pos, j - i
        if off < 31:
            out.append(((cnt - 1) << 5) | off)
        else:
            out.append(((cnt - 1) << 5) | 31)
            rest = off - 31
            while rest >= 255:
                out.append(255)
                rest -= 255
            out.append(rest)
        out += row[i:j]
        pos = j
        i = j
    return bytes(out)


def strip_zeros(row: bytes) -> bytes:
    return row.rstrip(b"\x00")


def _compress(mode: int, row: bytes, seed: bytes) -> bytes:
    if mode == 0:
        return strip_zeros(row)         # short rows are zero-filled by the reader
    if mode == 1:
        return rle(strip_zeros(row))
    if mode == 2:
        return packbits(strip_zeros(row))
    return delta(row, seed)


def planes_of(dots: np.ndarray, config: str) -> list[np.ndarray]:
    """(h, w, 4) 0/1 dots -> the configuration's packed plane rows (h, ceil(w/8)) each."""
    _, order = CONFIGS[config]
    w = dots.shape[1]
    out = []
    for ch, inv in order:
        bits = dots[..., ch].astype(np.uint8)
        if inv:
            bits = 1 - bits
        p = np.packbits(bits, axis=1)
        if inv and w % 8:               # pad bits past the width: zero
            p[:, -1] &= (0xFF << (8 - w % 8)) & 0xFF
        out.append(p)
    return out


def expected_dots(dots: np.ndarray, config: str) -> np.ndarray:
    """What the configuration can express of `dots` (inks it lacks are dropped)."""
    _, order = CONFIGS[config]
    keep = np.zeros(4, bool)
    for ch, _ in order:
        keep[ch] = True
    return (dots * keep).astype(np.uint8)


def encode_bits(dots: np.ndarray, config: str = "simple-kcmy", mode: int = 2, resolution: int | None = 300,
                *, header: bool = True, hpgl: bool = True, yoffset: bool = True, combine: bool = False,
                blocks: int = 1) -> bytes:
    """1-bit RTL of (h, w, 4) 0/1 dots: plane rows with ESC*b#V ... ESC*b#W; blank rows as
    ESC*b#Y (when `yoffset`); mode 5 packs rows into adaptive blocks (single plane only)."""
    setup, order = CONFIGS[config]
    h, w = dots.shape[:2]
    planes = planes_of(dots, config)
    ink = expected_dots(dots, config)
    out = bytearray()
    if header:
        out += ESC + b"%-12345X@PJL JOB NAME=\"test\"\r\n@PJL ENTER LANGUAGE=RTL\r\n"
    out += ESC + b"E"
    if hpgl:
        out += ESC + b"%0BIN;SP1;PU0,0;PD100,100;PU;SP0;" + ESC + b"%0A"
    out += setup
    if resolution:
        out += ESC + b"*t%dR" % resolution
    out += ESC + b"*r%dS" % w
    cuts = np.linspace(0, h, blocks + 1).astype(int)
    for b in range(blocks):
        out += ESC + b"*r1A"
        if mode != 5:
            out += ESC + b"*b%dM" % mode if not combine else b""
        seeds = [bytes(len(p[0])) for p in planes]
        y = cuts[b]
        if mode == 5:
            assert len(planes) == 1, "adaptive compression needs a single plane"
            out += ESC + b"*b5M" + _adaptive(planes[0][cuts[b]:cuts[b + 1]])
            out += ESC + b"*rC"
            continue
        while y < cuts[b + 1]:
            if yoffset and not ink[y].any():
                n = 0
                while y + n < cuts[b + 1] and not ink[y + n].any():
                    n += 1
                out += ESC + b"*b%dY" % n
                seeds = [bytes(len(p[0])) for p in planes]
                y += n
                continue
            for i, p in enumerate(planes):
                row = p[y].tobytes()
                data = _compress(mode, row, seeds[i])
                seeds[i] = row
                last = i == len(planes) - 1
                cmd = b"W" if last else b"V"
                if combine:
                    out += ESC + b"*b%dm%d" % (mode, len(data)) + cmd + data
                else:
                    out += ESC + b"*b%d" % len(data) + cmd + data
            y += 1
        out += ESC + b"*rC"
    out += ESC + b"E"
    if header:
        out += ESC + b"%-12345X@PJL EOJ\r\n" + ESC + b"%-12345X"
    return bytes(out)


def _adaptive(rows: np.ndarray) -> bytes:
    """Mode 5 blocks (each at most 32767 bytes) of single-plane rows: empty runs (4),
    repeats (5), and the rows themselves in methods 0..3 by turns."""
    blocks: list[bytes] = []
    cur = bytearray()
    seed = bytes(rows.shape[1])
    prev = None
    i, n = 0, rows.shape[0]
    turn = 0

    def add(elem: bytes):
        nonlocal cur
        if len(cur) + len(elem) > 32767:
            blocks.append(bytes(cur))
            cur = bytearray()
        cur += elem
    while i < n:
        row = rows[i].tobytes()
        if not rows[i].any():
            k = 0
            while i + k < n and not rows[i + k].any() and k < 65535:
                k += 1
            add(bytes([4, k >> 8, k & 255]))
            seed, prev = bytes(rows.shape[1]), None
            i += k
            continue
        if prev is not None and row == prev:
            k = 0
            while i + k < n and rows[i + k].tobytes() == prev and k < 65535:
                k += 1
            add(bytes([5, k >> 8, k & 255]))
            i += k
            continue
        method = turn % 4
        turn += 1
        data = _compress(method, row, seed)
        add(bytes([method, len(data) >> 8, len(data) & 255]) + data)
        seed = prev = row
        i += 1
    if cur:
        blocks.append(bytes(cur))
    return b"".join(ESC + b"*b%dW" % len(bl) + bl for bl in blocks)


def encode_contone(pixels: np.ndarray, space: str = "rgb", mode: int = 2, resolution: int | None = 150,
                   yoffset_rows: int = 0) -> bytes:
    """Contone RTL: configure image data direct by pixel, 8 bits per component, RGB or CMY
    (h, w, 3); `yoffset_rows` blank rows (ESC*b#Y) before the image."""
    h, w = pixels.shape[:2]
    out = bytearray(ESC + b"E")
    out += ESC + b"*v6W" + bytes([0 if space == "rgb" else 1, 3, 8, 8, 8, 8])
    if resolution:
        out += ESC + b"*t%dR" % resolution
    out += ESC + b"*r%dS" % w + ESC + b"*r1A"
    if yoffset_rows:
        out += ESC + b"*b%dY" % yoffset_rows
    if mode == 5:
        out += ESC + b"*b5M" + _adaptive(pixels.reshape(h, w * 3))
    else:
        out += ESC + b"*b%dM" % mode
        seed = bytes(w * 3)
        for y in range(h):
            row = pixels[y].tobytes()
            data = _compress(mode, row, seed) if mode == 3 else {0: row, 1: rle(row), 2: packbits(row)}[mode]
            seed = row
            out += ESC + b"*b%dW" % len(data) + data
    out += ESC + b"*rC" + ESC + b"E"
    return bytes(out)
