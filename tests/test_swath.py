"""The stroke planner: every halftone dot is fired exactly once, by a live nozzle, at the
place the geometry says (property-based over images, modes and profiles)."""


import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from support.printing import replay, variant_profile
from wideprint.driver import protocol as P
from wideprint.rip.profile import ProfileError
from wideprint.rip.swath import PASS_COUNTS, StrokePlanner


@st.composite
def jobs(draw):
    h = draw(st.integers(1, 700))
    w = draw(st.integers(1, 90))
    density = draw(st.sampled_from([0.0, 0.05, 0.5, 1.0]))
    seed = draw(st.integers(0, 2**31))
    passes = draw(st.sampled_from(PASS_COUNTS))
    dpi = draw(st.sampled_from([150, 300, 600]))
    bidir = draw(st.booleans())
    band = draw(st.integers(1, 300))
    ndead = draw(st.integers(0, 4)) if passes > 1 else 0
    dead = draw(st.lists(st.tuples(st.sampled_from(["C1", "C2", "M1", "M2", "Y1", "Y2", "K1", "K2"]),
                                   st.integers(1, 126)), min_size=ndead, max_size=ndead, unique=True))
    offsets = draw(st.lists(st.integers(0, 400).map(lambda v: v * 4), min_size=8, max_size=8))
    bidir_off = draw(st.integers(-3, 3))
    mask = draw(st.sampled_from(["checker", "random", "feather"]))
    return h, w, density, seed, passes, dpi, bidir, band, dead, offsets, bidir_off, mask


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(job=jobs())
def test_every_dot_fired_once_by_a_live_nozzle(tmp_path_factory, job):
    h, w, density, seed, passes, dpi, bidir, band, dead, offsets, bidir_off, mask = job
    tmp = tmp_path_factory.mktemp("prof")
    try:
        profile = variant_profile(tmp, dead, offsets, bidir={150: bidir_off, 300: bidir_off, 600: bidir_off})
        planner = StrokePlanner(profile, w, h, dpi, passes, bidir, mask)
    except ProfileError as exc:
        # only acceptable refusal: dead nozzles that leave a row with no live nozzle
        assert "unprintable" in str(exc)
        return
    rng = np.random.default_rng(seed)
    planes = (rng.random((h, w, 4)) < density).astype(np.uint8)
    out = []
    for y in range(0, h, band):
        out += planner.feed(planes[y:y + band])
    out += planner.finish()
    assert [p.index for p in out] == sorted({p.index for p in out})
    got = replay(profile, planner, out, h, w)
    assert np.array_equal(got, planes)
    if bidir:
        assert [p.direction for p in out] == [i % 2 for i in range(len(out))]
    else:
        assert all(p.direction == 0 for p in out)


def test_dead_nozzle_with_one_pass_is_refused_with_a_clear_message(tmp_path):
    profile = variant_profile(tmp_path, dead=[("M1", 57)])
    with pytest.raises(ProfileError, match="M1:57.*colour M.*1 pass"):
        StrokePlanner(profile, 10, 10, 300, 1)


def test_stroke_geometry_numbers(profile):
    pl = StrokePlanner(profile, 100, 1000, 300, 4)
    assert pl.advance == 63 and pl.s0 == 2
    assert pl.total_strokes == -(-1000 // 63) + 3
    assert pl.y0_rows == 3 * 63 + 2


def test_memory_window_is_bounded(profile):
    """Feeding a tall image band by band keeps only the planner's window."""
    pl = StrokePlanner(profile, 64, 20000, 300, 2)
    rng = np.random.default_rng(0)
    biggest = 0
    for y in range(0, 20000, 256):
        pl.feed((rng.random((256, 64, 4)) < 0.2).astype(np.uint8))
        biggest = max(biggest, pl._buf.shape[0])
    assert biggest <= 2 * pl.advance + 256


@pytest.mark.parametrize("mask", ["checker", "random", "feather"])
def test_pass_masks_share_dots_between_passes(profile, mask):
    """Every stroke prints a share of a full field; feathering gives the nozzles at the ends
    of the run fewer dots than those in the middle."""
    n, h, w = 4, 1200, 256
    pl = StrokePlanner(profile, w, h, 300, n, mask=mask)
    full = np.ones((h, w, 4), np.uint8)
    strokes = pl.feed(full) + pl.finish()
    per_nozzle = np.zeros(profile.nozzles)
    for sd in strokes:
        bits = P.words_to_nozzles(sd.words[0])
        per_nozzle += bits.sum(axis=0)
    used = per_nozzle[2:126]
    mid, ends = used[len(used) // 2 - 10:len(used) // 2 + 10].mean(), np.r_[used[:8], used[-8:]].mean()
    if mask == "feather":
        assert ends < 0.5 * mid
    else:
        assert abs(ends - mid) < 0.1 * mid


def test_prefetch_starts_at_once_and_stops_when_closed_or_dropped():
    """rip/pipeline.py Prefetch: the producer runs before the first item is asked for (the
    job's RIP works while the printer gets ready), items and errors arrive in order, and a
    consumer that closes it or just drops it stops its thread."""
    import gc
    import threading
    import time

    from wideprint.rip.pipeline import prefetch

    started = threading.Event()
    made = []

    def items(n, fail_at=None):
        started.set()
        for i in range(n):
            if i == fail_at:
                raise ValueError(f"item {i}")
            made.append(i)
            yield i

    def threads():
        return sum(t.name == "rip-prefetch" for t in threading.enumerate())

    base = threads()
    p = prefetch(items(3), depth=2)
    assert started.wait(2)                      # running before anyone iterates
    assert list(p) == [0, 1, 2]
    with pytest.raises(ValueError, match="item 1"):
        list(prefetch(items(5, fail_at=1)))
    for drop in (False, True):                  # an endless producer, abandoned
        made.clear()
        p = prefetch(items(10**9), depth=2)
        assert next(p) == 0
        if drop:
            del p
            gc.collect()
        else:
            p.close()
        deadline = time.monotonic() + 3
        while threads() > base and time.monotonic() < deadline:
            time.sleep(0.02)
        assert threads() == base
        assert len(made) <= 4                   # it stopped at its next item


def test_ordered_runs_bands_side_by_side_in_order():
    """rip/parallel.py `ordered`: whole bands on the band workers at once (not one band split
    and waited for), results in the jobs' order however the jobs finish, a job's error at
    its place, and `run_parallel` inside a band job runs there (a band worker that waited
    for the shared pool could leave both cores idle, or deadlock a pool of busy workers)."""
    import threading
    import time

    from wideprint.rip import parallel

    if parallel.WORKERS < 2:
        pytest.skip("one core: nothing runs side by side")
    running, most = [0], [0]
    lock = threading.Lock()

    def job(i, delay, fail=False):
        def run():
            with lock:
                running[0] += 1
                most[0] = max(most[0], running[0])
            time.sleep(delay)
            inner = []
            parallel.run_parallel(lambda k=k: inner.append(threading.current_thread().name)
                                  for k in range(3))
            with lock:
                running[0] -= 1
            if fail:
                raise ValueError(f"band {i}")
            return i, set(inner)
        return run

    # later jobs finish first: the order still holds
    out = list(parallel.ordered(job(i, 0.05 * (4 - i)) for i in range(5)))
    assert [i for i, _ in out] == [0, 1, 2, 3, 4]
    assert most[0] == 2                         # two bands at a time, never more than cores
    for _, names in out:                        # the inner jobs ran on the band's own thread
        assert len(names) == 1 and next(iter(names)).startswith("wideprint-band")
    running[0] = most[0] = 0                    # one worker: one band at a time, in order
    assert [i for i, _ in parallel.ordered((job(i, 0.01) for i in range(4)), workers=1)] == \
        [0, 1, 2, 3]
    assert most[0] == 1
    got = []
    with pytest.raises(ValueError, match="band 2"):
        for i, _ in parallel.ordered(job(i, 0.01, fail=i == 2) for i in range(6)):
            got.append(i)
    assert got == [0, 1]
    # outside a band worker run_parallel still uses the shared pool
    names = []
    parallel.run_parallel(lambda: (time.sleep(0.02), names.append(threading.current_thread().name))
                          for _ in range(2))
    assert all(n.startswith("wideprint-rip") for n in names)


def test_nibble_rows_match_the_numpy_reference():
    """rip/planes.py `_bits_to_nibbles` (a compiled loop) gives the packed encoding's bytes
    of the plane bits exactly as the four table look-ups in numpy it replaced, at every
    width (whole and partial last words)."""
    from wideprint.rip import planes

    def reference(bits, width):
        s = planes._SPREAD
        words = (s[bits[:, 0]] | s[bits[:, 1]] >> np.uint32(1) | s[bits[:, 2]] >> np.uint32(2)
                 | s[bits[:, 3]] >> np.uint32(3))
        return words.astype(">u4").view(np.uint8).reshape(bits.shape[0], -1)[:, :-(-width // 2)]

    rng = np.random.default_rng(5)
    for width in (1, 2, 3, 7, 8, 9, 15, 16, 17, 1023, 1024, 1031):
        bits = rng.integers(0, 256, (5, 4, -(-width // 8)), dtype=np.uint8)
        if width % 8:
            bits[:, :, -1] &= np.uint8((0xFF << (8 - width % 8)) & 0xFF)
        got = planes._bits_to_nibbles(bits, width)
        assert got.shape == (5, -(-width // 2))
        assert np.array_equal(got, reference(bits, width)), width
        # and back: the nibbles unpack to the same dots as the bits
        dots = np.unpackbits(got, axis=1, count=width * 4).reshape(5, width, 4)
        assert np.array_equal(dots, np.unpackbits(bits, axis=2, count=width).transpose(0, 2, 1))
