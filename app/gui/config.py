"""Where the GUI keeps its state, and the remembered settings (docs/gui.md).

- settings: ``<config dir>/gui.json`` (window layout, job defaults, device, emulator options)
- the user's printer profile: ``<config dir>/printers/user.toml``, a copy of the built-in
  default made on first use; calibration writes into it (rip.profile.save_calibration)
- the config dir is platformdirs' user config dir for "wideprint"
  (``~/.config/wideprint`` on Linux), or ``$WIDEPRINT_CONFIG_DIR`` when set (tests)
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

log = logging.getLogger("wideprint.gui")

APP = "wideprint"
SETTINGS_FILE = "gui.json"
USER_PROFILE = Path("printers") / "user.toml"


def default_config_dir() -> Path:
    env = os.environ.get("WIDEPRINT_CONFIG_DIR")
    if env:
        return Path(env)
    import platformdirs
    return Path(platformdirs.user_config_dir(APP))


def default_cache_dir() -> Path:
    env = os.environ.get("WIDEPRINT_CONFIG_DIR")
    if env:
        return Path(env) / "cache"
    import platformdirs
    return Path(platformdirs.user_cache_dir(APP))


def builtin_profile_path() -> Path:
    from ...rip.profile import DEFAULT_PROFILE
    return DEFAULT_PROFILE


def ensure_user_profile(config_dir: Path) -> Path:
    """The user's copy of the printer profile; copied from the built-in default on first use."""
    path = Path(config_dir) / USER_PROFILE
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(builtin_profile_path(), path)
        log.info("created the user printer profile %s (a copy of the built-in default)", path)
    return path


@dataclass
class GuiSettings:
    """Everything remembered between runs (JSON, unknown keys ignored)."""
    job: dict = field(default_factory=dict)          # JobSettings defaults for new jobs
    device_spec: str = "emulator"
    media_dir: str = ""                              # emulator: write each job's media here
    emulator_speed: float = 10.0                     # 0 = as fast as possible, 1 = real time
    emulator_faults: str = ""                        # e.g. "bidir-error=2 dead-nozzle=M1:57"
    last_dir: str = ""
    separations: list = field(default_factory=lambda: [True, True, True, True])
    geometry: str = ""                               # base64 QMainWindow geometry
    window_state: str = ""                           # base64 QMainWindow state (docks)
    splitter: str = ""
    calibration: dict = field(default_factory=dict)  # last pattern, dpi, width

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
            if k in s.__dataclass_fields__ and isinstance(v, type(getattr(s, k))) or (
                    k == "emulator_speed" and isinstance(v, (int, float))):
                setattr(s, k, v)
        return s

    def save(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".gui-", suffix=".json")
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(asdict(self), f, indent=2)
            os.replace(tmp, path)
        except OSError:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
