"""The emulator's media landing kernel (device_sim/media.py `_land_words`) against a plain
numpy reference: every set bit of a fire word lands at its nozzle's row and its fire's column
plus the nozzle's offset, in its ink's byte of the dot; drops off the sheet's rows or the paper's
edges count as stray, drops on rows already written out as late.  Forward and reverse strokes, batches that
run past either edge (the heads' offsets make a stroke fire beyond the paper), misdirected
nozzles, scattered columns."""

from __future__ import annotations

import numpy as np
import pytest

from wideprint.device_sim.media import _land_words
from wideprint.rip.planes import INK_SHIFT


def reference(win, base, height, width, words, cols, rows, dcols, channel):
    landed = stray = late = 0
    bits = np.unpackbits(words.astype("<u2").view(np.uint8), axis=1, bitorder="little")
    for f, z in zip(*np.nonzero(bits)):
        r, c = rows[z], cols[f] + dcols[z]
        if r < 0 or r >= height:          # the row first: off the sheet, or written out
            stray += 1
        elif r < base:
            late += 1
        elif c < 0 or c >= width:
            stray += 1
        else:
            win[r - base, c, channel] += 1
            landed += 1
    return landed, stray, late


@pytest.mark.parametrize("seed", range(40))
def test_landing_matches_the_reference(seed):
    rng = np.random.default_rng(seed)
    width, height, nwin = int(rng.integers(40, 400)), 300, 64
    base = int(rng.integers(0, 40))
    n = int(rng.integers(1, 300))
    kind = seed % 4
    start = int(rng.integers(-150, width + 50))
    if kind == 0:
        cols = start + np.arange(n)                        # forward
    elif kind == 1:
        cols = start - np.arange(n)                        # reverse
    elif kind == 2:
        cols = np.sort(rng.integers(-20, width + 20, n))   # scattered
    else:
        cols = np.full(n, start)                           # one column
    words = (rng.integers(0, 1 << 16, (n, 8)) & rng.integers(0, 1 << 16, (n, 8))).astype(np.uint16)
    rows = base - 3 + rng.permutation(np.arange(128)) // 2
    rows[rng.integers(0, 128, 4)] = rng.choice([-1, height, base - 1, base + nwin + 2])
    dcols = rng.integers(-3, 4, 128) * (seed % 3 == 0)
    channel = seed % 4
    win = np.zeros((nwin, width, 4), np.uint8)
    rows_in = np.where(rows >= base + nwin, -1, rows)   # past the window: the caller flushes first
    want_win = win.copy()
    want = reference(want_win, base, height, width, words, cols, rows_in, dcols, channel)
    got = _land_words(win.view(np.uint32).reshape(nwin, width), base, height, width, words,
                      cols.astype(np.int64), rows_in.astype(np.int64), dcols.astype(np.int64),
                      np.uint32(INK_SHIFT[channel]))
    assert tuple(int(x) for x in got) == want
    assert np.array_equal(win, want_win)


def test_media_lands_in_order_on_its_worker_and_reports_failures(tmp_path):
    """Media.land_words and the rows written out run on the media's worker thread in the
    order asked (device_sim/media.py): a row written out holds every drop landed on it
    before, the counts add up once read, and a failure in the worker is raised by the next
    call instead of being lost."""
    from wideprint.device_sim.media import Media
    from wideprint.rip.planes import read_planes

    width, height = 64, 40
    m = Media(width, height, 300, 300, window_rows=16, path=str(tmp_path / "m.tif"))
    rng = np.random.default_rng(7)
    want = np.zeros((height, width, 4), np.uint8)
    for k in range(30):                          # each batch further down the sheet
        top = min(k, height - 8)
        rows = top + np.arange(128) // 16        # 8 rows, 16 nozzles each (8 of them dead-end)
        rows[rows >= height] = -1
        cols = np.arange(width) if k % 2 == 0 else np.arange(width)[::-1].copy()
        words = (rng.integers(0, 1 << 16, (width, 8)) & 0x00FF).astype(np.uint16)  # bits 0-7
        ch = k % 4
        ref = want.copy()
        reference(ref, 0, height, width, words, cols, rows, np.zeros(128, np.int64), ch)
        want = ref
        m.land_words(ch, words, cols, rows)
        if k % 5 == 4:
            m.flush_below(top)                   # queued behind the landings above
    assert int(m.drops.sum()) == int(want.astype(np.int64).sum())
    m.close()
    assert np.array_equal(read_planes(str(tmp_path / "m.tif")), want)

    bad = Media(width, height, 300, 300, window_rows=16)
    bad._queue(None, lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        bad.snapshot()
    bad.close()
