"""Ways to reach the emulated printer.

- In-process (tests, `--device emulator`): host-side objects with the same duck types as
  the real transports (a pyserial port, a data channel), calling the Printer directly and
  synchronously, so a whole job runs deterministically in one thread.
- Standalone (`wideprint emulator`): see device_sim/server.py.
"""

from __future__ import annotations

import threading
import time

from .printer import Printer


class InProcessSerial:
    """A pyserial-like port wired to the emulated DSP."""

    synchronous = True     # the answer is there as soon as write() returns

    def __init__(self, printer: Printer, lock: threading.Lock):
        self.printer, self.lock = printer, lock
        self._rx = bytearray()
        self.timeout = 0.25
        self.baudrate = 57600
        self.is_open = True
        self.port = "emulator"

    def write(self, data: bytes) -> int:
        if not self.is_open:
            raise OSError("port closed")
        with self.lock:
            self._rx += self.printer.serial_in(bytes(data))
        return len(data)

    def read(self, size: int = 1) -> bytes:
        out = bytes(self._rx[:size])
        del self._rx[:size]
        return out

    @property
    def in_waiting(self) -> int:
        return len(self._rx)

    def reset_input_buffer(self) -> None:
        self._rx.clear()

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.is_open = False


class InProcessData:
    """The data channel wired to the emulated FPGA."""

    name = "emulator"

    def __init__(self, printer: Printer, lock: threading.Lock):
        self.printer, self.lock = printer, lock
        self._rx = bytearray()
        self.open = True

    def send(self, data: bytes) -> None:
        if not self.open or not self.printer.link_alive:
            self.open = False
            raise ConnectionError("data link down")
        with self.lock:
            self.printer.data_in(bytes(data))
            self._rx += self.printer.data_out()
        if not self.printer.link_alive:
            self.open = False
            raise ConnectionError("data link dropped")

    def recv(self, timeout: float = 0.0) -> bytes:
        with self.lock:
            self._rx += self.printer.data_out()
        if not self._rx and timeout > 0:
            time.sleep(min(timeout, 0.0005))     # the device answers synchronously; don't spin
        out = bytes(self._rx)
        self._rx.clear()
        return out

    def close(self) -> None:
        if self.open:
            self.open = False
            with self.lock:
                self.printer.data_link_lost()

    def reconnect(self) -> None:
        with self.lock:
            self.printer.data_link_up()
            self._rx.clear()
        self.open = True


def in_process(printer: Printer) -> tuple[InProcessSerial, InProcessData]:
    lock = threading.Lock()
    return InProcessSerial(printer, lock), InProcessData(printer, lock)
