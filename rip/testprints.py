"""Test prints (docs/testprints.md): dot patterns made directly on the device grid and
printed through the same planner and driver as any image.

- line:         one nozzle of one head draws a line along the sweep; after a feed, a second
                line (seed 000, 4.2.4 test 1)
- sawtooth:     a 118-bit shift register, initial value 00...10, shifted once per encoder
                trigger, drives nozzles 0..117 of one head (one nozzle per fire); nozzles
                118..126 are held on as a solid reference bar (seed 000, test 2; nozzle 127
                stays 0 as the XJ128 requires)
- nozzle-check: every head has its own block along the sweep, in which each nozzle prints a
                dash on an 8-step staircase, between two K frame bars: no other ink is near
                a dash, so a missing dash names a dead nozzle (docs/physical.md)
- bidir-align:  printed in two strokes, forward then reverse: for each candidate offset
                o = -R..R a block of vertical bars, drawn at x by the forward stroke and at
                x + o by the reverse stroke; the block whose bars continue straight across
                the stroke boundary is the correction (docs/testprints.md)
- head-align:   for every head, bars at x + o next to reference bars of head K1, for
                o = -R..R; the straight block per head is that head's correction
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from .pipeline import PrintableJob, RipSettings
from .profile import Profile, load_profile

from .settings import TEST_PATTERNS as PATTERNS  # noqa: E402 - light, for the CLI parser
ALIGN_RANGE = 4          # candidate offsets -4 .. +4 columns
ALIGN_BLOCK = 48         # columns per candidate block
ALIGN_PITCH = 8          # columns between bars
CHECK_STEPS = 8          # nozzle-check staircase: nozzle z prints at step z mod 8


def align_offsets() -> list[int]:
    return list(range(-ALIGN_RANGE, ALIGN_RANGE + 1))


def _bars(planes, rows, channel, x0, offset, width):
    for x in range(x0 + 4, x0 + width - 4, ALIGN_PITCH):
        if 0 <= x + offset < planes.shape[1]:
            planes[rows, x + offset, channel] = 1


def _slot_row(profile: Profile, head_name: str, nozzle: int, planner_s0: int) -> tuple[int, int]:
    """(image row, channel) that one-pass printing puts on this head's nozzle."""
    for h in profile.heads:
        if h.name == head_name:
            return h.y_rows + profile.heads_per_color * nozzle - planner_s0, h.channel
    raise ValueError(f"no head named {head_name!r}; heads: {', '.join(h.name for h in profile.heads)}")


@dataclass(frozen=True)
class NozzleCheck:
    """Where the nozzle check puts every nozzle's dash (image rows and columns, 1 pass)."""
    dash: int                   # columns per staircase step; a dash is dash - 1 long
    blocks: dict                # head name -> first column of its block
    rows: dict                  # head name -> image row of nozzle 0 (its nozzle z: + hpc z)
    heads_per_color: int
    width: int
    height: int

    def dash_at(self, head: str, nozzle: int) -> tuple[int, int, int]:
        """(image row, first column, end column) of one nozzle's dash."""
        x0 = self.blocks[head] + (nozzle % CHECK_STEPS) * self.dash
        return self.rows[head] + self.heads_per_color * nozzle, x0, x0 + self.dash - 1

    @property
    def bars(self) -> tuple[tuple[int, int], tuple[int, int]]:
        """The two K frame bars: (first column, end column)."""
        return (0, self.dash), (self.width - self.dash, self.width)


def nozzle_check_layout(profile: Profile, width: int) -> NozzleCheck:
    """Units of `dash` columns: a K bar, a gap, per head a staircase of 8 steps and a gap,
    a K bar."""
    units = 3 + len(profile.heads) * (CHECK_STEPS + 1)
    dash = max(3, width // units)
    s0, s1 = profile.usable_slots()
    blocks = {h.name: (2 + i * (CHECK_STEPS + 1)) * dash for i, h in enumerate(profile.heads)}
    rows = {h.name: h.y_rows - s0 for h in profile.heads}
    return NozzleCheck(dash, blocks, rows, profile.heads_per_color, units * dash, s1 - s0)


def make_pattern(kind: str, profile: Profile, width: int, head: str = "K1",
                 nozzle: int = 64) -> np.ndarray:
    """The pattern as planes (rows, width, 4) uint8 0/1 on the device grid, for 1 pass."""
    s0, s1 = profile.usable_slots()
    rows = s1 - s0
    if kind == "line":
        if not 1 <= nozzle <= profile.nozzles - 2:
            raise ValueError(f"nozzle must be 1..{profile.nozzles - 2} (0 and 127 never fire)")
        planes = np.zeros((2 * rows, width, 4), np.uint8)
        r, c = _slot_row(profile, head, nozzle, s0)
        planes[r, :, c] = 1              # first sweep
        planes[r + rows, :, c] = 1       # after one swath of feed
        return planes
    if kind == "sawtooth":
        planes = np.zeros((rows, width, 4), np.uint8)
        x = np.arange(width)
        # shift register of 118 bits, '1' starting at bit 1 ("00...10"), one shift per trigger
        n = (1 + x) % 118
        live = (n >= 1) & (n <= 126)                 # nozzle 0 never fires
        r, c = _slot_row(profile, head, 0, s0)
        planes[r + profile.heads_per_color * n[live], x[live], c] = 1
        for z in range(118, profile.nozzles - 1):    # solid bar, nozzle 127 held at 0
            planes[r + profile.heads_per_color * z, :, c] = 1
        return planes
    if kind == "nozzle-check":
        check = nozzle_check_layout(profile, width)
        planes = np.zeros((check.height, check.width, 4), np.uint8)
        for h in profile.heads:
            for z in range(1, profile.nozzles - 1):
                r, x0, x1 = check.dash_at(h.name, z)
                if 0 <= r < check.height:
                    planes[r, x0:x1, h.channel] = 1
        for x0, x1 in check.bars:            # fiducials: every K nozzle
            for h in profile.heads_of("K"):
                for z in range(1, profile.nozzles - 1):
                    r = check.rows[h.name] + check.heads_per_color * z
                    if 0 <= r < check.height:
                        planes[r, x0:x1, h.channel] = 1
        return planes
    if kind == "bidir-align":
        # 1-pass bidirectional: stroke 0 (forward) prints rows 0..rows-1, stroke 1 (reverse)
        # the next
        blocks = align_offsets()
        planes = np.zeros((2 * rows, len(blocks) * ALIGN_BLOCK, 4), np.uint8)
        for b, o in enumerate(blocks):
            x0 = b * ALIGN_BLOCK
            _bars(planes, slice(rows // 2, rows), 3, x0, 0, ALIGN_BLOCK)        # forward, K
            _bars(planes, slice(rows, rows + rows // 2), 3, x0, o, ALIGN_BLOCK)  # reverse, K
        return planes
    if kind == "head-align":
        blocks = align_offsets()
        names = [h.name for h in profile.heads]
        planes = np.zeros((rows, len(blocks) * ALIGN_BLOCK, 4), np.uint8)
        ref_row, ref_ch = _slot_row(profile, "K1", 20, s0)
        band = max(1, (profile.nozzles - 30) // len(names))
        for b, o in enumerate(blocks):
            x0 = b * ALIGN_BLOCK
            for i, name in enumerate(names):
                z0 = 25 + i * band
                for z in range(z0, z0 + band - 2):
                    r, c = _slot_row(profile, name, z, s0)
                    _bars(planes, r, c, x0, 0 if name == "K1" else o, ALIGN_BLOCK)
            for z in range(5, 20):                                  # K1 reference bars
                r, c = _slot_row(profile, "K1", z, s0)
                _bars(planes, r, c, x0, 0, ALIGN_BLOCK)
        return planes
    raise ValueError(f"test print must be one of {', '.join(PATTERNS)}")


@dataclass
class PatternJob(PrintableJob):
    """A test print with the RipJob interface the driver uses (width, height, settings,
    planner(), strokes(), write_planes())."""
    kind: str
    planes: np.ndarray
    settings: RipSettings = field(default_factory=lambda: RipSettings(passes=1))
    profile: Profile = field(default_factory=load_profile)

    @classmethod
    def for_pattern(cls, kind: str, profile: Profile, width: int, dpi: int = 150,
                    **kw) -> "PatternJob":
        """The pattern with the pass settings it needs (bidir-align prints bidirectionally)."""
        planes = make_pattern(kind, profile, width, **kw)
        return cls(kind, planes, RipSettings(dpi=dpi, passes=1, bidir=kind == "bidir-align"),
                   profile)

    def __post_init__(self):
        self.path = f"test-print:{self.kind}"
        self.height, self.width = self.planes.shape[:2]
        # a test print fires every nozzle, also those the profile lists as dead: a nozzle
        # check must show whether they work again, and one pass cannot be planned around them
        self.profile = dataclasses.replace(self.profile, layout=dataclasses.replace(
            self.profile.layout, dead_nozzles=frozenset()))

    def halftone_bands(self) -> Iterator[np.ndarray]:
        for y in range(0, self.height, self.settings.band_rows):
            yield self.planes[y:y + self.settings.band_rows]
