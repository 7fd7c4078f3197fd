"""The PCI card interface (docs/pci.md): what the data transport needs of the card, and
the card driven through VFIO.

A card is any object with these calls (`PciData` in driver/transport.py uses nothing else;
the emulator's card in device_sim/pci_card.py has the same, over the emulated card):

    name                          e.g. "vfio://0000:03:00.0"
    read32(bar, offset) -> int    a 32-bit register of BAR `bar`
    write32(bar, offset, value)
    config_read16(offset) -> int  PCI configuration space (command, status)
    config_write16(offset, value)
    dma_alloc(size) -> buffer     host memory the card may read: `.mem` (a writable
                                  memoryview), `.iova` (the address the card uses), `.size`
    dma_free(buffer)
    irq_wait(timeout) -> bool     True when the card's interrupt fired within `timeout` s
    irq_unmask()                  re-arm the interrupt (INTx is masked when it fires)
    close()
"""

from __future__ import annotations

from . import protocol as P
from .vfio import (VFIO_PCI_BAR0_REGION_INDEX, VFIO_PCI_CONFIG_REGION_INDEX,
                   VFIO_PCI_ERR_IRQ_INDEX, VFIO_PCI_INTX_IRQ_INDEX, VfioContainer,
                   VfioDevice, VfioError, VfioGroup, group_of, wait_eventfd)

IOVA_BASE = 0x1000_0000      # DMA buffers from 256 MiB up, below 4 GiB (docs/pci.md 7)
IOVA_LIMIT = 0xFEE0_0000     # the x86 interrupt window starts here


class CardError(ConnectionError):
    """The card is missing, not ours, or failed; the message says which and what to do."""


class VfioCard:
    """The card through vfio-pci: BAR0 (the 9054), BAR2 (the FPGA), config space, DMA
    buffers mapped with VFIO_IOMMU_MAP_DMA, INTx (and the AER error interrupt) as eventfds."""

    def __init__(self, bdf: str):
        self.bdf = bdf
        self.name = f"vfio://{bdf}"
        self.container = self.group = self.device = None
        self._next_iova = IOVA_BASE
        self.error_fd = None
        try:
            group = group_of(bdf)           # first: is there such a card, with a group?
            self.container = VfioContainer()
            self.group = VfioGroup(group, self.container)
            self.container.set_iommu()
            self.device = VfioDevice(self.group, bdf)
            self.bars = {bar: self.device.region(VFIO_PCI_BAR0_REGION_INDEX + bar)
                         for bar in (P.BAR_PLX, P.BAR_FPGA)}
            self.config = self.device.region(VFIO_PCI_CONFIG_REGION_INDEX)
            self.irq_fd = self.device.irq_eventfd(VFIO_PCI_INTX_IRQ_INDEX)
            try:
                self.error_fd = self.device.irq_eventfd(VFIO_PCI_ERR_IRQ_INDEX)
            except VfioError:
                self.error_fd = None         # no AER on this platform: BAR reads tell
        except (VfioError, OSError) as exc:
            self.close()
            raise CardError(f"PCI card {bdf}: {exc.strerror or exc}") from None

    def read32(self, bar: int, offset: int) -> int:
        return self.bars[bar].read(offset, 4)

    def write32(self, bar: int, offset: int, value: int) -> None:
        self.bars[bar].write(offset, 4, value & 0xFFFFFFFF)

    def config_read16(self, offset: int) -> int:
        return self.config.read(offset, 2)

    def config_write16(self, offset: int, value: int) -> None:
        self.config.write(offset, 2, value)

    def dma_alloc(self, size: int):
        if self._next_iova + size > IOVA_LIMIT:
            raise CardError(f"PCI card {self.bdf}: out of 32-bit DMA addresses")
        buf = self.container.map_dma(size, self._next_iova)
        self._next_iova += buf.size
        return buf

    def dma_free(self, buf) -> None:
        self.container.unmap_dma(buf)

    def irq_wait(self, timeout: float) -> bool:
        fds = [self.irq_fd] + ([self.error_fd] if self.error_fd is not None else [])
        fired = wait_eventfd(fds, timeout)
        if self.error_fd is not None and self.error_fd in fired:
            raise CardError(f"PCI card {self.bdf}: the platform reported a PCI bus error "
                            f"(AER) for the card; see dmesg")
        return self.irq_fd in fired

    def irq_unmask(self) -> None:
        self.device.irq_unmask(VFIO_PCI_INTX_IRQ_INDEX)

    def close(self) -> None:
        for part in (self.device, self.group, self.container):
            if part is not None:
                try:
                    part.close()
                except OSError:
                    pass
        self.device = self.group = self.container = None


def check_card(card) -> dict:
    """The bridge must be a 9054 and the FPGA a wideprint FPGA speaking our protocol major
    (docs/pci.md 1); returns the card's geometry registers."""
    hid = card.read32(P.BAR_PLX, P.PLX_PCIHIDR)
    if hid == 0xFFFFFFFF:
        raise CardError(f"PCI card {card.name}: the card does not answer (reads 0xFFFFFFFF)")
    if hid != P.PLX_PCIHIDR_9054:
        raise CardError(f"PCI card {card.name}: the bridge is not a PLX 9054 (PCIHIDR {hid:#010x})")
    ident = card.read32(P.BAR_FPGA, P.FPGA_ID)
    if ident != P.FPGA_ID_VALUE:
        raise CardError(f"PCI card {card.name}: not a wideprint card (FPGA ID {ident:#010x}, "
                        f"expected {P.FPGA_ID_VALUE:#010x} 'WPC1')")
    version = card.read32(P.BAR_FPGA, P.FPGA_VERSION)
    if version >> 8 != P.PROTOCOL_VERSION[0]:
        raise CardError(f"PCI card {card.name}: protocol {version >> 8}.{version & 0xFF}, "
                        f"this host speaks {P.PROTOCOL_VERSION[0]}.x")
    return {"heads": card.read32(P.BAR_FPGA, P.FPGA_HEADS),
            "fifo_words": card.read32(P.BAR_FPGA, P.FPGA_FIFO_WORDS),
            "ring_slots": card.read32(P.BAR_FPGA, P.FPGA_RING_SLOTS)}
