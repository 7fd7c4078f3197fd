"""The dot coder: zlib streams of 8-bit tiles whose samples are all 0 or 1, made straight
from the packed rows (docs/formats.md, "The dot coder").

Why by hand: a general deflate (ISA-L, zlib-ng, libdeflate) spends its time searching for
matches in bytes that are nearly all 0 or 1 (0.55 ms a 256 KB tile of a print's media).
Here the samples are known to be bits, eight to a byte of the rows the planes writer
already holds (two dots' C, M, Y, K), so one table lookup gives a byte's eight literals'
code bits, and the only match worth finding is a repeat of the byte before: 0.05-0.4 ms a
tile by content (0.12 ms a dense one), the same size.  The code is fixed (one dynamic-Huffman block header, built once
here), so the coder is one pass that writes bits; any inflate reads the result.
"""

from __future__ import annotations

import numpy as np

from .compiled import kernel

__all__ = ["deflate_dot_tile"]

# RFC 1951 3.2.5: length symbols 257..285, their base lengths and extra bits
_LENGTH_BASE = (3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67,
                83, 99, 115, 131, 163, 195, 227, 258)
_LENGTH_EXTRA = (0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5,
                 5, 5, 0)
_CL_ORDER = (16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15)
_DISTANCE = 5           # distance symbol 5: distances 7..8, one extra bit (1 -> 8)
_MIN_RUN = 2            # repeats of the previous byte worth a match (16 samples)


def _code_lengths() -> tuple[list[int], list[int]]:
    """The literal/length and distance code lengths (docs/formats.md)."""
    lit = [0] * 286
    lit[0], lit[1] = 1, 2
    for s in range(256, 286):                # end of block and the length symbols
        lit[s] = 6 if s in (266, 285) else 7
    dist = [0, 0, 0, 0, 1, 1]                # 4 is unused: it makes the code complete
    return lit, dist


def _canonical(lengths: list[int]) -> list[int]:
    """Each symbol's code (RFC 1951 3.2.2), bit-reversed: deflate sends a Huffman code's
    first bit first into the low end of the bit stream."""
    top = max(lengths)
    count = [0] * (top + 1)
    for n in lengths:
        if n:
            count[n] += 1
    code, first = 0, [0] * (top + 1)
    for bits in range(1, top + 1):
        code = (code + count[bits - 1]) << 1
        first[bits] = code
    out = [0] * len(lengths)
    for sym, n in enumerate(lengths):
        if n:
            out[sym] = int(format(first[n], f"0{n}b")[::-1], 2)
            first[n] += 1
    return out


class _Bits:
    """Little-endian bit writer for the block header (built once, in Python)."""

    def __init__(self):
        self.value, self.count = 0, 0

    def put(self, value: int, bits: int) -> None:
        self.value |= value << self.count
        self.count += bits


def _block_header(lit: list[int], dist: list[int]) -> _Bits:
    """BFINAL, BTYPE 10 and the two codes, sent as code lengths through the code-length
    code (RFC 1951 3.2.7), runs as symbols 16 (repeat), 17 and 18 (zeros)."""
    seq = lit + dist
    symbols: list[tuple[int, int, int]] = []        # (symbol, extra value, extra bits)
    i = 0
    while i < len(seq):
        j = i
        while j < len(seq) and seq[j] == seq[i]:
            j += 1
        run, v = j - i, seq[i]
        if v == 0:
            while run >= 11:
                r = min(run, 138)
                symbols.append((18, r - 11, 7))
                run -= r
            if run >= 3:
                symbols.append((17, run - 3, 3))
                run = 0
        else:
            symbols.append((v, 0, 0))
            run -= 1
            while run >= 3:
                r = min(run, 6)
                symbols.append((16, r - 3, 2))
                run -= r
        symbols += [(v, 0, 0)] * run
        i = j
    used = sorted({s for s, _, _ in symbols})
    bits = max(1, (len(used) - 1).bit_length())
    short = (1 << bits) - len(used)                 # that many one bit shorter: complete
    cl = [0] * 19
    for k, s in enumerate(used):
        cl[s] = bits - 1 if k < short else bits
    hclen = 19
    while cl[_CL_ORDER[hclen - 1]] == 0:
        hclen -= 1
    out = _Bits()
    out.put(1, 1)                                   # BFINAL
    out.put(2, 2)                                   # BTYPE 10: dynamic Huffman codes
    out.put(len(lit) - 257, 5)
    out.put(len(dist) - 1, 5)
    out.put(hclen - 4, 4)
    for k in range(hclen):
        out.put(cl[_CL_ORDER[k]], 3)
    codes = _canonical(cl)
    for s, extra, nbits in symbols:
        out.put(codes[s], cl[s])
        out.put(extra, nbits)
    return out


def _tables():
    lit, dist = _code_lengths()
    lcode, dcode = _canonical(lit), _canonical(dist)
    head = _block_header(lit, dist)
    whole = head.count // 8
    start = bytes((0x78, 0x01)) + (head.value & ((1 << (8 * whole)) - 1)).to_bytes(whole, "little")
    # a packed byte (two dots, C M Y K each, the first dot's C in bit 7) -> its 8 literals
    byte_code = np.zeros(256, np.int64)
    byte_bits = np.zeros(256, np.int64)
    ones = np.zeros(256, np.int64)          # Adler-32: the byte's samples that are 1 ...
    offsets = np.zeros(256, np.int64)       # ... and the sum of their offsets in the byte
    for v in range(256):
        code = n = 0
        for k in range(8):
            bit = (v >> (7 - k)) & 1
            code |= lcode[bit] << n
            n += lit[bit]
            ones[v] += bit
            offsets[v] += k * bit
        byte_code[v], byte_bits[v] = code, n
    # a match of L bytes (3..258) at distance 8: length symbol, its extra bits, distance
    match_code = np.zeros(259, np.int64)
    match_bits = np.zeros(259, np.int64)
    for length in range(3, 259):
        s = 28 if length == 258 else max(i for i in range(28) if _LENGTH_BASE[i] <= length)
        code, n = lcode[257 + s], lit[257 + s]
        code |= (length - _LENGTH_BASE[s]) << n
        n += _LENGTH_EXTRA[s]
        code |= dcode[_DISTANCE] << n
        n += dist[_DISTANCE]
        code |= 1 << n                       # distance 7 + 1
        n += 1
        match_code[length], match_bits[length] = code, n
    return (np.frombuffer(start, np.uint8).copy(), head.value >> (8 * whole), head.count - 8 * whole,
            byte_code, byte_bits, ones, offsets, match_code, match_bits, lcode[256], lit[256])


(_START, _HEAD_TAIL, _HEAD_TAIL_BITS, _BYTE_CODE, _BYTE_BITS, _ONES, _OFFSETS, _MATCH_CODE,
 _MATCH_BITS, _EOB_CODE, _EOB_BITS) = _tables()


@kernel(inline="always")
def _put(out, o, acc, n, code, bits):
    acc |= code << n
    n += bits
    if n >= 32:
        out[o] = acc & 0xFF
        out[o + 1] = (acc >> 8) & 0xFF
        out[o + 2] = (acc >> 16) & 0xFF
        out[o + 3] = (acc >> 24) & 0xFF
        o += 4
        acc >>= 32
        n -= 32
    return o, acc, n


@kernel()
def _dot_deflate(nib, out, start, head_tail, head_bits, byte_code, byte_bits, ones, offsets,
                 match_code, match_bits, eob_code, eob_bits):  # pragma: no cover - compiled
    """nib: a tile's packed bytes, flat; out: room for 2 bytes each and 64 more.  Returns
    the stream's length."""
    o = 0
    for i in range(start.shape[0]):
        out[o] = start[i]
        o += 1
    acc = np.int64(head_tail)
    n = np.int64(head_bits)
    size = nib.shape[0]
    prev = np.int64(-1)
    run = np.int64(0)
    # Everything written out in this one loop, not through helpers: a helper that takes
    # the arrays cost numba's reference counting on each of them at every call (NRT_incref
    # and NRT_decref were ~30 % of the coder's samples; one tile 0.20 -> 0.15 ms without),
    # and an inlined tuple return 4x more.
    for j in range(size + 1):
        v = np.int64(nib[j]) if j < size else np.int64(-2)     # -2: the end, flushes a run
        if v == prev:
            run += 1
            continue
        if run >= _MIN_RUN:             # 8 x run samples as matches at distance 8
            left = run * 8
            while left > 0:             # pieces of at most 258, none shorter than 3
                if left >= 261 or left == 258:
                    m = 258
                elif left > 258:
                    m = left - 3
                else:
                    m = left
                acc |= match_code[m] << n
                n += match_bits[m]
                if n >= 32:
                    out[o] = acc & 0xFF
                    out[o + 1] = (acc >> 8) & 0xFF
                    out[o + 2] = (acc >> 16) & 0xFF
                    out[o + 3] = (acc >> 24) & 0xFF
                    o += 4
                    acc >>= 32
                    n -= 32
                left -= m
        elif run:                       # one repeat (1 in 10 bytes of a dense tile): a literal
            acc |= byte_code[prev] << n     # n < 32 + 16: the byte below fits the 64 bits too
            n += byte_bits[prev]
        run = 0
        if j == size:
            break
        acc |= byte_code[v] << n        # at most 16 bits a byte
        n += byte_bits[v]
        if n >= 32:
            out[o] = acc & 0xFF
            out[o + 1] = (acc >> 8) & 0xFF
            out[o + 2] = (acc >> 16) & 0xFF
            out[o + 3] = (acc >> 24) & 0xFF
            o += 4
            acc >>= 32
            n -= 32
        prev = v
    o, acc, n = _put(out, o, acc, n, np.int64(eob_code), np.int64(eob_bits))
    while n > 0:                       # the last bits, padded to a byte
        out[o] = acc & 0xFF
        o += 1
        acc >>= 8
        n = n - 8 if n > 8 else 0
    # Adler-32 of the samples (RFC 1950): A = 1 + their sum, B = the sum of A after each
    # sample = N + sum (N - i) s_i; a loop of its own (inside the coder's loop it cost ~45 %)
    total = np.int64(size) * 8
    a = np.int64(0)
    b = np.int64(0)
    for j in range(size):
        v = np.int64(nib[j])
        c = ones[v]
        a += c
        b += (total - 8 * j) * c - offsets[v]
    a = (a + 1) % 65521
    b = (b + total) % 65521
    out[o] = (b >> 8) & 0xFF
    out[o + 1] = b & 0xFF
    out[o + 2] = (a >> 8) & 0xFF
    out[o + 3] = a & 0xFF
    return o + 4


def deflate_dot_tile(packed: np.ndarray) -> bytes:
    """A zlib stream of the 8-bit samples that `packed` holds as bits (any shape, C-contiguous
    uint8, most significant bit first: np.unpackbits(packed) are the samples)."""
    flat = np.ascontiguousarray(packed, dtype=np.uint8).reshape(-1)
    out = np.empty(2 * flat.size + 64, np.uint8)
    size = _dot_deflate(flat, out, _START, _HEAD_TAIL, _HEAD_TAIL_BITS, _BYTE_CODE, _BYTE_BITS,
                        _ONES, _OFFSETS, _MATCH_CODE, _MATCH_BITS, _EOB_CODE, _EOB_BITS)
    return out[:size].tobytes()
