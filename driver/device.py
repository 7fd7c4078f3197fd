"""Opening a printer from a device spec (docs/driver.md):

    emulator                                  in-process emulator (tests, demos)
    serial=PORT,data=URL                      a real or standalone-emulated printer
        PORT: /dev/ttyS0, /dev/ttyUSB0, /dev/pts/N, or socket://HOST:PORT
        URL:  tcp://HOST:PORT (standalone emulator)

and the host-side printer handle the job talks to.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
import zlib
from dataclasses import dataclass

from . import protocol as P
from .link import CommandLink, LinkError
from ..rip.profile import Profile


class TcpData:
    """Data channel over TCP (the standalone emulator)."""

    def __init__(self, host: str, port: int):
        self.addr = (host, port)
        self.name = f"tcp://{host}:{port}"
        self.sock: socket.socket | None = None
        self.reconnect()

    def reconnect(self) -> None:
        self.close()
        self.sock = socket.create_connection(self.addr, timeout=5.0)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def send(self, data: bytes) -> None:
        if self.sock is None:
            raise ConnectionError("data link closed")
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
                    raise ConnectionError("data link closed by the printer")
                chunks.append(chunk)
                self.sock.settimeout(0.0)
        except (BlockingIOError, socket.timeout):
            pass
        return b"".join(chunks)

    def close(self) -> None:
        if self.sock is not None:
            try:
                self.sock.close()
            finally:
                self.sock = None


@dataclass
class Device:
    """The host's handle on one printer: command link + data channel (+ the emulator
    object when it runs in-process, for tests and media output)."""
    link: CommandLink
    data: object
    profile: Profile
    emulator: object | None = None
    info: dict | None = None

    def connect(self) -> dict:
        self.link.handshake()
        self.info = self.link.identify()
        return self.info

    def load_head_config(self) -> None:
        digits = self.profile.head_config_digits()
        for first in range(0, len(digits), 400):
            chunk = digits[first:first + 400]
            packed = bytes(chunk[i] | ((chunk[i + 1] << 4) if i + 1 < len(chunk) else 0)
                           for i in range(0, len(chunk), 2))
            self.link.command(P.Op.HEAD_CONFIG_DATA, struct.pack("<H", first) + packed)
        packed_all = bytes(digits[i] | ((digits[i + 1] << 4) if i + 1 < len(digits) else 0)
                           for i in range(0, len(digits), 2))
        self.link.command(P.Op.HEAD_CONFIG_LOAD,
                          struct.pack("<HI", len(digits), zlib.crc32(packed_all) & 0xFFFFFFFF))

    def close(self) -> None:
        try:
            self.data.close()
        finally:
            close = getattr(self.link.port, "close", None)
            if close:
                close()


def open_device(spec: str, profile: Profile, faults=None, media_path=None,
                event_log=None, machine_profile: Profile | None = None,
                **emulator_options) -> Device:
    """The in-process emulator is built from `machine_profile` (the machine as it really
    is; default: the job's profile) and emulator_options (vcd_path, vcd_window,
    record_latched)."""
    spec = spec.strip()
    timeout = float(profile.raw["link"]["response_timeout_s"])
    if spec == "emulator":
        from ..device_sim.endpoints import in_process
        from ..device_sim.printer import Printer
        printer = Printer(machine_profile or profile, faults, media_path=media_path,
                          event_log=event_log, **emulator_options)
        serial_port, data = in_process(printer)
        return Device(CommandLink(serial_port, timeout), data, profile, emulator=printer)
    parts = dict(p.split("=", 1) for p in spec.split(",") if "=" in p)
    if "serial" not in parts or "data" not in parts:
        raise ValueError(f"device spec {spec!r}: use 'emulator' or 'serial=PORT,data=URL'")
    import serial  # pyserial
    baud = int(parts.get("baud", profile.raw["link"]["baud"]))
    try:
        port = serial.serial_for_url(parts["serial"], baudrate=baud, timeout=0.02)
    except (serial.SerialException, ValueError) as exc:
        raise LinkError(f"cannot open {parts['serial']}: {exc}") from None
    url = parts["data"]
    if url.startswith("tcp://"):
        host, _, p = url[6:].rpartition(":")
        try:
            data = TcpData(host or "127.0.0.1", int(p))
        except OSError as exc:
            raise LinkError(f"cannot connect data channel {url}: {exc}") from None
    else:
        raise ValueError(f"data channel {url!r}: supported: tcp://HOST:PORT")
    return Device(CommandLink(port, timeout), data, profile)
