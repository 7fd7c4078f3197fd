"""Where the GUI keeps its own state, and the remembered settings (docs/gui.md).

The queue, the history, the printers and their profiles are the print server's (its state
directory); the GUI keeps only what is the operator's: ``<config dir>/gui.json`` (the
settings for new jobs, the window layout, the last folder, the test print choices), saved
at each change, so a GUI that is killed loses nothing of it.  The config dir is
platformdirs' user config dir for "wideprint" (``~/.config/wideprint`` on Linux), or
``$WIDEPRINT_CONFIG_DIR`` when set (tests).
"""

from __future__ import annotations

import functools
import json
import logging
import os
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

log = logging.getLogger("wideprint.gui")

APP = "wideprint"
SETTINGS_FILE = "gui.json"


def default_config_dir() -> Path:
    env = os.environ.get("WIDEPRINT_CONFIG_DIR")
    if env:
        return Path(env)
    import platformdirs
    return Path(platformdirs.user_config_dir(APP))


@functools.lru_cache(maxsize=16)
def _load_profile_cached(path: str, mtime: int):
    from ...rip.profile import load_profile
    return load_profile(path)


def cached_profile(path: str | os.PathLike):
    """load_profile, cached per file modification time (calibration rewrites the file)."""
    p = str(path)
    try:
        mtime = os.stat(p).st_mtime_ns
    except OSError:
        mtime = -1
    return _load_profile_cached(p, mtime)


@dataclass
class GuiSettings:
    """Everything the GUI remembers (JSON, unknown keys ignored)."""
    job: dict = field(default_factory=dict)          # settings for new jobs (the schema's mapping)
    copies: int = 1                                  # copies of new jobs
    device_spec: str = "emulator"                    # the device of a server the GUI starts
    last_dir: str = ""
    geometry: str = ""                               # base64 QMainWindow geometry
    splitter: str = ""
    calibration: dict = field(default_factory=dict)  # last pattern, dpi, width
    add_held: bool = False                           # Add files: as held (look, then Release)
    preset: str = ""                                 # Add files: the server's preset ("": none)

    @classmethod
    def load(cls, path: Path) -> "GuiSettings":
        try:
            raw = json.loads(Path(path).read_text())
        except FileNotFoundError:
            return cls()
        except (OSError, ValueError) as exc:
            log.warning("%s: cannot read the GUI settings (%s); using defaults", path, exc)
            return cls()
        s = cls()
        if not isinstance(raw, dict):
            return s
        for k, v in raw.items():
            if k in s.__dataclass_fields__ and isinstance(v, type(getattr(s, k))):
                setattr(s, k, v)
        s.job = _checked_job(s.job)
        s.copies = max(1, min(100, s.copies))
        return s

    def save(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".gui-", suffix=".json")
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(asdict(self), f, indent=2)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except OSError:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise


def _checked_job(mapping: dict) -> dict:
    """Settings for new jobs as the schema accepts them (a hand-edited file that does not
    pass keeps the GUI startable: the settings go back to the defaults)."""
    from ...rip.settings import SettingsError, validate
    try:
        return validate(mapping)
    except SettingsError as exc:
        log.warning("the GUI's settings for new jobs are refused (%s); using the defaults", exc)
        return {}
