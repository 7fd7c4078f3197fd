"""The PCI card's FPGA: registers (seed table 4-7 plus extensions), the DMA ring, one FIFO
per head, and firing on encoder edges (docs/protocol.md sections 2.6, 2.7, 3).

All FIFOs of a line advance together (every block carries a part for every head in the
mask), so one level counter in fires describes them; words are kept per block.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from ..driver import protocol as P


@dataclass
class RingBlock:
    block: P.Block
    ready_s: float       # sim time at which the host had this block in its DMA buffer


class Fpga:
    def __init__(self, n_heads: int, fifo_words: int, pass_buffer_words: int, ring_blocks: int,
                 almost_empty_words: int = 64, block_words: int = 128):
        self.n_heads = n_heads
        self._absent_heads = (0,) * (8 - n_heads)      # their FIFO levels: always 0
        self.fifo_words = fifo_words
        self.pass_buffer_words = pass_buffer_words
        self.ring_blocks = ring_blocks
        self.almost_empty_words = almost_empty_words
        self.block_words = block_words
        self.regs = {P.REG_DIR: 1, P.REG_DPI: P.DPI_CODE[150], P.REG_WE_EN: 0,
                     P.REG_STROKE_LO: 0, P.REG_STROKE_HI: 0, P.REG_FIRE_START_LO: 0,
                     P.REG_FIRE_START_HI: 0, P.REG_FIRE_COUNT_LO: 0, P.REG_FIRE_COUNT_HI: 0,
                     P.REG_HEAD_MASK: (1 << n_heads) - 1}
        self.clear_fire_delays()
        self.configured_mask = 0
        self.underrun_mask = 0
        self.firing = False
        self.flush()

    # -- registers ------------------------------------------------------------------------
    @property
    def capacity_fires(self) -> int:
        return (self.fifo_words + self.pass_buffer_words) // P.WORDS_PER_FIRE

    def _pair(self, lo: int) -> int:
        v = self.regs[lo] | (self.regs[lo + 1] << 16)
        return v

    @property
    def stroke(self) -> int:
        return self._pair(P.REG_STROKE_LO)

    def clear_stroke(self) -> None:
        """A new job: no stroke yet (the stroke registers read NO_STROKE, nothing fired)."""
        self.regs[P.REG_STROKE_LO] = P.NO_STROKE & 0xFFFF
        self.regs[P.REG_STROKE_HI] = P.NO_STROKE >> 16
        self.fired = 0

    def clear_fire_delays(self) -> None:
        """FIRE_DELAY_FWD/REV0..7 to 0 (at power-up and a new job's JOB_BEGIN)."""
        for h in range(8):
            self.regs[P.REG_FIRE_DELAY_FWD0 + h] = 0
            self.regs[P.REG_FIRE_DELAY_REV0 + h] = 0

    def fire_delay_s(self, head: int, forward: bool) -> float:
        """Head h's fire delay after the trigger edge in this direction, seconds."""
        base = P.REG_FIRE_DELAY_FWD0 if forward else P.REG_FIRE_DELAY_REV0
        return self.regs[base + head] / P.FIRE_DELAY_HZ

    @property
    def fire_start(self) -> int:
        v = self._pair(P.REG_FIRE_START_LO)
        return v - (1 << 32) if v & 0x80000000 else v

    @property
    def fire_count(self) -> int:
        return self._pair(P.REG_FIRE_COUNT_LO)

    @property
    def forward(self) -> bool:
        return self.regs[P.REG_DIR] == 1

    @property
    def dpi(self) -> int:
        return P.DPI_FROM_CODE.get(self.regs[P.REG_DPI], 0)

    @property
    def we_en(self) -> bool:
        return self.regs[P.REG_WE_EN] == 1

    def write_reg(self, addr: int, value: int) -> bool:
        value &= 0xFFFF
        if addr == P.REG_FIFO_FLUSH:
            if value & 1:
                self.flush()
            return True
        if addr == P.REG_DPI and value not in P.DPI_FROM_CODE:
            return False
        if addr in (P.REG_DIR, P.REG_WE_EN) and value not in (0, 1):
            return False
        if addr not in self.regs:
            return False
        self.regs[addr] = value
        return True

    def read_reg(self, addr: int) -> int | None:
        if addr == P.REG_STATUS:
            return self.status_word()
        if P.REG_FIFO_LEVEL0 <= addr < P.REG_FIFO_LEVEL0 + 8:
            h = addr - P.REG_FIFO_LEVEL0
            return self.fifo_levels()[h]
        if P.REG_FIFO_FLAGS0 <= addr < P.REG_FIFO_FLAGS0 + 8:
            return self.fifo_flags() if addr - P.REG_FIFO_FLAGS0 < self.n_heads else 0
        if addr == P.REG_UNDERRUN:
            return self.underrun_mask
        if addr == P.REG_CONFIG:
            return self.configured_mask
        return self.regs.get(addr)

    def status_word(self) -> int:
        s = 0
        if self.forward:
            s |= P.STATUS_DIR
        if self.dpi == 600:
            s |= P.STATUS_DPI600
        if self.we_en:
            s |= P.STATUS_WE_EN
        if self.dpi == 300:
            s |= P.STATUS_DPI300
        if self.fifo_level_fires() == 0:
            s |= P.STATUS_FIFO_EMPTY
        if self.underrun_mask:
            s |= P.STATUS_UNDERRUN
        if self.configured_mask == (1 << self.n_heads) - 1:
            s |= P.STATUS_CONFIGURED
        if self.firing:
            s |= P.STATUS_FIRING
        return s

    # -- data path ------------------------------------------------------------------------
    def flush(self) -> None:
        self.ring: deque[RingBlock] = deque()
        self.fifo: deque[P.Block] = deque()      # blocks moved into the FIFOs, not all fired
        self.queued_fires = 0                    # fires accepted for the stroke (ring + FIFO + fired)
        self.loaded_fires = 0                    # fires moved into the FIFOs
        self.fired = 0                           # fires made in the current line
        self.blocks_moved = 0

    def flush_unfired(self) -> None:
        """FLUSH block (docs/protocol.md 3.1): drop the DMA ring; the FIFOs keep their words
        (they will fire); the next block must start at the first fire not in the FIFOs."""
        self.ring.clear()
        self.queued_fires = self.loaded_fires

    def fifo_level_fires(self) -> int:
        return self.loaded_fires - self.fired

    def fifo_level_words(self) -> int:
        return self.fifo_level_fires() * P.WORDS_PER_FIRE

    def fifo_flags(self) -> int:
        """EMPTY, ALMOST_EMPTY, FULL and WR_COUNT[1:0] of a head's FIFO (seed 4.2.2), and
        the DMA request they make together: room for one more block; LOW, the programmable
        level (docs/protocol.md, FIFO_FLAGS)."""
        depth = self.fifo_words + self.pass_buffer_words
        level = self.fifo_level_words()
        flags = 0
        if level == 0:
            flags |= P.FIFO_EMPTY
        if level <= P.WORDS_PER_FIRE:          # seed 4.2.2: the next read empties it
            flags |= P.FIFO_ALMOST_EMPTY
        if level <= self.almost_empty_words:    # the programmable level (extension)
            flags |= P.FIFO_LOW
        if level >= depth:
            flags |= P.FIFO_FULL
        flags |= min(3, level * 4 // depth) << P.FIFO_WR_COUNT_SHIFT
        if level + self.block_words <= depth:
            flags |= P.FIFO_DREQ
        return flags

    def fifo_levels(self) -> tuple[int, ...]:
        """Words in each of the 8 head FIFOs as reported (docs/protocol.md 2.5, 3.2): the
        heads advance together; a pass buffer beyond 16 bits reports 65535."""
        level = min(self.fifo_level_words(), 0xFFFF)
        return (level,) * self.n_heads + self._absent_heads

    def ring_free(self) -> int:
        return max(0, self.ring_blocks - len(self.ring))

    def accept(self, block: P.Block, ready_s: float) -> P.Fault:
        """A block from the data channel enters the DMA ring (or is refused with a fault)."""
        if block.kind == P.BLOCK_FLUSH:
            if block.stroke == self.stroke:
                self.flush_unfired()
            return P.Fault.NONE
        if block.stroke != self.stroke or block.first_fire != self.queued_fires:
            return P.Fault.DATA_SEQUENCE
        if block.head_mask != self.regs[P.REG_HEAD_MASK]:
            return P.Fault.DATA_SEQUENCE
        if len(self.ring) >= self.ring_blocks:
            return P.Fault.FIFO_OVERFLOW
        if block.fires * P.WORDS_PER_FIRE > self.capacity_fires * P.WORDS_PER_FIRE:
            return P.Fault.FIFO_OVERFLOW
        if self.queued_fires + block.fires > self.fire_count:
            return P.Fault.FIFO_OVERFLOW
        self.ring.append(RingBlock(block, ready_s))
        self.queued_fires += block.fires
        return P.Fault.NONE

    def room_for_next(self) -> bool:
        return bool(self.ring) and \
            self.fifo_level_fires() + self.ring[0].block.fires <= self.capacity_fires

    def move_next(self) -> P.Block:
        """DMA: the oldest ring block into the FIFOs."""
        rb = self.ring.popleft()
        self.fifo.append(rb.block)
        self.loaded_fires += rb.block.fires
        self.blocks_moved += 1
        return rb.block
