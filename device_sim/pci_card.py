"""The PCI card at register level (docs/pci.md): the PLX 9054's registers and DMA channel 0
(block mode and chained descriptors read from host memory, clear count write-back, demand
mode, done / terminal-count / abort interrupts), the FPGA on local address space 0 (ID and
geometry, the DATA port, the report FIFO, FIFO levels and flags, IRQ status and LINTi#),
and INTx as VFIO delivers it (signalled once, masked until the host unmasks).

`EmulatedPciCard` has the calls of the host's card interface (driver/pci_card.py), over
this card, in-process: the host's `PciData` transport runs unchanged against it.  Every
block the DMA carries goes into the emulated printer's data path (`Printer.data_in`), the
same as through the other transports; its reports come back through the report FIFO.
Host memory is the DMA buffers the host allocated, each at its IOVA; anything else is a
master abort, as the IOMMU makes it on the machine.
"""

from __future__ import annotations

import random
import threading
import time

from ..driver import protocol as P
from .printer import PCI_BYTES_S

IOVA_BASE = 0x1000_0000
PAGE = 4096


class MasterAbort(Exception):
    def __init__(self, address: int):
        super().__init__(f"master abort at {address:#x}")
        self.address = address


class DmaBuffer:
    def __init__(self, size: int, iova: int):
        self.size = -(-size // PAGE) * PAGE
        self.iova = iova
        self.mem = memoryview(bytearray(self.size))


class HostMemory:
    """The host's DMA buffers as the card sees them through the IOMMU."""

    def __init__(self):
        self.buffers: dict[int, DmaBuffer] = {}

    def _find(self, address: int, n: int) -> tuple[DmaBuffer, int]:
        for buf in self.buffers.values():
            if buf.iova <= address and address + n <= buf.iova + buf.size:
                return buf, address - buf.iova
        raise MasterAbort(address)

    def read(self, address: int, n: int) -> bytes:
        buf, off = self._find(address, n)
        return bytes(buf.mem[off:off + n])

    def write(self, address: int, data: bytes) -> None:
        buf, off = self._find(address, len(data))
        buf.mem[off:off + len(data)] = data


class EmulatedPciCard:
    """The card interface over the emulated card.  `lock` is the one the in-process
    command link holds while the DSP runs, so the line and the DMA never interleave."""

    # What a refill through this card costs beyond the host's own latency (the jitter
    # model) and the transfer itself (dma_time): INTx delivery to the waiting thread
    # (~5 us), the report read as 10 PIO reads of BAR2 (~1 us each), the register
    # accesses that reap the chain and start the next (~5 us) and the 16-byte descriptor
    # fetch: 20 us a block.
    REFILL_OVERHEAD_S = 20e-6

    def __init__(self, printer, lock: threading.Lock | None = None, faults=None,
                 dma_bytes_s: float | None = PCI_BYTES_S):
        self.printer = printer
        self.dma_bytes_s = dma_bytes_s      # a transfer takes this long in wall time (None: none)
        self._xfer_done_at: float | None = None
        self.lock = lock or threading.Lock()
        self.faults = faults or printer.faults
        self.name = "emulator-pci"
        self.rng = random.Random(self.faults.seed)
        self.memory = HostMemory()
        self._next_iova = IOVA_BASE
        # the 9054
        self.intcsr = 0
        self.dma = {P.PLX_DMAMODE0: 0, P.PLX_DMAPADR0: 0, P.PLX_DMALADR0: 0,
                    P.PLX_DMASIZ0: 0, P.PLX_DMADPR0: 0}
        self.dmacsr = P.DMACSR_DONE
        self.running = False
        self.loaded = False              # the current descriptor's registers are loaded
        self.dma0_active = False
        self.pci_command = 0
        self.pci_status = 0
        # the FPGA
        self.ctrl = 0
        self.irq_mask = 0
        self.fault_latched = False
        self._fault_seen = False
        self.reports = bytearray()
        # INTx through VFIO
        self.masked = False
        self.signalled = False
        # counters (tests, bench) and injected-fault bookkeeping
        self.descriptors_fetched = 0
        self.blocks_moved = 0
        self.chain_lengths: list[int] = []     # descriptors of each chain run
        self.interrupts = 0
        self.interrupts_lost = 0

    # -- the card interface ---------------------------------------------------------------------
    def read32(self, bar: int, offset: int) -> int:
        with self.lock:
            self._service()
            return (self._plx_read if bar == P.BAR_PLX else self._fpga_read)(offset) & 0xFFFFFFFF

    def write32(self, bar: int, offset: int, value: int) -> None:
        with self.lock:
            (self._plx_write if bar == P.BAR_PLX else self._fpga_write)(offset, value & 0xFFFFFFFF)
            self._service()

    def config_read16(self, offset: int) -> int:
        with self.lock:
            if offset == P.PCI_CFG_STATUS:
                return self.pci_status
            if offset == P.PCI_CFG_COMMAND:
                return self.pci_command
            return {P.PCI_CFG_VENDOR: P.PCI_VENDOR_PLX, P.PCI_CFG_VENDOR + 2: P.PCI_DEVICE_9054,
                    P.PCI_CFG_SUBVENDOR: P.PCI_SUBVENDOR,
                    P.PCI_CFG_SUBDEVICE: P.PCI_SUBDEVICE}.get(offset, 0)

    def config_write16(self, offset: int, value: int) -> None:
        with self.lock:
            if offset == P.PCI_CFG_STATUS:     # write 1 to clear
                self.pci_status &= ~(value & (P.PCI_STATUS_MASTER_ABORT | P.PCI_STATUS_TARGET_ABORT))
            elif offset == P.PCI_CFG_COMMAND:
                self.pci_command = value & 0xFFFF
            self._service()

    def dma_alloc(self, size: int) -> DmaBuffer:
        buf = DmaBuffer(size, self._next_iova)
        self._next_iova += buf.size + PAGE          # a guard page: overruns are master aborts
        self.memory.buffers[buf.iova] = buf
        return buf

    def dma_free(self, buf: DmaBuffer) -> None:
        self.memory.buffers.pop(buf.iova, None)

    POLL_S = 0.001      # the emulated card notices the printer's reports this often

    def irq_wait(self, timeout: float) -> bool:
        """Wait for the interrupt at most `timeout` s.  The printer advances when the DSP
        runs (under the shared lock), not on its own, so the card looks every POLL_S."""
        deadline = time.monotonic() + timeout
        while True:
            with self.lock:
                self._service()
                if self.signalled:
                    self.signalled = False
                    return True
            now = time.monotonic()
            if now >= deadline:
                return False
            time.sleep(min(self.POLL_S, deadline - now))

    def irq_unmask(self) -> None:
        with self.lock:
            self.masked = False
            self._service()

    def close(self) -> None:
        with self.lock:
            self.running = False

    # -- the 9054 ---------------------------------------------------------------------------------
    def _abort_active(self) -> bool:
        return bool(self.pci_status & (P.PCI_STATUS_MASTER_ABORT | P.PCI_STATUS_TARGET_ABORT))

    def _local_active(self) -> bool:
        return bool(self.ctrl & P.CTRL_IRQ_EN and self._irq_status() & self.irq_mask)

    def _plx_read(self, offset: int) -> int:
        if offset == P.PLX_INTCSR:
            v = self.intcsr
            v |= P.INTCSR_ABORT_ACTIVE if self._abort_active() else 0
            v |= P.INTCSR_LOCAL_ACTIVE if self._local_active() else 0
            v |= P.INTCSR_DMA0_ACTIVE if self.dma0_active else 0
            return v
        if offset == P.PLX_PCIHIDR:
            return P.PLX_PCIHIDR_9054
        if offset == P.PLX_DMACSR0:
            return self.dmacsr                  # DMACSR1 (byte 0xA9) reads 0: channel 1 idle
        return self.dma.get(offset, 0)

    def _plx_write(self, offset: int, value: int) -> None:
        if offset == P.PLX_INTCSR:
            self.intcsr = value & (P.INTCSR_HOST | 0xF)
        elif offset == P.PLX_DMACSR0:
            self._dmacsr_write(value & 0xFF)
        elif offset in self.dma and not self.running:
            self.dma[offset] = value

    def _dmacsr_write(self, value: int) -> None:
        if value & P.DMACSR_CLEAR_INT:
            self.dma0_active = False
        if value & P.DMACSR_ABORT:
            self._xfer_done_at = None
            if self.running:
                self.running = False
                self.dmacsr |= P.DMACSR_DONE
            return
        self.dmacsr = (self.dmacsr & P.DMACSR_DONE) | (value & P.DMACSR_ENABLE)
        if value & P.DMACSR_START and value & P.DMACSR_ENABLE and not self.running:
            self.dmacsr &= ~P.DMACSR_DONE
            self.running = True
            self.loaded = not self.dma[P.PLX_DMAMODE0] & P.DMAMODE_CHAIN
            self._next_desc = self.dma[P.PLX_DMADPR0]
            self.chain_lengths.append(0)

    def _finish(self) -> None:
        self.running = False
        self.dmacsr |= P.DMACSR_DONE
        if self.dma[P.PLX_DMAMODE0] & P.DMAMODE_DONE_IE:
            self.dma0_active = True

    def _abort(self, status_bit: int) -> None:
        """A master (or target) abort during the DMA: the channel stops with the transfer
        unfinished; the data path is down until the host resets it (CTRL.DATA_RESET)."""
        self.pci_status |= status_bit
        self.running = False
        self._xfer_done_at = None
        self.dmacsr |= P.DMACSR_DONE
        self.printer.data_link_lost()

    def _run_dma(self) -> None:
        f = self.faults
        chained = self.dma[P.PLX_DMAMODE0] & P.DMAMODE_CHAIN
        while self.running:
            if not self.pci_command & P.PCI_COMMAND_MASTER:
                return                            # not a bus master: nothing moves (a stall)
            if not self.loaded:                   # fetch the next descriptor from host memory
                address = self._next_desc & P.DPR_NEXT_MASK
                self.descriptors_fetched += 1
                try:
                    if f.pci_desc_error is not None and self.descriptors_fetched == f.pci_desc_error:
                        raise MasterAbort(address)
                    if not self._next_desc & P.DPR_PCI:
                        raise MasterAbort(address)   # descriptors on the local bus: none here
                    d = P.decode_dma_desc(self.memory.read(address, P.DMA_DESC.size))
                except MasterAbort:
                    self._abort(P.PCI_STATUS_MASTER_ABORT)
                    return
                self._desc_address = address
                self.dma.update({P.PLX_DMAPADR0: d.padr, P.PLX_DMALADR0: d.ladr,
                                 P.PLX_DMASIZ0: d.size, P.PLX_DMADPR0: d.dpr})
                self.loaded = True
            if self.printer.fpga.ring_free() == 0:
                return                            # demand mode: DREQ0# deasserted, wait
            size = self.dma[P.PLX_DMASIZ0] & P.DMASIZ_MASK
            if self.dma_bytes_s:                  # the transfer takes its time on the bus
                now = time.monotonic()
                if self._xfer_done_at is None:
                    self._xfer_done_at = now + size / self.dma_bytes_s
                if now < self._xfer_done_at:
                    return
                self._xfer_done_at = None
            padr, ladr = self.dma[P.PLX_DMAPADR0], self.dma[P.PLX_DMALADR0]
            self.blocks_moved += 1
            self.chain_lengths[-1] += 1
            try:
                data = self.memory.read(padr, size)
            except MasterAbort:
                self._abort(P.PCI_STATUS_MASTER_ABORT)
                return
            if ladr != P.FPGA_DATA or size % 4:
                self._abort(P.PCI_STATUS_TARGET_ABORT)   # the FPGA refuses other addresses
                return
            if f.pci_dma_abort is not None and self.blocks_moved == f.pci_dma_abort:
                self.printer.data_in(data[:size // 8 * 4])
                self._abort(P.PCI_STATUS_MASTER_ABORT)
                return
            stall = f.pci_bus_stall[1] if f.pci_bus_stall and \
                self.blocks_moved == f.pci_bus_stall[0] else 0.0
            if self.printer.link_alive:
                self.printer.data_in(data, delay_s=self.REFILL_OVERHEAD_S + stall)
            self.dma[P.PLX_DMASIZ0] = 0
            if chained and self.dma[P.PLX_DMAMODE0] & P.DMAMODE_CLEAR_COUNT:
                self.memory.write(self._desc_address + 8, bytes(4))
            dpr = self.dma[P.PLX_DMADPR0]
            if chained and dpr & P.DPR_TC_INT:
                self.dma0_active = True
            if not chained or dpr & P.DPR_END:
                self._finish()
                return
            self._next_desc = dpr
            self.loaded = False

    # -- the FPGA -----------------------------------------------------------------------------------
    def _irq_status(self) -> int:
        s = P.IRQ_REPORT if self.reports else 0
        s |= P.IRQ_DREQ if self.printer.fpga.ring_free() else 0
        return s | (P.IRQ_FAULT if self.fault_latched else 0)

    def _fpga_read(self, offset: int) -> int:
        fpga = self.printer.fpga
        if P.FPGA_FIFO_LEVEL0 <= offset < P.FPGA_FIFO_LEVEL0 + 32:
            return fpga.fifo_levels()[(offset - P.FPGA_FIFO_LEVEL0) // 4]
        if P.FPGA_FIFO_FLAGS0 <= offset < P.FPGA_FIFO_FLAGS0 + 32:
            h = (offset - P.FPGA_FIFO_FLAGS0) // 4
            return fpga.fifo_flags() if h < fpga.n_heads else 0
        if offset == P.FPGA_REPORT_DATA:
            word = int.from_bytes(self.reports[:4].ljust(4, b"\0"), "little")
            del self.reports[:4]
            return word
        major, minor = P.PROTOCOL_VERSION
        regs = {P.FPGA_ID: P.FPGA_ID_VALUE, P.FPGA_VERSION: major << 8 | minor,
                P.FPGA_HEADS: fpga.n_heads, P.FPGA_FIFO_WORDS: fpga.fifo_words + fpga.pass_buffer_words,
                P.FPGA_RING_SLOTS: fpga.ring_blocks, P.FPGA_CTRL: self.ctrl,
                P.FPGA_IRQ_STATUS: self._irq_status(), P.FPGA_IRQ_MASK: self.irq_mask,
                P.FPGA_REPORT_COUNT: len(self.reports) // 4, P.FPGA_RING_FREE: fpga.ring_free(),
                P.FPGA_STROKE: fpga.stroke, P.FPGA_BLOCKS_MOVED: fpga.blocks_moved,
                P.FPGA_FIRES_DONE: fpga.fired}
        return regs.get(offset, 0)

    def _fpga_write(self, offset: int, value: int) -> None:
        if offset == P.FPGA_CTRL:
            if value & P.CTRL_DATA_RESET:        # a new data link: drop any partial block
                self.printer.data_link_lost()
                self.printer.data_link_up()
                self.reports.clear()
            self.ctrl = value & P.CTRL_IRQ_EN
        elif offset == P.FPGA_IRQ_MASK:
            self.irq_mask = value & (P.IRQ_REPORT | P.IRQ_DREQ | P.IRQ_FAULT)
        elif offset == P.FPGA_IRQ_STATUS and value & P.IRQ_FAULT:
            self.fault_latched = False

    # -- time passes -------------------------------------------------------------------------------
    def _service(self) -> None:
        """Whatever the card does on its own between two host accesses: the DMA moves while
        the FPGA requests data, the FPGA's reports queue up, the interrupt line follows."""
        pr = self.printer
        if self.running:
            self._run_dma()
        self.reports += pr.data_out()
        faulted = pr.fault != P.Fault.NONE
        if faulted and not self._fault_seen:
            self.fault_latched = True
        self._fault_seen = faulted
        line = bool(self.intcsr & P.INTCSR_PCI_IE) and (
            (bool(self.intcsr & P.INTCSR_DMA0_IE) and self.dma0_active)
            or (bool(self.intcsr & P.INTCSR_ABORT_IE) and self._abort_active())
            or (bool(self.intcsr & P.INTCSR_LOCAL_IE) and self._local_active()))
        if line and not self.masked:             # level-triggered INTx: VFIO masks it at once
            self.masked = True
            self.interrupts += 1
            if self.faults.pci_irq_miss and self.rng.random() < self.faults.pci_irq_miss:
                self.interrupts_lost += 1
            else:
                self.signalled = True
