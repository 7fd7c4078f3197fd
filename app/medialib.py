"""Media entries and the media library (docs/media.md).

A *media* is a paper printed in one print mode, with everything that makes its colour:
total and per-ink ink limits, per-ink linearisation curves, the ICC output profile, the
drop budget, the measurements it was built from, the reference response that
`recalibrate` restores, verify's tolerances, and when and how it was made.  Each entry is
a folder holding `media.toml` (the fields of `FIELDS`, declared once here; docs/media.md's
table is checked against them), `profile.icc` and the measurement files (.ti3).  A new
version of an entry (recalibrate) keeps the previous media.toml in `history/`.

Shipped entries live in resources/media/, the user's in the media folder of the state
directory (`$WIDEPRINT_MEDIA_DIR`, else STATE/media: app/server/config.py's state dir).
A user entry of the same name hides a shipped one.
"""

from __future__ import annotations

import datetime as _dt
import os
import re
import shutil
import tarfile
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

SHIPPED = Path(__file__).resolve().parent.parent / "resources" / "media"
DEFAULT_MEDIA = "vinyl-300"           # the shipped media a job prints with unless told
ENTRY_FILE = "media.toml"
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
INKS = "CMYK"
IDENTITY = [[0.0, 0.0], [255.0, 255.0]]


@dataclass(frozen=True)
class Field:
    name: str
    kind: str          # str, int, float, bool, table, list
    default: Any
    doc: str


# the entry schema: every key of media.toml, once (docs/media.md "The entry")
FIELDS: tuple[Field, ...] = (
    Field("name", "str", "", "the media's name (its folder's)"),
    Field("version", "int", 1, "raised by every recalibration; the earlier media.toml is "
          "kept as history/media-vN.toml"),
    Field("created", "str", "", "when the entry was made (ISO 8601, UTC)"),
    Field("updated", "str", "", "when this version was made"),
    Field("description", "str", "", "free text for the operator"),
    Field("printer", "str", "default", "the printer profile it was made on"),
    Field("paper", "str", "solvent-vinyl", "the paper (the printer profile's [physical] "
          "media when made on the emulator)"),
    Field("dpi", "int", 300, "print mode: dpi across"),
    Field("passes", "int", 1, "print mode: weave passes"),
    Field("bidir", "bool", False, "print mode: both directions"),
    Field("dither", "str", "vced", "print mode: halftone"),
    Field("ink_limit_percent", "float", 300.0, "total ink limit for separations"),
    Field("channel_limits", "table", {c: 100.0 for c in INKS}, "per-ink limit, percent "
          "of a solid (the top of the ink's curve)"),
    Field("curves", "table", {c: IDENTITY for c in INKS}, "per-ink linearisation, "
          "points [in, out] on 0..255, applied after the separation"),
    Field("drop_budget", "table", {}, "dpi mode -> fraction of each ink amount it prints "
          "(docs/color.md); empty: the printer profile's"),
    Field("modes", "table", {}, "other dpi modes: dpi -> drop_budget, curves, icc, "
          "profcheck and dither: each mode linearised to the same reference and profiled in "
          "its mode, halftoned by its own dither if it has one (150 dpi: joint)"),
    Field("icc", "str", "profile.icc", "the ICC output profile (in the entry's folder)"),
    Field("measurements", "list", [], "the measurement files it was built from (CGATS "
          ".ti3, in the entry's folder)"),
    Field("reference", "table", {}, "the linearised response recalibrate restores: "
          "steps (percent) and each ink's ΔE2000 from paper"),
    Field("tolerances", "table", {"mean": 1.5, "p95": 3.0, "max": 6.0}, "verify's "
          "ΔE2000 limits"),
    Field("build", "table", {}, "how it was made: patches, seconds, profcheck figures"),
)
_KINDS = {"str": str, "int": int, "float": (int, float), "bool": bool, "table": dict,
          "list": list}


@dataclass
class Media:
    """One entry: its fields and its folder."""
    folder: Path
    values: dict = field(default_factory=dict)
    shipped: bool = False

    def __getattr__(self, name):
        values = self.__dict__.get("values", {})
        if name in values:
            return values[name]
        raise AttributeError(name)

    @property
    def icc_path(self) -> Path:
        return self.folder / self.values["icc"]

    def icc_for(self, dpi: int | None) -> Path:
        """The profile of a dpi mode: the mode's own if the entry has one, else the entry's."""
        mode = self.values["modes"].get(str(dpi), {}) if dpi is not None else {}
        return self.folder / mode["icc"] if mode.get("icc") else self.icc_path

    def all_iccs(self) -> list[Path]:
        return [self.icc_path] + [self.folder / m["icc"] for m in self.values["modes"].values()
                                  if m.get("icc")]

    def curves_255(self) -> dict[str, list[list[float]]]:
        """Each ink's curve with its channel limit applied (the curve's output scaled)."""
        out = {}
        for ink in INKS:
            pts = self.values["curves"].get(ink, IDENTITY)
            lim = float(self.values["channel_limits"].get(ink, 100.0)) / 100.0
            out[ink] = [[float(a), float(b) * lim] for a, b in pts]
        return out

    def dither_for(self, dpi: int | None) -> str:
        """The halftone of a dpi mode: the mode's own if it has one (a 150 dpi mode made by
        create: joint, docs/media.md "Every dpi mode the same colour"), else the entry's."""
        mode = self.values["modes"].get(str(dpi), {}) if dpi is not None else {}
        return str(mode.get("dither") or self.values["dither"])

    def settings_defaults(self) -> dict:
        """The print mode the media was made for, as job settings (rip/settings.py)."""
        return {k: self.values[k] for k in ("dpi", "passes", "bidir", "dither")}


def check_values(values: dict, where: str = "media") -> dict:
    """The entry's values with defaults filled in; ValueError naming a bad key."""
    known = {f.name: f for f in FIELDS}
    for k in values:
        if k not in known:
            raise ValueError(f"{where}: unknown key {k!r} (known: {', '.join(known)})")
    out = {}
    for f in FIELDS:
        v = values.get(f.name, f.default)
        if not isinstance(v, _KINDS[f.kind]) or (f.kind in ("int", "float") and isinstance(v, bool)):
            raise ValueError(f"{where}: {f.name} must be {f.kind}, not {v!r}")
        out[f.name] = v
    if not 0 < out["ink_limit_percent"] <= 400:
        raise ValueError(f"{where}: ink_limit_percent {out['ink_limit_percent']} not in (0, 400]")
    for ink, pts in out["curves"].items():
        if ink not in INKS or not pts or any(len(p) != 2 for p in pts):
            raise ValueError(f"{where}: curves.{ink}: points [in, out] of C, M, Y or K")
    return out


# -- the library ---------------------------------------------------------------------------
def user_dir(state_dir: Path | None = None) -> Path:
    """The user's media library: $WIDEPRINT_MEDIA_DIR, else STATE/media of `state_dir` (a
    print server's own state directory), else of the default state directory."""
    env = os.environ.get("WIDEPRINT_MEDIA_DIR")
    if env:
        return Path(env)
    if state_dir is None:
        from .server.config import default_state_dir
        state_dir = default_state_dir()
    return Path(state_dir) / "media"


def check_name(name: str) -> str:
    if not NAME_RE.match(name or ""):
        raise ValueError(f"media name {name!r}: letters, digits, '.', '_' and '-', "
                         f"at most 64, not starting with a punctuation mark")
    return name


def load(folder: Path, shipped: bool = False) -> Media:
    path = folder / ENTRY_FILE
    try:
        doc = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{path}: {exc}") from None
    values = check_values(doc, str(path))
    return Media(folder, values, shipped)


def find(name: str, library: Path | None = None) -> Media:
    """The entry called `name`: the user's (in `library`, default `user_dir()`), else the
    shipped one."""
    check_name(name)
    for base, shipped in ((library or user_dir(), False), (SHIPPED, True)):
        if (base / name / ENTRY_FILE).is_file():
            return load(base / name, shipped)
    have = ", ".join(m.name for m in list_media(library)) or "none"
    raise ValueError(f"no media {name!r} (have: {have}; `wideprint media list`)")


def list_media(library: Path | None = None) -> list[Media]:
    seen: dict[str, Media] = {}
    for base, shipped in ((library or user_dir(), False), (SHIPPED, True)):
        if not base.is_dir():
            continue
        for d in sorted(base.iterdir()):
            if (d / ENTRY_FILE).is_file() and d.name not in seen:
                try:
                    seen[d.name] = load(d, shipped)
                except ValueError:
                    continue
    return sorted(seen.values(), key=lambda m: m.name)


def now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()


def to_toml(values: dict) -> str:
    import tomlkit
    doc = tomlkit.document()
    doc.add(tomlkit.comment("wideprint media entry (docs/media.md): written by `wideprint media`"))
    for f in FIELDS:
        doc[f.name] = values[f.name]
    return tomlkit.dumps(doc)


def save(media: Media) -> Media:
    """Write the entry's media.toml; an existing one of an older version goes to history/."""
    values = check_values(media.values)
    media.folder.mkdir(parents=True, exist_ok=True)
    path = media.folder / ENTRY_FILE
    if path.is_file():
        old = tomllib.loads(path.read_text())
        if int(old.get("version", 1)) != values["version"]:
            hist = media.folder / "history"
            hist.mkdir(exist_ok=True)
            shutil.copy2(path, hist / f"media-v{int(old.get('version', 1))}.toml")
    tmp = path.with_suffix(".tmp")
    tmp.write_text(to_toml(values))
    tmp.replace(path)
    return replace(media, values=values)


def remove(name: str) -> Path:
    m = find(name)
    if m.shipped:
        raise ValueError(f"media {name!r} is shipped with wideprint (resources/media) and "
                         f"cannot be removed; a user entry of the same name would hide it")
    shutil.rmtree(m.folder)
    return m.folder


def export(name: str, out: Path) -> Path:
    m = find(name)
    with tarfile.open(out, "w:gz") as tar:
        tar.add(m.folder, arcname=m.name)
    return out


def import_(archive: Path, name: str | None = None, replace_existing: bool = False) -> Media:
    """An exported entry (.tar.gz holding one folder with media.toml) into the user's
    library, checked before it is kept."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp, tarfile.open(archive) as tar:
        tar.extractall(tmp, filter="data")
        tops = [d for d in Path(tmp).iterdir() if (d / ENTRY_FILE).is_file()]
        if len(tops) != 1:
            raise ValueError(f"{archive}: not an exported media (one folder with {ENTRY_FILE})")
        m = load(tops[0])
        name = check_name(name or m.name)
        dest = user_dir() / name
        if dest.exists():
            if not replace_existing:
                raise ValueError(f"media {name!r} exists in {user_dir()}; --replace to overwrite")
            shutil.rmtree(dest)
        if not m.icc_path.is_file():
            raise ValueError(f"{archive}: the entry's profile {m.values['icc']} is missing")
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copytree(tops[0], dest)
    m = load(dest)
    m.values["name"] = name
    return save(m)


# -- applying a media to a job ---------------------------------------------------------------
def resolve(mapping: dict, profile, library: Path | None = None) -> tuple[Any, dict]:
    """(printer profile, settings mapping) of a job whose settings name a `media`: the
    media's print mode under the settings given (given ones win), its ICC as the output
    profile unless one is given, and its ink limit, curves and drop budget in the profile
    (docs/media.md "A job's media").  The one place the command line and the print server
    turn a media name into what the RIP uses.  Without a media: both unchanged."""
    name = mapping.get("media")
    if not name:
        return profile, mapping
    media = find(name, library)
    if not media.icc_path.is_file():
        raise ValueError(f"media {name!r}: its profile {media.icc_path} is missing")
    given = {k: v for k, v in mapping.items() if v is not None}
    out = {**media.settings_defaults(), **given}
    if "dither" not in given:
        out["dither"] = media.dither_for(int(out["dpi"]))
    out.setdefault("output_icc", str(media.icc_for(int(out["dpi"]))))
    return apply_to_profile(media, profile, int(out["dpi"])), out


def apply_to_profile(media: Media, profile, dpi: int | None = None):
    """The printer profile with the media's ink limit, curves and drop budget; for a dpi
    mode of the entry's `modes`, that mode's curves and budget."""
    from ..rip.profile import CurvesSection
    mode = media.values["modes"].get(str(dpi)) if dpi is not None else None
    if mode is not None:
        media = replace(media, values={**media.values, "curves": mode["curves"],
                                       "drop_budget": {str(dpi): mode["drop_budget"]}})
    curves = {ink: tuple(tuple(p) for p in pts) for ink, pts in media.curves_255().items()}
    budget = dict(profile.color.drop_budget)
    budget.update({int(k): float(v) for k, v in media.values["drop_budget"].items()})
    color = replace(profile.color, ink_limit_percent=float(media.values["ink_limit_percent"]),
                    drop_budget=budget)
    return replace(profile, color=color, curves=CurvesSection(**curves))
