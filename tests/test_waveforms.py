"""What the heads see: the VCD waveform of the head interface (configuration load and print
cycles) and the words each head latched, compared with the RIP's, for every pass mode."""

import numpy as np
import pytest

from support.images import PX, random_planes, write_cmyk_tiff
from wideprint.app.devices import open_device
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.testprints import PatternJob, make_pattern


def parse_vcd(path):
    ids, changes, t = {}, {}, 0
    for line in open(path):
        line = line.strip()
        if line.startswith("$var"):
            _, _, width, ident, name, _ = line.split()
            ids[ident] = name
            changes[name] = []
        elif line.startswith("#"):
            t = int(line[1:])
        elif line and line[0] in "01" and line[1:] in ids:
            changes[ids[line[1:]]].append((t, int(line[0])))
        elif line.startswith("b") and " " in line:
            val, ident = line[1:].split()
            changes[ids[ident]].append((t, int(val, 2)))
    return changes


def rises(ch):
    return [t for t, v in ch if v == 1]


def value_at(ch, t):
    v = 0
    for tt, vv in ch:
        if tt > t:
            break
        v = vv
    return v


def test_vcd_configuration_trace_and_print_cycle(tmp_path, profile):
    vcd = tmp_path / "w.vcd"
    k1 = next(h.index for h in profile.heads if h.name == "K1")
    planes = make_pattern("sawtooth", profile, 400)
    job = PatternJob("sawtooth", planes, RipSettings(placement=PX, dpi=150), profile)
    dev = open_device("emulator", profile, vcd_path=str(vcd), vcd_window=(0, k1, 100, 3),
                      record_latched=True)
    PrintJob(dev, job).run()
    dev.emulator.close()
    sig = parse_vcd(vcd)
    # configuration: DI0..DI3 hold 1, 2, 0, 1, 2 at the first five DSTB rising edges
    dstb = rises(sig["K1_DSTB"])
    cfg = [t for t in dstb if value_at(sig["K1_DATA_nCONFIG"], t) == 0]
    assert len(cfg) == 1020
    assert set(np.diff(cfg)) == {2000}                              # 500 kHz
    digits = [sum(value_at(sig[f"K1_DI{b}"], t) << b for b in range(4)) for t in cfg[:5]]
    assert digits == [1, 2, 0, 1, 2]
    up = [t for t, v in sig["K1_DATA_nCONFIG"] if v == 1][0]
    assert cfg[-1] < up <= cfg[-1] + 2000                           # rises after the 1,020th
    # print cycles: 128 DSTB per fire on DI3, nozzle 127 first, then 3 CYCLESTB strobes
    fires = [t for t in dstb if t > up]
    assert len(fires) == 3 * 128
    latched = dev.emulator.latched_words(0)[k1]
    from wideprint.driver.protocol import words_to_nozzles
    for f in range(3):
        clocks = fires[128 * f:128 * (f + 1)]
        serial = [value_at(sig["K1_DI3"], t) for t in clocks]
        assert serial == list(words_to_nozzles(latched[100 + f])[::-1])
        strobes = [t for t in rises(sig["K1_CYCLESTB1"]) if clocks[-1] < t < clocks[-1] + 200_000]
        assert len(strobes) == 3
        for s in strobes:                      # at least two SAMPLECLK periods in each strobe
            assert len([t for t in rises(sig["K1_SAMPLECLK"]) if s <= t < s + 10_000]) >= 2
    assert sum(v for _, v in sig["K1_DI3"]) > 0                    # the sawtooth bit is there
    # encoder quadrature: A and B never change together
    a = {t for t, _ in sig["encoder_A"]}
    b = {t for t, _ in sig["encoder_B"]}
    assert a and b and len(a & b) <= 1                              # only the initial value
    # 150 dpi fires on the rising edge of channel A (docs/protocol.md, "DPI modes"): the
    # encoder edge each fire's data follows is A going high, on the trigger count 4n
    a_rise = [t for t, v in sig["encoder_A"] if v == 1]
    count = sig["qep_count"]
    for f in range(3):
        edge = max(t for t in a | b if t <= fires[128 * f])      # before its first DSTB
        assert edge in a_rise and edge not in b, f"fire {f}"
        assert value_at(count, edge) % 4 == 0


@pytest.mark.parametrize("dpi,passes,bidir", [(150, 1, False), (300, 2, True), (600, 4, True),
                                              (300, 3, False), (300, 6, True), (150, 8, True)])
def test_head_bit_streams_equal_the_rip_words(tmp_path, profile, dpi, passes, bidir):
    planes = random_planes(400, 150, seed=passes)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    settings = RipSettings(placement=PX, dpi=dpi, passes=passes, bidir=bidir)
    expected = {sd.index: sd.words for sd in RipJob(str(src), settings, profile).strokes()}
    dev = open_device("emulator", profile, record_latched=True)
    PrintJob(dev, RipJob(str(src), settings, profile)).run()
    dev.emulator.close()
    assert sorted(dev.emulator.latched) == sorted(expected)
    for i, words in expected.items():
        assert np.array_equal(dev.emulator.latched_words(i), words), f"stroke {i}"
