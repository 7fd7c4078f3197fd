"""The host's handle on one printer, and opening the real links (docs/driver.md).

A `Device` is a command link (serial, docs/protocol.md section 2) plus a data channel
(section 3) plus the printer profile the host drives it with.  Which concrete device a
spec names (the in-process emulator, a standalone emulator, a real printer) is decided
in app/devices.py; the driver only knows the links and what timing a device needs.

    serial=PORT,data=URL[,baud=N] a real or standalone-emulated printer
        PORT: /dev/ttyS0, /dev/ttyUSB0, /dev/pts/N, or socket://HOST:PORT (pyserial)
        URL:  usb://VID:PID[/SERIAL]   USB bulk (libusb)
              vfio://BDF               the PCI card through vfio-pci (docs/pci.md); pci://BDF
              /dev/NODE                a device node (or a pty stand-in)
              tcp://HOST:PORT          the standalone emulator's data port
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field

from . import protocol as P
from .link import CommandLink, LinkError
from .transport import NodeData, PciData, TcpData, UsbData
from ..rip.profile import Profile


def config_chunk_digits(bit_error_rate: float) -> int:
    """Head-configuration digits per HEAD_CONFIG_DATA frame for a line with this bit error
    rate: the largest even count whose request and answer (frame overhead, `first`, the
    packed digits, the 3-byte answer) cross the line intact 3 times in 4; 400 digits
    (200 bytes, near the frame limit) on a clean line, never fewer than 8."""
    if bit_error_rate <= 0:
        return 400
    budget_bits = math.log(1 / 0.75) / bit_error_rate     # (1 - p)^bits >= 0.75
    fixed = 10 * (2 * P.FRAME_OVERHEAD + 2 + 3)            # two frames' overhead, first, answer
    return int(max(8, min(400, 2 * ((budget_bits - fixed) / 10))) // 2 * 2)


@dataclass(frozen=True)
class Timing:
    """How the host paces its polling and retries for one device.  A real printer (or a
    standalone emulator) answers over a wire in real time: poll status every 10 ms and
    back off before reconnecting.  A device that answers synchronously in-process has
    nothing to wait for, so it carries zeros (docs/driver.md, "Timing")."""
    poll_interval_s: float = 0.01
    reconnect_backoff_s: float = 0.05      # x the attempt number

    @classmethod
    def synchronous(cls) -> "Timing":
        return cls(0.0, 0.0)


@dataclass
class Device:
    """The host's handle on one printer: command link + data channel + printer profile.
    `emulator` is an opaque handle the application attaches when the device is an
    in-process emulator (for its media output); nothing in the driver looks at it."""
    link: CommandLink
    data: object
    profile: Profile
    emulator: object | None = None
    info: dict | None = None
    timing: Timing = field(default_factory=Timing)

    def connect(self) -> dict:
        self.link.handshake()
        self.info = self.link.identify()
        return self.info

    def load_head_config(self, resume_from: int = 0) -> None:
        """Send the XJ128 configuration (docs/head-config.md) in HEAD_CONFIG_DATA frames,
        then HEAD_CONFIG_LOAD.  The frame size follows the line: 400 digits on a clean
        line, fewer as the measured bit error rate grows (docs/driver.md, "A noisy serial
        line").  A frame that fails its 3 tries raises LinkError with `.config_held` =
        the digits the printer acknowledged, so the caller can reconnect and resume there
        (HEAD_CONFIG_DATA rewrites from `first`, so resending a chunk is harmless)."""
        digits = self.profile.head_config_digits()
        first = resume_from
        while first < len(digits):
            n = config_chunk_digits(self.link.quality.bit_error_rate())
            try:
                held = self.link.call(P.Op.HEAD_CONFIG_DATA, first=first,
                                      digits=digits[first:first + n]).held
            except LinkError as exc:
                exc.config_held = first
                raise
            first = held
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
    """A data-channel transport from its URL (the real transports)."""
    try:
        if url.startswith("tcp://"):
            host, _, port = url[6:].rpartition(":")
            return TcpData(host or "127.0.0.1", int(port))
        if url.startswith("usb://"):
            ids, _, serial = url[6:].partition("/")
            vid, _, pid = ids.partition(":")
            return UsbData(int(vid, 16), int(pid, 16), serial or None)
        if url.startswith(("vfio://", "pci://")):
            from .pci_card import VfioCard
            return PciData(VfioCard(pci_address(url.partition("://")[2])))
        if url.startswith("/"):
            return NodeData(url)
    except (OSError, ConnectionError) as exc:
        raise LinkError(f"cannot open data channel {url}: {exc}") from None
    raise ValueError(f"data channel {url!r}: use usb://VID:PID[/SERIAL], vfio://BDF, /dev/NODE "
                     f"or tcp://HOST:PORT")


def pci_address(text: str) -> str:
    """'0000:03:00.0' or '03:00.0' (domain 0) -> the full address sysfs and VFIO use."""
    import re
    t = text.strip().lower()
    if re.fullmatch(r"[0-9a-f]{2}:[0-9a-f]{2}\.[0-7]", t):
        t = "0000:" + t
    if not re.fullmatch(r"[0-9a-f]{4}:[0-9a-f]{2}:[0-9a-f]{2}\.[0-7]", t):
        raise ValueError(f"PCI address {text!r}: use DOMAIN:BUS:DEVICE.FUNCTION, e.g. "
                         f"0000:03:00.0 (lspci -D)")
    return t


def parse_link_spec(spec: str) -> dict:
    """'serial=PORT,data=URL[,baud=N]' -> its parts; ValueError saying what is missing."""
    parts = dict(p.split("=", 1) for p in spec.split(",") if "=" in p)
    if "serial" not in parts or "data" not in parts:
        raise ValueError(f"device spec {spec!r}: use 'emulator', 'emulator-usb', 'emulator-pci' or "
                         f"'serial=PORT,data=URL' (docs/driver.md)")
    return parts


def open_serial(port: str, profile: Profile, baud: int | None = None):
    """The command channel's serial port (pyserial: a tty, a pty or socket://HOST:PORT)."""
    import serial  # pyserial
    try:
        return serial.serial_for_url(port, baudrate=int(baud or profile.link.baud),
                                     timeout=0.02)
    except (serial.SerialException, ValueError) as exc:
        raise LinkError(f"cannot open {port}: {exc}") from None


def open_link_device(spec: str, profile: Profile, data=None) -> Device:
    """A printer on real links from 'serial=PORT,data=URL[,baud=N]'.  `data`: an already
    opened data channel (the application's own transports), else opened from the URL."""
    parts = parse_link_spec(spec)
    port = open_serial(parts["serial"], profile, parts.get("baud"))
    try:
        if data is None:
            data = open_data(parts["data"])
    except Exception:
        port.close()
        raise
    return Device(CommandLink(port, profile.link.response_timeout_s), data, profile)
