"""The LUT cache (docs/color.md "The LUT cache"): a transform's 3-D LUT kept between
processes, in files named by what the LUT is made from."""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .icc import _Profile

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------------------
# The LUT cache (docs/color.md "The LUT cache"): lcms makes a transform's 33^3 grid in
# ~15 ms, a tenth of a small job's start-up; the grid, once made, is read back in ~0.2 ms.

LUT_CACHE_VERSION = 1    # raised whenever the LUT's values would come out differently
LUT_CACHE_FILES = 64     # transforms kept (18 MB); the least recently used go first


def cache_dir() -> str | None:
    """$WIDEPRINT_CACHE_DIR, else $XDG_CACHE_HOME/wideprint, else ~/.cache/wideprint; an
    empty $WIDEPRINT_CACHE_DIR turns the cache off."""
    env = os.environ.get("WIDEPRINT_CACHE_DIR")
    if env is not None:
        return env or None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "wideprint")


def _read_lut(path: str | None, size: int) -> np.ndarray | None:
    """The cached LUT, or None if there is none usable (missing, damaged, another shape:
    it is then made again and the file replaced)."""
    if path is None:
        return None
    try:
        lut = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None
    if lut.dtype != np.uint64 or lut.shape != (size,):
        return None
    with contextlib.suppress(OSError):
        os.utime(path)                  # recently used: kept when the cache is trimmed
    return np.ascontiguousarray(lut)


def _write_lut(path: str | None, lut: np.ndarray) -> None:
    """Kept for the next process: written whole under a temporary name, then renamed
    (rip/planes.py `output_file`, as every output file), so a reader never sees half a
    file; a cache that cannot be written is no error."""
    if path is None:
        return
    from ..planes import output_file
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with output_file(path) as tmp, open(tmp, "wb") as f:
            np.save(f, lut, allow_pickle=False)
        _trim(os.path.dirname(path))
    except OSError as exc:
        log.debug("LUT cache not written (%s): %s", path, exc)


def _trim(folder: str) -> None:
    """At most LUT_CACHE_FILES transforms: each job with a profile of its own (a file's
    embedded one) adds one, so the oldest used go."""
    entries = []
    for e in os.scandir(folder):
        if e.name.endswith(".npy"):
            with contextlib.suppress(OSError):
                entries.append((e.stat().st_mtime, e.path))
    for _, stale in sorted(entries)[:max(0, len(entries) - LUT_CACHE_FILES)]:
        with contextlib.suppress(OSError):
            os.unlink(stale)


def lut_file(profiles: tuple[_Profile, _Profile], intent: str, bpc: bool, size: int,
             lane_scale: int) -> str | None:
    """Where the 3-D LUT of a transform is kept between processes: named by what it is
    made from (its two profiles, the intent, black point compensation, the grid and the
    packing, this cache's version and the libvips whose LittleCMS makes the values);
    None when there is no cache."""
    folder = cache_dir()
    if folder is None:
        return None
    h = hashlib.sha256()
    try:
        for prof in profiles:
            h.update(prof.identity())
    except OSError:                 # a profile file gone since it was checked: no cache
        return None
    import pyvips as pv             # its LittleCMS makes the values
    h.update(f"|{intent}|{bpc}|{size}|{lane_scale}|{LUT_CACHE_VERSION}|libvips "
             f"{pv.version(0)}.{pv.version(1)}.{pv.version(2)}".encode())
    return os.path.join(folder, "lut3", h.hexdigest()[:40] + ".npy")
