"""The PCI card (issue 19, docs/pci.md): the VFIO structures and ioctl numbers against
linux/vfio.h itself, the PLX 9054 and the FPGA at register level in the emulator, and the
host's PciData transport printing through the emulated card bit-exact, in chained and in
block mode, across injected card faults."""

import collections
import ctypes
import os
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from support.images import PX, random_planes, write_cmyk_tiff
from wideprint.app.devices import open_device
from wideprint.device_sim.faults import Faults
from wideprint.device_sim.pci_card import EmulatedPciCard
from wideprint.device_sim.printer import Printer
from wideprint.driver import protocol as P
from wideprint.driver import vfio as V
from wideprint.driver.device import open_data, parse_link_spec, pci_address
from wideprint.driver.job import JobError, PrintJob
from wideprint.driver.link import LinkError
from wideprint.driver.pci_card import CardError, check_card
from wideprint.driver.transport import PciData
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes
from wideprint.rip.profile import DEFAULT_PROFILE, load_profile

# -- VFIO: ctypes layouts and ioctl numbers ------------------------------------------------------
# The values linux/vfio.h gives (checked against the header below when a compiler is there).
SIZES = {"vfio_group_status": 8, "vfio_device_info": 20, "vfio_region_info": 32,
         "vfio_irq_info": 16, "vfio_irq_set": 20, "vfio_iommu_type1_dma_map": 32,
         "vfio_iommu_type1_dma_unmap": 24}
OFFSETS = {("vfio_device_info", "cap_offset"): 16, ("vfio_region_info", "index"): 8,
           ("vfio_region_info", "size"): 16, ("vfio_region_info", "offset"): 24,
           ("vfio_irq_set", "count"): 16, ("vfio_iommu_type1_dma_map", "vaddr"): 8,
           ("vfio_iommu_type1_dma_map", "iova"): 16, ("vfio_iommu_type1_dma_map", "size"): 24,
           ("vfio_iommu_type1_dma_unmap", "iova"): 8, ("vfio_iommu_type1_dma_unmap", "size"): 16,
           ("vfio_irq_info", "count"): 12}
IOCTLS = {"VFIO_GET_API_VERSION": 0x3B64, "VFIO_CHECK_EXTENSION": 0x3B65,
          "VFIO_SET_IOMMU": 0x3B66, "VFIO_GROUP_GET_STATUS": 0x3B67,
          "VFIO_GROUP_SET_CONTAINER": 0x3B68, "VFIO_GROUP_UNSET_CONTAINER": 0x3B69,
          "VFIO_GROUP_GET_DEVICE_FD": 0x3B6A, "VFIO_DEVICE_GET_INFO": 0x3B6B,
          "VFIO_DEVICE_GET_REGION_INFO": 0x3B6C, "VFIO_DEVICE_GET_IRQ_INFO": 0x3B6D,
          "VFIO_DEVICE_SET_IRQS": 0x3B6E, "VFIO_DEVICE_RESET": 0x3B6F,
          "VFIO_IOMMU_GET_INFO": 0x3B70, "VFIO_IOMMU_MAP_DMA": 0x3B71,
          "VFIO_IOMMU_UNMAP_DMA": 0x3B72}
CONSTANTS = ("VFIO_API_VERSION", "VFIO_TYPE1_IOMMU", "VFIO_TYPE1v2_IOMMU",
             "VFIO_GROUP_FLAGS_VIABLE", "VFIO_DEVICE_FLAGS_PCI", "VFIO_REGION_INFO_FLAG_MMAP",
             "VFIO_PCI_CONFIG_REGION_INDEX", "VFIO_PCI_INTX_IRQ_INDEX", "VFIO_PCI_ERR_IRQ_INDEX",
             "VFIO_IRQ_INFO_EVENTFD", "VFIO_IRQ_SET_DATA_NONE", "VFIO_IRQ_SET_DATA_EVENTFD",
             "VFIO_IRQ_SET_ACTION_UNMASK", "VFIO_IRQ_SET_ACTION_TRIGGER",
             "VFIO_DMA_MAP_FLAG_READ", "VFIO_DMA_MAP_FLAG_WRITE")


def test_vfio_structures_and_ioctls_have_the_documented_layout():
    for name, size in SIZES.items():
        assert ctypes.sizeof(getattr(V, name)) == size, name
    for (name, field), off in OFFSETS.items():
        assert getattr(V, name).__dict__[field].offset == off, (name, field)
    for name, number in IOCTLS.items():
        assert getattr(V, name) == number, name
    assert ctypes.sizeof(V.vfio_irq_set_fd) == 24      # the header and one eventfd


def test_vfio_layouts_match_the_systems_linux_vfio_h(tmp_path):
    """A C program compiled against <linux/vfio.h> prints sizeof, offsetof and every ioctl
    number and constant; the Python side must agree with each."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None or not Path("/usr/include/linux/vfio.h").exists():
        pytest.fail("no C compiler or no linux/vfio.h: apt-get install gcc libc6-dev "
                    "linux-libc-dev (resources/debian-packages.txt; .ci/run does)")
    lines = ['#include <stdio.h>', '#include <stddef.h>', '#include <linux/vfio.h>',
             'int main(void) {']
    for name in SIZES:
        lines.append(f'printf("size {name} %zu\\n", sizeof(struct {name}));')
    for name, field in OFFSETS:
        lines.append(f'printf("offset {name}.{field} %zu\\n", offsetof(struct {name}, {field}));')
    for name in (*IOCTLS, *CONSTANTS):
        lines.append(f'printf("value {name} %lu\\n", (unsigned long)({name}));')
    lines.append("return 0; }")
    src = tmp_path / "vfio_layout.c"
    src.write_text("\n".join(lines))
    subprocess.run([cc, str(src), "-o", str(tmp_path / "vfio_layout")], check=True)
    out = subprocess.run([str(tmp_path / "vfio_layout")], check=True, capture_output=True,
                         text=True).stdout
    seen = 0
    for line in out.splitlines():
        kind, name, value = line.split()
        value = int(value)
        if kind == "size":
            assert ctypes.sizeof(getattr(V, name)) == value, name
        elif kind == "offset":
            struct, field = name.split(".")
            assert getattr(V, struct).__dict__[field].offset == value, name
        else:
            assert getattr(V, name) == value, name
        seen += 1
    assert seen == len(SIZES) + len(OFFSETS) + len(IOCTLS) + len(CONSTANTS)


def test_the_9054_register_values_are_the_data_books():
    """docs/pci.md 2, 3: offsets and the DMAMODE values programmed (plx9080.h bits)."""
    assert (P.PLX_INTCSR, P.PLX_DMAMODE0, P.PLX_DMAPADR0, P.PLX_DMALADR0, P.PLX_DMASIZ0,
            P.PLX_DMADPR0, P.PLX_DMACSR0) == (0x68, 0x80, 0x84, 0x88, 0x8C, 0x90, 0xA8)
    assert P.DMAMODE_CHAINED == 0x00031F43 and P.DMAMODE_BLOCK == 0x00031D43
    assert P.INTCSR_HOST == (1 << 8) | (1 << 10) | (1 << 11) | (1 << 18)
    desc = P.encode_dma_desc(0x10002000, P.FPGA_DATA, 2072, 0x10000010 | P.DPR_PCI | P.DPR_END)
    assert desc == bytes.fromhex("00200010" "00100000" "18080000" "13000010")
    assert P.decode_dma_desc(desc) == (0x10002000, 0x1000, 2072, 0x10000013)


def test_pci_addresses_and_the_data_url():
    assert pci_address("03:00.0") == "0000:03:00.0"
    assert pci_address("0000:0A:1f.7") == "0000:0a:1f.7"
    with pytest.raises(ValueError, match="DOMAIN:BUS:DEVICE.FUNCTION"):
        pci_address("3:0.0")
    assert parse_link_spec("serial=/dev/ttyS0,data=vfio://0000:03:00.0")["data"] == "vfio://0000:03:00.0"
    with pytest.raises(LinkError, match="no PCI device 0000:7f:1f.7"):
        open_data("vfio://0000:7f:1f.7")


def _fake_sysfs(root: Path, driver: str | None, sub=("0x1209", "0x5750"), other=None):
    """A sysfs tree with one 9054 at 0000:03:00.0 in IOMMU group 12 (and `other` beside it)."""
    devices, groups = root / "devices", root / "iommu_groups" / "12" / "devices"
    groups.mkdir(parents=True)
    (root / "drivers").mkdir()
    for bdf, drv, ids in (("0000:03:00.0", driver, ("0x10b5", "0x9054") + sub),
                          *([("0000:03:00.1", other, ("0x8086", "0x1234", "0x0", "0x0"))] if other else [])):
        dev = devices / bdf
        dev.mkdir(parents=True)
        for attr, val in zip(("vendor", "device", "subsystem_vendor", "subsystem_device"), ids):
            (dev / attr).write_text(val + "\n")
        (dev / "iommu_group").symlink_to(root / "iommu_groups" / "12")
        (groups / bdf).symlink_to(dev)
        if drv:
            (root / "drivers" / drv).mkdir(exist_ok=True)
            (dev / "driver").symlink_to(root / "drivers" / drv)
    return devices


def test_devices_listing_says_what_is_missing(tmp_path):
    sysfs = _fake_sysfs(tmp_path / "a", None)
    (card,) = V.list_plx9054(sysfs)
    assert card["wideprint"] and card["address"] == "0000:03:00.0"
    assert "driverctl set-override 0000:03:00.0 vfio-pci" in card["problems"][0]
    sysfs = _fake_sysfs(tmp_path / "b", "vfio-pci", other="e1000e")
    problems = V.list_plx9054(sysfs)[0]["problems"]
    assert any("IOMMU group 12 is not viable: 0000:03:00.1 is bound to e1000e" in p for p in problems)
    sysfs = _fake_sysfs(tmp_path / "c", "vfio-pci", sub=("0x10b5", "0x9054"))
    assert V.list_plx9054(sysfs)[0]["wideprint"] is False


# -- the card at register level -------------------------------------------------------------------
def _block(printer, stroke=0, first=0, fires=16):
    words = np.arange(printer.n_heads * fires * 8, dtype=np.uint16).reshape(printer.n_heads, fires, 8)
    return P.encode_block(stroke, first, (1 << printer.n_heads) - 1, words)


def _armed(profile):
    """A printer whose FPGA expects stroke 0 (SET_LINE's register effect) and its card."""
    printer = Printer(profile)
    printer.fpga.write_reg(P.REG_STROKE_LO, 0)
    printer.fpga.write_reg(P.REG_STROKE_HI, 0)
    printer.fpga.write_reg(P.REG_FIRE_COUNT_LO, 64)
    card = EmulatedPciCard(printer, dma_bytes_s=None)
    card.config_write16(P.PCI_CFG_COMMAND, P.PCI_COMMAND_MASTER)
    card.write32(P.BAR_PLX, P.PLX_INTCSR, P.INTCSR_HOST)
    return printer, card


def test_block_mode_dma_moves_one_block_into_the_fifos(profile):
    printer, card = _armed(profile)
    blk = _block(printer)
    buf = card.dma_alloc(4096)
    buf.mem[:len(blk)] = blk
    for reg, val in ((P.PLX_DMAMODE0, P.DMAMODE_BLOCK), (P.PLX_DMAPADR0, buf.iova),
                     (P.PLX_DMALADR0, P.FPGA_DATA), (P.PLX_DMASIZ0, len(blk)), (P.PLX_DMADPR0, 0)):
        card.write32(P.BAR_PLX, reg, val)
    assert not card.read32(P.BAR_PLX, P.PLX_INTCSR) & P.INTCSR_DMA0_ACTIVE
    card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_ENABLE | P.DMACSR_START)
    assert card.read32(P.BAR_PLX, P.PLX_DMACSR0) & P.DMACSR_DONE
    assert card.read32(P.BAR_PLX, P.PLX_INTCSR) & P.INTCSR_DMA0_ACTIVE       # done interrupt
    assert card.read32(P.BAR_FPGA, P.FPGA_BLOCKS_MOVED) == 1
    assert [card.read32(P.BAR_FPGA, P.FPGA_FIFO_LEVEL0 + 4 * h) for h in range(8)] == \
        [128] * printer.n_heads + [0] * (8 - printer.n_heads)
    flags = card.read32(P.BAR_FPGA, P.FPGA_FIFO_FLAGS0)
    assert not flags & (P.FIFO_EMPTY | P.FIFO_FULL) and flags & P.FIFO_DREQ   # half full: DREQ
    assert (flags >> P.FIFO_WR_COUNT_SHIFT) & 3 == 2
    # the report the move queued, through the report FIFO
    n = card.read32(P.BAR_FPGA, P.FPGA_REPORT_COUNT)
    assert n == P.ReportDecoder.SIZE // 4
    raw = b"".join(card.read32(P.BAR_FPGA, P.FPGA_REPORT_DATA).to_bytes(4, "little") for _ in range(n))
    (rep,) = P.ReportDecoder().feed(raw)
    assert (rep.blocks, rep.fifo[0]) == (1, 128)
    card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_ENABLE | P.DMACSR_CLEAR_INT)
    assert not card.read32(P.BAR_PLX, P.PLX_INTCSR) & P.INTCSR_DMA0_ACTIVE


def _chain(card, blocks, bufs, descs, end_at=None):
    for i, blk in enumerate(blocks):
        bufs.mem[i * 4096:i * 4096 + len(blk)] = blk
        last = i == len(blocks) - 1
        dpr = P.DPR_PCI | ((P.DPR_END | P.DPR_TC_INT) if last else 0) | \
            (0 if last else descs.iova + 16 * (i + 1))
        descs.mem[16 * i:16 * i + 16] = P.encode_dma_desc(bufs.iova + i * 4096, P.FPGA_DATA, len(blk), dpr)
    card.write32(P.BAR_PLX, P.PLX_DMAMODE0, P.DMAMODE_CHAINED)
    card.write32(P.BAR_PLX, P.PLX_DMADPR0, descs.iova | P.DPR_PCI)
    card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_ENABLE | P.DMACSR_START)


def test_chained_dma_reads_descriptors_from_host_memory_and_clears_their_counts(profile):
    printer, card = _armed(profile)
    blocks = [_block(printer, first=16 * i) for i in range(2)]
    bufs, descs = card.dma_alloc(2 * 4096), card.dma_alloc(4096)
    _chain(card, blocks, bufs, descs)
    assert card.read32(P.BAR_PLX, P.PLX_DMACSR0) & P.DMACSR_DONE
    assert [P.decode_dma_desc(descs.mem[16 * i:16 * i + 16]).size for i in range(2)] == [0, 0]
    assert card.read32(P.BAR_FPGA, P.FPGA_BLOCKS_MOVED) == 2 and card.chain_lengths == [2]


def test_demand_mode_waits_while_the_fpga_has_no_free_slot(profile):
    """The FPGA's block buffer (2 slots) in front of FIFOs that hold 2 blocks: the first 4
    blocks go, the fifth waits for DREQ0# with its descriptor loaded, not dropped."""
    printer, card = _armed(profile)
    blocks = [_block(printer, first=16 * i) for i in range(5)]
    printer.fpga.write_reg(P.REG_FIRE_COUNT_LO, 80)
    bufs, descs = card.dma_alloc(5 * 4096), card.dma_alloc(4096)
    _chain(card, blocks, bufs, descs)
    assert not card.read32(P.BAR_PLX, P.PLX_DMACSR0) & P.DMACSR_DONE
    assert card.read32(P.BAR_FPGA, P.FPGA_RING_FREE) == 0
    assert card.read32(P.BAR_FPGA, P.FPGA_FIFO_FLAGS0) & P.FIFO_FULL
    assert P.decode_dma_desc(descs.mem[64:80]).size == len(blocks[4])      # still to go
    assert printer.fault == P.Fault.NONE                                   # never overrun


def test_an_unmapped_descriptor_is_a_master_abort_the_host_names(profile):
    printer, card = _armed(profile)
    card.write32(P.BAR_PLX, P.PLX_DMAMODE0, P.DMAMODE_CHAINED)
    card.write32(P.BAR_PLX, P.PLX_DMADPR0, 0x7000_0000 | P.DPR_PCI)     # nothing mapped there
    card.write32(P.BAR_PLX, P.PLX_DMACSR0, P.DMACSR_ENABLE | P.DMACSR_START)
    assert card.config_read16(P.PCI_CFG_STATUS) & P.PCI_STATUS_MASTER_ABORT
    assert card.read32(P.BAR_PLX, P.PLX_INTCSR) & P.INTCSR_ABORT_ACTIVE
    assert card.read32(P.BAR_PLX, P.PLX_DMACSR0) & P.DMACSR_DONE
    card.config_write16(P.PCI_CFG_STATUS, P.PCI_STATUS_MASTER_ABORT)           # W1C
    assert not card.read32(P.BAR_PLX, P.PLX_INTCSR) & P.INTCSR_ABORT_ACTIVE


def test_the_transport_reports_an_iommu_fault_and_recovers_on_reconnect(profile):
    printer, card = _armed(profile)
    data = PciData(card, slots=4, slot_bytes=4096)
    try:
        mapped = data.bufs                  # the host's view, 16 MiB off: not mapped for the card
        data.bufs = SimpleNamespace(mem=mapped.mem, iova=mapped.iova + 0x100_0000, size=mapped.size)
        data.send(_block(printer))
        with pytest.raises(ConnectionError, match=r"master abort reading host memory at IOVA "
                           r"0x11\w+ \(descriptor 0\) - an IOMMU fault"):
            for _ in range(100):
                data.recv(0.01)
        with pytest.raises(ConnectionError, match="IOMMU fault"):
            data.send(_block(printer))      # the link stays down until reconnected
        data.bufs = mapped
        data.reconnect()
        data.send(_block(printer))
        assert card.read32(P.BAR_FPGA, P.FPGA_BLOCKS_MOVED) == 1
        assert data.stats["aborts"] == 1
    finally:
        data.close()


def test_a_card_that_is_not_ours_is_refused(profile):
    card = EmulatedPciCard(Printer(profile))
    card.read32 = lambda bar, off: P.PLX_PCIHIDR_9054 if bar == P.BAR_PLX else 0x12345678
    with pytest.raises(CardError, match="not a wideprint card .FPGA ID 0x12345678"):
        check_card(card)
    card.read32 = lambda bar, off: 0xFFFFFFFF
    with pytest.raises(CardError, match="does not answer"):
        check_card(card)


# -- printing through the card ----------------------------------------------------------------------
def _profile(tmp_path, **fpga):
    text = DEFAULT_PROFILE.read_text()
    for key, value in fpga.items():
        text = re.sub(rf"(?m)^{key}\s*=\s*\S+", f"{key} = {value}", text)
    path = tmp_path / "p.toml"
    path.write_text(text)
    return load_profile(path)


def print_pci(tmp_path, profile, faults=None, planes=None, chained=True, dma_bytes_s=None,
              expect_fail=False):
    planes = random_planes(300, 700, seed=19) if planes is None else planes
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    dev = open_device("emulator-pci", profile, faults, media_path=str(tmp_path / "m.tif"))
    card = dev.data.card
    if not chained or dma_bytes_s is not None:
        dev.data.close()
        card = EmulatedPciCard(dev.emulator, card.lock,
                               dma_bytes_s=dma_bytes_s if dma_bytes_s is not None else 60e6)
        dev.data = PciData(card, chained=chained)
    job = PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, passes=2, bidir=True), profile))
    try:
        if expect_fail:
            with pytest.raises(JobError) as err:
                job.run()
            return err.value, dev, card, planes, None
        rep = job.run()
    finally:
        dev.emulator.close()
        dev.data.close()
    return rep, dev, card, planes, read_planes(tmp_path / "m.tif")


def test_a_job_prints_bit_exact_through_the_emulated_card(tmp_path, profile):
    rep, dev, card, planes, media = print_pci(tmp_path, profile)
    assert np.array_equal(media, planes)
    assert rep.recoveries == 0 and dev.emulator.jobs_done[1]["stray"] == 0
    assert card.blocks_moved == dev.data.stats["blocks"] == dev.emulator.blocks_total
    assert dev.data.stats["interrupts"] > 0 and card.interrupts_lost == 0


def test_chained_dma_with_a_deep_ring_links_many_descriptors(tmp_path):
    """With 8 ring slots and the DMA taking its time on the bus, the blocks the host queues
    while a chain runs go out together as the next chain."""
    profile = _profile(tmp_path, dma_ring_blocks=8)
    rep, dev, card, planes, media = print_pci(tmp_path, profile, dma_bytes_s=4e6)
    assert np.array_equal(media, planes)
    lengths = collections.Counter(card.chain_lengths)
    assert max(lengths) >= 3 and sum(k * v for k, v in lengths.items()) == card.blocks_moved
    assert dev.data.stats["chains"] < dev.data.stats["blocks"]


def test_block_mode_prints_bit_exact(tmp_path, profile):
    rep, dev, card, planes, media = print_pci(tmp_path, profile, chained=False)
    assert np.array_equal(media, planes)
    assert set(card.chain_lengths) == {1} and card.descriptors_fetched == 0


@pytest.mark.parametrize("inject,what", [
    (["pci-desc-error=9"], "master abort fetching descriptor"),
    (["pci-dma-abort=23"], "master abort reading host memory"),
    (["pci-desc-error=3", "pci-dma-abort=40"], "master abort"),
])
def test_injected_dma_aborts_are_recovered_bit_exact(tmp_path, profile, inject, what, caplog):
    rep, dev, card, planes, media = print_pci(tmp_path, profile, Faults.parse(inject))
    assert np.array_equal(media, planes)
    assert rep.recoveries >= len(inject)
    assert what in caplog.text and "IOMMU fault" in caplog.text
    lines = [e for e in dev.emulator.events if e["event"] == "line"]
    assert len({e["stroke"] for e in lines}) == len(lines)       # no stroke run twice


def test_missed_interrupts_cost_time_not_data(tmp_path, profile):
    rep, dev, card, planes, media = print_pci(tmp_path, profile, Faults.parse(["pci-irq-miss=1"]))
    assert np.array_equal(media, planes)
    assert card.interrupts_lost == card.interrupts > 0
    assert dev.data.stats["interrupts"] == 0 and dev.data.stats["timeouts"] > 0


def test_a_bus_stall_starves_the_fifos_and_the_guard_resumes_exactly(tmp_path, profile):
    rep, dev, card, planes, media = print_pci(tmp_path, profile,
                                              Faults.parse(["pci-bus-stall=30:0.05"]))
    assert np.array_equal(media, planes)
    assert sum(e["pauses"] for e in dev.emulator.events if e["event"] == "line") >= 1


def test_a_bus_stall_without_the_guard_is_the_seeds_fifo_underrun(tmp_path, profile):
    err, dev, card, planes, _ = print_pci(tmp_path, profile,
                                          Faults.parse(["pci-bus-stall=30:0.05", "starve-guard=0"]),
                                          expect_fail=True)
    assert err.fault == P.Fault.FIFO_UNDERRUN
    assert "underrun" in str(err)


def test_cli_print_through_the_emulated_card_equals_cli_rip(tmp_path):
    """`wideprint print --device emulator-pci`: the media the card's DMA fed equals the
    planes `wideprint rip` writes, dot for dot."""
    root = Path(__file__).resolve().parent.parent
    sample = root / "resources" / "samples" / "sample.tif"
    exe = [sys.executable, "-m", "wideprint.app.cli"]
    opts = ["--passes", "2", "--bidir", "--dither", "bayer"]
    media, planes = tmp_path / "media.tif", tmp_path / "planes.tif"
    run = subprocess.run(exe + ["print", str(sample), "--device", "emulator-pci",
                                "--media-out", str(media)] + opts, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    subprocess.run(exe + ["rip", str(sample), "-o", str(planes)] + opts, check=True,
                   capture_output=True)
    assert np.array_equal(read_planes(media), read_planes(planes))
    assert read_planes(media).any()


# -- the VFIO side's own plumbing, without a card ----------------------------------------------------
def test_dma_buffers_are_page_aligned_memory_at_the_address_given_to_the_iommu():
    buf = V.MappedBuffer(5000, 0x1000_0000)
    try:
        assert buf.size == 8192 and buf.vaddr % 4096 == 0 and len(buf.mem) == 8192
        buf.mem[100:104] = b"WPD1"
        assert ctypes.string_at(buf.vaddr + 100, 4) == b"WPD1"    # what MAP_DMA's vaddr names
    finally:
        buf.close()


@pytest.mark.parametrize("mmappable", [True, False])
def test_region_access_by_mmap_or_by_pread(tmp_path, mmappable):
    """BAR access as VFIO gives it: a region of the device fd at `offset`, mmapped when the
    region allows it, else pread/pwrite (here a file stands in for the device fd)."""
    path = tmp_path / "dev"
    path.write_bytes(bytes(3 * 4096))
    fd = os.open(path, os.O_RDWR)
    try:
        info = V.vfio_region_info(index=2, size=4096, offset=4096,
                                  flags=V.VFIO_REGION_INFO_FLAG_READ | V.VFIO_REGION_INFO_FLAG_WRITE
                                  | (V.VFIO_REGION_INFO_FLAG_MMAP if mmappable else 0))
        region = V.Region(fd, info)
        assert (region.words is not None) == mmappable
        region.write(P.FPGA_CTRL, 4, 0x12345678)
        region.write(P.PCI_CFG_STATUS, 2, 0x2000)
        assert region.read(P.FPGA_CTRL, 4) == 0x12345678 and region.read(P.PCI_CFG_STATUS, 2) == 0x2000
        region.close()
        raw = path.read_bytes()
        assert raw[4096 + P.FPGA_CTRL:4096 + P.FPGA_CTRL + 4] == bytes.fromhex("78563412")
        assert raw[4096 + P.PCI_CFG_STATUS:4096 + P.PCI_CFG_STATUS + 2] == bytes.fromhex("0020")
    finally:
        os.close(fd)


def test_the_acceptance_images_print_bit_exact_through_the_card_across_injected_faults(tmp_path):
    """The sample acceptance suite's prints (resources/acceptance: the thesis' line and
    sawtooth, the nozzle check, the colour chart) through the register-level card with
    chained DMA, while the card loses descriptors, aborts DMA and drops interrupts: every
    one bit-exact, the faults recovered, not hidden."""
    import tifffile
    from wideprint.app import api
    steps = np.arange(0, 101, 10) * 255 // 100
    chart = np.zeros((5 * 24, 24 * len(steps), 4), np.uint8)
    for ink in range(5):
        for i, v in enumerate(steps):
            block = chart[ink * 24:(ink + 1) * 24, i * 24:(i + 1) * 24]
            if ink < 4:
                block[..., ink] = v
            else:
                block[..., :3] = v
    tifffile.imwrite(tmp_path / "chart.tif", chart, photometric="separated")
    faults = ["pci-desc-error=4", "pci-dma-abort=11", "pci-irq-miss=0.3"]
    chart_settings = {"passes": 2, "bidir": True, "placement": {"size": "pixels"}}
    with api.EmulatedPrinter(device="emulator-pci", faults=faults, workdir=tmp_path) as printer:
        results = [printer.print_pattern("line", head="K1", nozzle=64, width_mm=60),
                   printer.print_pattern("sawtooth", head="K1", width_mm=40),
                   printer.print_pattern("nozzle-check", width_mm=40),
                   printer.print(tmp_path / "chart.tif", chart_settings)]
    results[3].planes = api.rip(tmp_path / "chart.tif", chart_settings)
    for r in results:
        assert r.ok, r.message
        assert r.media is not None and np.array_equal(r.media, r.planes), r.report
    assert sum(r.report["recoveries"] for r in results) >= 2     # the aborts were recovered
