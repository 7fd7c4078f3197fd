"""Data-channel transports, host side (docs/driver.md "Device specs").

Every transport has the same four calls the streamer uses: send(bytes) (one DMA block),
recv(timeout) -> bytes (FPGA reports), reconnect(), close().

- TcpData:  the standalone emulator's data port (tcp://HOST:PORT)
- NodeData: the PCI card's device node (docs/protocol.md 3.1: one write() is one DMA block,
            read() returns reports); any character device or pty behaves the same
- UsbData:  USB bulk through pyusb: OUT endpoint 0x01 carries blocks, IN endpoint 0x81
            reports; the device is chosen by VID:PID and optionally its serial number
- PciData:  the PCI card at register level (docs/pci.md): blocks by demand-mode DMA, chained
            descriptors in host memory, from a ring of DMA buffers to the FPGA's DATA port;
            reports from the FPGA's report FIFO; over any card interface (driver/pci_card.py:
            VFIO on a real machine, the emulated card in tests)
"""

from __future__ import annotations

import os
import select
import socket
import termios
import threading
import time
import tty
from collections import deque

import numpy as np

from . import protocol as P
from .pci_card import CardError, check_card
from .protocol import EP_IN, EP_OUT, USB_PID, USB_VID   # the wire contract (docs/protocol.md 1)


class TcpData:
    def __init__(self, host: str, port: int):
        self.addr = (host, port)
        self.name = f"tcp://{host}:{port}"
        self.sock: socket.socket | None = None
        self.open = False
        self.reconnect()

    def reconnect(self) -> None:
        self.close()
        self.sock = socket.create_connection(self.addr, timeout=5.0)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.open = True

    def send(self, data: bytes) -> None:
        if self.sock is None:
            raise ConnectionError("data link closed")
        self.sock.settimeout(30.0)
        self.sock.sendall(data)

    def recv(self, timeout: float = 0.0) -> bytes:
        if self.sock is None:
            raise ConnectionError("data link closed")
        self.sock.settimeout(timeout if timeout > 0 else 0.0)
        chunks = []
        try:
            while True:
                chunk = self.sock.recv(65536)
                if not chunk:
                    self.open = False
                    raise ConnectionError("data link closed by the printer")
                chunks.append(chunk)
                self.sock.settimeout(0.0)
        except (BlockingIOError, socket.timeout):
            pass
        return b"".join(chunks)

    def close(self) -> None:
        self.open = False
        if self.sock is not None:
            try:
                self.sock.close()
            finally:
                self.sock = None


class NodeData:
    """A device node: write() = one DMA block, read() = reports (select for readiness)."""

    def __init__(self, path: str):
        self.path = path
        self.name = path
        self.fd: int | None = None
        self.open = False
        self.reconnect()

    def reconnect(self) -> None:
        self.close()
        self.fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY)
        if os.isatty(self.fd):                   # a pty stand-in: no line discipline
            tty.setraw(self.fd, termios.TCSANOW)
        self.open = True

    def send(self, data: bytes) -> None:
        if self.fd is None:
            raise ConnectionError("device node closed")
        view = memoryview(data)
        while view:
            n = os.write(self.fd, view)
            view = view[n:]

    def recv(self, timeout: float = 0.0) -> bytes:
        if self.fd is None:
            raise ConnectionError("device node closed")
        out = []
        wait = timeout
        while True:
            ready, _, _ = select.select([self.fd], [], [], wait)
            if not ready:
                break
            chunk = os.read(self.fd, 65536)
            if not chunk:
                self.open = False
                raise ConnectionError("device node closed by the driver")
            out.append(chunk)
            wait = 0
        return b"".join(out)

    def close(self) -> None:
        self.open = False
        if self.fd is not None:
            try:
                os.close(self.fd)
            finally:
                self.fd = None


class UsbData:
    """USB bulk through pyusb.  `backend` None = libusb (real hardware); the emulator
    passes device_sim.usb_backend.EmulatorUsbBackend."""

    def __init__(self, vid: int = USB_VID, pid: int = USB_PID, serial: str | None = None,
                 backend=None):
        self.vid, self.pid, self.serial, self.backend = vid, pid, serial, backend
        self.name = f"usb://{vid:04x}:{pid:04x}" + (f"/{serial}" if serial else "")
        self.dev = None
        self.open = False
        self.reconnect()

    def reconnect(self) -> None:
        import usb.core
        import usb.util
        self.close()
        if self.backend is not None and hasattr(self.backend, "reconnect"):
            self.backend.reconnect()

        def match(d):
            if self.serial is None:
                return True
            try:
                return usb.util.get_string(d, d.iSerialNumber) == self.serial
            except (usb.core.USBError, ValueError):
                return False
        try:
            dev = usb.core.find(idVendor=self.vid, idProduct=self.pid, custom_match=match,
                                backend=self.backend)
        except usb.core.NoBackendError:
            raise ConnectionError("no USB backend: install libusb-1.0 (Debian: libusb-1.0-0)") from None
        if dev is None:
            raise ConnectionError(f"no printer at {self.name}")
        dev.set_configuration()
        usb.util.claim_interface(dev, 0)
        self.dev = dev
        self.open = True

    def send(self, data: bytes) -> None:
        import usb.core
        if self.dev is None:
            raise ConnectionError("USB link closed")
        try:
            self.dev.write(EP_OUT, data, timeout=30_000)
        except usb.core.USBError as exc:
            self.open = False
            raise ConnectionError(f"USB write failed: {exc}") from exc

    def recv(self, timeout: float = 0.0) -> bytes:
        import usb.core
        if self.dev is None:
            raise ConnectionError("USB link closed")
        try:
            return bytes(self.dev.read(EP_IN, 65536, timeout=max(1, int(timeout * 1000))))
        except usb.core.USBTimeoutError:
            return b""
        except usb.core.USBError as exc:
            self.open = False
            raise ConnectionError(f"USB read failed: {exc}") from exc

    def close(self) -> None:
        if self.dev is not None:
            import usb.util
            try:
                usb.util.dispose_resources(self.dev)
            finally:
                self.dev = None
        self.open = False


class PciData:
    """The PCI card (docs/pci.md 3, 4, 6) over a card interface (driver/pci_card.py).

    `send(block)` copies the block into a free slot of a ring of DMA buffers and queues its
    descriptor; when DMA channel 0 is idle every queued descriptor goes out as one chain
    (or, `chained=False`, one block-mode transfer at a time).  A descriptor is done when the
    9054 has written 0 over its size (clear count mode); its slot is free again.  An
    interrupt thread (the driver's interrupt handler) waits on the card's interrupt, at
    most IRQ_POLL_S, and then services the card whether or not it came: done chains are
    reaped and the next one started, so the FIFOs stay fed between host calls and a missed
    interrupt costs at most that long.  `recv()` reads the FPGA's report FIFO.  A DMA abort,
    an unanswering card or a stalled DMA is a lost data link (ConnectionError naming the
    cause); `reconnect()` resets the channel and the FPGA's data path, and the job resumes
    the stroke with a FLUSH block (docs/protocol.md 3.3)."""

    STALL_S = 5.0              # no descriptor done for this long while one is queued: stalled
    ABORT_WAIT_S = 0.01
    IRQ_POLL_S = 0.05

    def __init__(self, card, slots: int = 16, slot_bytes: int = 65536, chained: bool = True):
        self.card, self.name = card, card.name
        self.slots, self.slot_bytes, self.chained = slots, slot_bytes, chained
        self.info = check_card(card)
        self.descs = card.dma_alloc(slots * P.DMA_DESC.size)
        self.bufs = card.dma_alloc(slots * slot_bytes)
        self.stats = {"blocks": 0, "chains": 0, "interrupts": 0, "timeouts": 0, "aborts": 0}
        self.error: str | None = None
        self.open = False
        self._rx = bytearray()
        self._cond = threading.Condition()
        self._stop = threading.Event()
        with self._cond:
            self._reset()
        self._thread = threading.Thread(target=self._irq_loop, name=f"irq-{self.name}",
                                        daemon=True)
        self._thread.start()

    # -- the link ------------------------------------------------------------------------------
    def reconnect(self) -> None:
        with self._cond:
            self._reset()

    def _reset(self) -> None:
        card = self.card
        self.inflight: list[tuple[int, int]] = []        # the running chain
        self._abort_channel()
        cmd = card.config_read16(P.PCI_CFG_COMMAND)
        card.config_write16(P.PCI_CFG_COMMAND, cmd | P.PCI_COMMAND_MEMORY | P.PCI_COMMAND_MASTER)
        status = card.config_read16(P.PCI_CFG_STATUS)
        card.config_write16(P.PCI_CFG_STATUS, status & (P.PCI_STATUS_MASTER_ABORT
                                                        | P.PCI_STATUS_TARGET_ABORT))
        card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_CLEAR_INT)
        card.write32(P.BAR_PLX, P.PLX_INTCSR, P.INTCSR_HOST)
        card.write32(P.BAR_FPGA, P.FPGA_CTRL, P.CTRL_DATA_RESET | P.CTRL_IRQ_EN)
        card.write32(P.BAR_FPGA, P.FPGA_IRQ_MASK, P.IRQ_REPORT | P.IRQ_FAULT)
        card.write32(P.BAR_FPGA, P.FPGA_IRQ_STATUS, P.IRQ_FAULT)
        self.free: deque[int] = deque(range(self.slots))
        self.queued: list[tuple[int, int]] = []          # (slot, bytes) not yet given to the DMA
        self._progress = time.monotonic()
        self.error = None
        self.open = True
        self._read_reports()
        self._rx = bytearray()                           # stale reports of the old link dropped
        card.irq_unmask()

    def send(self, data: bytes) -> None:
        n = len(data)
        if n > self.slot_bytes or n % 4:
            raise ValueError(f"a block of {n} bytes does not fit a {self.slot_bytes}-byte DMA "
                             f"slot in 32-bit words")
        with self._cond:
            self._check()
            while not self.free:
                self._cond.wait(self.IRQ_POLL_S)
                self._check()
                self._service()
            slot = self.free.popleft()
            off = slot * self.slot_bytes
            self.bufs.mem[off:off + n] = data
            self._write_desc(slot, self.bufs.iova + off, n, P.DPR_PCI | P.DPR_END | P.DPR_TC_INT)
            self.queued.append((slot, n))
            self.stats["blocks"] += 1
            self._service()

    def recv(self, timeout: float = 0.0) -> bytes:
        with self._cond:
            self._check()
            self._service()
            if not self._rx and timeout > 0:
                self._cond.wait(timeout)
                self._check()
                self._service()
            out = bytes(self._rx)
            self._rx.clear()
            return out

    def close(self) -> None:
        if self.card is None:
            return
        self._stop.set()
        self._thread.join()
        try:
            with self._cond:
                self._abort_channel()
                self.card.write32(P.BAR_PLX, P.PLX_INTCSR, 0)
                self.card.dma_free(self.descs)
                self.card.dma_free(self.bufs)
        except OSError:
            pass
        finally:
            self.open = False
            self.card.close()
            self.card = None

    def _irq_loop(self) -> None:
        """The interrupt handler: wake on the card's interrupt (or after IRQ_POLL_S), clear
        its sources, reap and restart the DMA, re-arm the interrupt."""
        while not self._stop.is_set():
            try:
                fired = self.card.irq_wait(self.IRQ_POLL_S)
            except CardError as exc:
                with self._cond:
                    self._failed(str(exc))
                continue
            with self._cond:
                if not self.open:
                    continue
                self.stats["interrupts" if fired else "timeouts"] += 1
                try:
                    self._service()
                    self.card.irq_unmask()
                except ConnectionError:
                    pass                          # recorded: the next send or recv raises it
                self._cond.notify_all()

    # -- DMA -----------------------------------------------------------------------------------
    def _desc_iova(self, slot: int) -> int:
        return self.descs.iova + slot * P.DMA_DESC.size

    def _write_desc(self, slot: int, padr: int, size: int, dpr: int) -> None:
        off = slot * P.DMA_DESC.size
        self.descs.mem[off:off + P.DMA_DESC.size] = P.encode_dma_desc(padr, P.FPGA_DATA, size, dpr)

    def _desc(self, slot: int) -> P.DmaDesc:
        off = slot * P.DMA_DESC.size
        return P.decode_dma_desc(self.descs.mem[off:off + P.DMA_DESC.size])

    def _start(self) -> None:
        card = self.card
        chain = self.queued if self.chained else self.queued[:1]
        self.queued = self.queued[len(chain):]
        if self.chained:
            for (slot, n), nxt in zip(chain, chain[1:] + [None]):
                d = self._desc(slot)
                dpr = (self._desc_iova(nxt[0]) | P.DPR_PCI) if nxt else \
                    (P.DPR_PCI | P.DPR_END | P.DPR_TC_INT)
                self._write_desc(slot, d.padr, n, dpr)
            card.write32(P.BAR_PLX, P.PLX_DMAMODE0, P.DMAMODE_CHAINED)
            card.write32(P.BAR_PLX, P.PLX_DMADPR0, self._desc_iova(chain[0][0]) | P.DPR_PCI)
        else:
            slot, n = chain[0]
            card.write32(P.BAR_PLX, P.PLX_DMAMODE0, P.DMAMODE_BLOCK)
            card.write32(P.BAR_PLX, P.PLX_DMAPADR0, self._desc(slot).padr)
            card.write32(P.BAR_PLX, P.PLX_DMALADR0, P.FPGA_DATA)
            card.write32(P.BAR_PLX, P.PLX_DMASIZ0, n)
            card.write32(P.BAR_PLX, P.PLX_DMADPR0, 0)
        self.inflight = chain
        self._progress = time.monotonic()
        self.stats["chains"] += 1
        card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_ENABLE | P.DMACSR_START)

    def _reap(self) -> None:
        """Free the slots whose descriptors are done; a chain that ended short was aborted."""
        if not self.inflight:
            return
        csr = self.card.read32(P.BAR_PLX, P.PLX_DMACSR0) & 0xFF   # first: write-backs precede DONE
        if not self.chained:
            done = len(self.inflight) if csr & P.DMACSR_DONE and not self._aborted() else 0
        else:
            done = 0
            while done < len(self.inflight) and self._desc(self.inflight[done][0]).size == 0:
                done += 1
        if done:
            self.free.extend(slot for slot, _ in self.inflight[:done])
            self.inflight = self.inflight[done:]
            self._progress = time.monotonic()
        if self.inflight and csr & P.DMACSR_DONE:
            self._fail(self._abort_message())
        if self.inflight and time.monotonic() - self._progress > self.STALL_S:
            self._abort_channel()
            self._fail(f"DMA stalled: no descriptor completed in {self.STALL_S:g} s (the card "
                       f"did not request data: DREQ0# held off)")

    def _aborted(self) -> bool:
        return bool(self.card.config_read16(P.PCI_CFG_STATUS)
                    & (P.PCI_STATUS_MASTER_ABORT | P.PCI_STATUS_TARGET_ABORT))

    def _abort_message(self) -> str:
        card = self.card
        status = card.config_read16(P.PCI_CFG_STATUS)
        slot = self.inflight[0][0] if self.inflight else None
        dpr = card.read32(P.BAR_PLX, P.PLX_DMADPR0) & P.DPR_NEXT_MASK
        padr = card.read32(P.BAR_PLX, P.PLX_DMAPADR0)
        if slot is not None and self.chained and dpr == self._desc_iova(slot):
            where = f"fetching descriptor {slot} at IOVA {dpr:#x}"
        else:
            where = f"reading host memory at IOVA {padr:#x}" + \
                (f" (descriptor {slot})" if slot is not None else "")
        self.stats["aborts"] += 1
        if status & P.PCI_STATUS_MASTER_ABORT:
            return (f"DMA aborted: master abort {where} - an IOMMU fault: the address is not "
                    f"mapped for the card (dmesg shows the DMAR / AMD-Vi fault)")
        if status & P.PCI_STATUS_TARGET_ABORT:
            return f"DMA aborted: target abort {where} (the card refused the transfer)"
        return f"DMA ended with descriptor {slot} not done ({where})"

    def _abort_channel(self) -> None:
        card = self.card
        csr = card.read32(P.BAR_PLX, P.PLX_DMACSR0) & 0xFF
        if csr & P.DMACSR_ENABLE and not csr & P.DMACSR_DONE:
            card.write32(P.BAR_PLX, P.PLX_DMACSR0, 0)
            card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_ABORT)
            deadline = time.monotonic() + self.ABORT_WAIT_S
            while not card.read32(P.BAR_PLX, P.PLX_DMACSR0) & P.DMACSR_DONE:
                if time.monotonic() > deadline:
                    break
        self.inflight = []

    # -- interrupts and reports ----------------------------------------------------------------
    def _service(self) -> None:
        card = self.card
        intcsr = card.read32(P.BAR_PLX, P.PLX_INTCSR)
        if intcsr == 0xFFFFFFFF:
            self._fail("the card does not answer (reads 0xFFFFFFFF)")
        if intcsr & P.INTCSR_DMA0_ACTIVE:
            card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_ENABLE | P.DMACSR_CLEAR_INT)
        if intcsr & P.INTCSR_ABORT_ACTIVE and not self.inflight:
            self._fail(self._abort_message())
        if card.read32(P.BAR_FPGA, P.FPGA_IRQ_STATUS) & P.IRQ_FAULT:
            card.write32(P.BAR_FPGA, P.FPGA_IRQ_STATUS, P.IRQ_FAULT)   # the DSP's status names it
        self._reap()
        if not self.inflight and self.queued:
            self._start()
        self._read_reports()

    def _read_reports(self) -> None:
        """Empty the FPGA's report FIFO into the host's buffer (which `recv` hands out): the
        FIFO's REPORT interrupt is a level, cleared by emptying it."""
        n = self.card.read32(P.BAR_FPGA, P.FPGA_REPORT_COUNT)
        if n == 0xFFFFFFFF:
            self._fail("the card does not answer (reads 0xFFFFFFFF)")
        if n:
            words = [self.card.read32(P.BAR_FPGA, P.FPGA_REPORT_DATA) for _ in range(n)]
            self._rx += np.array(words, dtype="<u4").tobytes()

    def _check(self) -> None:
        if not self.open:
            raise ConnectionError(self.error or f"{self.name}: data link closed")

    def _failed(self, message: str) -> None:
        self.open = False
        self.error = f"PCI card {self.name}: {message}"
        try:
            self._abort_channel()
        except OSError:
            pass
        self._cond.notify_all()

    def _fail(self, message: str):
        self._failed(message)
        raise ConnectionError(self.error)
