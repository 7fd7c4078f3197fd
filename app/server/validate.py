"""What the print server accepts: file names, job descriptions and their settings (the
settings themselves are checked by the one schema, rip/settings.py)."""

from __future__ import annotations

import logging
from pathlib import Path

from .config import MAX_COPIES, PRIORITY_RANGE

log = logging.getLogger("wideprint.server")


# -- validation ----------------------------------------------------------------------------
class Invalid(ValueError):
    """A request or file that is refused; the message says why."""

    def __init__(self, message: str, status: int = 400):
        super().__init__(message)
        self.status = status


def validate_name(name) -> str:
    """A submitted file name: a plain name, never a path."""
    if not isinstance(name, str):
        raise Invalid("name must be a string")
    if not name or len(name.encode("utf-8", "surrogateescape")) > 255:
        raise Invalid("name must be 1 to 255 bytes")
    if "/" in name or "\\" in name:
        raise Invalid(f"name {name!r} is a path: give a plain file name (no / or \\)")
    if name in (".", "..") or name.startswith("."):
        raise Invalid(f"name {name!r}: names starting with '.' are refused")
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in name):
        raise Invalid(f"name {name!r} contains control characters")
    return name


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_int(key: str, v, lo: int, hi: int) -> int:
    if not _is_int(v):
        raise Invalid(f"{key} must be an integer, not {type(v).__name__}")
    if not lo <= v <= hi:
        raise Invalid(f"{key} {v} is out of range ({lo}..{hi})")
    return v


def validate_settings(raw, profile, icc_dir: Path | None = None) -> dict:
    """RIP settings from a request or a preset, checked by the one settings schema
    (rip/settings.py) against the printer profile; ICC profiles are plain names of files
    in the server's icc/ folder, never paths."""
    from ...rip import settings as schema
    try:
        out = schema.validate(raw, profile)
    except schema.SettingsError as exc:
        raise Invalid(str(exc)) from None
    for key in ("input_icc", "output_icc"):
        v = out.get(key)
        if v is None:
            continue
        try:
            validate_name(v)
        except Invalid as exc:
            raise Invalid(f"{key}: {exc} (ICC profiles are named from the server's "
                          f"icc/ folder)") from None
        if icc_dir is not None and not (icc_dir / v).is_file():
            raise Invalid(f"{key} {v!r}: no such profile in {icc_dir}")
    if out.get("media"):
        from ..medialib import find, user_dir
        try:                       # icc_dir is STATE/icc: the server's library is STATE/media
            find(out["media"], user_dir(icc_dir.parent) if icc_dir is not None else None)
        except ValueError as exc:
            raise Invalid(f"media: {exc}") from None
    return out


def with_icc_paths(settings: dict, icc_dir: Path) -> dict:
    """A job's settings with its ICC profiles (plain names in the server's icc/ folder, as
    validate_settings accepts them) as the paths the RIP opens."""
    out = dict(settings)
    for key in ("input_icc", "output_icc"):
        if out.get(key):
            out[key] = str(Path(icc_dir) / out[key])
    return out


def rip_settings(settings: dict):
    """RipSettings from validated settings (placement given as a JSON object)."""
    from ...rip.settings import from_mapping
    return from_mapping(settings)


def job_rip_settings(settings: dict, profile, state_dir: Path):
    """(RipSettings, printer profile) a job rips with: its ICC names as paths in STATE/icc,
    its media (STATE/media, docs/media.md) applied to the settings and the profile, its
    spot colours resolved by the server's spot library (STATE/spots, docs/spot.md)."""
    from dataclasses import replace
    from ...rip.spot import library_dir
    from ..medialib import resolve, user_dir
    profile, mapping = resolve(with_icc_paths(settings, Path(state_dir) / "icc"), profile,
                               user_dir(state_dir))
    return replace(rip_settings(mapping), spot_dir=str(library_dir(state_dir))), profile


JOB_KEYS = {"name", "preset", "copies", "priority", "hold", "key", "client", "settings", "printer",
            "force", "rip_hold"}


def validate_job_request(raw, presets: dict, profile, icc_dir: Path | None,
                         printers: tuple = ()) -> dict:
    """The X-Wideprint-Job header of an upload: returns the checked request with the
    effective settings (preset overlaid by explicit settings)."""
    if not isinstance(raw, dict):
        raise Invalid("the job description must be a JSON object")
    unknown = set(raw) - JOB_KEYS
    if unknown:
        raise Invalid(f"unknown field {sorted(unknown)[0]!r} (known: {', '.join(sorted(JOB_KEYS))})")
    if "name" not in raw:
        raise Invalid("name is required")
    req: dict = {"name": validate_name(raw["name"])}
    printer = raw.get("printer")
    if printer in (None, "any"):
        printer = None
    elif not isinstance(printer, str) or (printers and printer not in printers):
        raise Invalid(f"unknown printer {printer!r} (printers: {', '.join(printers) or 'main'}, or any)")
    req["printer"] = printer
    preset = raw.get("preset")
    if preset is not None:
        if not isinstance(preset, str) or preset not in presets:
            raise Invalid(f"unknown preset {preset!r} (presets: {', '.join(sorted(presets))})")
    req["preset"] = preset
    req["copies"] = _check_int("copies", raw.get("copies", 1), 1, MAX_COPIES)
    req["priority"] = _check_int("priority", raw.get("priority", 0), *PRIORITY_RANGE)
    hold = raw.get("hold", False)
    if not isinstance(hold, bool):
        raise Invalid("hold must be true or false")
    req["hold"] = hold
    force = raw.get("force", False)             # past the fit checks (docs/server.md)
    if not isinstance(force, bool):
        raise Invalid("force must be true or false")
    req["force"] = force
    rip_hold = raw.get("rip_hold", False)       # held, ripped ahead (docs/server.md)
    if not isinstance(rip_hold, bool):
        raise Invalid("rip_hold must be true or false")
    req["rip_hold"] = rip_hold
    for k, limit in (("key", 200), ("client", 100)):
        v = raw.get(k)
        if v is not None and (not isinstance(v, str) or not 0 < len(v) <= limit or
                              any(ord(ch) < 32 for ch in v)):
            raise Invalid(f"{k} must be a printable string of 1..{limit} characters")
        req[k] = v
    from ...rip.settings import merge
    # the request's own settings over the preset's, placement field by field
    settings = merge(presets.get(preset, {}) if preset else {},
                     validate_settings(raw.get("settings", {}), profile, icc_dir))
    req["settings"] = settings
    return req
