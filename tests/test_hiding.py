"""Pass masks designed against the measured machine, "nozzle-error hiding" (issue 36,
docs/quality.md "Masks against the machine"): rip.masks.hiding_weights and
bench/banding_hiding.py, which measures the nozzles on a nozzle-check scan and prints the
banding chart with the shares."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from wideprint.app import api
from wideprint.rip import swath
from wideprint.rip.hiding import weave_slots
from wideprint.rip.masks import hiding_weights, stroke_error_um
from wideprint.rip.profile import load_profile
from wideprint.rip.stroke_hiding import STROKE_BINS, StrokeClasses, stroke_hiding_weights

REPO = Path(__file__).resolve().parents[1]


def _bench():
    spec = importlib.util.spec_from_file_location("banding_hiding", REPO / "bench" / "banding_hiding.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


bench = _bench()


@pytest.fixture(scope="module")
def profile():
    return load_profile()


def machine(profile, seed=1, dy_um=3.0, volume=0.03):
    rng = np.random.default_rng(seed)
    shape = (len(profile.heads), profile.nozzles)
    return rng.normal(0, dy_um, shape), 1.0 + rng.normal(0, volume, shape)


def row_errors(w, dy, vol, sl):
    h, z = sl[..., 0], sl[..., 1]
    return (w * dy[h, z]).sum(axis=2), (w * vol[h, z]).sum(axis=2)


def test_shares_are_shares_and_equal_without_errors(profile):
    sl = weave_slots(profile, 4)
    shape = (len(profile.heads), profile.nozzles)
    w = hiding_weights(np.zeros(shape), np.ones(shape), sl)
    assert w.shape == (4, sl.shape[1], 4) and np.allclose(w, 0.25)
    dy, vol = machine(profile)
    w = hiding_weights(dy, vol, sl)
    assert (w >= 0).all() and np.allclose(w.sum(axis=2), 1.0)
    assert np.array_equal(w, hiding_weights(dy, vol, sl))                  # deterministic


def test_the_rows_errors_cancel_where_equal_shares_average_them(profile):
    """The typical machine's spreads (3 µm, 3 %): every row's mean landing error and volume
    is brought near its colour's mean; equal shares leave each row the mean of 4 nozzles."""
    sl = weave_slots(profile, 4)
    dy, vol = machine(profile)
    d_eq, v_eq = row_errors(np.full(sl.shape[:3], 0.25), dy, vol, sl)
    d_h, v_h = row_errors(hiding_weights(dy, vol, sl), dy, vol, sl)
    spread = lambda a: float(np.std(a - a.mean(axis=1, keepdims=True)))   # noqa: E731
    assert spread(d_eq) == pytest.approx(1.5, rel=0.15)                   # 3 µm / sqrt 4
    assert spread(d_h) < 0.45 * spread(d_eq) and spread(v_h) < 0.65 * spread(v_eq)   # 0.36, 0.53


def test_a_feed_that_is_not_whole_steps_holds_the_shares_equal(profile, tmp_path):
    """The default profile's 4-pass advance is 183.29 steps: each stroke lands up to half a
    step off, 6.5 µm RMS against its neighbours, which per-row shares cannot follow; a roller
    sized for whole steps leaves none."""
    assert stroke_error_um(profile, 4) == pytest.approx(6.5, abs=0.2)
    whole = load_profile(bench.whole_step_profile(str(tmp_path), 4))
    assert stroke_error_um(whole, 4) < 0.1
    sl = weave_slots(profile, 4)
    dy, vol = machine(profile)
    free = np.abs(hiding_weights(dy, vol, sl) - 0.25).mean()
    held = np.abs(hiding_weights(dy, vol, sl, stroke_error_um=6.5) - 0.25).mean()
    assert held < 0.5 * free


def test_the_hiding_shares_print_every_dot_once(monkeypatch, profile, tmp_path):
    """The shares decide which pass fires a dot, never which dots fire: the media of the
    perfect printer is the planes, dot for dot (a tired machine's shares: far from equal)."""
    dy, vol = machine(profile, seed=2, dy_um=10.0, volume=0.08)
    shares = hiding_weights(dy, vol, weave_slots(profile, 4))
    assert (shares < 0.05).mean() > 0.2                    # many passes left out of a row
    monkeypatch.setattr(swath.StrokePlanner, "_pass_mask", bench._pass_mask)
    monkeypatch.setitem(bench._HIDING, 4, shares)
    assert _media_is_the_planes(tmp_path)


def _media_is_the_planes(tmp_path) -> bool:
    """A random image printed at 4 passes with the random mask (which the bench's hooks
    replace) on the perfect printer: is its bit-exact media the planes?"""
    import tifffile
    img = tmp_path / "img.tif"
    rng = np.random.default_rng(1)
    tifffile.imwrite(img, rng.integers(0, 256, (300, 160, 3), dtype=np.uint8), resolution=(300, 300))
    settings = dict(passes=4, pass_mask="random", dpi=300)
    planes = api.rip(img, settings)
    got = api.print_file(img, settings)
    return got.ok and api.compare(got.media, planes).equal


def test_hiding_halves_the_typical_machines_banding_on_whole_step_feeds(tmp_path, monkeypatch):
    """bench/banding_hiding.py on the typical machine (seed 1), 4 passes, the feed roller
    sized for whole steps: the nozzle check measures every nozzle's landing error within
    0.5 µm and its volume within 1 %, and the banding chart printed with the shares reads
    under 0.6 of the checkerboard's (measured 0.051 against 0.117)."""
    monkeypatch.setattr(swath.StrokePlanner, "_pass_mask", bench._pass_mask)
    monkeypatch.setattr(bench, "PROFILE", [bench.whole_step_profile(str(tmp_path), 4)])
    runs = {r["mask"]: r for r in bench.run("typical", 1, 4, str(tmp_path), load_profile(),
                                            masks=("checker", "hiding"))}
    err = runs["hiding"]["nozzle_check"]
    assert err["dy_um"] < 0.5 and err["volume_pct"] < 1.0 and err["stroke_error_um"] < 0.1
    assert runs["hiding"]["banding"] < 0.6 * runs["checker"]["banding"], runs


# -- shares per stroke (rip/stroke_hiding.py) ---------------------------------------------------

def test_the_stroke_classes_know_each_strokes_landing_error(profile):
    """The blocks' passes land where the driver's whole-step feeds put them (the same
    rounding as rip/profile.py `feed_steps_for_rows`), and a block's class knows them up to
    a shift common to its passes of at most half a class's width."""
    cl = StrokeClasses.of(profile, 4)
    a = cl.advance
    blocks = np.arange(600)
    exact = cl.block_errors_um(blocks)                                      # (B, N)
    steps = np.array([profile.feed_steps_for_rows(int(i * a)) for i in range(603)])
    driver = steps * profile.feed_um_per_step - np.arange(603) * a * profile.row_um
    assert np.allclose(exact, driver[blocks[:, None] + np.arange(4)], atol=1e-6)
    assert np.sqrt(np.mean((exact - exact.mean(axis=1, keepdims=True)) ** 2)) == pytest.approx(
        stroke_error_um(profile, 4), abs=0.05)
    off = exact - cl.class_errors_um()[cl.of_blocks(blocks)]
    assert np.ptp(off, axis=1).max() < 1e-6
    width = np.diff(np.append(cl.edges, 1.0)).max()
    assert np.abs(off).max() <= profile.feed_um_per_step * width / 2 + 1e-6
    assert cl.count <= STROKE_BINS + 4
    # a top margin moves every target (driver/job.py: feed_steps_for_rows(i A + top))
    top = StrokeClasses.of(profile, 4, top_rows=37)
    steps = np.array([profile.feed_steps_for_rows(int(i * a + 37)) for i in range(603)])
    driver = steps * profile.feed_um_per_step - (np.arange(603) * a + 37) * profile.row_um
    assert np.allclose(top.block_errors_um(blocks), driver[blocks[:, None] + np.arange(4)], atol=1e-6)
    assert not np.allclose(top.block_errors_um(blocks), exact, atol=1.0)


def test_stroke_shares_are_shares_and_cancel_the_strokes_errors_too(profile):
    """The typical machine's nozzle spreads and the default feed's rounding: a row's mean
    landing error, nozzles and strokes together, varies from row to row several times less
    with shares per stroke than with the shares per row phase (held towards equal by the
    rounding) or equal shares."""
    sl = weave_slots(profile, 4)
    dy, vol = machine(profile)
    cl = StrokeClasses.of(profile, 4)
    w = stroke_hiding_weights(dy, vol, sl, cl.class_errors_um())
    assert w.shape == (cl.count, 4, sl.shape[1], 4)
    assert (w >= 0).all() and np.allclose(w.sum(axis=3), 1.0)
    assert np.array_equal(w, stroke_hiding_weights(dy, vol, sl, cl.class_errors_um()))
    blocks = np.arange(400)
    f = cl.block_errors_um(blocks)[:, None, None, :]                        # (B, 1, 1, N)
    land = dy[sl[..., 0], sl[..., 1]][None] + f                              # (B, 4, A, N)

    def spread(shares):                                                       # µm, per colour
        rows = (shares * land).sum(axis=3)
        return float(np.std(rows - rows.mean(axis=(0, 2), keepdims=True)))
    equal = spread(np.full(land.shape, 0.25))
    per_phase = spread(hiding_weights(dy, vol, sl, stroke_error_um=stroke_error_um(profile, 4))[None])
    per_stroke = spread(w[cl.of_blocks(blocks)])
    assert per_stroke < 0.3 * per_phase and per_stroke < 0.3 * equal, (per_stroke, per_phase, equal)


def _stroke_planner(monkeypatch, shares, classes):
    monkeypatch.setattr(swath.StrokePlanner, "_pass_mask", bench._pass_mask)
    monkeypatch.setattr(swath.StrokePlanner, "_stroke_mask", bench._stroke_mask)
    monkeypatch.setitem(bench._STROKE, 4, (shares, classes))


@pytest.mark.parametrize("block_pack", [True, False])
def test_stroke_shares_select_per_stroke_in_both_packers(monkeypatch, profile, block_pack):
    """Equal shares in every class select as the random mask does, word for word; unequal
    ones print every dot once, with the same words from the block and the per-dot packer."""
    rng = np.random.default_rng(3)
    h, width = 600, 200
    dots = (rng.random((h, width, 4)) < 0.4).astype(np.uint8)

    def words(pack=block_pack):
        pl = swath.StrokePlanner(profile, width, h, 300, passes=4, mask="random")
        pl.block_pack = pack
        return [(s.index, s.first_column, s.words.tobytes(), tuple(s.dots))
                for s in pl.feed(dots) + pl.finish()]
    random = words()
    cl = StrokeClasses.of(profile, 4)
    a = cl.advance
    _stroke_planner(monkeypatch, np.full((cl.count, 4, a, 4), 0.25), cl)
    assert words() == random
    shares = rng.random((cl.count, 4, a, 4)) ** 3
    _stroke_planner(monkeypatch, shares / shares.sum(axis=3, keepdims=True), cl)
    got = words()
    assert got != random and got == words(not block_pack)
    assert np.array_equal(np.sum([g[3] for g in got], axis=0), dots.sum(axis=(0, 1)))


def test_the_stroke_shares_print_every_dot_once(monkeypatch, profile, tmp_path):
    """The media of the perfect printer is the planes, dot for dot, with a tired machine's
    shares per stroke (far from equal)."""
    dy, vol = machine(profile, seed=2, dy_um=10.0, volume=0.08)
    cl = StrokeClasses.of(profile, 4)
    shares = stroke_hiding_weights(dy, vol, weave_slots(profile, 4), cl.class_errors_um())
    assert (shares < 0.05).mean() > 0.2
    _stroke_planner(monkeypatch, shares, cl)
    assert _media_is_the_planes(tmp_path)


def test_stroke_hiding_halves_the_typical_machines_banding_on_the_default_feed(tmp_path, monkeypatch):
    """bench/banding_hiding.py on the typical machine (seed 1), 4 passes, the default feed
    (183.29 steps an advance): shares per stroke read under half the checkerboard's banding
    (measured 0.047 against 0.129) and below the shares per row phase (0.092)."""
    monkeypatch.setattr(swath.StrokePlanner, "_pass_mask", bench._pass_mask)
    monkeypatch.setattr(swath.StrokePlanner, "_stroke_mask", bench._stroke_mask)
    runs = {r["mask"]: r for r in bench.run("typical", 1, 4, str(tmp_path), load_profile(),
                                            masks=("checker", "hiding", "stroke-hiding"))}
    assert runs["stroke-hiding"]["nozzle_check"]["stroke_error_um"] > 6
    assert runs["stroke-hiding"]["banding"] < 0.5 * runs["checker"]["banding"], runs
    assert runs["stroke-hiding"]["banding"] < 0.8 * runs["hiding"]["banding"], runs
