"""Settings presets: read from presets.toml / presets.json in the state directory, checked
like the API's settings, and re-read when the file changes (docs/server.md, "Presets")."""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path

from .config import PRESET_FILES
from .validate import Invalid, validate_name, validate_settings

log = logging.getLogger("wideprint.server")


DEFAULT_PRESETS = {
    "default": {},
    "photo": {"passes": 4, "bidir": False, "dither": "vced", "dpi": 300},
    "banner": {"passes": 2, "bidir": True, "dither": "bayer", "dpi": 300},
}


def preset_file(state_dir: Path) -> Path | None:
    """The presets file in use: presets.toml, else presets.json (None: neither exists)."""
    for fname in PRESET_FILES:
        p = state_dir / fname
        if p.exists():
            return p
    return None


# what a preset may say of its jobs beside their settings (docs/server.md "Presets"):
# hold = true - its jobs are added held, to be looked at before they print, unless the
# submission says otherwise
JOB_DEFAULTS = ("hold",)


def read_presets(path: Path, profile, icc_dir: Path, holds: set | None = None) -> dict:
    """One presets file ({name: settings}), every preset checked like the API's settings;
    ValueError naming the file and the problem.  holds: filled with the names of the
    presets whose jobs are added held."""
    try:
        text = path.read_text()
        if path.suffix == ".toml":
            import tomllib
            raw = tomllib.loads(text)
        else:
            raw = json.loads(text)
    except OSError as exc:
        raise ValueError(f"{path}: {exc.strerror}") from None
    except ValueError as exc:                  # TOML / JSON syntax, bad UTF-8
        raise ValueError(f"{path}: {exc}") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: expected a table of presets")
    presets = {}
    for name, settings in raw.items():
        try:
            validate_name(name)
            if name in ("done", "failed"):
                raise Invalid("reserved for the hot folders' done/ and failed/")
            if isinstance(settings, dict) and "hold" in settings:
                settings = dict(settings)
                hold = settings.pop("hold")
                if not isinstance(hold, bool):
                    raise Invalid("hold must be true or false")
                if hold and holds is not None:
                    holds.add(name)
            presets[name] = validate_settings(settings, profile, icc_dir)
        except Invalid as exc:
            raise ValueError(f"{path}: preset {name!r}: {exc}") from None
    return presets


def load_presets(state_dir: Path, profile, holds: set | None = None) -> dict:
    """presets.toml or presets.json in the state dir ({name: settings}); written with
    the defaults on first start."""
    path = preset_file(state_dir)
    if path is None:
        path = state_dir / "presets.json"
        path.write_text(json.dumps(DEFAULT_PRESETS, indent=2) + "\n")
    return read_presets(path, profile, state_dir / "icc", holds)


class Presets:
    """The server's presets, kept in step with their file without a restart (docs/server.md,
    "Presets are re-read without a restart"): `get()` compares the file's stat signature
    with the one last read (one stat: cheap enough for every request and scan) and
    re-reads it when it changed; `reload()` re-reads on demand.  A file that cannot be read or has an invalid preset is
    logged and reported (`error`) and the presets in use are kept — a typo in the file
    never stops the server or the jobs that use the other presets.  At start-up there is
    nothing to keep, so there a broken file is fatal (as before)."""

    def __init__(self, state_dir: Path, profile):
        self.state_dir, self.profile = state_dir, profile
        self._lock = threading.Lock()
        self._sig = self._signature()          # before reading: a later write is seen
        self.held: set = set()                 # presets whose jobs are added held
        self.current = load_presets(state_dir, profile, self.held)
        self.path = preset_file(state_dir)
        self.loaded = time.time()
        self.error = ""

    def _signature(self):
        # mtime alone misses two writes within the clock's granularity; size and inode
        # (editors that write a new file and rename it) catch most of those
        path = preset_file(self.state_dir)
        try:
            st = path.stat() if path else None
        except OSError:
            st = None
        return None if st is None else (path.name, st.st_mtime_ns, st.st_size, st.st_ino)

    def get(self) -> dict:
        """The presets now, re-read first if the file changed since it was last read."""
        if self._signature() != self._sig:
            try:
                self.reload(only_if_changed=True)
            except ValueError:
                pass                           # logged, kept in `error`; the old ones stay
        return self.current

    def reload(self, only_if_changed: bool = False) -> dict:
        """Re-read the file: returns {added, removed, changed} preset names, or raises
        ValueError naming the file and the problem (the presets in use are kept, and the
        broken file is not read again until it changes or `reload` is asked for)."""
        with self._lock:
            sig = self._signature()            # before reading: a later write is seen next time
            if only_if_changed and sig == self._sig:
                return dict(added=[], removed=[], changed=[])   # another thread just did it
            path = preset_file(self.state_dir)
            try:
                if path is None:
                    raise ValueError(f"{self.state_dir}: no presets file "
                                     f"({' or '.join(PRESET_FILES)})")
                held: set = set()
                new = read_presets(path, self.profile, self.state_dir / "icc", held)
            except ValueError as exc:
                self._sig, self.error = sig, f"{exc}; the presets in use are kept"
                log.error("presets: %s", self.error)
                raise ValueError(self.error) from None
            old, self.current = self.current, new
            self._sig, self.path, self.error = sig, path, ""
            changed_hold = held ^ self.held
            self.held = held
            diff = dict(added=sorted(set(new) - set(old)), removed=sorted(set(old) - set(new)),
                        changed=sorted(n for n in set(new) & set(old)
                                       if new[n] != old[n] or n in changed_hold))
            if any(diff.values()):
                self.loaded = time.time()      # when the presets in use took effect
        if any(diff.values()):
            log.info("presets re-read from %s: %s", path,
                     "; ".join(f"{k} {', '.join(v)}" for k, v in diff.items() if v))
        return diff

    def holds(self, name: str | None) -> bool:
        """Whether jobs of preset `name` are added held by default (its `hold = true`)."""
        self.get()
        return name is not None and name in self.held

    def info(self) -> dict:
        return dict(file=str(self.path) if self.path else None, names=sorted(self.current),
                    loaded=self.loaded, error=self.error or None, held=sorted(self.held))
