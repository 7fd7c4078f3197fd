"""The job settings schema: every setting a print job takes, declared once (docs/settings.md).

One declaration per setting (name, type, default, choices — static or from the printer
profile —, range, help) feeds everything that takes or offers settings:

- the command line: `add_arguments()` builds the RIP and placement options of `print`,
  `rip` and `submit` from it (so `submit --help` lists what `print --help` lists);
- the print server: `validate()` checks a request's or a preset's settings with it;
- the GUI: its combo boxes take their choices and labels from it;
- the RIP: `from_mapping()` turns a checked mapping into `RipSettings` and `Placement`.

This module is deliberately light (standard library only): `wideprint --help` and the
server's request validation must not import numpy, numba or libvips.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Callable, Iterable, Mapping

# -- the choices (the RIP's modules import these names from here) ------------------------
METHODS = ("vced", "vector", "dbs", "fs", "jarvis", "stucki", "bayer", "bluenoise", "joint")   # rip/halftone.py
ORDERED = ("bayer", "bluenoise")                                 # screens, not diffusion
PASS_COUNTS = (1, 2, 3, 4, 6, 8)                                 # rip/swath.py weaves
# rip/swath.py; "hiding" plans with the nozzles the profile's calibration measured, per
# stroke; "hiding-rows" per row phase (better on a machine with a large random feed error at
# 6-8 passes: docs/quality.md "Nozzle-error hiding as a setting")
PASS_MASKS = ("checker", "random", "feather", "shingle", "hiding", "hiding-rows")
INTENTS = ("perceptual", "relative", "saturation", "absolute")   # rip/color.py (LittleCMS)
SIZES = ("physical", "pixels")                                   # rip/place.py
FILTERS = ("nearest", "linear", "cubic", "lanczos3")             # libvips kernels
ROTATIONS = (0, 90, 180, 270)                                    # degrees clockwise
ALIGNS = ("left", "center", "right")
PAGE_BOXES = ("crop", "trim", "bleed", "art", "media")             # PDF page boxes (docs/documents.md)
MARKS = ("none", "crop", "registration", "cut")                    # layout marks (docs/layout.md, cut.md)
#: the test prints (rip/testprints.py); named here so that building the CLI parser stays light
TEST_PATTERNS = ("line", "sawtooth", "nozzle-check", "bidir-align", "head-align", "bidir-scan",
                 "heads-scan", "feed-scan", "wedge-scan", "banding-scan")

#: largest placed image side, in device columns or rows (3.4 m at 600 dpi is 80,315 columns;
#: 1,000,000 rows is 68.55 m of media)
MAX_SIDE = 1_000_000
#: resolution assumed for files without resolution tags, pixels per inch
DEFAULT_PPI = 300.0
MM_PER_INCH = 25.4


class SettingsError(ValueError):
    """A setting that is refused; the message names the setting and the problem."""


# -- the declaration ---------------------------------------------------------------------
@dataclass(frozen=True)
class Setting:
    name: str                      # key in a settings mapping, field of RipSettings/Placement
    kind: type                     # int, float, bool or str
    default: Any
    help: str
    group: str = "rip"             # "rip": RipSettings; "placement": Placement
    choices: tuple[Any, ...] | None = None   # the allowed values, when fixed
    profile_choices: Callable[[Any], Iterable[Any]] | None = None   # Profile -> allowed values (dpi modes)
    minimum: float | None = None
    maximum: float | None = None
    nullable: bool = False         # None allowed (means: the profile's / file's value)
    nonnegative: bool = False
    positive: bool = False
    labels: dict[Any, str] | None = None     # choice -> words for the GUI
    section: str = ""              # the command line's option group, when not the group's own
    label: str = ""                # the GUI's name for it
    metavar: str | None = None

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    @property
    def where(self) -> str:
        return f"placement {self.name}" if self.group == "placement" else self.name

    def choices_for(self, profile: Any = None) -> tuple[Any, ...] | None:
        if self.profile_choices is not None and profile is not None:
            return tuple(self.profile_choices(profile))
        return self.choices

    def check(self, value: Any, profile: Any = None) -> Any:
        """The value, normalised (ints as int, numbers as float), or SettingsError."""
        if value is None:
            if self.nullable:
                return None
            raise SettingsError(f"{self.where} must not be null")
        choices = self.choices_for(profile)
        if self.kind is bool:
            if not isinstance(value, bool):
                raise SettingsError(f"{self.where} must be true or false, not {value!r}")
            return value
        if self.kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                if choices:
                    raise SettingsError(f"{self.where} must be one of {_words(choices)}, not {value!r}")
                raise SettingsError(f"{self.where} must be an integer, not {value!r}")
        elif self.kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise SettingsError(f"{self.where} must be a number{' or null' if self.nullable else ''}, "
                                    f"not {value!r}")
            value = float(value)
            if not math.isfinite(value):
                raise SettingsError(f"{self.where} must be a finite number, not {value!r}")
        elif self.kind is str:
            if not isinstance(value, str):
                raise SettingsError(f"{self.where} must be a string, not {value!r}")
        if choices is not None and value not in choices:
            src = " (the printer profile's modes)" if self.profile_choices and profile else ""
            raise SettingsError(f"{self.where} must be one of {_words(choices)}{src}, not {value!r}")
        if self.kind in (int, float):
            lo = -math.inf if self.minimum is None else self.minimum
            hi = math.inf if self.maximum is None else self.maximum
            if not lo <= value <= hi:
                raise SettingsError(f"{self.where} {value:g} is out of range ({lo:g}..{hi:g})")
            if self.positive and not value > 0:
                raise SettingsError(f"{self.where} must be a positive number, not {value!r}")
            if self.nonnegative and value < 0:
                raise SettingsError(f"{self.where} must not be negative, not {value!r}")
        return value


def _words(choices: Iterable[Any]) -> str:
    return ", ".join(str(c) for c in choices)


def _dpi_modes(profile: Any) -> tuple[Any, ...]:
    return tuple(profile.dpi_modes)


SETTINGS: tuple[Setting, ...] = (
    # the RIP and the weave
    Setting("dpi", int, 300, "scan-direction resolution: the encoder trigger mode",
            choices=(150, 300, 600), profile_choices=_dpi_modes, label="Resolution",
            labels={150: "150 dpi", 300: "300 dpi", 600: "600 dpi"}),
    Setting("passes", int, 1, "interleave passes of the weave: each row is printed in this "
            "many passes, each by other nozzles (docs/geometry.md)", choices=PASS_COUNTS,
            label="Passes", labels={n: f"{n} pass" + ("es" if n > 1 else "") for n in PASS_COUNTS}),
    Setting("bidir", bool, False, "print on both strokes of the carriage (left to right and back)",
            label="Direction", labels={False: "Unidirectional", True: "Bidirectional"}),
    Setting("pass_mask", str, "checker", "which pass prints which dot (docs/geometry.md; "
            "hiding: shares per stroke from the nozzles `wideprint calibrate nozzles` measured; "
            "hiding-rows: the same per row phase)",
            choices=PASS_MASKS, label="Pass mask",
            labels={"checker": "Checkerboard", "random": "Random (blue noise)",
                    "feather": "Feathered edges", "shingle": "Shingled (raised cosine)",
                    "hiding": "Nozzle-error hiding (calibrate nozzles)",
                    "hiding-rows": "Nozzle-error hiding per row (calibrate nozzles)"}),
    Setting("dither", str, "vced", "halftone: error diffusion (vced: variable coefficients "
            "with threshold modulation, the best for photographs; vector: the same with C and M, "
            "Y and K dots kept apart, the least grain in light mixed colours; dbs: vced's dots "
            "refined by direct binary search, the least visible error, ~2.4x the CPU; joint: C, M and Y "
            "decided together, no cell stacked that the coverage does not force, for 150 dpi; "
            "fs, jarvis, stucki) "
            "or an ordered screen (bluenoise: the fastest, dots of C and M apart; bayer)",
            choices=METHODS, label="Halftone",
            labels={"vced": "Variable-coefficient ED (photo)",
                    "vector": "Colour-aware ED (C/M, Y/K dots apart)",
                    "dbs": "Direct binary search (finest, slower)",
                    "joint": "Joint C/M/Y ED (dots apart, for 150 dpi)",
                    "fs": "Floyd–Steinberg", "jarvis": "Jarvis–Judice–Ninke", "stucki": "Stucki",
                    "bayer": "Bayer 16×16 (ordered)", "bluenoise": "Blue noise 256 (ordered, fastest)"}),
    Setting("ink_limit", float, None, "total ink limit in percent of one full channel "
            "(default: the printer profile's, for RGB and grey input)", nullable=True,
            minimum=1, maximum=400, label="Ink limit", metavar="PERCENT"),
    Setting("input_icc", str, None, "input ICC profile (overrides the file's embedded one)",
            nullable=True, label="Input ICC profile", metavar="ICC"),
    Setting("media", str, None, "print with this media (`wideprint media list`): its ICC output "
            "profile, ink limits, linearisation and print mode (settings given win); default: "
            "the printer profile's, with the shipped media's profile for RGB and grey",
            nullable=True, label="Media", metavar="NAME"),
    Setting("output_icc", str, None, "output CMYK ICC profile of the printer and media",
            nullable=True, label="Output ICC profile", metavar="ICC"),
    Setting("intent", str, "relative", "ICC rendering intent", choices=INTENTS,
            label="Rendering intent",
            labels={"perceptual": "Perceptual", "relative": "Relative colorimetric",
                    "saturation": "Saturation", "absolute": "Absolute colorimetric"}),
    # placement on the device grid and on the paper (docs/placement.md)
    Setting("size", str, "physical", "physical: from the file's resolution (300 ppi if absent); "
            "pixels: 1 image pixel = 1 device dot", group="placement", choices=SIZES, label="Size"),
    Setting("width_mm", float, None, "print this wide (keeps the aspect ratio unless "
            "--height-mm is given too)", group="placement", nullable=True, positive=True,
            metavar="MM", label="Width"),
    Setting("height_mm", float, None, "print this high", group="placement", nullable=True,
            positive=True, metavar="MM", label="Height"),
    Setting("scale", float, None, "multiply the physical size", group="placement",
            nullable=True, positive=True, metavar="F", label="Scale"),
    Setting("fit_width_mm", float, None, "scale to exactly this width", group="placement",
            nullable=True, positive=True, metavar="MM", label="Fit width"),
    Setting("rotate", int, 0, "degrees clockwise", group="placement", choices=ROTATIONS,
            label="Rotation", labels={r: f"{r}°" for r in ROTATIONS}),
    Setting("mirror", bool, False, "mirror the image (backlit film)", group="placement",
            label="Mirror"),
    Setting("filter", str, "lanczos3", "resampling filter", group="placement", choices=FILTERS,
            label="Resampling"),
    Setting("align", str, "left", "across the paper, within the side margins",
            group="placement", choices=ALIGNS, label="Align",
            labels={"left": "Left", "center": "Centre", "right": "Right"}),
    Setting("x_mm", float, 0.0, "then shift the image this far right (negative: left)",
            group="placement", metavar="MM", label="Offset"),
    Setting("margin_mm", float, None, "side margins (default: the printer profile's)",
            group="placement", nullable=True, nonnegative=True, metavar="MM", label="Side margins"),
    Setting("top_mm", float, 0.0, "blank paper fed before the image", group="placement",
            nonnegative=True, metavar="MM", label="Top margin"),
    # documents: PDF, PostScript, EPS (docs/documents.md)
    Setting("page_box", str, "crop", "PDF: the page box that is the page (crop, trim, bleed, "
            "art, media; a box the page lacks falls back to the CropBox, then the MediaBox)",
            group="placement", choices=PAGE_BOXES, label="Page box",
            labels={"crop": "CropBox", "trim": "TrimBox", "bleed": "BleedBox", "art": "ArtBox",
                    "media": "MediaBox"}),
    Setting("pages", str, "all", "PDF/PostScript: the pages to print, e.g. 1-3,5 or 4- (default "
            "all), one after another along the roll in one job", group="placement",
            metavar="LIST", label="Pages"),
    Setting("page_gap_mm", float, 10.0, "PDF/PostScript: blank paper between the pages of a "
            "document", group="placement", nonnegative=True, metavar="MM", label="Page gap"),
    # the layout on the roll: copies, nesting, tiles, marks, label (docs/layout.md)
    Setting("repeat_across", int, 1, "step-and-repeat: copies side by side across the paper",
            group="placement", section="layout", minimum=1, maximum=1000, metavar="N",
            label="Copies across"),
    Setting("repeat_along", int, 1, "step-and-repeat: rows of copies along the roll",
            group="placement", section="layout", minimum=1, maximum=1000, metavar="N",
            label="Copies along"),
    Setting("gap_mm", float, 5.0, "blank paper between copies, nested items and tiles",
            group="placement", section="layout", nonnegative=True, maximum=10000, metavar="MM",
            label="Gap"),
    Setting("nest", bool, False, "nest the files (and their copies) side by side across the "
            "paper in one job, to save media", group="placement", section="layout", label="Nest"),
    Setting("nest_copies", int, 1, "nesting: copies of each file in the nest", group="placement",
            section="layout", minimum=1, maximum=1000, metavar="N", label="Nest copies"),
    Setting("nest_rotate", bool, False, "nesting: items may be turned 90 degrees to pack better",
            group="placement", section="layout", label="Nest rotation"),
    Setting("nest_count", int, None, "nesting: start a job when it holds this many files",
            group="placement", section="layout", nullable=True, minimum=1, maximum=100000,
            metavar="N", label="Nest count"),
    Setting("nest_length_mm", float, None, "nesting: start a job when it is this long",
            group="placement", section="layout", nullable=True, positive=True, metavar="MM",
            label="Nest length"),
    Setting("nest_wait_s", float, None, "print server: start a nest when its first job has "
            "waited this long (seconds), however few jobs it holds", group="placement",
            section="layout", nullable=True, nonnegative=True, metavar="S", label="Nest wait"),
    Setting("nest_width_mm", float, None, "nesting: the width to pack into (default: the "
            "paper less the side margins)", group="placement", section="layout", nullable=True,
            positive=True, metavar="MM", label="Nest width"),
    Setting("tile_width_mm", float, None, "tiling: print the image as tiles at most this wide",
            group="placement", section="layout", nullable=True, positive=True, metavar="MM",
            label="Tile width"),
    Setting("tile_height_mm", float, None, "tiling: tiles at most this long", group="placement",
            section="layout", nullable=True, positive=True, metavar="MM", label="Tile height"),
    Setting("tile_overlap_mm", float, 0.0, "tiling: image shared by neighbouring tiles",
            group="placement", section="layout", nonnegative=True, metavar="MM",
            label="Tile overlap"),
    Setting("join_marks", bool, False, "tiling: ticks where the neighbouring tile's edge goes",
            group="placement", section="layout", label="Join marks"),
    Setting("marks", str, "none", "crop marks, or crop and registration marks, outside each "
            "image", group="placement", section="layout", choices=MARKS, label="Marks",
            labels={"none": "None", "crop": "Crop marks", "registration": "Crop + registration",
                    "cut": "Cutter registration marks"}),
    Setting("cut_mark_spacing_mm", float, 500.0, "marks cut: a pair of cutter registration marks "
            "at least every this many mm along the print (docs/cut.md)", group="placement",
            section="layout", minimum=20.0, maximum=100_000.0, label="Cut mark spacing", metavar="MM"),
    Setting("label", bool, False, "a job label under each image: name, date, settings",
            group="placement", section="layout", label="Job label"),
)

BY_NAME = {s.name: s for s in SETTINGS}
RIP_KEYS = tuple(s.name for s in SETTINGS if s.group == "rip")
PLACEMENT_KEYS = tuple(s.name for s in SETTINGS if s.group == "placement")


def setting(name: str) -> Setting:
    return BY_NAME[name]


# -- the settings objects ------------------------------------------------------------------
def _round(x: float) -> int:
    """Nearest integer, halves up (not banker's rounding)."""
    return int(math.floor(x + 0.5))


def _ppi(v: Any) -> float | None:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and v > 0 else None


def _finite(name: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"placement: {name} must be a number, not {v!r}") from None
    if not math.isfinite(f):
        raise ValueError(f"placement: {name} must be a finite number, not {v!r}")
    return f


def _positive(name: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"placement: {name} must be a number, not {v!r}") from None
    if not (math.isfinite(f) and f > 0):
        raise ValueError(f"placement: {name} must be a positive number, not {v!r}")
    return f


@dataclass
class Placement:
    """Where and how large the image goes on the device grid (docs/placement.md)."""

    size: str = "physical"  # "physical": from the file's xres/yres (DEFAULT_PPI when absent)
    #                         "pixels": 1 image pixel = 1 device dot, no resampling
    width_mm: float | None = None  # explicit size; with only one of them the aspect ratio is kept
    height_mm: float | None = None
    scale: float | None = None  # multiplies the physical size
    fit_width_mm: float | None = None  # scale (keeping the aspect ratio) to exactly this width
    rotate: int = 0  # 0, 90, 180, 270 degrees clockwise
    mirror: bool = False  # horizontal mirror on the device (applied after rotation)
    filter: str = "lanczos3"  # nearest | linear | cubic | lanczos3
    # where the image goes on the measured paper (applied by the driver, driver/job.py):
    align: str = "left"  # left | center | right, within the paper minus the side margins
    x_mm: float = 0.0  # then shifted this far to the right (negative: to the left)
    margin_mm: float | None = None  # side margins; None: the printer profile's [paper] margin_mm
    top_mm: float = 0.0  # blank paper fed before the image's first row
    # documents (PDF, PostScript, EPS; docs/documents.md)
    page_box: str = "crop"  # PDF: crop | trim | bleed | art | media
    pages: str = "all"  # which pages, e.g. "1-3,5"; printed one after another along the roll
    page_gap_mm: float = 10.0  # blank paper between pages
    # the layout on the roll (rip/layout.py, docs/layout.md); place() ignores these
    repeat_across: int = 1  # step-and-repeat copies across
    repeat_along: int = 1  # ... and along
    gap_mm: float = 5.0  # between the boxes of copies, nested items, tiles
    nest: bool = False  # the files (and copies) packed side by side
    nest_copies: int = 1  # copies of each file in a nest
    nest_rotate: bool = False  # nested items may be turned 90 degrees
    nest_count: int | None = None  # start rule: files per nest
    nest_length_mm: float | None = None  # start rule: nest length reached
    nest_wait_s: float | None = None  # start rule (print server): the first job waited this long
    nest_width_mm: float | None = None  # width to pack into; None: the paper less the margins
    tile_width_mm: float | None = None  # tiling on when either tile size is given
    tile_height_mm: float | None = None
    tile_overlap_mm: float = 0.0
    join_marks: bool = False  # tiles: ticks where the neighbour's edge goes
    marks: str = "none"  # none | crop | registration | cut (a contour cutter's, docs/cut.md)
    cut_mark_spacing_mm: float = 500.0  # marks cut: a pair at least this often along the print
    label: bool = False  # the job label under each image

    def check(self) -> None:
        """Raise ValueError naming the problem if the options are inconsistent."""
        if self.size not in SIZES:
            raise ValueError(f"placement: size must be 'physical' or 'pixels', not {self.size!r}")
        if self.filter not in FILTERS:
            raise ValueError(f"placement: filter must be one of {', '.join(FILTERS)}, not {self.filter!r}")
        if isinstance(self.rotate, bool) or self.rotate not in ROTATIONS:
            raise ValueError(f"placement: rotate must be 0, 90, 180 or 270 (degrees clockwise), not {self.rotate!r}")
        if self.align not in ALIGNS:
            raise ValueError(f"placement: align must be one of {', '.join(ALIGNS)}, not {self.align!r}")
        if self.page_box not in PAGE_BOXES:
            raise ValueError(f"placement: page_box must be one of {', '.join(PAGE_BOXES)}, not {self.page_box!r}")
        parse_pages(self.pages)
        _finite("x_mm", self.x_mm)
        for name in ("top_mm", "margin_mm", "page_gap_mm"):
            v = getattr(self, name)
            if v is not None and _finite(name, v) < 0:
                raise ValueError(f"placement: {name} must not be negative, not {v!r}")
        self.check_layout()
        given = {n: getattr(self, n) for n in ("width_mm", "height_mm", "scale", "fit_width_mm")
                 if getattr(self, n) is not None}
        for name, v in given.items():
            _positive(name, v)
        if self.size == "pixels" and given:
            raise ValueError("placement: size='pixels' places 1 image pixel per device dot; it cannot be "
                             f"combined with {', '.join(given)}")
        modes = [m for m, on in (("width_mm/height_mm", "width_mm" in given or "height_mm" in given),
                                 ("scale", "scale" in given), ("fit_width_mm", "fit_width_mm" in given)) if on]
        if len(modes) > 1:
            raise ValueError(f"placement: give only one of {' or '.join(modes)}")

    def check_layout(self) -> None:
        """The layout fields' consistency (docs/layout.md, "Modes"); ValueError naming them."""
        if self.marks not in MARKS:
            raise ValueError(f"placement: marks must be one of {', '.join(MARKS)}, not {self.marks!r}")
        for name in ("repeat_across", "repeat_along", "nest_copies"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"placement: {name} must be a whole number >= 1, not {v!r}")
        for name in ("gap_mm", "tile_overlap_mm"):
            if _finite(name, getattr(self, name)) < 0:
                raise ValueError(f"placement: {name} must not be negative, not {getattr(self, name)!r}")
        for name in ("nest_length_mm", "nest_width_mm", "tile_width_mm", "tile_height_mm"):
            if getattr(self, name) is not None:
                _positive(name, getattr(self, name))
        repeat = self.repeat_across > 1 or self.repeat_along > 1
        tiles = self.tile_width_mm is not None or self.tile_height_mm is not None
        if tiles and (self.nest or repeat):
            raise ValueError("placement: tiling (tile_width_mm/tile_height_mm) cannot be combined with "
                             + ("nest" if self.nest else "repeat_across/repeat_along"))
        if self.nest and repeat:
            raise ValueError("placement: nest packs the files side by side; give nest_copies for "
                             "copies, not repeat_across/repeat_along")
        for name in ("tile_width_mm", "tile_height_mm"):
            t = getattr(self, name)
            if t is not None and float(self.tile_overlap_mm) >= float(t):
                raise ValueError(f"placement: tile_overlap_mm {float(self.tile_overlap_mm):g} must be "
                                 f"smaller than {name} {float(t):g}")

    @property
    def quarter_turn(self) -> bool:
        return self.rotate in (90, 270)

    def target_size(self, src_w: int, src_h: int, xres: float | None, yres: float | None,
                    dpi: float, row_um: float) -> tuple[int, int]:
        """(width in device columns, height in device rows) after rotation."""
        self.check()
        src_w, src_h = int(src_w), int(src_h)
        if src_w < 1 or src_h < 1:
            raise ValueError(f"placement: the source image is {src_w} x {src_h} px")
        dpi = _positive("dpi", dpi)
        row_um = _positive("row_um", row_um)
        if self.size == "pixels":
            w, h = (src_h, src_w) if self.quarter_turn else (src_w, src_h)
            return _check_target(w, h, "")
        xr, yr = _ppi(xres), _ppi(yres)
        if xr is None and yr is None:
            xr = yr = DEFAULT_PPI
        xr, yr = xr or yr, yr or xr  # only one tag: square pixels
        assert xr is not None and yr is not None
        return self.target_size_inches(src_w / xr, src_h / yr, dpi, row_um)

    def target_size_inches(self, w_in: float, h_in: float, dpi: float, row_um: float) -> tuple[int, int]:
        """(columns, rows) after rotation for a source of w_in x h_in inches (unrotated):
        the arithmetic of target_size() from the physical size on; documents use it with
        their page size (`size` "pixels" counts as "physical" here)."""
        dpi = _positive("dpi", dpi)
        row_um = _positive("row_um", row_um)
        w_in, h_in = self.scaled_inches(w_in, h_in)
        wf, hf = w_in * dpi, h_in * MM_PER_INCH * 1000.0 / row_um
        if not (math.isfinite(wf) and math.isfinite(hf)) or wf > 10 * MAX_SIDE or hf > 10 * MAX_SIDE:
            return _check_target(math.inf, math.inf, f" ({w_in * 25.4:.6g} x {h_in * 25.4:.6g} mm)")
        return _check_target(_round(wf), _round(hf), f" ({w_in * 25.4:.6g} x {h_in * 25.4:.6g} mm)")

    def scaled_inches(self, w_in: float, h_in: float) -> tuple[float, float]:
        """The size on the media in inches, (across, along) after rotation, of a source of
        w_in x h_in inches (unrotated) under the size options."""
        self.check()
        w_in, h_in = float(w_in), float(h_in)
        if not (w_in > 0 and h_in > 0 and math.isfinite(w_in) and math.isfinite(h_in)):
            raise ValueError(f"placement: the source is {w_in * 25.4:g} x {h_in * 25.4:g} mm")
        if self.quarter_turn:
            w_in, h_in = h_in, w_in
        if self.width_mm is not None and self.height_mm is not None:
            w_in, h_in = float(self.width_mm) / MM_PER_INCH, float(self.height_mm) / MM_PER_INCH
        elif self.width_mm is not None or self.fit_width_mm is not None:
            mm = self.width_mm if self.width_mm is not None else self.fit_width_mm
            assert mm is not None
            want = float(mm) / MM_PER_INCH
            w_in, h_in = want, h_in * want / w_in
        elif self.height_mm is not None:
            want = float(self.height_mm) / MM_PER_INCH
            w_in, h_in = w_in * want / h_in, want
        elif self.scale is not None:
            w_in, h_in = w_in * float(self.scale), h_in * float(self.scale)
        return w_in, h_in


def parse_pages(text: str) -> list[tuple[int, int | None]]:
    """A page selection ("all", "3", "1-3,5", "4-") -> [(first, last or None)], 1-based;
    ValueError naming the problem."""
    if not isinstance(text, str):
        raise ValueError(f"placement: pages must be a string like 1-3,5 or all, not {text!r}")
    t = text.strip().lower().replace(" ", "")
    if t in ("", "all"):
        return [(1, None)]
    out: list[tuple[int, int | None]] = []
    for part in t.split(","):
        a, dash, b = part.partition("-")
        try:
            first = int(a)
            last = (int(b) if b else None) if dash else first
        except ValueError:
            raise ValueError(f"placement: pages must be like 1-3,5 or 4- or all, not {text!r}") from None
        if first < 1 or (last is not None and last < first):
            raise ValueError(f"placement: pages {part!r} is not a range of pages (pages count from 1)")
        out.append((first, last))
    return out


def _check_target(w: float, h: float, what: str) -> tuple[int, int]:
    if not (w >= 1 and h >= 1):
        raise ValueError(f"placement: the placed image would be {w} x {h} dots{what}: nothing to print "
                         f"(0 px); check the size options")
    if w > MAX_SIDE or h > MAX_SIDE:
        ws = "more than 10,000,000" if w == math.inf else f"{w:,}"
        hs = "more than 10,000,000" if h == math.inf else f"{h:,}"
        raise ValueError(f"placement: the placed image would be {ws} columns x {hs} rows{what}, "
                         f"more than the limit of {MAX_SIDE:,} per side; check the size options and "
                         f"the file's resolution")
    return int(w), int(h)


@dataclass
class RipSettings:
    dpi: int = 300
    passes: int = 1              # interleave passes of the weave (not carriage strokes)
    bidir: bool = False
    dither: str = "vced"
    pass_mask: str = "checker"
    ink_limit: float | None = None
    input_icc: str | None = None
    media: str | None = None     # the media entry the job was resolved with (app/medialib.py)
    output_icc: str | None = None
    intent: str = "relative"
    band_rows: int = 64          # rows per band: 64 keeps a 40,000 px wide job small
    spot_dir: str | None = None  # the spot library's folder (a print server's, docs/spot.md); None: the default
    placement: Placement = field(default_factory=Placement)   # physical size by default

    def check(self, profile: Any) -> None:
        """Every setting against the schema and the printer profile, then the placement's
        consistency; SettingsError (a ValueError) naming the setting."""
        for s in SETTINGS:
            obj = self.placement if s.group == "placement" else self
            s.check(getattr(obj, s.name), profile)
        self.placement.check()

    def as_mapping(self) -> dict[str, Any]:
        """The settings as a JSON-able mapping (placement nested), for the spool and reports."""
        out = {k: getattr(self, k) for k in RIP_KEYS}
        out["placement"] = asdict(self.placement)
        return out


# defaults come from the declarations; a test keeps the dataclasses in step with them
assert {f.name for f in fields(Placement)} == set(PLACEMENT_KEYS)
assert {f.name for f in fields(RipSettings)} - {"band_rows", "spot_dir", "placement"} == set(RIP_KEYS)


# -- mappings: requests, presets, saved settings -------------------------------------------
def validate(mapping: Any, profile: Any = None) -> dict[str, Any]:
    """A settings mapping (a request's, a preset's: only the keys given) checked against
    the schema and the printer profile: known keys only, right types, allowed values.
    Placement settings go in a nested "placement" object.  Returns the normalised mapping;
    SettingsError names the setting and the problem."""
    if not isinstance(mapping, dict):
        raise SettingsError("settings must be a JSON object")
    out: dict[str, Any] = {}
    for key, value in mapping.items():
        if key == "placement":
            out["placement"] = validate_placement(value)
            continue
        s = BY_NAME.get(key)
        if s is None or s.group != "rip":
            hint = " (a placement setting: put it in \"placement\")" if key in PLACEMENT_KEYS else ""
            raise SettingsError(f"unknown setting {key!r}{hint} (known: {', '.join(RIP_KEYS)}, placement)")
        out[key] = s.check(value, profile)
    return out


def validate_placement(mapping: Any) -> dict[str, Any]:
    if not isinstance(mapping, dict):
        raise SettingsError("placement must be a JSON object")
    out: dict[str, Any] = {}
    for key, value in mapping.items():
        s = BY_NAME.get(key)
        if s is None or s.group != "placement":
            raise SettingsError(f"unknown placement field {key!r} (known: {', '.join(PLACEMENT_KEYS)})")
        out[key] = s.check(value)
    try:
        Placement(**out).check()
    except ValueError as exc:
        raise SettingsError(str(exc)) from None
    return out


def from_mapping(mapping: Mapping[str, Any] | None = None, profile: Any = None,
                 **overrides: Any) -> RipSettings:
    """RipSettings from a settings mapping (checked with `validate`), the schema's defaults
    for everything not given; `overrides` are internal fields such as band_rows."""
    checked = validate(mapping or {}, profile)
    placement = Placement(**checked.pop("placement", {}))
    rs = RipSettings(placement=placement, **checked, **overrides)
    if profile is not None:
        rs.check(profile)
    return rs


def merge(*mappings: Mapping[str, Any] | None) -> dict[str, Any]:
    """Settings mappings overlaid left to right (a preset, then a request's own settings);
    placement fields merge one by one."""
    out: dict[str, Any] = {}
    for m in mappings:
        for k, v in (m or {}).items():
            if k == "placement":
                out["placement"] = {**out.get("placement", {}), **v}
            else:
                out[k] = v
    return out


# -- the command line ----------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The RIP and placement options, from the schema.  Every option defaults to "not
    given" (argparse.SUPPRESS), so `mapping_from_args` sees only what the user typed:
    `print` and `rip` fill in the schema's defaults, `submit` lets the preset's stand."""
    rip = parser.add_argument_group("RIP settings (docs/settings.md)")
    place = parser.add_argument_group("placement (docs/placement.md)")
    layout = parser.add_argument_group("layout on the roll (docs/layout.md)")
    for s in SETTINGS:
        group = layout if s.section == "layout" else place if s.group == "placement" else rip
        default = "" if s.default is None else f" (default {_cli_value(s.default)})"
        if s.kind is bool:
            group.add_argument(s.flag, dest=s.name, action=argparse.BooleanOptionalAction,
                               default=argparse.SUPPRESS, help=s.help + default)
            continue
        kw: dict[str, Any] = dict(dest=s.name, default=argparse.SUPPRESS, help=s.help + default,
                        type={int: int, float: float, str: str}[s.kind])
        if s.choices is not None:
            kw["choices"] = s.choices
            if s.profile_choices is not None:
                kw["help"] += "; the printer profile's dpi modes"
        if s.metavar:
            kw["metavar"] = s.metavar
        group.add_argument(s.flag, **kw)


def _cli_value(v: Any) -> str:
    return {True: "on", False: "off"}.get(v, str(v)) if isinstance(v, bool) else str(v)


def mapping_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The settings the user gave on the command line, as a nested settings mapping."""
    out: dict[str, Any] = {}
    for s in SETTINGS:
        if hasattr(args, s.name):
            value = getattr(args, s.name)
            if s.group == "placement":
                out.setdefault("placement", {})[s.name] = value
            else:
                out[s.name] = value
    return out
