"""The settings of one queued job, as the GUI edits them, and their translation into the
RIP's RipSettings and Placement."""

from __future__ import annotations

import functools
import math
import os
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

from ...rip.settings import RipSettings
from ...rip.profile import Profile, load_profile
from ...rip.settings import setting

# placement size modes offered by the GUI -> rip.place.Placement fields
SIZE_MODES = {
    "original": "Original size (file resolution)",
    "size": "Width / height (mm)",
    "scale": "Scale (%)",
    "fit": "Fit to media width",
    "pixels": "1 image pixel = 1 dot",
}
# the GUI's names for the schema's choices (rip/settings.py declares them once)
ALIGN_NAMES = setting("align").labels
DITHER_NAMES = setting("dither").labels
INTENT_NAMES = setting("intent").labels


@functools.lru_cache(maxsize=16)
def _load_profile_cached(path: str, mtime: float) -> Profile:
    return load_profile(path)


def cached_profile(path: str | os.PathLike) -> Profile:
    """load_profile, cached per file modification time (calibration rewrites the file)."""
    p = str(path)
    try:
        mtime = os.stat(p).st_mtime_ns
    except OSError:
        mtime = -1
    return _load_profile_cached(p, mtime)


@dataclass
class JobSettings:
    profile: str = ""                 # printer profile TOML ("" = the user profile)
    dpi: int = 300
    passes: int = 1
    bidir: bool = False
    dither: str = setting("dither").default        # the schema's default halftone
    pass_mask: str = "checker"        # which pass prints which dot (rip/swath.py PASS_MASKS)
    input_icc: str = ""
    output_icc: str = ""
    intent: str = "relative"
    ink_limit: float | None = None    # percent; None = the profile's default (RGB/grey only)
    copies: int = 1
    # placement (rip/place.py)
    size_mode: str = "original"
    width_mm: float | None = None
    height_mm: float | None = None
    scale_pct: float = 100.0
    fit_width_mm: float | None = None  # None: the paper's printable width at print time
    rotate: int = 0
    mirror: bool = False
    filter: str = "lanczos3"
    align: str = "left"                # across the paper, within the side margins
    x_mm: float = 0.0                  # then shifted right (negative: left)
    margin_mm: float | None = None     # side margins; None = the printer profile's
    top_mm: float = 0.0                # blank paper before the image

    @classmethod
    def from_dict(cls, d: dict | None) -> "JobSettings":
        s = cls()
        names = {f.name for f in fields(cls)}
        for k, v in (d or {}).items():
            if k in names:
                setattr(s, k, v)
        s.validate()
        return s

    def as_dict(self) -> dict:
        return asdict(self)

    def copy(self, **changes) -> "JobSettings":
        return replace(self, **changes)

    def validate(self) -> None:
        """Repair values a hand-edited settings file may hold (keeps the GUI startable)."""
        # a value the schema refuses goes back to the schema's default
        for name in ("dpi", "passes", "bidir", "dither", "pass_mask", "intent", "rotate",
                     "filter", "align"):
            try:
                setting(name).check(getattr(self, name))
            except ValueError:
                setattr(self, name, setting(name).default)
        if self.size_mode not in SIZE_MODES:
            self.size_mode = "original"
        for name in ("x_mm", "top_mm", "margin_mm"):
            v = getattr(self, name)
            if v is None and name == "margin_mm":
                continue
            try:
                v = float(v)
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v) or (name != "x_mm" and v < 0):
                v = None if name == "margin_mm" else 0.0
            setattr(self, name, v)
        try:
            self.copies = max(1, min(999, int(self.copies)))
        except (TypeError, ValueError):
            self.copies = 1

    def placement(self, media_width_mm: float | None = None):
        """A rip.place.Placement for these settings."""
        from ...rip.place import Placement
        kw = dict(rotate=int(self.rotate), mirror=bool(self.mirror), filter=self.filter,
                  align=self.align, x_mm=float(self.x_mm), margin_mm=self.margin_mm,
                  top_mm=float(self.top_mm))
        m = self.size_mode
        if m == "pixels":
            return Placement(size="pixels", **kw)
        if m == "size" and (self.width_mm or self.height_mm):
            return Placement(width_mm=self.width_mm or None, height_mm=self.height_mm or None, **kw)
        if m == "scale":
            return Placement(scale=float(self.scale_pct) / 100.0, **kw)
        if m == "fit":
            w = self.fit_width_mm or media_width_mm
            if w:
                return Placement(fit_width_mm=float(w), **kw)
        return Placement(**kw)

    def rip_settings(self, media_width_mm: float | None = None) -> RipSettings:
        return RipSettings(dpi=int(self.dpi), passes=int(self.passes), bidir=bool(self.bidir),
                           dither=self.dither, ink_limit=self.ink_limit,
                           input_icc=self.input_icc or None, output_icc=self.output_icc or None,
                           intent=self.intent, pass_mask=self.pass_mask,
                           placement=self.placement(media_width_mm))

    def profile_path(self, user_profile: Path) -> str:
        return self.profile or str(user_profile)

    def summary(self) -> str:
        mask = f" {self.pass_mask}" if self.passes > 1 and self.pass_mask != "checker" else ""
        return (f"{self.dpi} dpi, {self.passes} pass{'es' if self.passes > 1 else ''}{mask} "
                f"{'bi' if self.bidir else 'uni'}, {self.dither}")


def printable_width_mm(profile: Profile, paper_mm: float | None = None,
                       margin_mm: float | None = None) -> float:
    """Paper width less both side margins (the job's, else the profile's; the emulator's
    sheet when no paper was measured)."""
    paper = paper_mm or profile.paper.default_width_mm
    margin = float(profile.paper.margin_mm if margin_mm is None else margin_mm)
    return max(0.0, paper - 2 * margin)


def profile_label(path: str | Path, user_profile: Path) -> str:
    p = Path(path)
    if p == Path(user_profile):
        return "User profile (calibrated)"
    from ...rip.profile import DEFAULT_PROFILE
    if p == DEFAULT_PROFILE:
        return "Built-in default"
    return p.stem
