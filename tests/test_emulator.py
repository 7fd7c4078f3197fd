"""The emulator reproduces the seed thesis' own tests (000, 4.2.4) and reports every
injected fault the way the device would."""

import numpy as np
import pytest

from support.images import PX, random_planes, write_cmyk_tiff
from wideprint.device_sim.endpoints import in_process
from wideprint.device_sim.faults import Faults
from wideprint.device_sim.printer import Printer
from wideprint.driver import protocol as P
from wideprint.app.devices import open_device
from wideprint.driver.device import Device
from wideprint.driver.job import JobError, PrintJob
from wideprint.driver.link import CommandLink, DeviceError
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes
from wideprint.rip.testprints import PatternJob, make_pattern


def run(job, profile, media, faults=None, machine=None, **kw):
    dev = open_device("emulator", profile, faults, media_path=str(media), machine_profile=machine)
    try:
        return PrintJob(dev, job, **kw).run(), dev.emulator
    finally:
        dev.emulator.close()


def pattern(kind, profile, width_cols=600, dpi=150, **kw):
    planes = make_pattern(kind, profile, width_cols, **kw)
    return PatternJob(kind, planes, RipSettings(placement=PX, dpi=dpi, passes=1), profile), planes


def connected(printer=None):
    printer = printer or Printer()
    ser, data = in_process(printer)
    link = CommandLink(ser)
    link.handshake()
    return printer, link


# -- seed test 3: the DSP-FPGA interface ------------------------------------------------------
def test_dir_dpi_we_en_read_back_through_status():
    printer, link = connected()
    from wideprint.rip.profile import load_profile
    Device(link, None, load_profile()).load_head_config()
    link.call(P.Op.ENABLE, on=1)
    for dir_, dpi, we in [(1, 150, 0), (0, 600, 1), (1, 300, 1), (0, 150, 0)]:
        link.write_reg(P.REG_DIR, dir_)
        link.write_reg(P.REG_DPI, P.DPI_CODE[dpi])
        link.write_reg(P.REG_WE_EN, we)
        st = link.read_reg(P.REG_STATUS)
        assert st & P.STATUS_DIR == dir_
        assert bool(st & P.STATUS_DPI600) == (dpi == 600)
        assert bool(st & P.STATUS_DPI300) == (dpi == 300)
        assert bool(st & P.STATUS_WE_EN) == bool(we)
        assert st & P.STATUS_CONFIGURED
    with pytest.raises(DeviceError, match="BAD_ARGUMENT"):
        link.write_reg(P.REG_DPI, 7)


def test_print_enable_refused_before_head_configuration():
    printer, link = connected()
    link.call(P.Op.ENABLE, on=1)
    with pytest.raises(DeviceError, match="HEADS_NOT_CONFIGURED"):
        link.write_reg(P.REG_WE_EN, 1)
    assert printer.fault == P.Fault.HEAD_CONFIG


# -- the configuration trace (000, fig. 4-11) --------------------------------------------------
def test_head_configuration_trace(profile):
    printer, link = connected()
    Device(link, None, profile).load_head_config()
    trace = printer.config_traces[-1]
    assert trace.digits[:5] == [1, 2, 0, 1, 2]
    assert len(trace.digits) == 1020
    period = np.diff(trace.dstb_rise_ns)
    assert (period == 2000).all()                       # DSTB at 500 kHz
    assert trace.data_nconfig_rise_ns > trace.dstb_rise_ns[-1]   # after the 1,020th digit
    assert trace.data_nconfig_rise_ns - trace.dstb_rise_ns[-1] <= 2000
    assert all(h.configured for h in printer.heads)


def test_configuration_with_a_bad_crc_is_refused(profile):
    printer, link = connected()
    digits = profile.head_config_digits()
    link.call(P.Op.HEAD_CONFIG_DATA, first=0, digits=digits[:400])
    with pytest.raises(DeviceError, match="CONFIG_CRC"):
        link.call(P.Op.HEAD_CONFIG_LOAD, count=1020, crc=12345)
    assert not any(h.configured for h in printer.heads)


# -- seed test 1: one nozzle draws a line; a feed; a second line ---------------------------------
def test_one_nozzle_line(tmp_path, profile):
    job, planes = pattern("line", profile, head="C1", nozzle=37)
    rep, emu = run(job, profile, tmp_path / "m.tif")
    media = read_planes(tmp_path / "m.tif")
    assert np.array_equal(media, planes)
    rows = np.flatnonzero(media[:, :, 0].any(axis=1))
    assert len(rows) == 2                                 # two lines
    for r in rows:
        assert (media[r, :, 0] == 1).all()                 # no breaks, no doubled dots
    assert media[:, :, 1:].sum() == 0
    assert rep.strokes_printed == 2


# -- seed test 2: the sawtooth ----------------------------------------------------------------
def test_sawtooth_slope_is_the_same_at_two_speeds(tmp_path, profile):
    job, planes = pattern("sawtooth", profile, width_cols=500)
    run(job, profile, tmp_path / "slow.tif", speed_mm_s=100)
    job2, _ = pattern("sawtooth", profile, width_cols=500)
    run(job2, profile, tmp_path / "fast.tif", speed_mm_s=660)
    slow, fast = read_planes(tmp_path / "slow.tif"), read_planes(tmp_path / "fast.tif")
    assert np.array_equal(slow, planes) and np.array_equal(fast, planes)
    k = slow[:, :, 3]
    # one nozzle per fire on the ramp: each column has exactly one dot above the bar
    bar_top = profile.heads_per_color * 118 - 2
    assert (k[:bar_top].sum(axis=0) <= 1).all()
    # the ramp climbs one nozzle (2 rows) per column and repeats every 118 columns
    col = np.argmax(k[:bar_top] > 0, axis=0)
    assert col[10] - col[9] == 2 and col[128] == col[10]


def test_printing_stops_when_the_carriage_stops(tmp_path, profile):
    job, planes = pattern("sawtooth", profile, width_cols=500)
    limit = 5_000           # counts: a limit switch trips while K1 is drawing the ramp
    with pytest.raises(JobError, match="right limit switch.*stroke 0, column"):
        run(job, profile, tmp_path / "m.tif", Faults(limit_at=limit))
    media = read_planes(tmp_path / "m.tif")
    # the print is exact up to the column where the line stopped, and empty after it
    printed = media[:, :, 3].any(axis=0)
    assert printed.any() and not printed.all()
    last = np.flatnonzero(printed)[-1]
    assert np.array_equal(media[:, :last + 1], planes[:, :last + 1])
    assert media[:, last + 1:].sum() == 0


# -- faults -------------------------------------------------------------------------------------
def test_dead_nozzle_misses_exactly_its_dots(tmp_path, profile):
    job, planes = pattern("nozzle-check", profile, width_cols=160)
    run(job, profile, tmp_path / "m.tif", Faults(dead_nozzle=[("M1", 57)]))
    media = read_planes(tmp_path / "m.tif")
    m1 = next(h for h in profile.heads if h.name == "M1")
    row = m1.y_rows + 2 * 57 - 2
    expected = planes.copy()
    expected[row, :, 1] = 0
    assert planes[row, :, 1].any()
    assert np.array_equal(media, expected)


def test_nozzle_check_fires_nozzles_the_profile_lists_as_dead(tmp_path, profile):
    """A test print ignores the profile's dead list (one pass could not avoid them, and the
    check must show whether a marked nozzle works again): a listed nozzle that works prints
    its row, one that is really dead misses exactly its row."""
    from support.printing import variant_profile
    listed = variant_profile(tmp_path, dead=[("M1", 57), ("K2", 3)])
    assert listed.dead_nozzles
    job = PatternJob.for_pattern("nozzle-check", listed, 160)
    planes = job.planes
    run(job, listed, tmp_path / "m.tif", Faults(dead_nozzle=[("M1", 57)]))
    media = read_planes(tmp_path / "m.tif")
    m1 = next(h for h in profile.heads if h.name == "M1")
    row = m1.y_rows + 2 * 57 - 2
    expected = planes.copy()
    expected[row, :, 1] = 0                        # M1:57 is really dead; K2:3 works again
    assert planes[row, :, 1].any()
    assert np.array_equal(media, expected)


@pytest.mark.parametrize("faults,pattern_text", [
    (Faults(overtemp=[("K2", 0)]), r"over-temperature \(head K2, stroke 0, column"),
    (Faults(paper_length_mm=5), r"paper out"),
    (Faults(encoder_glitch_at=9_000), r"encoder glitch.*stroke 0, column"),
    (Faults(fifo_words=128, host_jitter="loaded", seed=3, starve_guard=0),
     r"FIFO underrun.*stroke \d+, column"),
])
def test_device_faults_stop_the_job_with_a_clear_message(tmp_path, profile, faults, pattern_text):
    planes = random_planes(600, 2000, seed=5)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    with pytest.raises(JobError, match=pattern_text):
        run(RipJob(str(src), RipSettings(placement=PX), profile), profile, tmp_path / "m.tif", faults)


def test_overspeed_is_refused_by_the_driver_and_caught_by_the_device(tmp_path, profile):
    job, _ = pattern("sawtooth", profile, width_cols=300, dpi=600)
    with pytest.raises(JobError, match="above their 8300 Hz"):
        run(job, profile, tmp_path / "a.tif", speed_mm_s=500)
    job, _ = pattern("sawtooth", profile, width_cols=300, dpi=600)
    with pytest.raises(JobError, match="fire rate above the head's maximum"):
        run(job, profile, tmp_path / "b.tif", speed_mm_s=500, allow_overspeed=True)


def test_serial_noise_is_retried_and_the_print_is_still_exact(tmp_path, profile):
    planes = random_planes(500, 300, seed=8)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    rep, emu = run(RipJob(str(src), RipSettings(placement=PX, passes=2, bidir=True), profile), profile,
                   tmp_path / "m.tif", Faults(serial_byte_error=1e-3, seed=4))
    assert rep.retries > 0
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)


def test_fifo_levels_and_min_level_are_reported(tmp_path, profile):
    planes = random_planes(300, 400, seed=2)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    rep, emu = run(RipJob(str(src), RipSettings(placement=PX), profile), profile, tmp_path / "m.tif",
                   Faults(host_jitter="typical"))
    lines = [e for e in emu.events if e["event"] == "line"]
    assert lines and all(0 <= e["min_fifo_words"] <= profile.fifo_words for e in lines)
    assert all(e["fault"] == "NONE" and e["fired"] == e["fires"] for e in lines)


def test_starved_line_pauses_and_resumes_with_every_dot_in_place(tmp_path, profile):
    """The same starving host as the underrun fault above, with the starve guard on."""
    planes = random_planes(600, 2000, seed=5)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    rep, emu = run(RipJob(str(src), RipSettings(placement=PX), profile), profile, tmp_path / "m.tif",
                   Faults(fifo_words=128, host_jitter="loaded", seed=3))
    pauses = sum(e["pauses"] for e in emu.events if e["event"] == "line")
    assert pauses > 0
    assert any(e["event"] == "resumed" for e in emu.events)
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)


# -- calibration: alignment prints find an injected misalignment; the profile fixes it -------
def test_bidir_alignment_finds_and_fixes_the_offset(tmp_path, profile):
    import shutil
    from wideprint.rip.profile import DEFAULT_PROFILE, save_calibration
    from wideprint.rip.testprints import ALIGN_BLOCK, PatternJob, align_offsets
    machine = Faults(bidir_error=2)
    job = PatternJob.for_pattern("bidir-align", profile, 0)
    run(job, profile, tmp_path / "a.tif", machine)
    media = read_planes(tmp_path / "a.tif")[:, :, 3]
    rows = job.height // 2
    fwd, rev = media[:rows].any(axis=0), media[rows:].any(axis=0)
    aligned = [o for b, o in enumerate(align_offsets())
               if np.array_equal(fwd[b * ALIGN_BLOCK:(b + 1) * ALIGN_BLOCK],
                                 rev[b * ALIGN_BLOCK:(b + 1) * ALIGN_BLOCK])]
    assert aligned == [2]
    copy = tmp_path / "p.toml"
    shutil.copy(DEFAULT_PROFILE, copy)
    fixed = save_calibration(copy, bidir_offset_columns={150: 2, 300: 2, 600: 2})
    assert fixed.bidir_offset_columns[300] == 2
    planes = random_planes(700, 200, seed=12)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    run(RipJob(str(src), RipSettings(placement=PX, passes=2, bidir=True), fixed), fixed, tmp_path / "m.tif",
        machine)
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)
    # and the uncalibrated profile on the same machine does not print exactly
    run(RipJob(str(src), RipSettings(placement=PX, passes=2, bidir=True), profile), profile,
        tmp_path / "bad.tif", Faults(bidir_error=2))
    assert not np.array_equal(read_planes(tmp_path / "bad.tif"), planes)


def test_head_alignment_finds_a_misplaced_head(tmp_path, profile):
    import shutil
    from wideprint.rip.profile import DEFAULT_PROFILE, save_calibration
    from wideprint.rip.testprints import PatternJob
    machine = Faults(head_error=[("M1", 12)])            # M1 sits 12 counts (3 columns) right
    from wideprint.rip.testprints import ALIGN_BLOCK, align_offsets
    job = PatternJob.for_pattern("head-align", profile, 0)            # 150 dpi: 4 counts/column
    run(job, profile, tmp_path / "h.tif", machine)
    media = read_planes(tmp_path / "h.tif")
    ref = media[:40, :, 3].any(axis=0)                                # K1 reference bars
    m1_rows = [r for r in range(media.shape[0]) if media[r, :, 1].any()]
    aligned = []
    for b, o in enumerate(align_offsets()):
        blk = slice(b * ALIGN_BLOCK, (b + 1) * ALIGN_BLOCK)
        m1 = media[m1_rows[0], blk, 1] > 0                            # the first M1 row
        if np.array_equal(m1, ref[blk]):
            aligned.append(o)
    assert aligned == [-3]
    copy = tmp_path / "p.toml"
    shutil.copy(DEFAULT_PROFILE, copy)
    m1 = next(h for h in profile.heads if h.name == "M1")
    fixed = save_calibration(copy, head_x_counts={"M1": m1.x_counts + 12})
    planes = random_planes(300, 200, seed=13)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    run(RipJob(str(src), RipSettings(placement=PX), fixed), fixed, tmp_path / "m.tif", machine,
        machine=profile)
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)


def test_fifo_flags_follow_the_level(profile):
    """Seed 4.2.2's FIFO flags, readable per head, and the DMA request they make."""
    printer, link = connected()
    Device(link, None, profile).load_head_config()
    link.call(P.Op.ENABLE, on=1)
    link.command(P.Op.HOME)
    link.call(P.Op.SET_LINE, stroke=1, direction=0, dpi=300, fire_start=5000, fire_count=64,
              speed=15000, accel=47000)
    flags = link.read_reg(P.REG_FIFO_FLAGS0)
    assert flags & P.FIFO_EMPTY and flags & P.FIFO_ALMOST_EMPTY and flags & P.FIFO_DREQ
    assert not flags & P.FIFO_FULL and flags >> P.FIFO_WR_COUNT_SHIFT & 3 == 0
    words = np.zeros((8, 16, 8), np.uint16)
    for first in (0, 16):                      # two 128-word blocks fill a 256-word FIFO
        printer.data_in(P.encode_block(1, first, 0xFF, words))
        flags = link.read_reg(P.REG_FIFO_FLAGS0 + 3)
    assert printer.fpga.fifo_level_words() == 256
    assert flags & P.FIFO_FULL and not flags & P.FIFO_DREQ and not flags & P.FIFO_EMPTY
    assert flags >> P.FIFO_WR_COUNT_SHIFT & 3 == 3
    printer.data_in(P.encode_block(1, 32, 0xFF, words))   # waits in the DMA ring
    assert printer.fpga.ring_free() == profile.ring_blocks - 1


def test_data_stall_starves_a_fast_line_but_prints_exactly(tmp_path, profile):
    planes = random_planes(300, 2000, seed=6)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    rep, emu = run(RipJob(str(src), RipSettings(placement=PX), profile), profile,
                   tmp_path / "m.tif", Faults(data_stall=0.02))
    assert sum(e["pauses"] for e in emu.events if e["event"] == "line") > 0
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)


@pytest.mark.parametrize("level,flags", [
    (0, {"EMPTY", "ALMOST_EMPTY", "LOW", "DREQ"}),
    (8, {"ALMOST_EMPTY", "LOW", "DREQ"}),        # one fire's words: the next read empties it
    (16, {"LOW", "DREQ"}),
    (64, {"LOW", "DREQ"}),                        # the profile's almost_empty_words
    (72, {"DREQ"}),
    (256, {"FULL"}),
])
def test_fifo_flags_are_the_seeds(profile, level, flags, monkeypatch):
    """FIFO_FLAGS (docs/protocol.md, seed 4.2.2): ALMOST_EMPTY as the seed defines it (the
    next read empties the FIFO), the programmable LOW level beside it."""
    from wideprint.device_sim.fpga import Fpga
    fpga = Fpga(8, fifo_words=256, pass_buffer_words=0, ring_blocks=4, almost_empty_words=64)
    monkeypatch.setattr(fpga, "fifo_level_words", lambda *a: level)
    got = fpga.fifo_flags()
    names = {n for n in ("EMPTY", "ALMOST_EMPTY", "FULL", "DREQ", "LOW")
             if got & getattr(P, f"FIFO_{n}")}
    assert names == flags
