"""The RIP as one streaming pipeline: file -> bands -> CMYK -> halftone -> strokes.

Pure: the same file and settings always give the same bits.  Every stage works on bands
of `band_rows` rows, so memory is bounded by the band and the planner window, never by the
image length.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from .color import Separator, default_output_icc
from .halftone import ORDERED, Halftoner
from .inputs import open_source, prescreened_packed
from .load import ImageSource, open_image  # noqa: F401 - re-exported
from .parallel import ordered
from .place import place  # noqa: F401 - re-exported
from .printable import PrintableJob  # the base (rip/printable.py); re-exported here
from .profile import COLORS, Profile, load_profile
from .screen import OrderedScreen
from .settings import Placement, RipSettings  # noqa: F401 - re-exported: the settings schema's objects
from .swath import StrokePlanner, pack_dots, top_margin_rows, unpack_dots


BAND_PIXELS = 1 << 19     # pixels per band, at most (RipJob.band_rows)


class Prefetch:
    """`items` run in a background thread, `depth` items ahead, from the moment this is
    made: so the RIP works on the first strokes while the printer is brought to readiness,
    and on the next ones while it prints this one.  Exceptions arrive in order.  close()
    (also when the consumer drops it: the thread holds no reference to it, so it is
    collected; and by `yield from` when its generator closes) stops the thread at its next
    item."""

    _DONE = object()

    def __init__(self, items: Iterator, depth: int = 2):
        import queue
        import threading
        self._q: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._finished = False
        threading.Thread(target=Prefetch._produce, args=(items, self._q, self._stop),
                         name="rip-prefetch", daemon=True).start()

    @staticmethod
    def _produce(items: Iterator, q, stop) -> None:
        import queue
        try:
            for item in items:
                while not stop.is_set():
                    try:
                        q.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            q.put(Prefetch._DONE)
        except BaseException as exc:  # handed to the consumer
            q.put(exc)

    def __iter__(self):
        return self

    def __next__(self):
        if self._finished:
            raise StopIteration
        item = self._q.get()
        if item is self._DONE:
            self.close()
            raise StopIteration
        if isinstance(item, BaseException):
            self.close()
            raise item
        return item

    def close(self) -> None:
        self._finished = True
        self._stop.set()

    def __del__(self):
        self.close()


def prefetch(items: Iterator, depth: int = 2) -> Prefetch:
    """`Prefetch(items, depth)`: the thread starts now, not at the first item."""
    return Prefetch(items, depth)


def profile_curves(profile: Profile, dpi: int | None = None) -> np.ndarray | None:
    """(4, 256) float LUT from the profile's [curves] and, for a dpi mode, its [color]
    drop_budget (the curve's output times the budget, not rounded: the separation rounds
    it by position, docs/color.md "Linearisation"); None if identity."""
    lut = np.empty((4, 256))
    x = np.arange(256)
    budget = 1.0 if dpi is None else profile.color.drop_budget.get(dpi, 1.0)
    for c, name in enumerate(COLORS):
        pts = np.asarray(getattr(profile.curves, name), dtype=np.float64)
        lut[c] = np.clip(budget * np.interp(x, pts[:, 0], pts[:, 1]), 0, 255)
    return None if np.array_equal(lut, np.broadcast_to(x, (4, 256))) else lut


@dataclass
class RipJob(PrintableJob):
    """One file ripped for one printer: the image placed on the device grid (columns at the
    dpi mode, rows at the profile's row pitch; rip/place.py), halftoned, planned into strokes."""
    path: str
    settings: RipSettings = field(default_factory=RipSettings)
    profile: Profile = field(default_factory=load_profile)
    more: tuple = ()                     # further files of a nested layout (docs/layout.md)
    paper_mm: float | None = None        # the measured paper width, when known (nesting)
    names: tuple = ()                    # the files' names on labels (path, *more), if not theirs

    def __post_init__(self):
        self.settings.check(self.profile)
        from .layout import LayoutJob, wants_layout
        self.layout: LayoutJob | None = None
        if wants_layout(self.settings.placement, self.more):
            # one layout is one job: its items placed on one sheet, composed in bands
            self.layout = LayoutJob([self.path, *self.more], self.settings, self.profile,
                                    paper_mm=self.paper_mm, names=self.names, make_job=RipJob)
            self.source = None
            self.width, self.height = self.layout.width, self.layout.height
            return
        # the image area on the device grid: an image placed (physical size, scaled, rotated,
        # mirrored), a PDF/PostScript page rendered onto it, or RTL raster (rip/inputs.py)
        self.source: ImageSource = open_source(self.path, self.settings, self.profile)
        self.width, self.height = self.source.width, self.source.height

    @property
    def band_rows(self) -> int:
        """Rows per band: the setting's (64), fewer on wide images so that a band stays
        about BAND_PIXELS, 16 at least (a 40,000 px wide job's bands are 16 rows: every stage holds a
        band or two of it, bits identical for any banding)."""
        return max(1, min(self.settings.band_rows, max(16, BAND_PIXELS // max(1, self.width))))

    @property
    def ink_limit(self) -> float | None:
        """--ink-limit if given; else the profile's limit for separations we make (RGB,
        grey, and documents, whose RGB Ghostscript separates with the RIP's profiles);
        CMYK files print as they are."""
        if self.settings.ink_limit is not None:
            return self.settings.ink_limit
        if self.layout is not None:
            return self.layout.ink_limit
        if self.source.colorspace == "cmyk" and not getattr(self.source, "separated", False):
            return None
        return self.profile.color.ink_limit_percent

    def _separator(self) -> Separator:
        s = self.settings
        if getattr(self.source, "separated", False):    # documents: Ghostscript applied the ICC path
            return Separator("cmyk", 8, intent=s.intent, ink_limit=self.ink_limit,
                             curves=profile_curves(self.profile, s.dpi))
        return Separator(self.source.colorspace, self.source.depth,
                         embedded_icc=self.source.icc, input_icc=s.input_icc,
                         output_icc=s.output_icc or default_output_icc(self.source.colorspace),
                         intent=s.intent, ink_limit=self.ink_limit,
                         curves=profile_curves(self.profile, s.dpi))

    def _dead_rows(self):
        """(per colour the dead row phases, their period) when the weave leaves rows only
        dead nozzles print (one pass): the RIP gives those rows' dots to their neighbours
        (rip/deadrows.py); None when every row has a live nozzle.  ValueError when a dead
        row's neighbour is dead too."""
        if not hasattr(self, "_dead_cache"):
            s = self.settings
            self._dead_cache = None
            # a layout's items are compensated as the sheet (its rows), not each alone
            if self.profile.dead_nozzles and getattr(self, "compensate_dead", True) and \
                    not getattr(self.source, "prescreened", False):
                planner = StrokePlanner(self.profile, self.width, self.height, s.dpi, s.passes,
                                        s.bidir, s.pass_mask, dead_rows_empty=True)
                dead = planner.dead_row_phases()
                if any(d.size for d in dead):
                    from .deadrows import check_neighbours

                    def name(c, phase):
                        h, z = planner._slot_table_dead(c, int(phase) + planner.s0)
                        return f"{self.profile.heads[h].name}:{z}" if h >= 0 else f"row {phase}"
                    check_neighbours(dead, planner.advance, name)
                    self._dead_cache = (dead, planner.advance)
        return self._dead_cache

    def planner(self) -> StrokePlanner:
        s = self.settings
        return StrokePlanner(self.profile, self.width, self.height, s.dpi, s.passes, s.bidir,
                             s.pass_mask, dead_rows_empty=self._dead_rows() is not None,
                             top_rows=top_margin_rows(self.profile, s))

    def halftone_bands(self) -> Iterator[np.ndarray]:
        """The halftoned image, top to bottom, as (h, W, 4) uint8 0/1 bands (rows only dead
        nozzles print given to their neighbours: rip/deadrows.py)."""
        dead = self._dead_rows()
        if dead is None:
            yield from self._halftone_bands()
            return
        from .deadrows import compensate
        yield from compensate(self._halftone_bands(), *dead)

    def packed_bands(self) -> Iterator[np.ndarray]:
        if self._dead_rows() is None:
            yield from self._packed_bands()
            return
        for band in self.halftone_bands():
            yield pack_dots(band)

    def _halftone_bands(self) -> Iterator[np.ndarray]:
        if self.layout is not None:
            yield from self.layout.halftone_bands()
            return
        if getattr(self.source, "prescreened", False):  # 1-bit RTL: the file's own dots
            yield from self.source.bands(self.band_rows)
            return
        if self.settings.dither in ORDERED:
            for bits in self._packed_bands():
                yield unpack_dots(bits, self.width)
            return
        sep = self._separator()
        ht = Halftoner(self.settings.dither, self.width, channels=4)
        # one band worker separates the next bands while the diffusion works on this one
        # (band after band, the longest stage: it needs the other core to itself; with two
        # separating side by side, in-process fs took 0.63 s instead of 0.55, median of 7
        # pairs); the reader loads in the separation's prefetch thread
        separated = ordered(((lambda band=band: sep.convert(band))
                             for band in self.source.bands(self.band_rows)), workers=1)
        # the diffusion in a thread of its own, so that the caller's packing and stroke
        # planning of a band overlap the diffusion of the next (in-process fs 0.45 -> 0.43 s,
        # vced 0.60 -> 0.57 s, median of 7 and 5 pairs; print --bidir 1.48 -> 1.43 s)
        diffused = (ht.process(cmyk) for cmyk in prefetch(separated, depth=1))
        yield from prefetch(diffused, depth=1)

    def packed_native(self) -> bool:
        if self._dead_rows() is not None:
            return False
        return self.settings.dither in ORDERED or getattr(self.source, "prescreened", False)

    def _packed_bands(self) -> Iterator[np.ndarray]:
        """The halftone as packed bits (h, 4, ceil(W / 8)).  Ordered methods take the fused
        path (rip/screen.py): no CMYK or dot planes are made, and loading plus screening the
        next bands (on both cores) overlaps the stroke packing of this one."""
        s = self.settings
        if self.layout is not None:
            yield from self.layout.packed_bands()
            return
        if getattr(self.source, "prescreened", False):  # 1-bit RTL: the file's own dots
            yield from prefetch(prescreened_packed(self.source, self.band_rows), depth=1)
            return
        if s.dither not in ORDERED:
            for band in self._halftone_bands():
                yield pack_dots(band)
            return
        screen = OrderedScreen(self._separator(), Halftoner(s.dither, self.width, channels=4))
        # the reader thread loads the next band while the band workers screen the ones
        # before it, side by side, and the caller packs the strokes of the first
        loaded = prefetch(self.source.bands(self.band_rows), depth=1)
        yield from ordered(screen.job(band) for band in loaded)

    def close(self) -> None:
        (self.layout or self.source).close()
