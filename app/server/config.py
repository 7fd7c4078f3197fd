"""The print server's configuration, state directory, token and file-system helpers
(docs/server.md)."""

from __future__ import annotations

import logging
import os
import re
import secrets
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger("wideprint.server")


DEFAULT_PORT = 8631
DEFAULT_MAX_FILE = 4 * 1024 ** 3          # 4 GiB
TOKEN_FILE = "token"
SERVER_FILE = "server.json"
PRESET_FILES = ("presets.toml", "presets.json")
# the formats the RIP prints (detected by content, rip/inputs.py; the suffix is kept on the
# spool copy and when renaming): images, PDF/PostScript/EPS (Ghostscript), HP RTL
IMAGE_SUFFIXES = (".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".png",
                  ".pdf", ".ps", ".eps", ".epsf", ".ai", ".rtl", ".prn", ".plt", ".hpgl", ".pcl")
IGNORED_SUFFIXES = (".part", ".tmp", ".temp", ".crdownload", ".partial", ".download", "~",
                    ".swp", ".reason.txt")
MAX_COPIES = 100
PRIORITY_RANGE = (-100, 100)
CHUNK = 1 << 20
SQLITE_MAX_INT = 2 ** 63 - 1               # ids and numbers the API accepts (SQLite INTEGER)
DEFAULT_SETTLE_S = 5.0                     # a hot-folder file unchanged this long is complete
DEFAULT_API_TIMEOUT_S = 30.0               # an API connection silent this long is closed
DEFAULT_API_CONNECTIONS = 32               # API connections served at once; more get 503


def default_state_dir() -> Path:
    """WIDEPRINT_STATE_DIR, else /var/lib/wideprint for root, else the user's state dir."""
    env = os.environ.get("WIDEPRINT_STATE_DIR")
    if env:
        return Path(env)
    if os.geteuid() == 0:
        return Path("/var/lib/wideprint")
    try:
        from platformdirs import user_state_dir
        return Path(user_state_dir("wideprint"))
    except ImportError:
        return Path.home() / ".local" / "state" / "wideprint"


def ensure_token(state_dir: Path) -> str:
    """The API token: created 0600 on first start, read by clients."""
    path = state_dir / TOKEN_FILE
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return path.read_text().strip()
    token = secrets.token_urlsafe(32)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    return token


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def unique_names(name: str):
    """NAME, then NAME-1, NAME-2, ... (before an image suffix: a-1.tif), for a name that
    is taken already."""
    yield name
    stem, suffix = name, ""
    for s in IMAGE_SUFFIXES:
        if name.lower().endswith(s):
            stem, suffix = name[:-len(s)], name[-len(s):]
    i = 1
    while True:
        yield f"{stem}-{i}{suffix}"
        i += 1


@dataclass
class PrinterConfig:
    """One printer of the server: its name (used by jobs, the API and the GUI), its device
    spec and its printer profile."""
    name: str = "main"
    device: str = "emulator"
    profile_path: str | None = None


PRINTER_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,31}$")


@dataclass
class ServerConfig:
    device: str = "emulator"
    state_dir: Path = field(default_factory=default_state_dir)
    media_dir: Path | None = None
    hot_folder_root: Path | None = None
    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    on_crash: str = "resume"               # resume | hold | reprint (docs/server.md "Crash recovery")
    max_file_bytes: int = DEFAULT_MAX_FILE
    scan_interval: float = 1.0
    start_paused: bool = False
    profile_path: str | None = None
    inject: list = field(default_factory=list)   # emulator faults (--inject KIND=VALUE)
    reconnect_backoff: tuple = (0.5, 30.0)
    keep_failed_s: float = 7 * 86400       # spool copies of failed/cancelled jobs (requeue)
    settle_s: float = DEFAULT_SETTLE_S     # hot folders: unchanged this long (and no writer)
    api_timeout_s: float = DEFAULT_API_TIMEOUT_S      # idle API connections are closed
    api_max_connections: int = DEFAULT_API_CONNECTIONS  # served at once; more: 503
    printers: list = field(default_factory=list)   # PrinterConfig; empty: one, "main", of
    #                                                device/profile_path above

    def printer_configs(self) -> list[PrinterConfig]:
        """The server's printers: the ones configured, else one called "main"."""
        out = list(self.printers) or [PrinterConfig("main", self.device, self.profile_path)]
        names = [p.name for p in out]
        for name in names:
            if not PRINTER_NAME.match(name):
                raise ValueError(f"printer name {name!r}: use letters, digits, '.', '_' or '-' "
                                 f"(1-32, starting with a letter or digit)")
        if len(set(names)) != len(names):
            raise ValueError(f"printer names must differ: {', '.join(names)}")
        return out
