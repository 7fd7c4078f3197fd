"""ICC profiles through LittleCMS, as libvips (pyvips ``icc_transform``) runs it (docs/color.md):
an input or output profile (a libvips built-in, a file, or a file's embedded bytes), read,
checked and tried on a few pixels so that a broken one fails with its file's name, and the
transform of an array through two of them."""

from __future__ import annotations

import hashlib
import logging
import os
import struct
from typing import Any

import numpy as np

# The shipped default media's ICC output profile (docs/media.md, made by `wideprint media
# create` on the default emulated printer): separations of RGB and grey use it when a job
# names neither a media nor an output profile.  CMYK files still print as they are.
DEFAULT_OUTPUT_ICC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                                  "resources", "media", "vinyl-300", "profile.icc")


def default_output_icc(colorspace: str) -> str | None:
    """The output profile of a job that names none: the default media's for RGB and grey
    (None for CMYK, or if the file is not installed: then libvips' built-in `cmyk`)."""
    return DEFAULT_OUTPUT_ICC if colorspace != "cmyk" and os.path.isfile(DEFAULT_OUTPUT_ICC) else None



_SPACE_NAMES = {b"RGB ": "RGB", b"CMYK": "CMYK", b"GRAY": "grey", b"Lab ": "LAB", b"XYZ ": "XYZ"}


def _icc_header_problem(data: bytes) -> str | None:
    if len(data) < 132:
        return f"not an ICC profile (only {len(data)} bytes)"
    if data[36:40] != b"acsp":
        return "not an ICC profile (no 'acsp' signature)"
    (declared,) = struct.unpack(">I", data[:4])
    if declared > len(data):
        return f"truncated ICC profile (header says {declared} bytes, there are {len(data)})"
    if declared < 132:
        return f"corrupt ICC profile (header says {declared} bytes)"
    return None


def _icc_space(data: bytes) -> bytes:
    return bytes(data[16:20])


def _vips():
    import pyvips

    return pyvips


def _vips_detail(e: Exception) -> str:
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip() and not ln.strip().startswith("unable to call")]
    return "; ".join(dict.fromkeys(lines)) or str(e)


class _Profile:
    """An input or output profile: a libvips built-in name, a file, or embedded bytes."""

    def __init__(self, name: str | None = None, path: str | None = None, data: bytes | None = None,
                 space: bytes = b"RGB ", digest: bytes | None = None):
        self.name, self.path, self.data, self.space = name, path, data, space
        self.digest = digest        # of a file's bytes, as read when it was checked

    def identity(self) -> bytes:
        """What the profile's transform depends on: its bytes' digest, or for a built-in
        one its name (the libvips that holds it is in the cache key too)."""
        import hashlib
        if self.data is not None:
            return hashlib.sha256(self.data).digest()
        if self.path is not None:
            if self.digest is None:
                with open(self.path, "rb") as f:
                    self.digest = hashlib.sha256(f.read()).digest()
            return self.digest
        return f"built-in {self.name}".encode()

    def describe(self) -> str:
        if self.path:
            return self.path
        if self.data is not None:
            return "embedded profile"
        return f"built-in {self.name}"


_INTERP = {1: ("b-w", "grey16"), 3: ("srgb", "rgb16"), 4: ("cmyk", "cmyk")}


def _icc_transform(arr: np.ndarray, bands: int, inp: _Profile, out: _Profile, intent: str, bpc: bool,
                   depth: int, out_depth: int) -> np.ndarray:
    """(h, w, bands) uint8/uint16 -> (h, w, 4|...) through lcms (pyvips)."""
    pv = _vips()
    img = pv.Image.new_from_array(np.ascontiguousarray(arr))
    img = img.copy(interpretation=_INTERP[bands][1 if depth == 16 else 0])
    kw: dict[str, Any] = dict(intent=intent, depth=out_depth, black_point_compensation=bpc)
    if inp.data is not None:
        img.set_type(pv.GValue.blob_type, "icc-profile-data", inp.data)
        kw["embedded"] = True
        if bands in (3, 4):
            kw["input_profile"] = "srgb" if bands == 3 else "cmyk"
    else:
        kw.update(embedded=False, input_profile=inp.path or inp.name)
    res = img.icc_transform(out.path or out.name, **kw)
    return res.numpy()



def load_icc_file(path, role: str, spaces: tuple[bytes, ...], intent: str, bpc: bool) -> _Profile:
    """A profile file checked: readable, an ICC profile of one of `spaces`, not a device
    link, and usable by lcms (`trial`); ValueError naming the file if not."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise ValueError(f"{path}: cannot read {role} ICC profile: {e.strerror or e}") from None
    problem = _icc_header_problem(data)
    if problem:
        raise ValueError(f"{path}: {problem}")
    space = _icc_space(data)
    if space not in spaces:
        want = " or ".join(_SPACE_NAMES.get(s, s.decode("latin-1").strip()) for s in spaces)
        got = _SPACE_NAMES.get(space, space.decode("latin-1", "replace").strip())
        raise ValueError(f"{path}: {role} ICC profile is for {got}, need {want}")
    if data[12:16] == b"link":
        raise ValueError(f"{path}: device-link ICC profiles are not supported")
    prof = _Profile(path=path, space=space, digest=hashlib.sha256(data).digest())
    trial(prof, role, space, intent, bpc)
    return prof


def trial(prof: _Profile, role: str, space: bytes, intent: str, bpc: bool) -> None:
    """Run a few pixels through lcms so that a broken profile fails now, with its file name.
    libvips only *warns* about an input profile lcms cannot parse (and falls back to a default), so
    its warnings are captured too."""
    pv = _vips()
    bands = {b"RGB ": 3, b"CMYK": 4, b"GRAY": 1}.get(space, 3)
    captured: list[str] = []

    class _Grab(logging.Handler):
        def emit(self, record):
            captured.append(record.getMessage())

    grab = _Grab(logging.WARNING)
    vlog = logging.getLogger("pyvips")
    old_level, old_disabled = vlog.level, vlog.disabled
    vlog.addHandler(grab)
    vlog.setLevel(logging.WARNING)  # even if the application silenced libvips' warnings
    vlog.disabled = False
    try:
        _trial_transform(prof, role, bands, intent, bpc)
    except pv.Error as e:
        raise ValueError(f"{prof.describe()}: unusable {role} ICC profile: {_vips_detail(e)}") from None
    finally:
        vlog.removeHandler(grab)
        vlog.setLevel(old_level)
        vlog.disabled = old_disabled
    bad = [m for m in captured if "profile" in m.lower()]
    if bad:
        detail = bad[0].replace("VIPS:", "").strip()
        raise ValueError(f"{prof.describe()}: unusable {role} ICC profile: {detail}")


def _trial_transform(prof: _Profile, role: str, bands: int, intent: str, bpc: bool) -> None:
    if role == "output":
        _icc_transform(np.zeros((1, 2, 3), np.uint8), 3, _Profile(name="srgb"), prof, intent, bpc, 8, 8)
    else:
        _icc_transform(np.zeros((1, 2, bands), np.uint8), bands, prof, _Profile(name="cmyk", space=b"CMYK"),
                       intent, bpc, 8, 8)


def embedded_profile(data: bytes, spaces: tuple[bytes, ...], intent: str,
                     bpc: bool) -> tuple[_Profile | None, str | None]:
    """A file's embedded profile, if usable: (the profile, None), else (None, the warning
    that says why it is ignored and the default input profile used)."""
    data = bytes(data)
    problem = _icc_header_problem(data)
    if problem is None and _icc_space(data) not in spaces:
        problem = f"it is for {_SPACE_NAMES.get(_icc_space(data), 'another colour space')}"
    if problem is None:
        prof = _Profile(data=data, space=_icc_space(data))
        try:
            trial(prof, "input", _icc_space(data), intent, bpc)
            return prof, None
        except ValueError as e:
            problem = str(e)
    return None, f"embedded ICC profile ignored ({problem}); using the default input profile"
