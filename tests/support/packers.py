"""The two stroke packers side by side: the same job planned with the block packer and
with the per-dot packer (rip/swath.py), and the check that they give the same strokes."""

from __future__ import annotations

import numpy as np

from wideprint.rip.swath import StrokePlanner, pack_dots


def plan_both(profile, dots, passes=1, mask="checker", bidir=False, band=64):
    """The same job planned with the block packer and with the per-dot packer."""
    height, width = dots.shape[:2]

    def plan(block):
        planner = StrokePlanner(profile, width, height, 300, passes, bidir, mask)
        planner.block_pack = block
        out = []
        for a in range(0, height, band):
            out += planner.feed_packed(pack_dots(dots[a:a + band]))
        return out + planner.finish()

    return plan(True), plan(False)


def assert_same_strokes(fast, slow, dots):
    assert len(fast) == len(slow) > 1
    for f, s in zip(fast, slow):
        assert (f.index, f.direction, f.top_row, f.first_column) == \
               (s.index, s.direction, s.top_row, s.first_column)
        assert np.array_equal(f.words, s.words)
        assert np.array_equal(f.dots, s.dots)
    assert sum(int(f.dots.sum()) for f in fast) == int(dots.sum())
