"""The print server's configuration, state directory, token and file-system helpers
(docs/server.md)."""

from __future__ import annotations

import errno
import logging
import os
import re
import secrets
import stat
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


MIN_TOKEN = 32                             # characters: a shorter token file is refused
MAX_TOKEN_FILE = 4096                      # bytes: a token file larger than this is refused
TOKEN_CHARS = re.compile(r"^[A-Za-z0-9._~+/=-]+$")    # RFC 6750 token68


class TokenError(ValueError):
    """A token file the server will not use (the message names the file and the fix)."""


def read_token_file(path: Path, fix_mode: bool = True) -> str:
    """A bearer token from its file, checked (docs/server.md "Users and roles"): a regular
    file (not a symbolic link), UTF-8 text of at least MIN_TOKEN characters from the bearer
    token alphabet, with nothing else but a final line end.  A file readable by group or
    others is made 0600 with a warning (fix_mode), or refused when it cannot be.  Anything
    else raises TokenError naming the file: an empty, short, binary or unreadable token file
    must never turn authentication off or into a guess."""
    fix = (f"delete it and the server makes a new one at its next start (clients read "
           f"the new one), or write a token of {MIN_TOKEN} or more characters "
           f"(letters, digits, -._~+/=) into it")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
    except FileNotFoundError:
        raise
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise TokenError(f"the token file {path} is a symbolic link: refused") from None
        raise TokenError(f"the token file {path} cannot be read ({exc.strerror}): fix its "
                         f"owner or mode (0600, the server's user)") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise TokenError(f"the token file {path} is not a regular file: {fix}")
        mode = stat.S_IMODE(st.st_mode)
        if mode & 0o077:
            if not fix_mode:
                raise TokenError(f"the token file {path} is readable by others (mode "
                                 f"{mode:04o}): make it 0600")
            try:
                os.fchmod(fd, 0o600)
            except OSError as exc:
                raise TokenError(f"the token file {path} is readable by others (mode "
                                 f"{mode:04o}) and cannot be made 0600 ({exc.strerror})") from None
            log.warning("the token file %s was readable by others (mode %04o): made 0600; "
                        "anyone who read it meanwhile can use the API (delete the file to "
                        "make a new token)", path, mode)
        data = os.read(fd, MAX_TOKEN_FILE + 1)
    except OSError as exc:
        raise TokenError(f"the token file {path} cannot be read ({exc.strerror})") from None
    finally:
        os.close(fd)
    if len(data) > MAX_TOKEN_FILE:
        raise TokenError(f"the token file {path} is not a token (larger than "
                         f"{MAX_TOKEN_FILE} bytes): {fix}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise TokenError(f"the token file {path} is not text (binary or not UTF-8): "
                         f"{fix}") from None
    token = text.strip()
    if not token:
        raise TokenError(f"the token file {path} is empty: {fix}")
    if any(ch.isspace() for ch in token):
        raise TokenError(f"the token file {path} holds blanks or several lines: {fix}")
    if not TOKEN_CHARS.match(token):
        raise TokenError(f"the token file {path} holds characters a bearer token cannot "
                         f"have: {fix}")
    if len(token) < MIN_TOKEN:
        raise TokenError(f"the token file {path} is too short ({len(token)} characters, "
                         f"at least {MIN_TOKEN}): {fix}")
    return token


def new_token() -> str:
    return secrets.token_urlsafe(32)                  # 43 characters, 256 bits


def write_token_file(path: Path, token: str, replace: bool = False) -> None:
    """Write a token file whole or not at all: a temporary file (0600), fsync'd, then
    linked to its name (FileExistsError if it exists and not `replace`) or renamed over
    it, and the directory fsync'd — a crash never leaves an empty token file behind."""
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(token + "\n")
            f.flush()
            os.fsync(f.fileno())
        if replace:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)
    finally:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
    _fsync_dir(path.parent)


def ensure_token(state_dir: Path) -> str:
    """The API's operator token (the `token` file): made on first start (0600, written
    whole), else read and checked (`read_token_file`: TokenError naming the file for an
    empty, short, binary or unreadable one; made 0600 with a warning when others could read
    it)."""
    path = Path(state_dir) / TOKEN_FILE
    try:
        return read_token_file(path)
    except FileNotFoundError:
        pass
    token = new_token()
    try:
        write_token_file(path, token)
    except FileExistsError:                 # made meanwhile by someone else: theirs counts
        return read_token_file(path)
    log.info("made a new API token in %s", path)
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
    archive_days: float = 30.0             # done jobs' files, for reprints (archive.OPTIONS)
    archive_max_gb: float = 20.0           # the archive's total size (archive.OPTIONS)
    archive_planes: bool = False           # done jobs keep their ripped planes (archive.OPTIONS)
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
