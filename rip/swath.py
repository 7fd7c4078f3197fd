"""Swath and stroke planner: halftone rows -> per-stroke, per-head 128-bit nozzle words.

Words (docs/architecture.md): a *pass* is one interleave pass of the weave (the `passes`
setting: every row is printed by N passes, each with other nozzles); a *stroke* is one
movement of the carriage printing one swath.  The planner turns the weave's N passes into
the job's strokes: stroke i prints pass j of the rows it covers.

The geometry is docs/geometry.md; in short, with N passes and A rows of paper advance:
- a colour's heads print swath slots 0 .. swath_rows-1; only the profile's usable run
  [s0, s0 + N*A) is used (nozzles 0 and 127 never fire);
- stroke i has image row T_i = (i - N + 1) * A - s0 under slot 0, so every image row is
  under the usable run in exactly N consecutive strokes i = floor(r/A) + j, j = 0 .. N-1
  (the row's pass j of the weave), at slot (r mod A) + (N - 1 - j) * A + s0;
- the pass mask gives each dot one j (checker: (x + r) mod N; random: blue-noise ranks
  split evenly; feather: blue-noise ranks split by weights that fall off towards the ends
  of the nozzle run, hiding stroke-boundary banding; shingle: the same with raised-cosine
  shares over a measured taper per pass count, `shingle_weights`); a dot whose slot is a dead nozzle
  moves to the next live j (nozzle-out compensation), so no dot is lost or doubled;
- head h fires image column x at trigger column x - x_h / k (k = counts per column);
  reverse strokes fire in descending columns, shifted by the profile's bidir offset; the
  calibration's whole-column head shifts are added per direction (docs/calibration.md).
Memory: a rolling window of N*A rows plus one input band.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from .compiled import kernel

from .parallel import run_parallel, split
from .planes import INK_SHIFT
from .profile import COLORS, Profile, ProfileError

from .settings import PASS_COUNTS, PASS_MASKS  # noqa: F401 - declared with the settings schema
MASK_LEVELS = 256           # quantisation of the random / feather / shingle masks
FEATHER = 0.25              # fraction of the nozzle run, at each end, that fades out
#: shingle: the raised-cosine taper at each end of the nozzle run, in advances (A rows), per
#: pass count; measured against the banding of the typical machine (docs/rip.md "Pass
#: masks", bench/banding_bench.py)
SHINGLE_TAPER = {2: 1.0, 3: 1.0, 4: 1.0, 6: 1.0, 8: 1.0}


def top_margin_rows(profile: Profile, settings) -> int:
    """The job's top margin in rows (placement top_mm): the driver feeds stroke i to
    `feed_steps_for_rows(i A + top_margin_rows)` (driver/job.py), the hiding mask plans for it."""
    return int(round(float(settings.placement.top_mm) * 1000 / profile.row_um))


@dataclass
class StrokeData:
    index: int            # stroke number in the job, 0-based (blank strokes keep their number)
    direction: int        # 0 forward, 1 reverse
    top_row: int          # image row under swath slot 0
    first_column: int     # lowest trigger column, relative to the job origin x0 / k
    words: np.ndarray     # uint16 (heads, fires, 8), firing order
    dots: np.ndarray      # drops per colour (4,)

    @property
    def fires(self) -> int:
        return self.words.shape[1]


class StrokePlanner:
    """Plans the carriage strokes of a job from the weave's passes (N = `passes`)."""

    def __init__(self, profile: Profile, width: int, height: int, dpi: int, passes: int = 1,
                 bidir: bool = False, mask: str = "checker", dead_rows_empty: bool = False,
                 top_rows: int = 0):
        if passes not in PASS_COUNTS:
            raise ValueError(f"passes must be one of {PASS_COUNTS}, not {passes}")
        if mask not in PASS_MASKS:
            raise ValueError(f"pass mask must be one of {PASS_MASKS}, not {mask!r}")
        self.profile, self.width, self.height, self.dpi = profile, width, height, dpi
        self.k = profile.k(dpi)
        self.n = passes
        self.bidir = bidir
        s0, s1 = profile.usable_slots()
        self.s0 = s0
        self.advance = (s1 - s0) // passes
        if self.advance < 1:
            raise ProfileError(f"{profile.path}: too few usable nozzles for {passes} passes")
        self.total_strokes = -(-height // self.advance) + passes - 1
        self._slot_table = profile.slot_table()
        # dead_rows_empty: the halftone has no dots in rows only dead nozzles print (the
        # RIP moved them to the neighbour rows: rip/deadrows.py), so those rows need no
        # live nozzle
        self._dead_rows_empty = dead_rows_empty
        self._remap = self._dead_nozzle_remap()
        self.mask = mask
        # the job's top margin (driver/job.py `top_rows`): the driver feeds stroke i to
        # `feed_steps_for_rows(i A + top_rows)`, whose rounding the hiding shares follow
        self.top_rows = int(top_rows)
        self._stroke_masks = None           # hiding: the selection per stroke (rip/hiding.py)
        self._qmask, self._sel = self._pass_mask(mask)
        self._mask_rows, self._mask_index = self._mask_bit_rows()
        # whole 8 x 8 blocks of dots move at once (`_pack_stroke_blocks`); the per-dot kernel
        # gives the same words (tests/test_screen.py switches this off to compare)
        self.block_pack = True
        hpc = profile.heads_per_color
        # per head: nozzle -> slot
        self._head_slots = [h.y_rows + hpc * np.arange(profile.nozzles) for h in profile.heads]
        # trigger column of image column 0, per direction and head: x_counts / k less the
        # calibration's whole-column shift (the bidir offset is the reverse strokes'; the
        # rest of the shift is the driver's fire delay, docs/calibration.md)
        shift, _ = profile.fire_shift(dpi)
        base = np.array([h.x_counts // self.k for h in profile.heads], np.int64)
        self._head_cols = [base - shift[0], base - shift[1]]
        # rolling window of halftone rows: rows [self._base, self._base + self._len) held in
        # one preallocated buffer that grows only if a band is taller than any before, as
        # bits (rows, colour, width / 8): a 40,000 px wide window is 8x smaller than bytes
        self._wbytes = -(-width // 8)
        self._store = np.zeros((0, 4, self._wbytes), np.uint8)
        self._len = 0
        self._base = 0
        self._next_stroke = 0
        self._printed = 0
        self._rows_in = 0

    # -- geometry helpers (also used by tests and the driver) --------------------------
    def top_row(self, i: int) -> int:
        """Image row under swath slot 0 at stroke i."""
        return (i - self.n + 1) * self.advance - self.s0

    @property
    def y0_rows(self) -> int:
        """Paper row of image row 0, counted from swath slot 0 at the first stroke."""
        return -self.top_row(0)

    def _dead_nozzle_remap(self) -> np.ndarray:
        """(4, A, N) -> the j that prints a dot whose mask says j, for rows r mod A."""
        n, a = self.n, self.advance
        rho = np.arange(a)[:, None]
        j = np.arange(n)[None, :]
        slots = rho + (n - 1 - j) * a + self.s0                    # (A, N)
        alive = self._slot_table[:, slots, 0] >= 0                   # (4, A, N)
        remap = np.empty((len(COLORS), a, n), np.int16)
        for c in range(len(COLORS)):
            for r in range(a):
                live = np.flatnonzero(alive[c, r])
                if live.size == 0 and self._dead_rows_empty:
                    remap[c, r] = np.arange(n)       # no dots there: nothing to remap
                    continue
                if live.size == 0:
                    dead = [f"{self.profile.heads[h].name}:{z}" for h, z in
                            (tuple(self._slot_table_dead(c, int(s))) for s in slots[r])]
                    raise ProfileError(
                        f"{self.profile.path}: dead nozzles {', '.join(dead)} leave colour "
                        f"{COLORS[c]} rows unprintable with {n} pass(es); use more passes")
                for jj in range(n):
                    # first live j at or after jj, cyclically
                    later = live[live >= jj]
                    remap[c, r, jj] = later[0] if later.size else live[0]
        return remap

    def dead_row_phases(self) -> list[np.ndarray]:
        """Per colour, the row phases r mod A that no live nozzle prints in any pass of the
        weave (only with 1 pass, or dead nozzles lined up across every pass)."""
        n, a = self.n, self.advance
        rho = np.arange(a)[:, None]
        j = np.arange(n)[None, :]
        slots = rho + (n - 1 - j) * a + self.s0
        alive = self._slot_table[:, slots, 0] >= 0                    # (4, A, N)
        return [np.flatnonzero(~alive[c].any(axis=1)) for c in range(len(COLORS))]

    def _slot_table_dead(self, c: int, slot: int) -> tuple[int, int]:
        for h in self.profile.heads:
            if h.channel == c:
                z, rem = divmod(slot - h.y_rows, self.profile.heads_per_color)
                if rem == 0 and 0 <= z < self.profile.nozzles:
                    return h.index, z
        return -1, -1

    def _pass_mask(self, mask: str) -> tuple[np.ndarray, np.ndarray]:
        """A tile of mask levels q and, per colour and row phase, the j each level selects
        (dead-nozzle remap included): j(r, x) = sel[c, r mod A, qmask[r mod th, x mod tw]]."""
        n, a = self.n, self.advance
        if mask == "checker":
            t = np.arange(24)                       # 24 = lcm of the pass counts
            qmask = ((t[:, None] + t[None, :]) % n).astype(np.int16)
            jsel = np.broadcast_to(np.arange(n), (a, n))
        else:
            from .halftone import load_bluenoise_mask
            ranks = load_bluenoise_mask()
            qmask = (ranks.astype(np.int64) * MASK_LEVELS // ranks.size).astype(np.int16)
            u = (np.arange(MASK_LEVELS) + 0.5) / MASK_LEVELS
            if mask == "hiding":
                # the measured nozzles' shares per block of strokes and colour
                # (rip/hiding.py); no measurement stored is an error naming `calibrate
                # nozzles`, never another mask.  `_sel` is the first class's (the selection
                # of a stroke is `_stroke_mask`'s)
                from .hiding import stroke_masks
                masks = self._stroke_masks = stroke_masks(self.profile, n, self._remap, self.top_rows)
                return masks.qmask, masks.sel[0]
            if mask == "hiding-rows":
                # the same measurement, shares per colour and row phase held towards equal
                # ones by the feeds' RMS rounding error (rip/hiding.py `hiding_shares`)
                from .hiding import hiding_shares
                weights = hiding_shares(self.profile, n)
            elif mask == "random" or n == 1:
                weights = np.ones((a, n))
            elif mask == "shingle":
                weights = shingle_weights(n, a)
            else:
                # position of each (row phase, j) slot in the used run, 0..1
                rho = np.arange(a)[:, None]
                j = np.arange(n)[None, :]
                pos = (rho + (n - 1 - j) * a + 0.5) / (n * a)
                weights = np.clip(np.minimum(pos, 1 - pos) / FEATHER, 0.05, 1.0)
            cum = np.cumsum(weights / weights.sum(axis=-1, keepdims=True), axis=-1)
            jsel = np.minimum((u[:, None] > cum[..., None, :]).sum(axis=-1), n - 1)
        sel = np.empty((len(COLORS), a, jsel.shape[-1]), np.int16)
        for c in range(len(COLORS)):
            js = jsel[c] if jsel.ndim == 3 else jsel          # hiding: per colour
            sel[c] = np.take_along_axis(self._remap[c], np.asarray(js, np.int64), axis=1)
        return np.ascontiguousarray(qmask), sel

    def _mask_bit_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The pass mask as packed bits, for the block packer: rows (U, th, N, tw / 8) and
        index (4, A) such that bit x (x = 0 in bit 7 of byte 0, repeating every tw columns)
        of rows[index[c, r mod A], r mod th, j] is set where the mask gives the dot at
        (r, x) of colour c to pass j of the weave.  Colours and row phases whose selection
        is the same share a row set (without dead nozzles or feathering there is one)."""
        th, tw = self._qmask.shape
        assert tw % 8 == 0, "the pass mask tile must be whole bytes wide"
        if self._stroke_masks is not None:
            return self._stroke_masks.rows, self._stroke_masks.index[0]
        sel = self._sel.reshape(-1, self._sel.shape[-1])               # (4 * A, levels)
        unique, index = np.unique(sel, axis=0, return_inverse=True)
        rows = np.empty((len(unique), th, self.n, tw // 8), np.uint8)
        j = np.arange(self.n, dtype=np.int16)[None, :, None]
        for u, srow in enumerate(unique):
            jsel = srow[self._qmask]                                  # (th, tw): j of each dot
            rows[u] = np.packbits(jsel[:, None, :] == j, axis=-1)
        return rows, index.reshape(self._sel.shape[:2]).astype(np.int64)

    def _stroke_mask(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stroke i's selection: (mask rows, mask index, sel) as `_mask_bit_rows` and
        `_pass_mask` give them, the index and sel per colour and image row modulo their
        length: the same for every stroke, per row phase (r mod A).  The hiding shares
        (per stroke, rip/stroke_hiding.py) give the N A rows of a stroke their own (r mod N A)."""
        if self._stroke_masks is not None:
            return self._stroke_masks(i)
        return self._mask_rows, self._mask_index, self._sel

    # -- streaming ----------------------------------------------------------------------
    def feed(self, band: np.ndarray) -> list[StrokeData]:
        """Add the next halftone rows (h, W, 4) of 0/1; returns the strokes now complete."""
        if band.shape[1:] != (self.width, 4):
            raise ValueError(f"band must be (h, {self.width}, 4)")
        pack_dots(band, self._window_rows(band.shape[0]))
        return self._emit(final=False)

    def feed_packed(self, bits: np.ndarray) -> list[StrokeData]:
        """Add the next halftone rows as packed bits (h, 4, ceil(W / 8)) (`pack_dots`)."""
        if bits.shape[1:] != (4, self._wbytes) or bits.dtype != np.uint8:
            raise ValueError(f"packed band must be uint8 (h, 4, {self._wbytes})")
        self._window_rows(bits.shape[0])[:] = bits
        return self._emit(final=False)

    def _window_rows(self, n: int) -> np.ndarray:
        """The next n rows of the window, to be filled by the caller."""
        if self._len + n > self._store.shape[0]:
            store = np.empty((self._len + 2 * n, 4, self._wbytes), np.uint8)
            store[:self._len] = self._store[:self._len]
            self._store = store
        rows = self._store[self._len:self._len + n]
        self._len += n
        self._rows_in += n
        return rows

    @property
    def _buf(self) -> np.ndarray:
        """The window's packed bits (rows, 4, width / 8)."""
        return self._store[:self._len]

    def finish(self) -> list[StrokeData]:
        if self._rows_in != self.height:
            raise ValueError(f"got {self._rows_in} rows, expected {self.height}")
        return self._emit(final=True)

    def _emit(self, final: bool) -> list[StrokeData]:
        out = []
        while self._next_stroke < self.total_strokes:
            i = self._next_stroke
            need = min((i + 1) * self.advance, self.height)
            if self._rows_in < need and not final:
                break
            data = self._build(i)
            self._next_stroke += 1
            if data is not None:
                out.append(data)
            # drop rows no later stroke needs
            keep_from = max(0, (self._next_stroke - self.n + 1) * self.advance)
            if keep_from > self._base:
                drop = min(keep_from - self._base, self._len)
                self._store[:self._len - drop] = self._store[drop:self._len]   # in place
                self._len -= drop
                self._base = keep_from
        return out

    def _build(self, i: int) -> StrokeData | None:
        top = self.top_row(i)
        lo = max(0, top + self.s0)
        hi = min(self.height, top + self.s0 + self.n * self.advance)
        if hi <= lo:
            return None
        heads = self.profile.heads
        direction = (self._printed % 2) if self.bidir else 0     # if this stroke prints
        cols = self._head_cols[direction]
        spread_lo = -int(cols.max())                  # trigger column of image column 0, farthest head
        fires_all = self.width + int(cols.max() - cols.min())
        words = np.zeros((len(heads), fires_all, 8), np.uint16)
        channel = np.array([h.channel for h in heads])
        y_rows = np.array([h.y_rows for h in heads])
        parts = split(len(heads))
        dots_parts = np.zeros((len(parts), 4), np.int64)
        spans = np.array([[fires_all, 0]] * len(parts), np.int64)   # fires with a dot: [lo, hi)
        hpc = self.profile.heads_per_color
        mask_rows, mask_index, sel = self._stroke_mask(i)
        if self.block_pack:
            words8 = words.view(np.uint8)                   # (heads, fires, 16), little-endian
            run_parallel(
                (lambda w=w, a=a, b=b: _pack_stroke_blocks(
                    self._buf, self.width, self._base, lo, hi, top, i, self.advance, self.n,
                    self.s0, mask_rows, mask_index, self._slot_table, channel,
                    y_rows, cols, hpc, spread_lo, a, b, words8, dots_parts[w], spans[w]))
                for w, (a, b) in enumerate(parts))
        else:
            run_parallel(
                (lambda w=w, a=a, b=b: _pack_stroke(
                    self._buf, self.width, self._base, lo, hi, top, i, self.advance, self.n,
                    self.s0, self._qmask, sel, self._slot_table, channel, y_rows, cols,
                    hpc, spread_lo, a, b, words, dots_parts[w], spans[w]))
                for w, (a, b) in enumerate(parts))
        dots = dots_parts.sum(axis=0)
        t0, t1 = int(spans[:, 0].min()), int(spans[:, 1].max())
        if t1 <= t0:
            return None
        words = words[:, t0:t1]
        self._printed += 1
        first = spread_lo + t0
        if direction == 1:
            words = words[:, ::-1]
        return StrokeData(i, direction, top, first, np.ascontiguousarray(words), dots)


def shingle_weights(n: int, a: int, taper: float | None = None) -> np.ndarray:
    """(A, N) each pass's share of the rows of phase r mod A (docs/rip.md "Pass masks"):
    the nozzle run's share rises and falls as a raised cosine over `taper` advances at each
    end (SHINGLE_TAPER), flat between, so a row's passes hand over smoothly from stroke to
    stroke and a feed error's step is spread over the taper; rows normalised to 1."""
    taper = SHINGLE_TAPER.get(n, 1.0) if taper is None else taper
    t = max(taper * a, 1e-9)
    rho = np.arange(a)[:, None]
    j = np.arange(n)[None, :]
    s = rho + (n - 1 - j) * a + 0.5                      # the slot in the used run, 0..N A
    edge = np.minimum(s, n * a - s)                      # distance from the run's nearer end
    w = np.where(edge < t, 0.5 - 0.5 * np.cos(np.pi * np.minimum(edge / t, 1.0)), 1.0)
    return w / w.sum(axis=1, keepdims=True)


def pack_dots(band: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Halftone dots (h, W, 4) 0/1 -> packed bits (h, 4, ceil(W / 8)), x = 0 in bit 7 of
    byte 0 (np.packbits order): the planner window's layout."""
    band = np.ascontiguousarray(band)
    if out is None:
        out = np.empty((band.shape[0], 4, -(-band.shape[1] // 8)), np.uint8)
    _pack_bits(band, out)
    return out


def unpack_dots(bits: np.ndarray, width: int) -> np.ndarray:
    """Packed bits (h, 4, ceil(W / 8)) -> dots (h, W, 4) uint8 0/1."""
    dots = np.unpackbits(bits, axis=2, count=width)          # (h, 4, W)
    return np.ascontiguousarray(dots.transpose(0, 2, 1))


@kernel()
def _pack_bits(band, out):
    """(rows, width, 4) dots -> (rows, 4, width/8) bits, x = 0 in bit 7 of byte 0; any
    non-zero value is a dot.  Eight dots at a time for the four inks together: each dot
    as one uint32 of its 4 ink bytes (planes.INK_SHIFT), each byte folded to its bit 0,
    shifted into place and OR-ed, one lane per ink (no lane can carry into the next):
    2.6x the speed of a bit per ink and dot (1.66 -> 0.63 ns a dot)."""
    rows, width = band.shape[0], band.shape[1]
    full = width // 8
    m1 = np.uint32(0x01010101)
    l0, l1, l2, l3 = (np.uint32(INK_SHIFT[0]), np.uint32(INK_SHIFT[1]), np.uint32(INK_SHIFT[2]),
                      np.uint32(INK_SHIFT[3]))
    ff = np.uint32(0xFF)
    for r in range(rows):
        px = band[r].reshape(-1).view(np.uint32)
        o0, o1, o2, o3 = out[r, 0], out[r, 1], out[r, 2], out[r, 3]
        for xb in range(full):
            acc = np.uint32(0)
            for i in range(8):
                x = px[xb * 8 + i]
                x |= x >> np.uint32(4)           # bit 0 of each byte: any of its bits
                x |= x >> np.uint32(2)
                x |= x >> np.uint32(1)
                acc |= (x & m1) << np.uint32(7 - i)
            o0[xb] = (acc >> l0) & ff
            o1[xb] = (acc >> l1) & ff
            o2[xb] = (acc >> l2) & ff
            o3[xb] = (acc >> l3) & ff
        for c in range(4):                        # the last, partial byte
            o = out[r, c]
            for xb in range(full, o.shape[0]):
                v = 0
                x0 = xb * 8
                for i in range(8):
                    x = x0 + i
                    if x < width and band[r, x, c]:
                        v |= 128 >> i
                o[xb] = v


@kernel(inline="always")
def _nozzle_row(h, z, ch, head_y, hpc, s0, n, advance, slot_table, top, lo, hi):
    """The image row nozzle z of head h prints in this stroke, or -1 (a nozzle outside the
    usable run, dead-end or dead, or a row outside [lo, hi))."""
    slot = head_y[h] + hpc * z
    if slot < s0 or slot >= s0 + n * advance or slot >= slot_table.shape[1]:
        return -1
    if slot_table[ch, slot, 0] != h:
        return -1
    r = top + slot
    if r < lo or r >= hi:
        return -1
    return r


@kernel(inline="always")
def _transpose8(x):
    """8x8 bit matrix in a uint64, byte k bit i -> byte i bit k (H. Warren, Hacker's
    Delight, 2nd ed., 7-3)."""
    t = (x ^ (x >> np.uint64(7))) & np.uint64(0x00AA00AA00AA00AA)
    x = x ^ t ^ (t << np.uint64(7))
    t = (x ^ (x >> np.uint64(14))) & np.uint64(0x0000CCCC0000CCCC)
    x = x ^ t ^ (t << np.uint64(14))
    t = (x ^ (x >> np.uint64(28))) & np.uint64(0x00000000F0F0F0F0)
    return x ^ t ^ (t << np.uint64(28))


@kernel(inline="always")
def _popcount(x):
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return np.int64((x * np.uint64(0x0101010101010101)) >> np.uint64(56))


@kernel()
def _pack_stroke_blocks(buf, width, base, lo, hi, top, i_stroke, advance, n, s0, mask_rows,
                        mask_index, slot_table, head_channel, head_y, head_col, hpc, spread_lo,
                        h0, h1, words8, dots, span):
    """Whole 8 x 8 blocks (8 nozzles x 8 columns) at once: each nozzle's byte of packed dots
    ANDed with its byte of the pass mask (the dots this stroke prints of that row: its pass
    j of the weave, `StrokePlanner._mask_bit_rows`), the 8 bytes transposed into the 8
    columns' bytes of nozzle bits.  words8 is the words array as bytes (heads, fires, 16): byte g of a fire
    holds nozzles 8g .. 8g+7, bit z & 7.  span [lo, hi) widens to the fires that got a dot.
    Same words as `_pack_stroke` (tests/test_screen.py)."""
    flat = buf.reshape(-1)                          # the window as bytes: row, colour, byte
    masks = mask_rows.reshape(-1)
    th, tb = mask_rows.shape[1], mask_rows.shape[3]
    wb = buf.shape[2]
    offs = np.empty(8, np.int64)
    moffs = np.empty(8, np.int64)
    for h in range(h0, h1):
        ch = head_channel[h]
        t_off = -head_col[h] - spread_lo
        count = 0
        for g in range(16):
            keep = np.uint64(0)
            for k in range(8):
                r = _nozzle_row(h, 8 * g + k, ch, head_y, hpc, s0, n, advance, slot_table,
                                top, lo, hi)
                rr = r if r >= 0 else lo                         # a real row, masked off
                offs[k] = ((rr - base) * 4 + ch) * wb
                j = i_stroke - rr // advance
                j = min(max(j, 0), n - 1)
                moffs[k] = ((mask_index[ch, rr % mask_index.shape[1]] * th + rr % th) * n + j) * tb
                if r >= 0:
                    keep |= np.uint64(0xFF) << np.uint64(8 * k)
            if keep == 0:
                continue
            o0, o1, o2, o3 = offs[0], offs[1], offs[2], offs[3]
            o4, o5, o6, o7 = offs[4], offs[5], offs[6], offs[7]
            m0, m1, m2, m3 = moffs[0], moffs[1], moffs[2], moffs[3]
            m4, m5, m6, m7 = moffs[4], moffs[5], moffs[6], moffs[7]
            first_xb = -1
            last_xb = -1
            first_x = np.uint64(0)
            last_x = np.uint64(0)
            mb = 0                                        # xb mod tb: the mask tile's byte
            for xb in range(wb):
                x = (np.uint64(flat[o0 + xb] & masks[m0 + mb])
                     | np.uint64(flat[o1 + xb] & masks[m1 + mb]) << np.uint64(8)
                     | np.uint64(flat[o2 + xb] & masks[m2 + mb]) << np.uint64(16)
                     | np.uint64(flat[o3 + xb] & masks[m3 + mb]) << np.uint64(24)
                     | np.uint64(flat[o4 + xb] & masks[m4 + mb]) << np.uint64(32)
                     | np.uint64(flat[o5 + xb] & masks[m5 + mb]) << np.uint64(40)
                     | np.uint64(flat[o6 + xb] & masks[m6 + mb]) << np.uint64(48)
                     | np.uint64(flat[o7 + xb] & masks[m7 + mb]) << np.uint64(56))
                mb += 1
                if mb == tb:
                    mb = 0
                x &= keep
                if x == 0:
                    continue
                count += _popcount(x)
                x = _transpose8(x)                 # byte c, bit k = nozzle k at column 7 - c
                if first_xb < 0:
                    first_xb = xb
                    first_x = x
                last_xb = xb
                last_x = x
                x0 = (xb << 3) + t_off
                if (xb << 3) + 8 <= width:         # no branch per column: zeros store too
                    for i in range(8):
                        words8[h, x0 + i, g] = np.uint8((x >> np.uint64(8 * (7 - i))) & np.uint64(0xFF))
                else:
                    for i in range(width - (xb << 3)):
                        words8[h, x0 + i, g] = np.uint8((x >> np.uint64(8 * (7 - i))) & np.uint64(0xFF))
            if first_xb >= 0:                      # the fires with a dot: exact columns
                i = 0
                while (first_x >> np.uint64(8 * (7 - i))) & np.uint64(0xFF) == 0:
                    i += 1
                span[0] = min(span[0], (first_xb << 3) + i + t_off)
                i = 7
                while (last_x >> np.uint64(8 * (7 - i))) & np.uint64(0xFF) == 0:
                    i -= 1
                span[1] = max(span[1], (last_xb << 3) + i + 1 + t_off)
        dots[ch] += count


@kernel()
def _pack_stroke(buf, width, base, lo, hi, top, i_stroke, advance, n, s0, qmask, sel,
                 slot_table, head_channel, head_y, head_col, hpc, spread_lo, h0, h1, words,
                 dots, span):
    """Set bit z of word (head, trigger column) for every dot of rows [lo, hi) that stroke
    i_stroke prints (docs/geometry.md): slot = y_rows + hpc*z, image row r = top + slot, the
    row's pass of the weave j = i_stroke - r // advance must equal the pass mask's
    (dead-nozzle remapped) j.
    span [lo, hi) widens to the fires that got a dot."""
    th, tw = qmask.shape
    for h in range(h0, h1):
        ch = head_channel[h]
        for z in range(128):
            r = _nozzle_row(h, z, ch, head_y, hpc, s0, n, advance, slot_table, top, lo, hi)
            if r < 0:
                continue
            j = i_stroke - r // advance
            row = r - base
            word = z >> 4
            bit = np.uint16(1 << (z & 15))
            t_off = -head_col[h] - spread_lo
            qrow = qmask[r % th]
            srow = sel[ch, r % sel.shape[1]]
            pix = buf[row, ch]                          # packed bits, x = 0 in bit 7
            out = words[h, :, word]
            count = 0
            first = -1
            last = -1
            for x0 in range(0, width, tw):             # whole mask tiles: no modulo per dot
                xe = min(width, x0 + tw)
                for x in range(x0, xe):
                    if (pix[x >> 3] >> (7 - (x & 7))) & 1 and srow[qrow[x - x0]] == j:
                        out[x + t_off] |= bit
                        count += 1
                        last = x
                        if first < 0:
                            first = x
            dots[ch] += count
            if count:
                span[0] = min(span[0], first + t_off)
                span[1] = max(span[1], last + 1 + t_off)
