"""Spot colours: named colour libraries, their files, per-media recipes and how a name
resolves to inks (docs/spot.md).

A library is named colours with their CIELAB (D50, 2°); a recipe is C, M, Y, K fractions
(0..1, before the media's curves and ink limit) saved for one media.  A name resolves for
a media to its saved recipe, else to its Lab taken through the media's ICC profile
(LittleCMS through libvips, absolute colorimetric), with the CIEDE2000 (libvips ``dE00``)
between the target and what the profile says that recipe prints.

Standard library plus numpy and pyvips: the rendering (rip/spot_pdf.py, rip/document.py)
and the commands (app/cli/spot.py) share this module.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import re
import tempfile
import unicodedata
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from .cutnames import is_cut_name

__all__ = ["Spot", "Library", "Resolved", "SpotBook", "library_dir", "fold", "parse_text",
           "write_text", "parse_cxf3", "write_cxf3", "read_file", "lab_to_cmyk", "cmyk_to_lab",
           "delta_e2000"]

#: above this ΔE2000 between the target and its profile round trip, a colour is out of gamut
GAMUT_DE = 1.0
#: the shipped default media (app/medialib.py DEFAULT_MEDIA): its profile is rip/color/icc.py's
DEFAULT_MEDIA = "vinyl-300"
CXF_NS = "http://colorexchangeformat.com/CxF3-core"
LIB_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


def library_dir(state_dir: str | os.PathLike | None = None) -> Path:
    """$WIDEPRINT_SPOT_DIR, else STATE/spots: STATE is `state_dir` when given (a print
    server's --state-dir, as app/medialib.py user_dir), else as app/server/config.py: the
    state directory's environment variable, /var/lib/wideprint for root, else the user's."""
    env = os.environ.get("WIDEPRINT_SPOT_DIR")
    if env:
        return Path(env)
    if state_dir is not None:
        return Path(state_dir) / "spots"
    state = os.environ.get("WIDEPRINT_STATE_DIR")
    if state:
        return Path(state) / "spots"
    if os.geteuid() == 0:
        return Path("/var/lib/wideprint/spots")
    from platformdirs import user_state_dir
    return Path(user_state_dir("wideprint")) / "spots"


def fold(name: str) -> str:
    """The key a name is matched by: NFC, case folded, '_' and white space runs as one blank."""
    s = unicodedata.normalize("NFC", name).replace("_", " ")
    return " ".join(s.split()).casefold()


@dataclass
class Spot:
    name: str
    lab: tuple[float, float, float]
    library: str = ""


def _check_lab(name: str, lab: Iterable[float], where: str) -> tuple[float, float, float]:
    v = tuple(float(x) for x in lab)
    if len(v) != 3 or not all(np.isfinite(v)):
        raise ValueError(f"{where}: {name!r}: Lab must be three numbers")
    if not 0.0 <= v[0] <= 100.0 or abs(v[1]) > 200 or abs(v[2]) > 200:
        raise ValueError(f"{where}: {name!r}: Lab {v} out of range (L 0..100, a and b ±200)")
    return (v[0], v[1], v[2])


def _check_spot_name(name: str, where: str) -> str:
    name = " ".join(name.split())
    if not name or len(name) > 127:
        raise ValueError(f"{where}: a colour name must be 1..127 characters")
    if is_cut_name(name):
        raise ValueError(f"{where}: {name!r} is a cut colour name (rip/cutnames.py): it is "
                         f"never printed, so it cannot be a library colour")
    return name


# -- files --------------------------------------------------------------------------------
_TEXT_RE = re.compile(r"^(.*):\s*([-+\d.eE]+)[\s,]+([-+\d.eE]+)[\s,]+([-+\d.eE]+)\s*$")


def parse_text(text: str, where: str = "text") -> list[Spot]:
    """`NAME: L a b` a line (docs/spot.md)."""
    out: list[Spot] = []
    for i, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        m = _TEXT_RE.match(s)
        if not m:
            raise ValueError(f"{where}:{i}: not 'NAME: L a b': {s[:80]!r}")
        name = _check_spot_name(m.group(1), f"{where}:{i}")
        try:
            values = [float(v) for v in m.group(2, 3, 4)]
        except ValueError:
            raise ValueError(f"{where}:{i}: {name!r}: L a b are not numbers: {s[:80]!r}") from None
        lab = _check_lab(name, values, f"{where}:{i}")
        out.append(Spot(name, lab))
    return out


def write_text(spots: Iterable[Spot]) -> str:
    lines = ["# wideprint spot colours: NAME: L a b (CIELAB D50, 2 degree observer)"]
    lines += [f"{s.name}: {s.lab[0]:.2f} {s.lab[1]:.2f} {s.lab[2]:.2f}" for s in spots]
    return "\n".join(lines) + "\n"


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _children(el, name: str):
    return [c for c in el if _local(c.tag) == name]


def _find(el, *path: str):
    for name in path:
        nxt = _children(el, name) if el is not None else []
        el = nxt[0] if nxt else None
    return el


def parse_cxf3(data: bytes, where: str = "CxF3", warnings: list | None = None) -> list[Spot]:
    """The Objects of a CxF3 document that have a ColorCIELab in D50, 2° (docs/spot.md)."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise ValueError(f"{where}: not XML: {e}") from None
    if _local(root.tag) != "CxF":
        raise ValueError(f"{where}: not a CxF3 document (root element {_local(root.tag)!r})")
    specs: dict[str, tuple[str, str]] = {}
    for cs in root.iter():
        if _local(cs.tag) != "ColorSpecification":
            continue
        tri = _find(cs, "TristimulusSpec")
        ill = (_find(tri, "Illuminant").text or "").strip() if _find(tri, "Illuminant") is not None else "D50"
        obs = (_find(tri, "Observer").text or "").strip() if _find(tri, "Observer") is not None else "2_Degree"
        specs[cs.get("Id", "")] = (ill, obs)
    out: list[Spot] = []
    for obj in root.iter():
        if _local(obj.tag) != "Object":
            continue
        name = obj.get("Name") or obj.get("Id") or ""
        labs = [el for el in obj.iter() if _local(el.tag) == "ColorCIELab"]
        if not labs:
            if warnings is not None:
                warnings.append(f"{where}: {name!r} has no ColorCIELab (spectral or RGB only): skipped")
            continue
        def d50(el) -> bool:
            ill, obs = specs.get(el.get("ColorSpecification", ""), ("D50", "2_Degree"))
            return ill.upper() == "D50" and obs.startswith("2")
        lab_el = next((el for el in labs if d50(el)), labs[0])     # an object may give several
        ill, obs = specs.get(lab_el.get("ColorSpecification", ""), ("D50", "2_Degree"))
        if not d50(lab_el):
            raise ValueError(f"{where}: {name!r}: Lab in {ill}, {obs}: wideprint's libraries are "
                             f"D50, 2 degree (convert it, or export it so from the source)")
        vals = []
        for k in ("L", "A", "B"):
            el = _find(lab_el, k)
            if el is None or not (el.text or "").strip():
                raise ValueError(f"{where}: {name!r}: ColorCIELab lacks {k}")
            vals.append(float(el.text.strip()))
        nm = _check_spot_name(name, where)
        out.append(Spot(nm, _check_lab(nm, vals, where)))
    if not out:
        raise ValueError(f"{where}: no Object with a ColorCIELab")
    return out


def write_cxf3(spots: Iterable[Spot], title: str = "wideprint") -> bytes:
    """A CxF3 document: one ColorSpecification (D50, 2°) and an Object per colour."""
    ET.register_namespace("cc", CXF_NS)

    def q(t: str) -> str:
        return f"{{{CXF_NS}}}{t}"
    root = ET.Element(q("CxF"))
    fh = ET.SubElement(root, q("FileInformation"))
    ET.SubElement(fh, q("Creator")).text = "wideprint"
    ET.SubElement(fh, q("CreationDate")).text = now()
    ET.SubElement(fh, q("Description")).text = title
    res = ET.SubElement(root, q("Resources"))
    coll = ET.SubElement(res, q("ObjectCollection"))
    for i, s in enumerate(spots, 1):
        obj = ET.SubElement(coll, q("Object"), ObjectType="Standard", Name=s.name, Id=f"c{i}")
        cv = ET.SubElement(obj, q("ColorValues"))
        lab = ET.SubElement(cv, q("ColorCIELab"), ColorSpecification="CSD50-2")
        for k, v in zip("LAB", s.lab):
            ET.SubElement(lab, q(k)).text = f"{v:.4f}"
    csc = ET.SubElement(res, q("ColorSpecificationCollection"))
    cs = ET.SubElement(csc, q("ColorSpecification"), Id="CSD50-2")
    tri = ET.SubElement(cs, q("TristimulusSpec"))
    ET.SubElement(tri, q("Illuminant")).text = "D50"
    ET.SubElement(tri, q("Observer")).text = "2_Degree"
    ET.SubElement(tri, q("Method")).text = "E308"
    ET.SubElement(cs, q("MeasurementSpec"))
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def read_file(path: str | Path, warnings: list | None = None) -> list[Spot]:
    """A CxF3 (XML) or text list, by content."""
    data = Path(path).read_bytes()
    head = data[:512].lstrip(b"\xef\xbb\xbf").lstrip()
    if head.startswith(b"<"):
        return parse_cxf3(data, str(path), warnings)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: neither CxF3 (XML) nor UTF-8 text") from None
    return parse_text(text, str(path))


# -- colour -------------------------------------------------------------------------------
def _lab_image(lab: np.ndarray):
    import pyvips
    a = np.ascontiguousarray(np.asarray(lab, np.float32).reshape(1, -1, 3))
    return pyvips.Image.new_from_memory(a.tobytes(), a.shape[1], 1, 3, "float").copy(interpretation="lab")


#: the ICC profile connection space's white, XYZ (x 100) and Bradford's cone matrix
D50_XYZ = np.array([96.422, 100.0, 82.521])
BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])


def media_white(icc: str) -> np.ndarray:
    """The profile's media white point (its `wtpt` tag), XYZ x 100."""
    import struct
    data = Path(icc).read_bytes()
    n = struct.unpack(">I", data[128:132])[0]
    for i in range(min(n, 1000)):
        sig, off, size = struct.unpack(">4sII", data[132 + 12 * i: 144 + 12 * i])
        if sig == b"wtpt" and data[off:off + 4] == b"XYZ " and size >= 20:
            return np.array(struct.unpack(">3i", data[off + 8: off + 20]), np.float64) / 65536 * 100
    return D50_XYZ.copy()


def _adapt(lab: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Lab seen under white `src` -> under white `dst` (Bradford, as media verify measures)."""
    a = np.asarray(lab, np.float64).reshape(-1, 3)
    xyz_img = _lab_image(a).Lab2XYZ(temp=list(D50_XYZ))
    xyz = np.ndarray(buffer=xyz_img.write_to_memory(), dtype=np.float32, shape=a.shape).astype(np.float64)
    m = np.linalg.inv(BRADFORD) @ np.diag((BRADFORD @ dst) / (BRADFORD @ src)) @ BRADFORD
    out = np.ascontiguousarray((xyz @ m.T).astype(np.float32))
    import pyvips
    im = pyvips.Image.new_from_memory(out.tobytes(), a.shape[0], 1, 3, "float").copy(interpretation="xyz")
    lab_img = im.XYZ2Lab(temp=list(D50_XYZ))
    return np.ndarray(buffer=lab_img.write_to_memory(), dtype=np.float32, shape=a.shape).astype(np.float64)


def lab_to_cmyk(lab: np.ndarray, icc: str) -> np.ndarray:
    """Lab (n, 3) D50, as measured -> ink fractions (n, 4): absolute colorimetric as media
    verify measures it (the Lab adapted from the profile's media white to D50, Bradford,
    then the profile's relative B2A through LittleCMS).  libvips' own absolute intent is
    not used: it took this profile's white as (95, 2.3, 15.1) where its wtpt is (95, 0, -2)."""
    rel = _adapt(lab, media_white(icc), D50_XYZ)
    im = _lab_image(rel).icc_export(output_profile=str(icc), intent="relative", depth=16)
    return np.ndarray(buffer=im.write_to_memory(), dtype=np.uint16, shape=(rel.shape[0], 4)) / 65535.0


def cmyk_to_lab(cmyk: np.ndarray, icc: str) -> np.ndarray:
    """Ink fractions (n, 4) -> the Lab (n, 3) the profile says they print, paper included."""
    import pyvips
    c = np.ascontiguousarray(np.clip(np.round(np.asarray(cmyk, np.float64).reshape(-1, 4) * 65535), 0,
                                     65535).astype(np.uint16))
    im = pyvips.Image.new_from_memory(c.tobytes(), c.shape[0], 1, 4, "ushort").copy(interpretation="cmyk")
    out = im.icc_import(input_profile=str(icc), intent="relative", pcs="lab")
    rel = np.ndarray(buffer=out.write_to_memory(), dtype=np.float32, shape=(c.shape[0], 3)).astype(np.float64)
    return _adapt(rel, D50_XYZ, media_white(icc))


def delta_e2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """CIEDE2000 of (n, 3) pairs, by libvips' dE00."""
    a = np.asarray(lab1, np.float64).reshape(-1, 3)
    b = np.asarray(lab2, np.float64).reshape(-1, 3)
    d = _lab_image(a).dE00(_lab_image(b))
    return np.ndarray(buffer=d.write_to_memory(), dtype=np.float32, shape=(a.shape[0],)).astype(np.float64)


def now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()


def _write_json(path: Path, data) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=path.parent)
    with os.fdopen(fd, "w") as f:
        json.dump(data, f, indent=1, ensure_ascii=False)
        f.write("\n")
    os.replace(tmp, path)


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: unreadable ({e})") from None


# -- the library on disk ------------------------------------------------------------------
@dataclass
class Library:
    name: str
    colours: list[Spot] = field(default_factory=list)
    description: str = ""


@dataclass
class Resolved:
    """How one name prints on one media."""
    name: str
    resolved: str                    # recipe | library | alternate | cut
    cmyk: tuple | None = None        # ink fractions
    lab: tuple | None = None         # the library's target
    de2000: float | None = None      # target -> what the recipe prints (profile, or measured)
    library: str | None = None
    media: str | None = None

    @property
    def in_gamut(self) -> bool | None:
        return None if self.de2000 is None else self.de2000 <= GAMUT_DE

    def as_dict(self) -> dict:
        r = lambda v, n=4: None if v is None else [round(float(x), n) for x in v]  # noqa: E731
        return {"name": self.name, "resolved": self.resolved, "library": self.library,
                "media": self.media, "cmyk": r(self.cmyk), "lab": r(self.lab, 2),
                "de2000": None if self.de2000 is None else round(self.de2000, 2),
                "in_gamut": self.in_gamut}


class SpotBook:
    """The spot folder: libraries, recipes per media, swatch measurements."""

    def __init__(self, folder: Path | str | None = None):
        self.folder = Path(folder) if folder is not None else library_dir()

    # libraries
    def _lib_path(self, name: str) -> Path:
        if not LIB_NAME_RE.match(name or ""):
            raise ValueError(f"library name {name!r}: letters, digits, '.', '_' and '-', at most 64")
        return self.folder / "libraries" / f"{name}.json"

    def libraries(self) -> list[Library]:
        out = []
        d = self.folder / "libraries"
        for p in sorted(d.glob("*.json")) if d.is_dir() else []:
            data = _read_json(p) or {}
            lib = Library(p.stem, [Spot(c["name"], tuple(c["lab"]), p.stem) for c in data.get("colours", [])],
                          data.get("description", ""))
            out.append(lib)
        return out

    def library(self, name: str) -> Library:
        p = self._lib_path(name)
        if not p.is_file():
            raise KeyError(f"no spot library {name!r} (wideprint spot list)")
        return next(lib for lib in self.libraries() if lib.name == name)

    def save_library(self, lib: Library) -> None:
        _write_json(self._lib_path(lib.name), {"name": lib.name, "description": lib.description,
                                               "colours": [{"name": s.name, "lab": list(s.lab)}
                                                           for s in lib.colours]})

    def colours(self) -> dict[str, Spot]:
        """Every colour by its folded name."""
        out: dict[str, Spot] = {}
        for lib in self.libraries():
            for s in lib.colours:
                out.setdefault(fold(s.name), s)
        return out

    def find(self, name: str) -> Spot | None:
        return self.colours().get(fold(name))

    def add(self, spots: list[Spot], library: str, replace: bool = False) -> Library:
        """Put colours in a library (made if new); a name in another library, or twice in
        this one, is refused unless `replace` (then it moves here)."""
        self._lib_path(library)
        seen: set[str] = set()
        for s in spots:
            if fold(s.name) in seen:
                raise ValueError(f"{s.name!r} is given twice")
            seen.add(fold(s.name))
        libs = {lib.name: lib for lib in self.libraries()}
        for lib in libs.values():
            clash = [c for c in lib.colours if fold(c.name) in seen]
            if clash and not replace:
                raise ValueError(f"{clash[0].name!r} is already in library {lib.name!r}; --replace "
                                 f"to overwrite")
            if clash:
                lib.colours = [c for c in lib.colours if fold(c.name) not in seen]
                if lib.name != library:
                    self.save_library(lib)
        lib = libs.get(library) or Library(library)
        lib.colours += [Spot(s.name, s.lab, library) for s in spots]
        self.save_library(lib)
        return lib

    def remove(self, name: str) -> Spot:
        for lib in self.libraries():
            hit = [c for c in lib.colours if fold(c.name) == fold(name)]
            if hit:
                lib.colours = [c for c in lib.colours if fold(c.name) != fold(name)]
                self.save_library(lib)
                return hit[0]
        raise KeyError(f"no spot colour {name!r} (wideprint spot list)")

    def remove_library(self, name: str) -> None:
        p = self._lib_path(name)
        if not p.is_file():
            raise KeyError(f"no spot library {name!r}")
        p.unlink()

    # recipes
    def _recipe_path(self, media: str) -> Path:
        if not LIB_NAME_RE.match(media or ""):
            raise ValueError(f"media name {media!r}")
        return self.folder / "recipes" / f"{media}.json"

    def recipes(self, media: str) -> dict:
        return _read_json(self._recipe_path(media)) or {}

    def save_recipe(self, media: str, name: str, cmyk, **info) -> dict:
        c = [float(v) for v in cmyk]
        if len(c) != 4 or not all(0.0 <= v <= 1.0 for v in c):
            raise ValueError(f"a recipe is four ink fractions 0..1, not {cmyk}")
        data = self.recipes(media)
        data = {k: v for k, v in data.items() if fold(k) != fold(name)}
        entry = {"cmyk": [round(v, 5) for v in c], "saved": now(), **info}
        data[name] = entry
        _write_json(self._recipe_path(media), data)
        return entry

    def forget_recipe(self, media: str, name: str) -> bool:
        data = self.recipes(media)
        kept = {k: v for k, v in data.items() if fold(k) != fold(name)}
        if len(kept) != len(data):
            _write_json(self._recipe_path(media), kept)
        return len(kept) != len(data)

    def recipe(self, media: str, name: str) -> dict | None:
        return next((v for k, v in self.recipes(media).items() if fold(k) == fold(name)), None)

    # swatches
    def swatch_path(self, media: str, name: str) -> Path:
        safe = re.sub(r"[^A-Za-z0-9._-]+", "_", fold(name)).strip("_") or "colour"
        return self.folder / "swatches" / self._recipe_path(media).stem / f"{safe}.json"

    def save_swatch(self, media: str, name: str, data: dict) -> Path:
        p = self.swatch_path(media, name)
        _write_json(p, data)
        return p

    def swatch(self, media: str, name: str) -> dict | None:
        return _read_json(self.swatch_path(media, name))

    # resolution
    def resolve(self, name: str, media: str, icc: str | None) -> Resolved:
        """How `name` prints on `media` whose output profile is `icc` (docs/spot.md)."""
        if is_cut_name(name):
            return Resolved(name, "cut", media=media)
        spot = self.find(name)
        if spot is None:
            return Resolved(name, "alternate", media=media)
        saved = self.recipe(media, name) if media else None
        if saved is not None:
            return Resolved(name, "recipe", tuple(saved["cmyk"]), spot.lab, saved.get("de2000"),
                            spot.library, media)
        if not icc:
            return Resolved(name, "alternate", lab=spot.lab, library=spot.library, media=media)
        cmyk = lab_to_cmyk(np.array([spot.lab]), icc)[0]
        back = cmyk_to_lab(cmyk[None], icc)
        de = float(delta_e2000(np.array([spot.lab]), back)[0])
        return Resolved(name, "library", tuple(float(v) for v in cmyk), spot.lab, de, spot.library, media)
