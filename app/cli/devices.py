"""`wideprint devices`: the serial ports, USB printers, PCI cards and device nodes this
machine can reach."""

from __future__ import annotations

from .common import EXIT_OK


def cmd_devices(args) -> int:
    """What printers this machine can reach: serial ports, USB printers, device nodes."""
    import glob
    from ...driver.transport import USB_PID, USB_VID
    try:
        from serial.tools import list_ports
        ports = list(list_ports.comports())
    except Exception as exc:  # noqa: BLE001 - listing must never crash
        ports, err = [], exc
        print(f"serial ports: cannot list ({err})")
    print("serial ports (command channel):")
    for p in ports:
        print(f"  {p.device:20s} {p.description}" + (f" [{p.hwid}]" if p.hwid != "n/a" else ""))
    if not ports:
        print("  none")
    print(f"USB printers {USB_VID:04x}:{USB_PID:04x} (data channel):")
    try:
        import usb.core
        import usb.util
        found = list(usb.core.find(find_all=True, idVendor=USB_VID, idProduct=USB_PID) or [])
        for d in found:
            try:
                serial = usb.util.get_string(d, d.iSerialNumber)
            except Exception:  # noqa: BLE001 - no permission: say so
                serial = "? (no permission: install resources/udev/60-wideprint.rules)"
            print(f"  usb://{USB_VID:04x}:{USB_PID:04x}/{serial}  bus {d.bus} address {d.address}")
        if not found:
            print("  none")
    except usb.core.NoBackendError:
        print("  cannot look: libusb-1.0 is not installed (Debian: apt-get install libusb-1.0-0)")
    from ...driver.vfio import list_plx9054
    print("PCI cards (PLX 9054, data channel through vfio-pci; docs/pci.md):")
    cards = list_plx9054()
    for c in cards:
        if not c["wideprint"]:
            print(f"  {c['address']}  a PLX 9054 that is not a wideprint card (subsystem "
                  f"{c['subsystem']}); usable only as vfio://{c['address']} if it is one")
            continue
        state = "ready" if not c["problems"] else "not ready: " + "; ".join(c["problems"])
        print(f"  vfio://{c['address']}  {state}")
    if not cards:
        print("  none")
    nodes = sorted(glob.glob("/dev/wideprint*"))
    print("device nodes (data channel):")
    for n in nodes:
        print(f"  {n}")
    if not nodes:
        print("  none")
    print("emulator: --device emulator (in-process), or run `wideprint emulator` for a spec")
    return EXIT_OK


def add_parser(sub) -> None:
    p = sub.add_parser("devices", help="list the serial ports, USB printers and device nodes")
    p.set_defaults(func=cmd_devices)
