"""Data-channel transports, host side (docs/driver.md "Device specs").

Every transport has the same four calls the streamer uses: send(bytes) (one DMA block),
recv(timeout) -> bytes (FPGA reports), reconnect(), close().

- TcpData:  the standalone emulator's data port (tcp://HOST:PORT)
- NodeData: the PCI card's device node (docs/protocol.md 3.1: one write() is one DMA block,
            read() returns reports); any character device or pty behaves the same
- UsbData:  USB bulk through pyusb: OUT endpoint 0x01 carries blocks, IN endpoint 0x81
            reports; the device is chosen by VID:PID and optionally its serial number
"""

from __future__ import annotations

import os
import select
import socket
import termios
import tty

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
