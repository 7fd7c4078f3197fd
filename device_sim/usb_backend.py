"""The emulated printer as a USB device, through a custom pyusb backend.

pyusb's `usb.core.find(backend=...)` enumerates whatever the backend reports; this one
reports the printer's USB function (VID 0x1209, PID 0x5750, one vendor-class interface with
bulk OUT 0x01 for data blocks and bulk IN 0x81 for FPGA reports, docs/driver.md) and
carries its bulk transfers to a data-channel endpoint: the in-process emulator, or the
standalone emulator's TCP data port.  The host code above it is the real USB code.
"""

from __future__ import annotations

import array
from types import SimpleNamespace

import usb.backend
import usb.core

from ..driver.protocol import EP_IN, EP_OUT, USB_PID, USB_VID

STRINGS = {1: "wideprint", 2: "WP-3400 print data (emulated)", 3: "WP3400-EMU-0001"}
LANGID_EN_US = 0x0409


def _device_descriptor():
    return SimpleNamespace(
        bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0, bDeviceSubClass=0,
        bDeviceProtocol=0, bMaxPacketSize0=64, idVendor=USB_VID, idProduct=USB_PID,
        bcdDevice=0x0100, iManufacturer=1, iProduct=2, iSerialNumber=3, bNumConfigurations=1,
        address=7, bus=1, port_number=1, port_numbers=(1,), speed=3)   # speed 3 = high


class EmulatorUsbBackend(usb.backend.IBackend):
    """`endpoint`: an object with send(bytes), recv(timeout) -> bytes, reconnect()."""

    def __init__(self, endpoint):
        super().__init__()
        self.endpoint = endpoint
        self._dev = object()
        self._config = 0

    def reconnect(self) -> None:
        if hasattr(self.endpoint, "reconnect") and not getattr(self.endpoint, "open", True):
            self.endpoint.reconnect()

    # -- descriptors ------------------------------------------------------------------
    def enumerate_devices(self):
        yield self._dev

    def get_device_descriptor(self, dev):
        return _device_descriptor()

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError("configuration index out of range")
        return SimpleNamespace(bLength=9, bDescriptorType=2, wTotalLength=32, bNumInterfaces=1,
                               bConfigurationValue=1, iConfiguration=0, bmAttributes=0xC0,
                               bMaxPower=50, extra_descriptors=[])

    def get_interface_descriptor(self, dev, intf, alt, config):
        if config != 0 or intf != 0 or alt != 0:
            raise IndexError("interface index out of range")
        return SimpleNamespace(bLength=9, bDescriptorType=4, bInterfaceNumber=0,
                               bAlternateSetting=0, bNumEndpoints=2, bInterfaceClass=0xFF,
                               bInterfaceSubClass=0, bInterfaceProtocol=0, iInterface=0,
                               extra_descriptors=[])

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        if config != 0 or intf != 0 or alt != 0 or ep not in (0, 1):
            raise IndexError("endpoint index out of range")
        addr = (EP_OUT, EP_IN)[ep]
        return SimpleNamespace(bLength=7, bDescriptorType=5, bEndpointAddress=addr,
                               bmAttributes=0x02, wMaxPacketSize=512, bInterval=0,
                               bRefresh=0, bSynchAddress=0, extra_descriptors=[])

    # -- handles ----------------------------------------------------------------------
    def open_device(self, dev):
        return dev

    def close_device(self, dev_handle):
        pass

    def set_configuration(self, dev_handle, config_value):
        self._config = config_value

    def get_configuration(self, dev_handle):
        return self._config

    def claim_interface(self, dev_handle, intf):
        pass

    def release_interface(self, dev_handle, intf):
        pass

    def set_interface_altsetting(self, dev_handle, intf, altsetting):
        pass

    def is_kernel_driver_active(self, dev_handle, intf):
        return False

    def clear_halt(self, dev_handle, ep):
        pass

    def reset_device(self, dev_handle):
        pass

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        # GET_DESCRIPTOR (string) is all the host asks for
        if bmRequestType == 0x80 and bRequest == 6 and wValue >> 8 == 3:
            index = wValue & 0xFF
            if index == 0:
                body = LANGID_EN_US.to_bytes(2, "little")
            elif index in STRINGS:
                body = STRINGS[index].encode("utf-16-le")
            else:
                raise usb.core.USBError("no such string", errno=32)
            desc = bytes((2 + len(body), 3)) + body
            n = min(len(desc), len(data))
            data[:n] = array.array("B", desc[:n])
            return n
        if bmRequestType & 0x80:
            return 0
        return len(data) if data is not None else 0

    # -- bulk ---------------------------------------------------------------------------
    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        if ep != EP_OUT:
            raise usb.core.USBError("not an OUT endpoint", errno=32)
        try:
            self.endpoint.send(bytes(data))
        except ConnectionError as exc:
            raise usb.core.USBError(f"device disconnected: {exc}", errno=19) from None
        return len(data)

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        if ep != EP_IN:
            raise usb.core.USBError("not an IN endpoint", errno=32)
        try:
            got = self.endpoint.recv(timeout / 1000 if timeout else 0.0)
        except ConnectionError as exc:
            raise usb.core.USBError(f"device disconnected: {exc}", errno=19) from None
        if not got:
            raise usb.core.USBTimeoutError("timeout", errno=110, error_code=-7)
        if len(got) > len(buff):
            raise usb.core.USBError("overflow", errno=75)
        buff[:len(got)] = array.array("B", got)
        return len(got)
