"""Opening a printer from a device spec (docs/driver.md):

    emulator                      in-process emulator (tests, demos)
    emulator-usb                  in-process emulator, data channel through pyusb
    serial=PORT,data=URL[,baud=N] a real or standalone-emulated printer
        PORT: /dev/ttyS0, /dev/ttyUSB0, /dev/pts/N, or socket://HOST:PORT (pyserial)
        URL:  usb://VID:PID[/SERIAL]   USB bulk (libusb)
              /dev/NODE                the PCI card's device node (or a pty stand-in)
              tcp://HOST:PORT          the standalone emulator's data port
              usb-emu://HOST:PORT      the standalone emulator as a USB device (pyusb)

and the host-side printer handle the job talks to.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import protocol as P
from .link import CommandLink, LinkError
from .transport import NodeData, TcpData, UsbData
from ..rip.profile import Profile


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
        for first in range(0, len(digits), 400):            # 400 digits = 200 bytes a frame
            self.link.call(P.Op.HEAD_CONFIG_DATA, first=first, digits=digits[first:first + 400])
        self.link.call(P.Op.HEAD_CONFIG_LOAD, count=len(digits),
                       crc=P.crc32(P.pack_digits(digits)))

    def close(self) -> None:
        try:
            self.data.close()
        finally:
            close = getattr(self.link.port, "close", None)
            if close:
                close()


def open_data(url: str):
    """A data-channel transport from its URL."""
    try:
        if url.startswith("tcp://"):
            host, _, port = url[6:].rpartition(":")
            return TcpData(host or "127.0.0.1", int(port))
        if url.startswith("usb-emu://"):
            from ..device_sim.usb_backend import EmulatorUsbBackend
            host, _, port = url[10:].rpartition(":")
            return UsbData(backend=EmulatorUsbBackend(TcpData(host or "127.0.0.1", int(port))))
        if url.startswith("usb://"):
            ids, _, serial = url[6:].partition("/")
            vid, _, pid = ids.partition(":")
            return UsbData(int(vid, 16), int(pid, 16), serial or None)
        if url.startswith("/"):
            return NodeData(url)
    except (OSError, ConnectionError) as exc:
        raise LinkError(f"cannot open data channel {url}: {exc}") from None
    raise ValueError(f"data channel {url!r}: use usb://VID:PID[/SERIAL], /dev/NODE, "
                     f"tcp://HOST:PORT or usb-emu://HOST:PORT")


def open_device(spec: str, profile: Profile, faults=None, media_path=None,
                event_log=None, machine_profile: Profile | None = None,
                **emulator_options) -> Device:
    """The in-process emulator is built from `machine_profile` (the machine as it really
    is; default: the job's profile) and emulator_options (vcd_path, vcd_window,
    record_latched)."""
    spec = spec.strip()
    timeout = float(profile.raw["link"]["response_timeout_s"])
    if spec in ("emulator", "emulator-usb"):
        from ..device_sim.endpoints import in_process
        from ..device_sim.printer import Printer
        printer = Printer(machine_profile or profile, faults, media_path=media_path,
                          event_log=event_log, **emulator_options)
        serial_port, data = in_process(printer)
        if spec == "emulator-usb":
            from ..device_sim.usb_backend import EmulatorUsbBackend
            data = UsbData(backend=EmulatorUsbBackend(data))
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
    try:
        data = open_data(parts["data"])
    except Exception:
        port.close()
        raise
    return Device(CommandLink(port, timeout), data, profile)
