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
- bidir-scan, heads-scan, feed-scan: patterns measured on a scan to a fraction of a
                column or row (`wideprint calibrate`, docs/calibration.md): vertical
                segments and one-row dashes whose centroids are read, between two K bars
                that locate the pattern on the scanner glass; `scan_layout` names them
- wedge-scan:   a step wedge of each ink (WEDGE_STEPS), through the profile's curves and
                the dpi mode's drop budget and the RIP's default halftone, between the
                same K bars: `wideprint calibrate wedge` reads each step's tone
                (docs/color.md "Linearisation")
- banding-scan: the banding and grain chart (docs/quality.md): flat tints of each ink and
                mixes (BANDING_TINTS) as strips along the feed, BANDING_LENGTH_MM long
                (several swath periods at any pass count), between the same K bars, printed
                with the job's passes, pass mask and direction: `wideprint quality` and
                `wideprint calibrate banding` measure its scan
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
WEAVE_PATTERN = "banding-scan"   # the one pattern printed with the job's weave


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


# -- patterns measured on a scan (docs/calibration.md) ----------------------------------------
BAR_UM = 2000.0          # the K frame bars (fiducials): width
BAR_GAP_UM = 1500.0      # paper between a bar and the marks
SEG_PITCH_UM = 800.0     # between vertical segments: no window holds another's ink
SEGMENTS = 4             # vertical segments per head block
SEG_NOZZLES = (4, 124)   # a segment: these nozzles, one column
DASH_UM = 1500.0         # a one-row dash (heads-scan)
HEAD_DASH_NOZZLES = tuple(range(8, 124, 15))          # 8 dashes a head, 30 rows apart
FEED_STROKES = 4
FEED_NOZZLES = tuple(range(8, 124, 20))               # K1 dashes in every stroke
FEED_DASH_UM = 3000.0
FEED_DASHES_X = 3                                     # dashes per nozzle row, along the sweep
SCAN_PATTERNS = ("bidir-scan", "heads-scan", "feed-scan", "wedge-scan", "banding-scan")
WEDGE_STEPS = (0, 26, 51, 77, 102, 128, 153, 179, 204, 230, 255)   # 0, 10 %, ... 100 %
WEDGE_STROKES = 2        # one pass: the wedge is two strokes tall (about 35 mm)
WEDGE_GAP_UM = 1000.0    # paper between patches
WEDGE_DITHER = "vced"    # the RIP's default halftone
#: the banding and grain chart's tints (docs/quality.md "The chart"): name, C M Y K amounts
#: 0..255.  Light and middle tints of each ink (grain shows in the light ones, banding in
#: the middle ones) and the three two-ink mixes and a three-ink grey
BANDING_TINTS: tuple[tuple[str, tuple[int, int, int, int]], ...] = (
    ("C25", (64, 0, 0, 0)), ("C50", (128, 0, 0, 0)), ("M25", (0, 64, 0, 0)),
    ("M50", (0, 128, 0, 0)), ("Y50", (0, 0, 128, 0)), ("K25", (0, 0, 0, 64)),
    ("K50", (0, 0, 0, 128)), ("C30M30", (77, 77, 0, 0)), ("M40Y40", (0, 102, 102, 0)),
    ("C25M25Y25", (64, 64, 64, 0)))
BANDING_LENGTH_MM = 64.0     # along the feed: 3.7 swaths at 4 passes, 15 feeds
BANDING_GAP_UM = 1000.0      # paper between strips


@dataclass(frozen=True)
class Mark:
    """One measured mark: cells [r0, r1) x [c0, c1) hold its dots and no other ink.
    kind 'x' (a vertical segment: its x is read), 'y' (a one-row dash: its y), or
    'dash' (a nozzle check dash: its ink)."""
    kind: str
    head: str
    channel: int
    stroke: int
    nozzle: int
    r0: int
    r1: int
    c0: int
    c1: int


@dataclass(frozen=True)
class ScanLayout:
    """A pattern to be scanned: its planes, its two K frame bars and its marks."""
    kind: str
    planes: np.ndarray
    bars: tuple[Mark, Mark]
    marks: tuple[Mark, ...]
    rows_per_stroke: int


def _cols(um: float, col_um: float) -> int:
    return max(1, int(round(um / col_um)))


def scan_layout(kind: str, profile: Profile, width: int, dpi: int = 150) -> ScanLayout:
    """The marks of a scan pattern (SCAN_PATTERNS or nozzle-check), 1 pass, `width`
    columns at `dpi`.  Sizes are in µm, so the pattern looks the same at every dpi."""
    s0, s1 = profile.usable_slots()
    a = s1 - s0                                   # rows per stroke, one pass
    hpc = profile.heads_per_color
    heads = profile.heads
    if kind == "nozzle-check":
        check = nozzle_check_layout(profile, width)
        planes = make_pattern(kind, profile, width)
        marks = []
        for h in heads:
            for z in range(1, profile.nozzles - 1):
                r, x0, x1 = check.dash_at(h.name, z)
                if 0 <= r < check.height:
                    marks.append(Mark("dash", h.name, h.channel, 0, z, r, r + 1, x0, x1))
        (b0, b1), (b2, b3) = check.bars
        bars = (Mark("bar", "K", 3, 0, 0, 0, check.height, b0, b1),
                Mark("bar", "K", 3, 0, 0, 0, check.height, b2, b3))
        return ScanLayout(kind, planes, bars, tuple(marks), a)
    if kind == "wedge-scan":
        return _wedge_layout(profile, width, dpi)
    if kind == "banding-scan":
        return _banding_layout(profile, width, dpi)
    if kind not in SCAN_PATTERNS:
        raise ValueError(f"not a scan pattern: {kind!r} (one of nozzle-check, {', '.join(SCAN_PATTERNS)})")
    col_um = profile.k(dpi) * 25_400.0 / profile.counts_per_inch
    strokes = {"bidir-scan": 2, "heads-scan": 1, "feed-scan": FEED_STROKES}[kind]
    planes = np.zeros((strokes * a, width, 4), np.uint8)
    bar, gap = _cols(BAR_UM, col_um), _cols(BAR_GAP_UM, col_um)
    inner0, inner1 = bar + gap, width - bar - gap
    seg_pitch = _cols(SEG_PITCH_UM, col_um)

    def row(h, z, stroke=0):
        return h.y_rows + hpc * z - s0 + stroke * a

    marks: list[Mark] = []

    def segment(h, c, stroke):
        rs = [row(h, z, stroke) for z in range(*SEG_NOZZLES)]
        planes[rs, c, h.channel] = 1
        marks.append(Mark("x", h.name, h.channel, stroke, 0, min(rs), max(rs) + 1, c, c + 1))

    def dash(h, z, c0, c1, stroke):
        r = row(h, z, stroke)
        planes[r, c0:c1, h.channel] = 1
        marks.append(Mark("y", h.name, h.channel, stroke, z, r, r + 1, c0, c1))

    if kind == "feed-scan":
        k1 = next(h for h in heads if h.name == "K1") if any(h.name == "K1" for h in heads) \
            else profile.heads_of("K")[0]
        dl = _cols(FEED_DASH_UM, col_um)
        pitch = (inner1 - inner0) // FEED_DASHES_X
        if pitch < dl + seg_pitch:
            raise ValueError(f"feed-scan needs at least "
                             f"{(2 * (BAR_UM + BAR_GAP_UM) + FEED_DASHES_X * (FEED_DASH_UM + SEG_PITCH_UM)) / 1000:.0f} mm")
        for st in range(strokes):
            for i in range(FEED_DASHES_X):
                c0 = inner0 + i * pitch + (pitch - dl) // 2
                for z in FEED_NOZZLES:
                    dash(k1, z, c0, c0 + dl, st)
    else:
        dl = _cols(DASH_UM, col_um) if kind == "heads-scan" else 0
        need = SEGMENTS * seg_pitch + (dl + seg_pitch if dl else 0)
        pitch = (inner1 - inner0) // len(heads)
        if pitch < need:
            per = need * col_um / 1000
            raise ValueError(f"{kind} needs at least {2 * (BAR_UM + BAR_GAP_UM) / 1000 + len(heads) * per:.0f} mm "
                             f"({len(heads)} head blocks of {per:.1f} mm)")
        for i, h in enumerate(heads):
            x = inner0 + i * pitch + (pitch - need) // 2 + seg_pitch // 2
            for j in range(SEGMENTS):
                for st in range(strokes):
                    segment(h, x + j * seg_pitch, st)
            if dl:
                c0 = x + SEGMENTS * seg_pitch
                for z in HEAD_DASH_NOZZLES:
                    dash(h, z, c0, c0 + dl, 0)
    bars = []
    for c0, c1 in ((0, bar), (width - bar, width)):        # every K nozzle, first stroke
        for h in profile.heads_of("K"):
            for z in range(1, profile.nozzles - 1):
                r = row(h, z)
                if 0 <= r < a:
                    planes[r, c0:c1, h.channel] = 1
        bars.append(Mark("bar", "K", 3, 0, 0, 0, a, c0, c1))
    return ScanLayout(kind, planes, tuple(bars), tuple(marks), a)


def _wedge_layout(profile: Profile, width: int, dpi: int) -> ScanLayout:
    """Four rows of patches (C, M, Y, K), one per WEDGE_STEPS amount, halftoned through the
    profile's curves and drop budget; K bars over every row at both ends.  Mark.nozzle
    holds the step's nominal amount."""
    from .halftone import Halftoner
    from .pipeline import profile_curves
    from .profile import COLORS
    s0, s1 = profile.usable_slots()
    rows = WEDGE_STROKES * (s1 - s0)
    col_um = profile.k(dpi) * 25_400.0 / profile.counts_per_inch
    bar, gap = _cols(BAR_UM, col_um), _cols(BAR_GAP_UM, col_um)
    inner0, inner1 = bar + gap, width - bar - gap
    pitch = (inner1 - inner0) // len(WEDGE_STEPS)
    pgap, rgap = _cols(WEDGE_GAP_UM, col_um), max(1, int(round(WEDGE_GAP_UM / 2 / profile.row_um)))
    if pitch < 3 * pgap:
        raise ValueError(f"wedge-scan needs at least "
                         f"{(2 * (BAR_UM + BAR_GAP_UM) + len(WEDGE_STEPS) * 3 * WEDGE_GAP_UM) / 1000:.0f} mm")
    lut = profile_curves(profile, dpi)
    amounts = np.zeros((rows, width, 4), np.uint8)
    marks = []
    for ch in range(4):
        r0, r1 = ch * rows // 4 + rgap, (ch + 1) * rows // 4 - rgap
        for i, v in enumerate(WEDGE_STEPS):
            c0 = inner0 + i * pitch + pgap // 2
            c1 = c0 + pitch - pgap
            amounts[r0:r1, c0:c1, ch] = v if lut is None else np.rint(lut[ch, v])
            marks.append(Mark("patch", COLORS[ch], ch, 0, v, r0, r1, c0, c1))
    planes = Halftoner(WEDGE_DITHER, width).process(amounts)
    bars = []
    for c0, c1 in ((0, bar), (width - bar, width)):
        planes[:, c0:c1, 3] = 1
        bars.append(Mark("bar", "K", 3, 0, 0, 0, rows, c0, c1))
    return ScanLayout("wedge-scan", planes, tuple(bars), tuple(marks), s1 - s0)


def _banding_layout(profile: Profile, width: int, dpi: int) -> ScanLayout:
    """The banding and grain chart (docs/quality.md "The chart"): one strip along the feed
    per BANDING_TINTS entry, the whole length, through the profile's curves and drop budget
    and the RIP's default halftone; K bars over the whole length at both ends.  Mark.head
    holds the tint's name, Mark.nozzle its index."""
    from .halftone import Halftoner
    from .pipeline import profile_curves
    rows = int(round(BANDING_LENGTH_MM * 1000.0 / profile.row_um))
    col_um = profile.k(dpi) * 25_400.0 / profile.counts_per_inch
    bar, gap = _cols(BAR_UM, col_um), _cols(BAR_GAP_UM, col_um)
    inner0, inner1 = bar + gap, width - bar - gap
    pitch = (inner1 - inner0) // len(BANDING_TINTS)
    pgap = _cols(BANDING_GAP_UM, col_um)
    if pitch < 4 * pgap:
        raise ValueError(f"banding-scan needs at least "
                         f"{(2 * (BAR_UM + BAR_GAP_UM) + len(BANDING_TINTS) * 4 * BANDING_GAP_UM) / 1000:.0f} mm")
    lut = profile_curves(profile, dpi)
    amounts = np.zeros((rows, width, 4), np.uint8)
    strips: list[Mark] = []
    for i, (name, cmyk) in enumerate(BANDING_TINTS):
        c0 = inner0 + i * pitch + pgap // 2
        c1 = c0 + pitch - pgap
        for ch, v in enumerate(cmyk):
            if v:
                amounts[:, c0:c1, ch] = v if lut is None else np.rint(lut[ch, v])
        strips.append(Mark("patch", name, int(np.argmax(cmyk)), 0, i, 0, rows, c0, c1))
    planes = Halftoner(WEDGE_DITHER, width).process(amounts)
    frame = (Mark("bar", "K", 3, 0, 0, 0, rows, 0, bar), Mark("bar", "K", 3, 0, 0, 0, rows, width - bar, width))
    for m in frame:
        planes[:, m.c0:m.c1, 3] = 1
    s0, s1 = profile.usable_slots()
    return ScanLayout("banding-scan", planes, frame, tuple(strips), s1 - s0)


def make_pattern(kind: str, profile: Profile, width: int, head: str = "K1",
                 nozzle: int = 64, dpi: int = 150) -> np.ndarray:
    """The pattern as planes (rows, width, 4) uint8 0/1 on the device grid, for 1 pass."""
    s0, s1 = profile.usable_slots()
    rows = s1 - s0
    if kind in SCAN_PATTERNS:
        return scan_layout(kind, profile, width, dpi).planes
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
                    passes: int = 1, pass_mask: str | None = None, bidir: bool = False,
                    **kw) -> "PatternJob":
        """The pattern with the pass settings it needs (bidir-align prints bidirectionally);
        the banding chart is printed the way a job would be: `passes`, `pass_mask`, `bidir`
        (the other patterns are one pass: their marks are placed per stroke)."""
        planes = make_pattern(kind, profile, width, dpi=dpi, **kw)
        if kind == WEAVE_PATTERN:
            weave = RipSettings(dpi=dpi, passes=passes, bidir=bidir)
            if pass_mask is not None:
                weave = dataclasses.replace(weave, pass_mask=pass_mask)
            return cls(kind, planes, weave, profile)
        if passes != 1 or pass_mask is not None or bidir:
            raise ValueError(f"{kind} prints in one pass as it is drawn; passes, pass masks and "
                             f"bidirectional printing are for {WEAVE_PATTERN}")
        return cls(kind, planes, RipSettings(dpi=dpi, passes=1,
                                             bidir=kind in ("bidir-align", "bidir-scan")),
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
