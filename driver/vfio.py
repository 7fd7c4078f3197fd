"""Linux VFIO from user space, standard library only (docs/pci.md section 7).

The ioctl numbers and structures are those of `linux/vfio.h` (API version 0): every ioctl
is `_IO(VFIO_TYPE, VFIO_BASE + n)` with VFIO_TYPE ';' and VFIO_BASE 100, and takes a
structure whose first field `argsz` is its size.  tests/test_pci.py compiles a C program
against the system's header and checks each number, size and offset below.

    container = VfioContainer()                 # /dev/vfio/vfio
    group = VfioGroup(group_of("0000:03:00.0")) # /dev/vfio/N, viable, joined to the container
    container.set_iommu()                       # type1 (v2 when offered)
    dev = VfioDevice(group, "0000:03:00.0")     # regions (BARs, config), interrupts
    buf = container.map_dma(65536, iova)        # host memory the device may read and write
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import mmap
import os
import select
from pathlib import Path

VFIO_API_VERSION = 0
VFIO_TYPE = ord(";")
VFIO_BASE = 100


def _io(n: int) -> int:
    """_IO(VFIO_TYPE, VFIO_BASE + n): no direction and no size bits."""
    return (VFIO_TYPE << 8) | (VFIO_BASE + n)


VFIO_GET_API_VERSION = _io(0)           # 0x3B64
VFIO_CHECK_EXTENSION = _io(1)
VFIO_SET_IOMMU = _io(2)
VFIO_GROUP_GET_STATUS = _io(3)
VFIO_GROUP_SET_CONTAINER = _io(4)
VFIO_GROUP_UNSET_CONTAINER = _io(5)
VFIO_GROUP_GET_DEVICE_FD = _io(6)
VFIO_DEVICE_GET_INFO = _io(7)
VFIO_DEVICE_GET_REGION_INFO = _io(8)
VFIO_DEVICE_GET_IRQ_INFO = _io(9)
VFIO_DEVICE_SET_IRQS = _io(10)
VFIO_DEVICE_RESET = _io(11)
VFIO_IOMMU_GET_INFO = _io(12)
VFIO_IOMMU_MAP_DMA = _io(13)
VFIO_IOMMU_UNMAP_DMA = _io(14)          # 0x3B72

VFIO_TYPE1_IOMMU = 1
VFIO_TYPE1v2_IOMMU = 3
VFIO_GROUP_FLAGS_VIABLE = 1 << 0
VFIO_GROUP_FLAGS_CONTAINER_SET = 1 << 1
VFIO_DEVICE_FLAGS_RESET = 1 << 0
VFIO_DEVICE_FLAGS_PCI = 1 << 1
VFIO_REGION_INFO_FLAG_READ = 1 << 0
VFIO_REGION_INFO_FLAG_WRITE = 1 << 1
VFIO_REGION_INFO_FLAG_MMAP = 1 << 2
VFIO_PCI_BAR0_REGION_INDEX = 0
VFIO_PCI_CONFIG_REGION_INDEX = 7
VFIO_PCI_INTX_IRQ_INDEX = 0
VFIO_PCI_ERR_IRQ_INDEX = 3
VFIO_IRQ_INFO_EVENTFD = 1 << 0
VFIO_IRQ_INFO_MASKABLE = 1 << 1
VFIO_IRQ_INFO_AUTOMASKED = 1 << 2
VFIO_IRQ_SET_DATA_NONE = 1 << 0
VFIO_IRQ_SET_DATA_BOOL = 1 << 1
VFIO_IRQ_SET_DATA_EVENTFD = 1 << 2
VFIO_IRQ_SET_ACTION_MASK = 1 << 3
VFIO_IRQ_SET_ACTION_UNMASK = 1 << 4
VFIO_IRQ_SET_ACTION_TRIGGER = 1 << 5
VFIO_DMA_MAP_FLAG_READ = 1 << 0
VFIO_DMA_MAP_FLAG_WRITE = 1 << 1

u32, u64, s32 = ctypes.c_uint32, ctypes.c_uint64, ctypes.c_int32


class vfio_group_status(ctypes.Structure):
    _fields_ = [("argsz", u32), ("flags", u32)]


class vfio_device_info(ctypes.Structure):
    _fields_ = [("argsz", u32), ("flags", u32), ("num_regions", u32), ("num_irqs", u32),
                ("cap_offset", u32)]


class vfio_region_info(ctypes.Structure):
    _fields_ = [("argsz", u32), ("flags", u32), ("index", u32), ("cap_offset", u32),
                ("size", u64), ("offset", u64)]


class vfio_irq_info(ctypes.Structure):
    _fields_ = [("argsz", u32), ("flags", u32), ("index", u32), ("count", u32)]


class vfio_irq_set(ctypes.Structure):
    """The header; `data[]` (here: one eventfd) follows it (vfio_irq_set_fd)."""
    _fields_ = [("argsz", u32), ("flags", u32), ("index", u32), ("start", u32), ("count", u32)]


class vfio_irq_set_fd(ctypes.Structure):
    _fields_ = [("hdr", vfio_irq_set), ("fd", s32)]


class vfio_iommu_type1_dma_map(ctypes.Structure):
    _fields_ = [("argsz", u32), ("flags", u32), ("vaddr", u64), ("iova", u64), ("size", u64)]


class vfio_iommu_type1_dma_unmap(ctypes.Structure):
    _fields_ = [("argsz", u32), ("flags", u32), ("iova", u64), ("size", u64)]


STRUCTURES = (vfio_group_status, vfio_device_info, vfio_region_info, vfio_irq_info,
              vfio_irq_set, vfio_iommu_type1_dma_map, vfio_iommu_type1_dma_unmap)


def _new(cls, **fields):
    obj = cls(**fields)
    obj.argsz = ctypes.sizeof(cls)
    return obj


class VfioError(OSError):
    """An ioctl or open that failed, with what was being done and what to check."""


def _ioctl(fd: int, request: int, arg, what: str) -> int:
    try:
        return fcntl.ioctl(fd, request, arg, True) if not isinstance(arg, int) \
            else fcntl.ioctl(fd, request, arg)
    except OSError as exc:
        raise VfioError(exc.errno, f"{what}: {os.strerror(exc.errno)}") from None


def _open(path: str, what: str) -> int:
    try:
        return os.open(path, os.O_RDWR | os.O_CLOEXEC)
    except FileNotFoundError:
        raise VfioError(errno.ENOENT, f"{path} does not exist: {what}") from None
    except PermissionError:
        raise VfioError(errno.EACCES, f"{path}: permission denied (install "
                        f"resources/udev/60-wideprint.rules, docs/pci.md 7)") from None


# -- sysfs: where the card is, who drives it ---------------------------------------------------
SYSFS_PCI = Path("/sys/bus/pci/devices")


def _attr(dev: Path, name: str) -> str:
    try:
        return (dev / name).read_text().strip()
    except OSError:
        return ""


def group_of(bdf: str, sysfs: Path = SYSFS_PCI) -> int:
    link = sysfs / bdf / "iommu_group"
    if not (sysfs / bdf).exists():
        raise VfioError(errno.ENODEV, f"no PCI device {bdf} (lspci -D lists the addresses)")
    if not link.exists():
        raise VfioError(errno.ENODEV, f"{bdf} has no IOMMU group: enable the IOMMU "
                        f"(intel_iommu=on on Intel; docs/pci.md 7)")
    return int(os.path.basename(os.readlink(link)))


def driver_of(dev: Path) -> str | None:
    link = dev / "driver"
    return os.path.basename(os.readlink(link)) if link.exists() else None


def describe(bdf: str, sysfs: Path = SYSFS_PCI) -> list[str]:
    """What stands between this machine and driving the card at `bdf` through VFIO
    (empty: nothing)."""
    dev = sysfs / bdf
    problems = []
    drv = driver_of(dev)
    if drv != "vfio-pci":
        problems.append(f"not bound to vfio-pci (bound to {drv or 'no driver'}; bind: "
                        f"sudo driverctl set-override {bdf} vfio-pci)")
    try:
        group = group_of(bdf, sysfs)
    except VfioError as exc:
        return problems + [exc.strerror]
    others = []
    for member in sorted((dev / "iommu_group").resolve().joinpath("devices").glob("*")):
        d = driver_of(member)
        if member.name != bdf and d not in (None, "vfio-pci", "pci-stub", "pcieport"):
            others.append(f"{member.name} is bound to {d}")
    if others:
        problems.append(f"IOMMU group {group} is not viable: " + "; ".join(others)
                        + " (give those devices to vfio-pci too)")
    node = f"/dev/vfio/{group}"
    if drv == "vfio-pci":
        if not os.path.exists(node):
            problems.append(f"{node} is missing (is the vfio-pci module loaded?)")
        elif not os.access(node, os.R_OK | os.W_OK):
            problems.append(f"{node}: permission denied (install resources/udev/60-wideprint.rules)")
    return problems


def list_plx9054(sysfs: Path = SYSFS_PCI, vendor: int = 0x10B5, device: int = 0x9054,
                 subvendor: int = 0x1209, subdevice: int = 0x5750) -> list[dict]:
    """Every PLX 9054 function: address, subsystem IDs, whether it is a wideprint card,
    its driver and what is missing to drive it (docs/pci.md 1, 7)."""
    out = []
    for dev in sorted(sysfs.glob("*")) if sysfs.exists() else []:
        if _attr(dev, "vendor") != f"0x{vendor:04x}" or _attr(dev, "device") != f"0x{device:04x}":
            continue
        sv, sd = _attr(dev, "subsystem_vendor"), _attr(dev, "subsystem_device")
        out.append({"address": dev.name, "subsystem": f"{sv[2:]}:{sd[2:]}",
                    "wideprint": sv == f"0x{subvendor:04x}" and sd == f"0x{subdevice:04x}",
                    "driver": driver_of(dev), "problems": describe(dev.name, sysfs)})
    return out


# -- container, group, device ------------------------------------------------------------------
class MappedBuffer:
    """Anonymous page-aligned host memory mapped for the device at `iova`."""

    def __init__(self, size: int, iova: int):
        self.size = -(-size // mmap.PAGESIZE) * mmap.PAGESIZE
        self.iova = iova
        self._map = mmap.mmap(-1, self.size, flags=mmap.MAP_SHARED | mmap.MAP_ANONYMOUS,
                              prot=mmap.PROT_READ | mmap.PROT_WRITE)
        self._anchor = ctypes.c_char.from_buffer(self._map)
        self.vaddr = ctypes.addressof(self._anchor)
        self.mem = memoryview(self._map)

    def close(self) -> None:
        self.mem.release()
        del self._anchor
        self._map.close()


class VfioContainer:
    def __init__(self, path: str = "/dev/vfio/vfio"):
        self.fd = _open(path, "load the vfio module (modprobe vfio-pci)")
        version = _ioctl(self.fd, VFIO_GET_API_VERSION, 0, "VFIO_GET_API_VERSION")
        if version != VFIO_API_VERSION:
            raise VfioError(errno.EPROTO, f"unknown VFIO API version {version}")
        self.iommu = None
        self.maps: dict[int, MappedBuffer] = {}

    def set_iommu(self) -> int:
        for kind in (VFIO_TYPE1v2_IOMMU, VFIO_TYPE1_IOMMU):
            if _ioctl(self.fd, VFIO_CHECK_EXTENSION, kind, "VFIO_CHECK_EXTENSION"):
                _ioctl(self.fd, VFIO_SET_IOMMU, kind, "VFIO_SET_IOMMU")
                self.iommu = kind
                return kind
        raise VfioError(errno.ENODEV, "the kernel offers no type1 IOMMU for VFIO "
                        "(is the IOMMU enabled? docs/pci.md 7)")

    def map_dma(self, size: int, iova: int) -> MappedBuffer:
        buf = MappedBuffer(size, iova)
        arg = _new(vfio_iommu_type1_dma_map, flags=VFIO_DMA_MAP_FLAG_READ | VFIO_DMA_MAP_FLAG_WRITE,
                   vaddr=buf.vaddr, iova=iova, size=buf.size)
        try:
            _ioctl(self.fd, VFIO_IOMMU_MAP_DMA, arg,
                   f"VFIO_IOMMU_MAP_DMA of {buf.size} bytes at IOVA {iova:#x} "
                   f"(locked memory: raise RLIMIT_MEMLOCK, docs/pci.md 7)")
        except VfioError:
            buf.close()
            raise
        self.maps[iova] = buf
        return buf

    def unmap_dma(self, buf: MappedBuffer) -> None:
        arg = _new(vfio_iommu_type1_dma_unmap, iova=buf.iova, size=buf.size)
        try:
            _ioctl(self.fd, VFIO_IOMMU_UNMAP_DMA, arg, "VFIO_IOMMU_UNMAP_DMA")
        finally:
            self.maps.pop(buf.iova, None)
            buf.close()

    def close(self) -> None:
        for buf in list(self.maps.values()):
            try:
                self.unmap_dma(buf)
            except VfioError:
                pass
        os.close(self.fd)


class VfioGroup:
    def __init__(self, group: int, container: VfioContainer):
        self.number = group
        self.fd = _open(f"/dev/vfio/{group}", "bind the card to vfio-pci (docs/pci.md 7)")
        status = _new(vfio_group_status)
        _ioctl(self.fd, VFIO_GROUP_GET_STATUS, status, "VFIO_GROUP_GET_STATUS")
        if not status.flags & VFIO_GROUP_FLAGS_VIABLE:
            os.close(self.fd)
            raise VfioError(errno.EBUSY, f"IOMMU group {group} is not viable: a device in "
                            f"/sys/kernel/iommu_groups/{group}/devices is bound to another "
                            f"driver (give it to vfio-pci too)")
        _ioctl(self.fd, VFIO_GROUP_SET_CONTAINER, ctypes.c_int(container.fd),
               "VFIO_GROUP_SET_CONTAINER")

    def device_fd(self, bdf: str) -> int:
        return _ioctl(self.fd, VFIO_GROUP_GET_DEVICE_FD, bytearray(bdf.encode() + b"\0"),
                      f"VFIO_GROUP_GET_DEVICE_FD {bdf}")

    def close(self) -> None:
        os.close(self.fd)


class Region:
    """One device region: a BAR or the configuration space; mmapped when it can be."""

    def __init__(self, fd: int, info: vfio_region_info):
        self.fd, self.index = fd, info.index
        self.size, self.offset, self.flags = info.size, info.offset, info.flags
        self.words = None
        self._map = None
        if info.flags & VFIO_REGION_INFO_FLAG_MMAP and info.size >= mmap.PAGESIZE:
            try:
                self._map = mmap.mmap(fd, info.size, flags=mmap.MAP_SHARED,
                                      prot=mmap.PROT_READ | mmap.PROT_WRITE, offset=info.offset)
                self.words = (ctypes.c_uint32 * (info.size // 4)).from_buffer(self._map)
            except OSError:
                self._map = None

    def read(self, offset: int, size: int) -> int:
        if self.words is not None and size == 4:
            return self.words[offset >> 2]
        return int.from_bytes(os.pread(self.fd, size, self.offset + offset), "little")

    def write(self, offset: int, size: int, value: int) -> None:
        if self.words is not None and size == 4:
            self.words[offset >> 2] = value
            return
        os.pwrite(self.fd, int(value).to_bytes(size, "little"), self.offset + offset)

    def close(self) -> None:
        self.words = None
        if self._map is not None:
            self._map.close()


class VfioDevice:
    def __init__(self, group: VfioGroup, bdf: str):
        self.bdf = bdf
        self.fd = group.device_fd(bdf)
        info = _new(vfio_device_info)
        _ioctl(self.fd, VFIO_DEVICE_GET_INFO, info, "VFIO_DEVICE_GET_INFO")
        if not info.flags & VFIO_DEVICE_FLAGS_PCI:
            raise VfioError(errno.ENODEV, f"{bdf} is not a PCI device")
        self.num_regions, self.num_irqs = info.num_regions, info.num_irqs
        self.regions: dict[int, Region] = {}
        self.eventfds: dict[int, int] = {}

    def region(self, index: int) -> Region:
        if index not in self.regions:
            info = _new(vfio_region_info, index=index)
            _ioctl(self.fd, VFIO_DEVICE_GET_REGION_INFO, info,
                   f"VFIO_DEVICE_GET_REGION_INFO {index}")
            if info.size == 0:
                raise VfioError(errno.ENODEV, f"{self.bdf}: region {index} is not implemented")
            self.regions[index] = Region(self.fd, info)
        return self.regions[index]

    def irq_info(self, index: int) -> vfio_irq_info:
        info = _new(vfio_irq_info, index=index)
        _ioctl(self.fd, VFIO_DEVICE_GET_IRQ_INFO, info, f"VFIO_DEVICE_GET_IRQ_INFO {index}")
        return info

    def irq_eventfd(self, index: int) -> int:
        """An eventfd the kernel signals when interrupt `index` (vector 0) fires."""
        info = self.irq_info(index)
        if info.count < 1 or not info.flags & VFIO_IRQ_INFO_EVENTFD:
            raise VfioError(errno.ENODEV, f"{self.bdf}: interrupt index {index} unavailable")
        efd = os.eventfd(0, os.EFD_CLOEXEC | os.EFD_NONBLOCK)
        arg = vfio_irq_set_fd(_new(vfio_irq_set, flags=VFIO_IRQ_SET_DATA_EVENTFD
                                   | VFIO_IRQ_SET_ACTION_TRIGGER, index=index, start=0, count=1),
                              efd)
        arg.hdr.argsz = ctypes.sizeof(arg)
        try:
            _ioctl(self.fd, VFIO_DEVICE_SET_IRQS, arg, f"VFIO_DEVICE_SET_IRQS {index}")
        except VfioError:
            os.close(efd)
            raise
        self.eventfds[index] = efd
        return efd

    def irq_unmask(self, index: int = VFIO_PCI_INTX_IRQ_INDEX) -> None:
        arg = _new(vfio_irq_set, flags=VFIO_IRQ_SET_DATA_NONE | VFIO_IRQ_SET_ACTION_UNMASK,
                   index=index, start=0, count=1)
        _ioctl(self.fd, VFIO_DEVICE_SET_IRQS, arg, "VFIO_DEVICE_SET_IRQS unmask")

    def irq_disable(self, index: int) -> None:
        arg = _new(vfio_irq_set, flags=VFIO_IRQ_SET_DATA_NONE | VFIO_IRQ_SET_ACTION_TRIGGER,
                   index=index, start=0, count=0)
        _ioctl(self.fd, VFIO_DEVICE_SET_IRQS, arg, "VFIO_DEVICE_SET_IRQS disable")

    def close(self) -> None:
        for index, efd in list(self.eventfds.items()):
            try:
                self.irq_disable(index)
            except VfioError:
                pass
            os.close(efd)
        self.eventfds.clear()
        for region in self.regions.values():
            region.close()
        os.close(self.fd)


def wait_eventfd(fds: list[int], timeout: float) -> list[int]:
    """The eventfds of `fds` that fired within `timeout` seconds (their counters read)."""
    ready, _, _ = select.select(fds, [], [], max(0.0, timeout))
    for fd in ready:
        try:
            os.eventfd_read(fd)
        except BlockingIOError:
            pass
    return ready
