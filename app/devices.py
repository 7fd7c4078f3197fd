"""Device specs -> devices: the one place that composes printers (docs/driver.md).

    emulator                      the emulator in-process (tests, demos, acceptance runs)
    emulator-usb                  the same, its data channel through pyusb
    emulator-pci                  the same, its data channel the PCI card at register level
                                  (the host's PciData over device_sim.pci_card, docs/pci.md)
    serial=PORT,data=URL[,baud=N] a real printer or a standalone emulator
        PORT: /dev/ttyS0, /dev/ttyUSB0, /dev/pts/N, or socket://HOST:PORT (pyserial)
        URL:  usb://VID:PID[/SERIAL]   USB bulk (libusb)
              vfio://BDF               the PCI card through vfio-pci (docs/pci.md)
              /dev/NODE                a device node (or a pty stand-in)
              tcp://HOST:PORT          the standalone emulator's data port
              usb-emu://HOST:PORT      the standalone emulator as a USB device (pyusb)

The driver (driver/) knows links and printers, never the emulator; the emulator
(device_sim/) knows only the wire.  Only here do the two meet, for the command line, the
GUI and the print server alike.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:          # imported when a device is opened: `--help` stays light
    from ..driver.device import Device
    from ..rip.profile import Profile

EMULATOR_SPECS = ("emulator", "emulator-usb", "emulator-pci")
DEVICE_HELP = ("the printer: emulator (in-process), emulator-usb (in-process, data through "
               "pyusb), emulator-pci (in-process, data through the emulated PCI card), or "
               "serial=PORT,data=URL[,baud=N] with PORT a tty, pty or socket://HOST:PORT and URL "
               "usb://VID:PID[/SERIAL], vfio://BDF (the PCI card), /dev/NODE, tcp://HOST:PORT "
               "or usb-emu://HOST:PORT (docs/driver.md)")


def is_emulator_spec(spec: str) -> bool:
    return spec.strip() in EMULATOR_SPECS


def parse_inject(items: list[str] | None):
    """`--inject KIND=VALUE` items as the emulator's Faults (ValueError naming the bad one)."""
    from ..device_sim.faults import Faults
    return Faults.parse(items)


def open_device(spec: str, profile: "Profile", faults=None, media_path=None, event_log=None,
                machine_profile: "Profile | None" = None, *,
                printer_class=None, wrap: Callable | None = None, inject: list[str] | None = None,
                live=None, **emulator_options) -> Device:
    """Open the device a spec names.

    For the in-process emulator: it is built from `machine_profile` (the machine as it
    really is; default: the job's profile), `faults`, `media_path` (a path, or a function
    of the job id), `event_log` and `emulator_options` (vcd_path, vcd_window,
    record_latched, scan_path and scan_dpi: docs/physical.md); `printer_class` replaces device_sim's Printer (the GUI's live view)
    and `wrap(port, data, printer) -> (port, data)` wraps its endpoints (the GUI paces
    them to the machine's real speed).  The emulator is attached as `device.emulator`."""
    from ..driver.device import Device, Timing, open_link_device, parse_link_spec
    from ..driver.link import CommandLink, LinkError
    from ..driver.transport import TcpData, UsbData
    spec = spec.strip()
    if inject and faults is None:
        faults = parse_inject(inject)
    if spec in EMULATOR_SPECS:
        from ..device_sim.endpoints import in_process
        from ..device_sim.printer import Printer
        if live is not None and printer_class is None:
            from .livemedia import live_printer_class
            printer_class = live_printer_class()
        printer = (printer_class or Printer)(machine_profile or profile, faults,
                                             media_path=media_path, event_log=event_log,
                                             **emulator_options)
        if live is not None:
            printer.live = live
        port, data = in_process(printer)
        lock = data.lock
        if wrap is not None:
            port, data = wrap(port, data, printer)
        if spec == "emulator-usb":
            from ..device_sim.usb_backend import EmulatorUsbBackend
            data = UsbData(backend=EmulatorUsbBackend(data))
        elif spec == "emulator-pci":
            from ..device_sim.pci_card import EmulatedPciCard
            from ..driver.transport import PciData
            data = PciData(EmulatedPciCard(printer, lock))
        link = CommandLink(port, profile.link.response_timeout_s)
        return Device(link, data, profile, emulator=printer, timing=Timing.synchronous())
    if emulator_options.get("scan_path"):
        raise ValueError(f"a scan needs the in-process emulator (--device emulator), not {spec}")
    parts = parse_link_spec(spec)
    data = None
    if parts["data"].startswith("usb-emu://"):
        # a standalone emulator presenting itself as a USB device: pyusb over its TCP port
        from ..device_sim.usb_backend import EmulatorUsbBackend
        host, _, port_no = parts["data"][len("usb-emu://"):].rpartition(":")
        try:
            data = UsbData(backend=EmulatorUsbBackend(TcpData(host or "127.0.0.1", int(port_no))))
        except (OSError, ConnectionError) as exc:
            raise LinkError(f"cannot open data channel {parts['data']}: {exc}") from None
    return open_link_device(spec, profile, data=data)


def close_device(dev: "Device") -> None:
    """Close a device; an in-process emulator first finishes its outputs (media, logs)."""
    try:
        if dev.emulator is not None:
            dev.emulator.close()
    finally:
        dev.close()


def emulated_seconds(printer, job_id: int) -> float | None:
    """How long the emulated printer took for a job in its own (simulated) time: from the
    job's JOB_BEGIN to its JOB_END, or to now for a job that stopped; what the real printer
    would take.  None when the event log no longer holds the job's start."""
    end = None
    for e in reversed(printer.events):
        if e.get("job") != job_id:
            continue
        if e["event"] == "job_end" and end is None:
            end = e["t"]
        elif e["event"] == "job_begin":
            return round((printer.time if end is None else end) - e["t"], 3)
    return None
