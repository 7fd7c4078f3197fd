"""Nozzle-error hiding as a setting (issue 36; docs/quality.md "Nozzle-error hiding as a
setting", docs/calibration.md "nozzles"): `wideprint calibrate nozzles` measures every
nozzle's landing error and drop volume on a 1200 dpi scan of the nozzle check and keeps
them in the printer profile; `--pass-mask hiding` prints with shares made from them."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import tifffile
import tomlkit

from wideprint.app import api
from wideprint.app.cli import main
from wideprint.device_sim.faults import Faults
from wideprint.device_sim.physical import PhysicalModel
from wideprint.rip.hiding import hiding_shares, weave_slots
from wideprint.rip.profile import DEFAULT_PROFILE, ProfileError, load_profile, save_calibration
from wideprint.rip.swath import StrokePlanner

ROOT = Path(__file__).resolve().parents[1]
MACHINE = ["--inject", "machine=typical", "--inject", "seed=1"]


def run(capsys, argv):
    capsys.readouterr()
    rc = main(argv)
    out = capsys.readouterr()
    return rc, out.out, out.err


def nozzle_check(tmp_path, name, width_mm, scan_dpi, inject=()):
    scan = tmp_path / f"{name}.tif"
    assert main(["test-print", "nozzle-check", "--dpi", "150", "--width-mm", str(width_mm),
                 "--scan-out", str(scan), "--scan-dpi", str(scan_dpi), *MACHINE,
                 *[a for i in inject for a in ("--inject", i)]]) == 0
    return str(scan)


def calibrate(capsys, scan, width_mm, profile):
    rc, out, err = run(capsys, ["calibrate", "nozzles", "--scan", scan, "--width-mm",
                                str(width_mm), "--write", "--profile", str(profile), "--json"])
    assert rc == 0, err
    return json.loads(out)


def a_profile(tmp_path, name="printer.toml"):
    path = tmp_path / name
    shutil.copy(DEFAULT_PROFILE, path)
    return path


@pytest.fixture(scope="module")
def typical(tmp_path_factory):
    """The typical machine (seed 1) calibrated from a 200 mm nozzle check scanned at 1200
    dpi, as bench/banding_hiding.py measures it: (profile path, what calibrate wrote)."""
    d = tmp_path_factory.mktemp("typical")
    profile = a_profile(d)
    scan = d / "nc.tif"
    assert main(["test-print", "nozzle-check", "--dpi", "150", "--width-mm", "200",
                 "--scan-out", str(scan), "--scan-dpi", "1200", *MACHINE]) == 0
    assert main(["calibrate", "nozzles", "--scan", str(scan), "--width-mm", "200", "--write",
                 "--profile", str(profile)]) == 0
    return profile


def test_calibrate_nozzles_recovers_the_typical_machines_errors(typical):
    """Every nozzle's landing error within 0.3 µm of the machine's (spread 3.0 µm; the head's
    common offset aside) and its drop volume within 0.6 % (spread 3.3 %): measured 0.26 µm
    and 0.55 %, as the bench. Stored in the profile, dated, every head and nozzle."""
    prof = load_profile(typical)
    lay = prof.layout
    assert lay.nozzles_measured and lay.nozzles_measured.endswith("Z")
    assert set(lay.nozzle_dy_um) == {h.name for h in prof.heads}
    dy = np.array([lay.nozzle_dy_um[h.name] for h in prof.heads])
    vol = 1 + np.array([lay.nozzle_volume_pct[h.name] for h in prof.heads]) / 100
    model = PhysicalModel(load_profile(), Faults.parse(["machine=typical", "seed=1"]))
    live = vol > 0
    assert live.sum() == 8 * 126 and (vol[:, [0, 127]] == 0).all()       # no dash: no drop
    dy_t, vol_t = model.spread_dy_um[live], model.volume[live]
    e_dy = np.std(dy[live] - dy[live].mean() - (dy_t - dy_t.mean()))
    e_vol = np.std(vol[live] - vol_t) * 100
    print(f"dy within {e_dy:.3f} µm (spread {dy_t.std():.2f}), volume within {e_vol:.3f} % "
          f"(spread {vol_t.std() * 100:.2f})")
    assert e_dy < 0.3 and e_vol < 0.6
    assert dy_t.std() > 2.5 and vol_t.std() > 0.025            # the errors were there to find


def test_hiding_reads_under_half_the_checkers_banding_on_that_machine(typical, tmp_path, capsys):
    """The banding chart at 4 passes on the machine just calibrated, each mask scanned and
    measured by `wideprint quality`: hiding's shares per stroke read 0.046 against the
    checkerboard's 0.129 ΔL* (0.36x, bench/results/banding_hiding_setting.json); shares per
    row phase read 0.092 (0.71x) and fail this."""
    banding = {}
    for mask in ("checker", "hiding"):
        scan = tmp_path / f"chart-{mask}.tif"
        assert main(["test-print", "banding-scan", "--dpi", "300", "--passes", "4",
                     "--pass-mask", mask, "--width-mm", "100", "--scan-out", str(scan),
                     "--scan-dpi", "600", "--profile", str(typical), *MACHINE]) == 0
        rc, out, _ = run(capsys, ["quality", str(scan), "--passes", "4", "--json"])
        assert rc == 0
        banding[mask] = json.loads(out)["summary"]["banding"]
    print(banding)
    assert banding["hiding"] <= 0.5 * banding["checker"], banding


def test_dead_nozzles_and_the_errors_are_written_together(tmp_path, capsys):
    """The dead nozzle the scan shows is in the dead list and stored as no drop, in the same
    --write; on a scan of 600 dpi the errors are refused, naming the file (the dead nozzles
    are still found and written), and a stored measurement stays as it was."""
    profile = a_profile(tmp_path)
    scan = nozzle_check(tmp_path, "nc", 50, 1200, ["dead-nozzle=M1:57"])
    got = calibrate(capsys, scan, 50, profile)["found"]
    assert got["dead"] == ["M1:57"] and got["errors"]["nozzles"] == 8 * 126 - 1
    prof = load_profile(profile)
    m1 = next(h for h in prof.heads if h.name == "M1")
    assert prof.dead_nozzles == {(m1.index, 57)}
    assert prof.layout.nozzle_volume_pct["M1"][57] == -100.0
    assert prof.layout.nozzle_dy_um["M1"][57] == 0.0
    before = Path(profile).read_text()
    coarse = nozzle_check(tmp_path, "coarse", 50, 600, ["dead-nozzle=M1:57"])
    rc, out, _ = run(capsys, ["calibrate", "nozzles", "--scan", coarse, "--width-mm", "50",
                              "--write", "--profile", str(profile)])
    assert rc == 0
    assert f"{coarse}: a 600 dpi scan is too coarse to measure the nozzles' landing errors" in out
    assert "needs 1200 dpi" in out and "nozzles: 1008 dashes measured; 1 dead: M1:57" in out
    assert Path(profile).read_text() == before


def test_hiding_without_a_measurement_names_calibrate_nozzles(tmp_path, capsys):
    """Never a silent fallback to another mask: the planner refuses, and a print fails
    with the message."""
    with pytest.raises(ProfileError) as exc:
        StrokePlanner(load_profile(), 100, 100, 300, 4, mask="hiding")
    msg = str(exc.value)
    assert msg.startswith(f"{DEFAULT_PROFILE}: pass mask \"hiding\" needs the nozzles measured")
    assert "wideprint calibrate nozzles --scan nc.tif --write --profile PRINTER.toml" in msg
    img = tmp_path / "img.tif"
    tifffile.imwrite(img, np.full((40, 40, 3), 128, np.uint8), resolution=(300, 300))
    rc, out, err = run(capsys, ["print", str(img), "--passes", "4", "--pass-mask", "hiding"])
    assert rc != 0 and "wideprint calibrate nozzles" in out + err


def measured_profile(tmp_path, seed=2, dy_um=10.0, volume=0.08, dead=(("C2", 40),)):
    """A profile holding a tired machine's measurement (and a dead nozzle)."""
    path = a_profile(tmp_path, f"measured-{seed}.toml")
    prof = load_profile(path)
    rng = np.random.default_rng(seed)
    dy = {h.name: list(rng.normal(0, dy_um, prof.nozzles)) for h in prof.heads}
    pct = {h.name: list(rng.normal(0, volume * 100, prof.nozzles)) for h in prof.heads}
    for h, z in dead:
        dy[h][z], pct[h][z] = 0.0, -100.0
    return save_calibration(path, dead_nozzles=list(dead),
                            nozzle_errors=(dy, pct, "2026-11-28T15:00:00Z"))


def test_hiding_prints_the_same_dots_as_checker(tmp_path):
    """The shares decide which pass fires a dot, never which dots fire: on the perfect
    printer the media of a hiding print (per stroke, and per row phase: hiding-rows) is the
    planes, as the checkerboard's is, dot for dot, with the same ink; the plan is the same
    every time."""
    prof = measured_profile(tmp_path)
    shares = hiding_shares(prof, 4)
    assert (shares < 0.05).mean() > 0.08                    # far from equal: 11 % under 0.05
    assert np.allclose(shares.sum(axis=2), 1.0) and (shares >= 0).all()
    c2 = next(h for h in prof.heads if h.name == "C2")      # C2:40 dead: no share
    slot = c2.y_rows + 40 * prof.heads_per_color - prof.usable_slots()[0]
    assert shares[0, slot % 63, 3 - slot // 63] == 0.0
    assert not ((weave_slots(prof, 4)[..., 0] == c2.index) & (weave_slots(prof, 4)[..., 1] == 40)).any()
    plan = {}
    for mask in ("hiding", "hiding-rows"):
        one = plan[mask] = StrokePlanner(prof, 160, 300, 300, 4, mask=mask)
        two = StrokePlanner(prof, 160, 300, 300, 4, mask=mask)
        for i in (0, 4, 7):
            assert all(np.array_equal(a, b) for a, b in zip(one._stroke_mask(i), two._stroke_mask(i)))
    # hiding's selection changes from stroke to stroke (the blocks' classes); hiding-rows'
    # is one per row phase for every stroke
    assert not np.array_equal(plan["hiding"]._stroke_mask(4)[2], plan["hiding"]._stroke_mask(5)[2])
    assert plan["hiding-rows"]._stroke_mask(4)[2] is plan["hiding-rows"]._stroke_mask(5)[2]
    img = tmp_path / "img.tif"
    rng = np.random.default_rng(1)
    tifffile.imwrite(img, rng.integers(0, 256, (300, 160, 3), dtype=np.uint8), resolution=(300, 300))
    planes = api.rip(img, dict(passes=4, dpi=300), profile=prof)
    got = {m: api.print_file(img, dict(passes=4, pass_mask=m, dpi=300), profile=prof)
           for m in ("checker", "hiding", "hiding-rows")}
    for m, res in got.items():
        assert res.ok and api.compare(res.media, planes).equal, m
    assert got["hiding"].ink_ml == got["checker"].ink_ml == got["hiding-rows"].ink_ml


def test_the_profile_keeps_a_whole_dated_measurement(tmp_path):
    """A measurement missing a head, a nozzle or its date is refused at load, naming the
    key."""
    prof = measured_profile(tmp_path, dead=())
    bad = tmp_path / "bad.toml"

    def refused(edit, match):
        doc = tomlkit.parse(Path(prof.path).read_text())
        edit(doc["layout"])
        bad.write_text(tomlkit.dumps(doc))
        with pytest.raises(ProfileError, match=match):
            load_profile(bad)

    refused(lambda lay: lay.remove("nozzles_measured"), r"\[layout\] nozzles_measured: missing")
    refused(lambda lay: lay["nozzle_volume_pct"].remove("K1"),
            r"nozzle_volume_pct: no values for head\(s\) K1")
    refused(lambda lay: lay["nozzle_dy_um"]["K1"].pop(),
            r"nozzle_dy_um.K1: 127 values, the head has 128 nozzles")


def test_the_setting_is_offered_and_documented(capsys):
    with pytest.raises(SystemExit):
        main(["print", "--help"])
    out = capsys.readouterr().out
    assert "hiding" in out.split("--pass-mask", 1)[1].split("\n")[0]
    assert "calibrate nozzles" in " ".join(out.split())
    docs = {name: (ROOT / "docs" / name).read_text() for name in
            ("rip.md", "quality.md", "calibration.md", "settings.md")}
    assert "| `hiding` |" in docs["rip.md"] and "| `hiding-rows` |" in docs["rip.md"]
    assert "## Nozzle-error hiding as a setting" in docs["quality.md"]
    assert "nozzle_dy_um" in docs["calibration.md"] and "1200 dpi" in docs["calibration.md"]


def test_the_block_packer_plans_hiding_as_the_per_dot_kernel(tmp_path):
    """The per-colour selection through both packers (docs/rip.md): the same words, dots
    and spans, every dot once, with a dead nozzle and unequal shares per colour."""
    from support.packers import assert_same_strokes, plan_both
    prof = measured_profile(tmp_path)
    dots = (np.random.default_rng(3).random((400, 131, 4)) < 0.4).astype(np.uint8)
    fast, slow = plan_both(prof, dots, 4, "hiding", bidir=True, band=37)
    assert_same_strokes(fast, slow, dots)
    planner = StrokePlanner(prof, 131, 400, 300, 4, mask="hiding")
    assert len(np.unique(planner._sel.reshape(-1, planner._sel.shape[-1]), axis=0)) > 4 * 50


def test_hiding_plans_the_strokes_the_driver_feeds(tmp_path):
    """The per-stroke shares' classes follow the feeds the print really makes: with a 5 mm
    top margin (73 rows: every block's feed rounding shifted) the emulator's paper position
    at each printed stroke is the classes' whole-step target `round((i A + top) steps/row)`,
    which a plan for no margin misses; the same dots land as the planes."""
    prof = measured_profile(tmp_path)
    img = tmp_path / "img.tif"
    tifffile.imwrite(img, np.random.default_rng(2).integers(0, 256, (700, 120, 3), dtype=np.uint8),
                     resolution=(300, 300))
    settings = dict(passes=4, pass_mask="hiding", dpi=300, placement=dict(top_mm=5))
    res = api.print_file(img, settings, profile=prof)
    assert res.ok and api.compare(res.media, api.rip(img, dict(passes=4, dpi=300), profile=prof)).equal
    paper, at = None, {}
    for e in res.events:
        if e["event"] == "feed":
            paper = e["paper_steps"]
        elif e["event"] == "line":
            at[e["stroke"]] = paper
    from wideprint.rip.pipeline import RipJob
    classes = RipJob(str(img), api.rip_settings(settings, prof), prof).planner()._stroke_masks.classes
    assert classes.top_rows == 73 and len(at) > 10

    def targets(cl):
        i = np.array(sorted(at))
        x = (i * cl.advance + cl.top_rows) * cl.row_steps
        return np.floor(x + 0.5) - np.floor(x[0] + 0.5)
    fed = np.array([at[i] for i in sorted(at)]) - at[min(at)]
    assert np.array_equal(targets(classes), fed)
    from dataclasses import replace
    assert not np.array_equal(targets(replace(classes, top_rows=0)), fed)


def test_hiding_calls_the_kernels_random_does(tmp_path):
    """The per-stroke selection reaches both packers with the argument types of the random
    mask's (tools/build_kernels.py warms random up, not hiding): the compiled kernels take
    it; a read-only or strided array would go to numba's JIT."""
    from wideprint.rip.compiled import _key
    prof = measured_profile(tmp_path)
    hiding = StrokePlanner(prof, 64, 300, 300, 4, mask="hiding", top_rows=11)
    random = StrokePlanner(prof, 64, 300, 300, 4, mask="random")
    for i in (0, 5, 9):
        assert [_key(a) for a in hiding._stroke_mask(i)] == [_key(a) for a in random._stroke_mask(i)]
    assert _key(hiding._qmask) == _key(random._qmask)
