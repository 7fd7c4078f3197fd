"""The physical media model and the emulated scanner (docs/physical.md): dots are measured
on the scan where the bit-exact media and the model put them, and every injected error
moves them by the injected amount."""

import numpy as np
import pytest
import tifffile

from support.images import PX
from wideprint.app.devices import open_device
from wideprint.device_sim.faults import Faults, Length
from wideprint.device_sim.physical import PhysicalModel, dot_diameter_um
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipSettings
from wideprint.rip.planes import read_planes
from wideprint.rip.testprints import PatternJob, nozzle_check_layout

# the band each ink darkens most: C absorbs red, M green, Y blue, K all
BAND = (0, 1, 2, 1)


def scan_job(tmp_path, name, planes, profile, faults=None, dpi=150, bidir=False, scan_dpi=1200):
    """Print 1-pass planes on the emulator with a scan: (media, scan, scanner, printer)."""
    job = PatternJob(name, planes, RipSettings(placement=PX, dpi=dpi, passes=1, bidir=bidir), profile)
    media_path, scan_path = tmp_path / f"{name}.tif", str(tmp_path / f"{name}-scan.tif")
    dev = open_device("emulator", profile, faults, media_path=str(media_path), scan_path=scan_path,
                      scan_dpi=scan_dpi)
    try:
        PrintJob(dev, job).run()
    finally:
        dev.emulator.close()
    return read_planes(media_path), tifffile.imread(scan_path), dev.emulator.scans[scan_path], dev.emulator


def dots(rows, cols, every_row=5, every_col=4, first_row=3, first_col=3, channels=(0, 1, 2, 3)):
    """Isolated single dots, far enough apart (4 columns, 5 rows) that each can be measured
    alone; the ink cycles along a row, and successive dot rows alternate heads of a colour."""
    planes = np.zeros((rows, cols, 4), np.uint8)
    for i, r in enumerate(range(first_row, rows - 2, every_row)):
        for j, c in enumerate(range(first_col, cols - 2, every_col)):
            planes[r, c, channels[(i + j) % len(channels)]] = 1
    return planes


def centroids(scan, scanner, media, geo_col_um, geo_row_um):
    """For every drop of the media: (row, col, channel, predicted scan u, v, measured u, v)."""
    white = np.median(scan.reshape(-1, scan.shape[-1]), axis=0)
    r_px = int(np.ceil(scanner.dot_um / scanner.pix)) + 1
    out = []
    rr, cc, ch = np.nonzero(media)
    u, v = scanner.paper_to_scan((cc + 0.5) * geo_col_um, (rr + 0.5) * geo_row_um)
    for r, c, k, pu, pv in zip(rr, cc, ch, u, v):
        i0, j0 = int(round(pu)), int(round(pv))
        win = scan[j0 - r_px:j0 + r_px + 1, i0 - r_px:i0 + r_px + 1, BAND[k]].astype(np.float64)
        dark = np.clip(white[BAND[k]] - win - 6.0, 0, None)          # 4 sigma above the noise
        jj, ii = np.mgrid[j0 - r_px:j0 + r_px + 1, i0 - r_px:i0 + r_px + 1]
        w = dark.sum()
        out.append((r, c, k, pu, pv, (ii * dark).sum() / w, (jj * dark).sum() / w))
    return np.array(out)


def shift_um(meas, scanner):
    """Measured minus predicted position of each drop, in µm (an unrotated scan)."""
    return (meas[:, 5] - meas[:, 3]) * scanner.pix, (meas[:, 6] - meas[:, 4]) * scanner.pix


@pytest.fixture(scope="module")
def rows(profile):
    s0, s1 = profile.usable_slots()
    return s1 - s0


@pytest.fixture(scope="module")
def baseline(tmp_path_factory, profile, rows):
    """A 2-stroke bidirectional print of isolated dots, perfect machine: the reference the
    injected errors are measured against."""
    tmp = tmp_path_factory.mktemp("base")
    planes = dots(2 * rows, 64)
    return planes, scan_job(tmp, "base", planes, profile, bidir=True)


def measure(run):
    """Measured centroids of a scan_job's drops, its scanner and job geometry."""
    media, scan, scanner, printer = run
    geo = printer.geometry
    return centroids(scan, scanner, media, geo.col_um, geo.row_um), scanner, geo


# -- a perfect machine ------------------------------------------------------------------------
def test_scan_dots_sit_where_the_bit_exact_media_puts_them(baseline, profile):
    planes, run = baseline
    media, scan = run[:2]
    assert np.array_equal(media, planes)
    assert scan.shape[2] == 3 and scan.dtype == np.uint8
    meas, scanner, geo = measure(run)
    assert len(meas) == planes.sum() > 500
    assert scanner.drops == planes.sum() and scanner.late == 0
    dx, dy = shift_um(meas, scanner)
    dot = scanner.dot_um
    half_step = profile.feed_um_per_step / 2          # the feed rounds to whole steps
    print(f"dx {np.abs(dx).max():.2f} µm, dy {dy.min():.2f}..{dy.max():.2f} µm, dot {dot:.0f} µm")
    assert np.abs(dx).max() < 0.05 * dot               # 5 µm: servo ripple and measurement
    assert np.abs(dy).max() < half_step + 0.03 * dot   # the feed's rounding, and measurement
    assert np.abs(dx).max() > 0 and np.abs(dy).max() > 0  # measured, not copied


def injected(tmp_path, baseline, profile, inject):
    """The baseline job on a machine with these injections: (its media, measured shift of
    every drop against the perfect machine's, in µm: dx, dy, with the drops' rows,
    columns and inks)."""
    planes = baseline[0]
    run = scan_job(tmp_path, "inj", planes, profile, Faults.parse(inject), bidir=True)
    ref, scanner, _ = measure(baseline[1])
    got, _, _ = measure(run)
    assert np.array_equal(got[:, :3], ref[:, :3])             # the same drops, same cells
    dx = (got[:, 5] - ref[:, 5]) * scanner.pix
    dy = (got[:, 6] - ref[:, 6]) * scanner.pix
    return run[0], dx, dy, got[:, 0].astype(int), got[:, 2].astype(int), run[3]


def test_bidirectional_error_moves_the_reverse_strokes_dots(tmp_path, baseline, profile, rows):
    media, dx, dy, r, ink, _ = injected(tmp_path, baseline, profile, ["bidir-error=0.3col"])
    # a third of a column lands in the same cell: the media cannot show it, the scan does
    assert np.array_equal(media, baseline[0])
    col_um = 25_400 / 150
    rev = r >= rows                                          # stroke 1 runs in reverse
    print(f"reverse dx {dx[rev].mean():.2f} ± {dx[rev].std():.2f} µm (injected {-0.3 * col_um:.2f})")
    assert abs(dx[rev].mean() + 0.3 * col_um) < 1.0
    assert np.abs(dx[rev] + 0.3 * col_um).max() < 3.0
    assert np.abs(dx[~rev]).max() < 3.0 and np.abs(dy).max() < 3.0


def test_head_offset_moves_only_that_heads_dots(tmp_path, baseline, profile):
    media, dx, dy, r, ink, printer = injected(tmp_path, baseline, profile,
                                              ["head-offset=C2:x=20um,y=-10um"])
    c2 = next(h for h in profile.heads if h.name == "C2")
    s0, _ = profile.usable_slots()
    mine = (ink == c2.channel) & ((r + s0 - c2.y_rows) % profile.heads_per_color == 0)
    assert mine.sum() > 20 and (~mine).sum() > 100
    print(f"C2 dx {dx[mine].mean():.2f}, dy {dy[mine].mean():.2f} µm")
    assert abs(dx[mine].mean() - 20) < 1.0 and abs(dy[mine].mean() + 10) < 1.0
    assert np.abs(dx[mine] - 20).max() < 3.0 and np.abs(dy[mine] + 10).max() < 3.0
    assert np.abs(dx[~mine]).max() < 3.0 and np.abs(dy[~mine]).max() < 3.0


def test_feed_error_moves_each_stroke_by_the_feeds_before_it(tmp_path, baseline, profile, rows):
    media, dx, dy, r, ink, printer = injected(tmp_path, baseline, profile, ["feed-error=15um"])
    feeds, before = 0, []
    for e in printer.events:                 # feeds that moved the paper before each line
        if e["event"] == "feed" and e["steps"]:
            feeds += 1
        elif e["event"] == "line":
            before.append(feeds)
    assert len(before) == 2 and before[1] == before[0] + 1
    for stroke, n in enumerate(before):
        mine = (r >= stroke * rows) & (r < (stroke + 1) * rows)
        print(f"stroke {stroke}: dy {dy[mine].mean():.2f} µm after {n} feeds")
        assert abs(dy[mine].mean() - 15 * n) < 1.0
        assert np.abs(dy[mine] - 15 * n).max() < 3.0
    assert np.abs(dx).max() < 3.0


def test_misdirected_nozzle_moves_its_dots_only(tmp_path, profile, rows):
    """One nozzle's line (the thesis' test 1): every drop of M1:57 misdirected."""
    planes = np.zeros((rows, 40, 4), np.uint8)
    m1 = next(h for h in profile.heads if h.name == "M1")
    s0, _ = profile.usable_slots()
    for z in (51, 57, 63):
        planes[m1.y_rows + 2 * z - s0, 2:38:3, 1] = 1
    run0 = scan_job(tmp_path, "line0", planes, profile)
    base = measure(run0)[0]
    run = scan_job(tmp_path, "line1", planes, profile, Faults.parse(["misdirect=M1:57:x=6um,y=8um"]))
    got, scanner, _ = measure(run)
    dx, dy = (got[:, 5] - base[:, 5]) * scanner.pix, (got[:, 6] - base[:, 6]) * scanner.pix
    hit = got[:, 0] == m1.y_rows + 2 * 57 - s0
    print(f"M1:57 dx {dx[hit].mean():.2f}, dy {dy[hit].mean():.2f} µm")
    assert abs(dx[hit].mean() - 6) < 1.0 and abs(dy[hit].mean() - 8) < 1.0
    assert np.abs(dx[~hit]).max() < 2.0 and np.abs(dy[~hit]).max() < 2.0
    assert np.array_equal(run[0], planes)                   # a few µm: the same cells
    # the scans differ only around that nozzle's dots: the rest, noise included, is identical
    differs = np.flatnonzero((run0[1] != run[1]).any(axis=(1, 2)))
    v57 = got[hit, 6].mean()
    reach = (scanner.dot_um / 2 + 3 * 10 + 8) / scanner.pix + 2        # dot, blur, shift
    assert differs.size and np.abs(differs - v57).max() < reach


def test_scanner_geometry_rotation_scale_and_placement(tmp_path, baseline, profile):
    """A sheet rotated 2 degrees, scanned 0.3 % fine and 1 mm off: every dot is where
    paper_to_scan says, with the same residuals as the straight scan."""
    planes, run0 = baseline
    run = scan_job(tmp_path, "rot", planes, profile, bidir=True,
                   faults=Faults.parse(["scan-rotation=2", "scan-scale=1.003", "scan-offset=1,-0.5"]))
    ref, scanner0, _ = measure(run0)
    got, scanner, _ = measure(run)
    res0 = np.hypot(*shift_um(ref, scanner0))
    u, v = got[:, 5] - got[:, 3], got[:, 6] - got[:, 4]
    assert np.hypot(u, v).max() * scanner.pix < res0.max() + 2.0
    # and the dots really moved: a row of dots 60 columns long climbs by sin(2°) of its length
    assert np.ptp(got[got[:, 0] == got[0, 0], 6]) * scanner.pix > 0.03 * 55 * 25_400 / 150


def test_firing_phases_land_a_third_of_a_fire_period_apart(tmp_path, profile, rows):
    """At 600 dpi the carriage runs at half the design speed: phases A and C land
    (p - 1) T (V - Vd) from B (docs/physical.md), on the scan, not on the media."""
    planes = dots(rows, 96, every_row=5, every_col=6, channels=(3,))
    media, scan, scanner, printer = scan_job(tmp_path, "ph", planes, profile, dpi=600)
    assert np.array_equal(media, planes)
    geo = printer.geometry
    meas = centroids(scan, scanner, media, geo.col_um, geo.row_um)
    dx, _ = shift_um(meas, scanner)
    model = PhysicalModel(profile, Faults())
    count_um = 25_400 / profile.counts_per_inch
    s0, _ = profile.usable_slots()
    nozzle = (meas[:, 0].astype(int) + s0) // profile.heads_per_color
    phase = (nozzle - 1) % 3
    expect = (model.v_design - profile.speed_counts_s(600)) * model.t_gap * count_um
    by_phase = [dx[phase == p].mean() for p in range(3)]
    print("phase A/B/C dx", [f"{v:.2f}" for v in by_phase], f"expected ±{expect:.2f} µm")
    assert expect > 10
    for p in range(3):
        assert abs(by_phase[p] - (1 - p) * expect) < 1.5
    assert abs(by_phase[0] - by_phase[2]) < 25_400 / 600 / 1.5       # under 2/3 of a column


# -- the nozzle check ------------------------------------------------------------------------
def test_dead_nozzle_is_a_missing_dash_in_the_nozzle_check_scan(tmp_path, profile):
    job = PatternJob.for_pattern("nozzle-check", profile, 230)
    check = nozzle_check_layout(profile, job.width)
    assert job.width == check.width
    media_path, scan_path = tmp_path / "m.tif", str(tmp_path / "s.tif")
    dev = open_device("emulator", profile, Faults.parse(["dead-nozzle=M1:57"]),
                      media_path=str(media_path), scan_path=scan_path, scan_dpi=600)
    try:
        PrintJob(dev, job).run()
    finally:
        dev.emulator.close()
    scan = tifffile.imread(scan_path).astype(np.float64)
    scanner, geo = dev.emulator.scans[scan_path], dev.emulator.geometry
    white = np.median(scan.reshape(-1, 3), axis=0)

    def darkness(head, nozzle):
        """Mean darkening of each band over the dash's place on the scan."""
        r, x0, x1 = check.dash_at(head, nozzle)
        u0, v0 = scanner.paper_to_scan(x0 * geo.col_um, r * geo.row_um)
        u1, v1 = scanner.paper_to_scan(x1 * geo.col_um, (r + 1) * geo.row_um)
        box = scan[int(v0):int(np.ceil(v1)), int(u0):int(np.ceil(u1))]
        return (white - box).mean(axis=(0, 1))

    m1 = {z: darkness("M1", z) for z in range(1, profile.nozzles - 1)}
    printed = np.median([d[1] for z, d in m1.items() if z != 57])
    print(f"M1 dashes darken green by {printed:.1f} levels; M1:57 by {m1[57][1]:.1f}")
    assert printed > 20
    assert np.abs(m1[57]).max() < 0.05 * printed             # nothing there: no other ink
    assert min(d[1] for z, d in m1.items() if z != 57) > 0.5 * printed
    # every other head's nozzle 57 printed its dash, each in its own block
    for h in profile.heads:
        if h.name != "M1":
            assert darkness(h.name, 57).max() > 0.5 * printed * (0.3 if h.color == "Y" else 1)
    # the media agrees: exactly that dash is missing
    media = read_planes(media_path)
    r, x0, x1 = check.dash_at("M1", 57)
    assert not media[r, x0:x1].any() and job.planes[r, x0:x1, 1].all()


def test_nozzle_check_gives_every_head_its_own_place(profile):
    job = PatternJob.for_pattern("nozzle-check", profile, 600)
    check = nozzle_check_layout(profile, 600)
    planes = job.planes
    owner = np.full(planes.shape[:2], -1)
    for h in profile.heads:
        for z in range(1, profile.nozzles - 1):
            r, x0, x1 = check.dash_at(h.name, z)
            assert planes[r, x0:x1, h.channel].all()
            assert (owner[max(r - 2, 0):r + 3, x0 - 1:x1 + 1] == -1).all()   # nothing near it
            owner[r, x0:x1] = h.index
    inked = planes.any(axis=2)
    bars = np.zeros_like(inked)
    for x0, x1 in check.bars:
        bars[:, x0:x1] = True
    assert np.array_equal(inked & ~bars, owner >= 0)           # nothing else but the K bars
    assert planes[:, :, 3][bars].mean() > 0.95


# -- the command line and the injections -----------------------------------------------------
def test_test_print_writes_a_scan_and_refuses_it_for_other_devices(tmp_path, capsys):
    from wideprint.app.cli import main
    scan = tmp_path / "s.tif"
    assert main(["test-print", "nozzle-check", "--width-mm", "20", "--scan-out", str(scan),
                 "--scan-dpi", "300", "--inject", "scan-mode=grey"]) == 0
    with tifffile.TiffFile(scan) as tf:
        page = tf.pages[0]
        assert page.shape == (page.shape[0], page.shape[1]) and page.dtype == np.uint8
        assert page.tags["XResolution"].value == (300, 1)
        img = page.asarray()
    assert img.min() < 160 and np.median(img) > 220
    capsys.readouterr()
    assert main(["test-print", "nozzle-check", "--device", "serial=/dev/null,data=tcp://127.0.0.1:9",
                 "--scan-out", str(tmp_path / "x.tif")]) == 2
    assert "--scan-out needs the in-process emulator" in capsys.readouterr().err
    assert main(["print", str(tmp_path / "none.tif"), "--device", "serial=/dev/null,data=tcp://127.0.0.1:9",
                 "--scan-out", str(tmp_path / "x.tif")]) == 2
    assert "--scan-out needs the in-process emulator" in capsys.readouterr().err


def test_injection_values_parse_with_their_units():
    f = Faults.parse(["bidir-error=0.3col", "head-offset=C2:x=20um,y=-10um", "feed-error=15um",
                      "misdirect=M1:57:5um", "misdirect=K2:3:x=-0.1mm", "dot-diameter=120um",
                      "scan-rotation=1.5", "scan-scale=1.002", "scan-offset=2,-1.5mm"])
    assert f.bidir_error == Length(0.3, "col")
    assert f.head_offset == [("C2", Length(20), Length(-10))]
    assert f.feed_error == Length(15) and Faults.parse(["feed-error=0.1%"]).feed_error_fraction == 0.001
    assert f.misdirect == [("M1", 57, Length(0), Length(5)), ("K2", 3, Length(-0.1, "mm"), Length(0))]
    assert f.scan_offset == (2.0, -1.5) and f.scan_rotation == 1.5
    assert Faults.parse(["bidir-error=2"]).bidir_error == Length(2, "col")
    for bad in ("misdirect=M1:57", "head-offset=C2:z=3um", "bidir-error=fast", "scan-mode=sepia",
                "feed-error-fraction=1", "feed-error=2col", "dot-diameter=1row", "scan-blur=-3um"):
        with pytest.raises(ValueError, match="--inject"):
            Faults.parse([bad])
    with pytest.raises(ValueError, match="no head named"):
        from wideprint.rip.profile import load_profile
        PhysicalModel(load_profile(), Faults.parse(["misdirect=Q9:5:3um"]))


def test_dot_diameter_from_the_drop_volume(profile):
    assert 95 < dot_diameter_um(profile) < 110               # 40 pl: a 42 µm drop spread 2.4 x
    assert dot_diameter_um(profile, Faults.parse(["dot-diameter=0.12mm"])) == pytest.approx(120)
