"""Hot folders: one folder per preset; a completely written file becomes a job and moves
to done/ or failed/ when the job ends (docs/server.md, "Hot folders" and "Hot folders: the
rules").

Everything below the root is reached through directory descriptors opened with
O_DIRECTORY | O_NOFOLLOW, and every stat, open, rename, mkdir and unlink is relative to
one of them (`dir_fd=`): a symbolic link anywhere below the root — a preset folder, done/,
failed/, a file — is never followed, so the server never reads, moves or creates anything
outside the root.
"""

from __future__ import annotations

import codecs
import errno
import logging
import os
import stat
import threading
import time
import uuid
from pathlib import Path

from .config import IGNORED_SUFFIXES, unique_names
from .ports import HotFolderHost  # what it sees of the server (core.py composes it)
from .validate import Invalid, validate_name

log = logging.getLogger("wideprint.server")

O_DIR = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
O_FILE = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC
SUBFOLDERS = ("failed", "done")        # failed/ first: an impostor done/ is moved into it
REASON = ".reason.txt"
NAME_MAX = 255                         # bytes, Linux


class NotAFolder(OSError):
    """A path below the root that should be a real folder is a link or something else."""


def _pct(err: UnicodeDecodeError | UnicodeEncodeError) -> tuple[str, int]:
    bad = err.object[err.start:err.end]
    if isinstance(bad, str):                       # surrogateescape'd bytes
        bad = bad.encode("utf-8", "surrogateescape")
    return "".join(f"%{b:02X}" for b in bad), err.end


codecs.register_error("wideprint-percent", _pct)


def safe_name(name: str) -> str:
    """A name that can be shown and used anywhere: bytes that are not UTF-8 and control
    characters become %XX (`caf\\xe9.tif` -> `caf%E9.tif`)."""
    raw = os.fsencode(name)
    text = raw.decode("utf-8", "wideprint-percent")
    return "".join(f"%{ord(c):02X}" if ord(c) < 32 or ord(c) == 127 else c for c in text)


def shown(name: str) -> str:
    """A name for a log line or a reason file: as it is when it is printable UTF-8,
    otherwise its repr (a name never forges a log line)."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return repr(os.fsencode(name))[1:]
    return name if name.isprintable() else repr(name)


def name_problem(name: str) -> str | None:
    """Why a file name cannot be a job's name (None: it can)."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return (f"the name {shown(name)} is not valid UTF-8: the server cannot name it; "
                f"give the file a UTF-8 name and drop it again")
    try:
        validate_name(name)
    except Invalid as exc:
        return str(exc)
    return None


def fit_name(name: str, room: int) -> str:
    """`name` shortened (its stem, on a character boundary) so that it and `room` more bytes
    fit in a file name."""
    limit = NAME_MAX - room
    if len(os.fsencode(name)) <= limit:
        return name
    stem, dot, suffix = name.rpartition(".")
    if not dot or len(os.fsencode("." + suffix)) > 16:
        stem, suffix = name, ""
    else:
        suffix = "." + suffix
    keep = limit - len(os.fsencode(suffix))
    while len(os.fsencode(stem)) > keep:
        stem = stem[:-1]
    return stem + suffix


# -- writers ------------------------------------------------------------------------------------
def writers_open(dev: int, ino: int) -> bool:
    """Whether any process we can see has the file (dev, ino) open for writing (Linux
    /proc; processes in other containers or machines are not seen)."""
    proc = "/proc"
    try:
        pids = os.listdir(proc)
    except OSError:
        return False
    for pid in pids:
        if not pid.isdigit():
            continue
        fd_dir = f"{proc}/{pid}/fd"
        try:
            fds = os.listdir(fd_dir)
        except OSError:
            continue
        for fd in fds:
            try:
                st = os.stat(f"{fd_dir}/{fd}")
            except OSError:
                continue
            if st.st_ino != ino or st.st_dev != dev:
                continue
            try:
                with open(f"{proc}/{pid}/fdinfo/{fd}") as f:
                    for line in f:
                        if line.startswith("flags:"):
                            flags = int(line.split()[1], 8)
                            if flags & os.O_ACCMODE in (os.O_WRONLY, os.O_RDWR):
                                return True
            except (OSError, ValueError):
                continue
    return False


def open_for_writing(path: str) -> bool:
    """Whether any process we can see has this file open for writing.  The path itself
    is looked at (lstat): a symbolic link is not followed."""
    try:
        st = os.lstat(path)
    except OSError:
        return False
    if not stat.S_ISREG(st.st_mode):
        return False
    return writers_open(st.st_dev, st.st_ino)


def _kind(st) -> str:
    m = st.st_mode
    return ("a folder" if stat.S_ISDIR(m) else "a FIFO" if stat.S_ISFIFO(m)
            else "a socket" if stat.S_ISSOCK(m)
            else "a device" if stat.S_ISCHR(m) or stat.S_ISBLK(m)
            else "a symbolic link" if stat.S_ISLNK(m) else "a file" if stat.S_ISREG(m)
            else "not a regular file")


class HotFolders(threading.Thread):
    """ROOT/PRESET/ for every preset, each with done/ and failed/.  A file becomes a job
    once complete: its size, modification time and inode unchanged for the settle time and
    open for writing by nobody.  Dotfiles and partial names (*.part, *.tmp, ...) are
    ignored, folders are left alone; names that cannot be named (not UTF-8, control
    characters), symbolic links, non-regular files (FIFOs, sockets, devices), hard-linked,
    oversize, empty and unreadable files go to failed/ with NAME.reason.txt, once.

    Nothing below the root is reached by a path: see the module's doc."""

    def __init__(self, server: HotFolderHost, root: Path):
        super().__init__(name="wideprint-hot-folders", daemon=True)
        self.srv = server
        self.root = Path(os.path.abspath(root))
        # the root is the administrator's path (links in it are theirs): opened once, and
        # everything below it is reached from this descriptor only
        self.root.mkdir(parents=True, exist_ok=True)
        self.root_fd: int | None = os.open(self.root, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        # (preset, name) -> (signature, monotonic time it was first seen so)
        self.seen: dict[tuple[str, str], tuple[tuple, float]] = {}
        # (preset, name) -> signature of a file refused but not movable: not tried again
        # (nor logged) until it changes
        self.stuck: dict[tuple[str, str], tuple] = {}
        # (preset, name) -> (dev, ino, size, mtime) of the file a job was made of (moved
        # when it ends; an inode number alone may be reused by a new file of that name)
        self.taken: dict[tuple[str, str], tuple] = {}
        self.warned: dict[str, str] = {}
        self.stopping = threading.Event()
        self.lock = threading.RLock()
        self.make_folders(server.presets)

    # -- folders --------------------------------------------------------------------------
    def _warn_once(self, key: str, message: str | None) -> None:
        """Log a standing problem once (again only when it changes); None: it is gone."""
        if message is None:
            if self.warned.pop(key, None) is not None:
                log.info("hot folder %s: fine again", key)
            return
        if self.warned.get(key) != message:
            self.warned[key] = message
            log.warning("hot folder %s", message)

    def _describe(self, dir_fd: int, name: str) -> str:
        try:
            st = os.lstat(name, dir_fd=dir_fd)
        except OSError:
            return "gone"
        if stat.S_ISLNK(st.st_mode):
            try:
                return f"a symbolic link to {shown(os.readlink(name, dir_fd=dir_fd))}"
            except OSError:
                return "a symbolic link"
        return _kind(st)

    def _open_dir(self, parent_fd: int, name: str, make: bool) -> int:
        """The real folder `name` in parent_fd (made when missing and `make`); NotAFolder
        when it is a symbolic link or not a folder: never followed."""
        for _ in range(3):
            try:
                return os.open(name, O_DIR, dir_fd=parent_fd)
            except FileNotFoundError:
                if not make:
                    raise
                try:
                    os.mkdir(name, dir_fd=parent_fd)
                except FileExistsError:
                    pass
            except OSError as exc:
                if exc.errno in (errno.ELOOP, errno.ENOTDIR):
                    raise NotAFolder(exc.errno, f"{name} is {self._describe(parent_fd, name)}, "
                                                f"not a folder") from None
                raise
        raise FileNotFoundError(errno.ENOENT, f"{name} keeps disappearing")

    def _preset_fd(self, preset: str, make: bool = True) -> int | None:
        """The preset's folder, or None (logged once) when it is not a real folder: it is
        then not scanned and nothing is moved into or out of it."""
        if self.root_fd is None:
            return None
        try:
            fd = self._open_dir(self.root_fd, preset, make)
        except FileNotFoundError:
            return None
        except OSError as exc:
            self._warn_once(preset, f"{self.root / preset}: {exc.strerror}: not scanned, "
                                    "nothing is moved there (make it a real folder again: "
                                    "remove it and the server makes it)")
            return None
        self._warn_once(preset, None)
        return fd

    def _sub_fd(self, pfd: int, preset: str, sub: str, depth: int = 0) -> int:
        """done/ or failed/ of a preset folder, made when missing.  One that is not a real
        folder (a symbolic link, a file) is never followed: it is moved into failed/ with a
        reason and a real folder is made in its place."""
        for _ in range(3):
            try:
                return self._open_dir(pfd, sub, make=True)
            except NotAFolder:
                if depth >= 2:
                    raise
                self._evict(pfd, preset, sub, depth)
        raise NotAFolder(errno.ELOOP, f"{preset}/{sub} keeps being replaced")

    def _evict(self, pfd: int, preset: str, sub: str, depth: int) -> None:
        what = self._describe(pfd, sub)
        tmp = f".{sub}.not-a-folder.{uuid.uuid4().hex[:12]}"   # a dotfile: never scanned
        try:
            os.rename(sub, tmp, src_dir_fd=pfd, dst_dir_fd=pfd)
        except FileNotFoundError:
            return
        reason = (f"{preset}/{sub} was {what}, not a folder: links are never followed; "
                  f"it was moved here and a real {sub}/ folder was made")
        log.warning("hot folder %s", reason)
        try:
            os.mkdir(sub, dir_fd=pfd)
        except FileExistsError:
            pass
        ffd = self._sub_fd(pfd, preset, "failed", depth + 1)
        try:
            self._rename_into(pfd, tmp, ffd, sub, reason)
        finally:
            os.close(ffd)

    def make_folders(self, presets) -> None:
        """ROOT/PRESET/{done,failed}/ for the presets (start-up, every scan, and presets
        added to the file later).  A removed preset's folder is left as it is."""
        with self.lock:
            for preset in presets:
                pfd = self._preset_fd(preset)
                if pfd is None:
                    continue
                try:
                    for sub in SUBFOLDERS:
                        try:
                            os.close(self._sub_fd(pfd, preset, sub))
                        except OSError as exc:
                            self._warn_once(f"{preset}/{sub}", f"{preset}/{sub}: {exc}")
                        else:
                            self._warn_once(f"{preset}/{sub}", None)
                finally:
                    os.close(pfd)

    # -- moving -----------------------------------------------------------------------------
    def _rename_into(self, src_fd: int, name: str, dst_fd: int, dest_name: str,
                     reason: str | None) -> str:
        """Rename src_fd/name to a free name in dst_fd (the entry itself: a link or FIFO
        is moved, never its target), and write DEST.reason.txt next to it."""
        base = fit_name(dest_name, len(REASON) + 8)
        for cand in unique_names(base):
            if not (self._exists(dst_fd, cand) or self._exists(dst_fd, cand + REASON)):
                break
        # the reason first, then the file: whoever sees the file in failed/ sees why
        wrote = reason is not None and self._write_reason(dst_fd, cand, reason)
        try:
            os.rename(name, cand, src_dir_fd=src_fd, dst_dir_fd=dst_fd)
        except OSError:
            if wrote:
                try:
                    os.unlink(cand + REASON, dir_fd=dst_fd)
                except OSError:
                    pass
            raise
        return cand

    @staticmethod
    def _write_reason(dst_fd: int, cand: str, reason: str) -> bool:
        """DEST.reason.txt, written aside and renamed: never seen half written."""
        tmp = f".{uuid.uuid4().hex}.reason.tmp"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                         | os.O_CLOEXEC, 0o644, dir_fd=dst_fd)
            try:
                with os.fdopen(fd, "w", encoding="utf-8", errors="replace") as f:
                    f.write(reason.rstrip() + "\n")
                os.rename(tmp, cand + REASON, src_dir_fd=dst_fd, dst_dir_fd=dst_fd)
            except BaseException:
                try:
                    os.unlink(tmp, dir_fd=dst_fd)
                except OSError:
                    pass
                raise
        except OSError as exc:
            log.warning("hot folder: cannot write the reason for %s: %s", shown(cand),
                        exc.strerror or exc)
            return False
        return True

    @staticmethod
    def _exists(dir_fd: int, name: str) -> bool:
        try:
            os.lstat(name, dir_fd=dir_fd)
        except FileNotFoundError:
            return False
        except OSError:
            return True
        return True

    def _move(self, pfd: int, preset: str, name: str, sub: str, reason: str | None,
              dest_name: str | None = None) -> bool:
        try:
            sfd = self._sub_fd(pfd, preset, sub)
        except OSError as exc:
            log.warning("hot folder %s: cannot move %s to %s/: %s", preset, shown(name), sub, exc)
            return False
        try:
            self._rename_into(pfd, name, sfd, dest_name or name, reason)
        except OSError as exc:
            log.warning("hot folder %s: cannot move %s to %s/: %s", preset, shown(name), sub,
                        exc.strerror or exc)
            return False
        finally:
            os.close(sfd)
        return True

    def _refuse(self, pfd: int, preset: str, name: str, reason: str, sig: tuple,
                dest_name: str | None = None) -> None:
        key = (preset, name)
        self.seen.pop(key, None)
        if self.stuck.get(key) == sig:
            return                              # refused before and could not be moved
        log.warning("hot folder %s: %s", preset, reason)
        if self._move(pfd, preset, name, "failed", reason, dest_name):
            self.stuck.pop(key, None)
        else:
            self.stuck[key] = sig

    def finish(self, hot_path: str, state: str, reason: str | None) -> None:
        """A hot-folder job ended: its original goes to done/, or failed/ with the reason.
        Found by its preset folder and name from the root's descriptor: a preset folder
        that is no longer a real folder is not entered; a file replaced since the job was
        made (another inode) is left for the scanner."""
        p = Path(hot_path)
        if str(p.parent.parent) != str(self.root):
            log.warning("hot folder: %s is not in %s; not moved", shown(hot_path), self.root)
            return
        preset, name = p.parent.name, p.name
        with self.lock:
            pfd = self._preset_fd(preset, make=False)
            if pfd is None:
                return
            try:
                try:
                    st = os.lstat(name, dir_fd=pfd)
                except OSError:
                    return                           # gone (moved or deleted by the user)
                ident = self.taken.pop((preset, name), None)
                if ident is not None and ident != _ident(st):
                    log.info("hot folder %s: %s was replaced while its job ran; the new file "
                             "is left for the scanner", preset, shown(name))
                    return
                if state == "done":
                    self._move(pfd, preset, name, "done", None)
                else:
                    self._move(pfd, preset, name, "failed", reason)
            finally:
                os.close(pfd)

    # -- scanning -----------------------------------------------------------------------------
    def run(self) -> None:
        while not self.stopping.wait(self.srv.config.scan_interval):
            try:
                self.scan_once()
            except Exception:  # noqa: BLE001 - the scanner must keep going
                log.exception("hot folder scan")

    def close(self) -> None:
        self.stopping.set()
        with self.lock:
            if self.root_fd is not None:
                os.close(self.root_fd)
                self.root_fd = None

    @staticmethod
    def ignored(name: str) -> bool:
        low = name.lower()
        return name.startswith(".") or low.endswith(IGNORED_SUFFIXES) or name.startswith("~$")

    def scan_once(self) -> None:
        presets = self.srv.presets             # re-read first if the file changed
        with self.lock:
            if self.root_fd is None:
                return
            self.make_folders(presets)
            active = self.srv.spool.active_hot_paths()
            present: set[tuple[str, str]] = set()
            for preset, settings in presets.items():
                pfd = self._preset_fd(preset, make=False)
                if pfd is None:
                    continue
                try:
                    try:
                        names = os.listdir(pfd)
                    except OSError as exc:
                        self._warn_once(preset, f"{self.root / preset}: {exc.strerror}")
                        continue
                    for name in names:
                        if name in SUBFOLDERS or self.ignored(name):
                            continue
                        if self.stopping.is_set():
                            return
                        self._consider(pfd, preset, settings, name, active, present)
                finally:
                    os.close(pfd)
            for gone in set(self.seen) - present:
                del self.seen[gone]
            for gone in set(self.stuck) - present:
                del self.stuck[gone]

    def _consider(self, pfd: int, preset: str, settings: dict, name: str, active: set,
                  present: set) -> None:
        try:
            st = os.lstat(name, dir_fd=pfd)
        except OSError:
            return
        if stat.S_ISDIR(st.st_mode):
            return                               # a folder being copied, or the user's own
        key = (preset, name)
        present.add(key)
        path = str(self.root / preset / name)
        if path in active:
            return                               # its job is waiting or printing
        sig = (st.st_size, st.st_mtime_ns, st.st_ino, st.st_dev, st.st_mode, st.st_nlink)
        problem = name_problem(name)
        if problem is not None:                  # refused at once, under a name that can be
            return self._refuse(pfd, preset, name, problem, sig, dest_name=safe_name(name))
        if stat.S_ISLNK(st.st_mode):
            try:
                target = os.readlink(name, dir_fd=pfd)
            except OSError:
                target = "?"
            # where it points is judged from the link's text alone: nothing is looked up
            folder = str(self.root / preset)
            full = os.path.normpath(os.path.join(folder, target))
            inside = full.startswith(folder + os.sep)
            return self._refuse(pfd, preset, name, f"{name} is a symbolic link to "
                                f"{shown(target)}" + ("" if inside else ", outside the hot folder")
                                + ": links are never followed; copy the file itself", sig)
        if not stat.S_ISREG(st.st_mode):
            return self._refuse(pfd, preset, name, f"{name} is {_kind(st)}: only regular files "
                                "are printed", sig)
        limit = self.srv.config.max_file_bytes
        if st.st_size > limit:
            return self._refuse(pfd, preset, name, f"{name} is {st.st_size} bytes, above the "
                                f"{limit}-byte limit", sig)
        now = time.monotonic()
        prev = self.seen.get(key)
        if prev is None or prev[0] != sig:
            self.seen[key] = (sig, now)          # new or still changing: look again
            return
        if now - prev[1] < self.srv.config.settle_s:
            return                               # not unchanged for the settle time yet
        if writers_open(st.st_dev, st.st_ino):
            return                               # unchanged but still open: a slow writer
        if st.st_nlink > 1:
            return self._refuse(pfd, preset, name, f"{name} has {st.st_nlink} hard links: a "
                                "hard link may be a file from outside the hot folder; copy "
                                "the file itself", sig)
        if st.st_size == 0:
            return self._refuse(pfd, preset, name, f"{name} is empty", sig)
        self._take(pfd, preset, settings, name, path, st, sig)

    def _take(self, pfd: int, preset: str, settings: dict, name: str, path: str, st,
              sig: tuple) -> None:
        key = (preset, name)
        try:
            fd = os.open(name, O_FILE, dir_fd=pfd)
        except OSError as exc:
            return self._refuse(pfd, preset, name, f"{name}: cannot open "
                                f"({exc.strerror})", sig)
        try:
            fst = os.fstat(fd)
            if (not stat.S_ISREG(fst.st_mode) or (fst.st_dev, fst.st_ino) != (st.st_dev, st.st_ino)
                    or fst.st_nlink > 1):
                self.seen.pop(key, None)         # replaced between lstat and open: look again
                return
            with os.fdopen(fd, "rb", closefd=False) as f:
                try:
                    job, _ = self.srv.queue_file(
                        f, name, fst.st_size, check=lambda: _check_same(fd, fst),
                        source=f"hot:{preset}", settings=dict(settings), preset=preset,
                        client="hot-folder", hot_path=path, fit="width")
                except Invalid as exc:
                    # a file too wide for the paper is refused as the API refuses it, in
                    # words that name it already (docs/server.md "Fit before it fails"); one
                    # the roll left cannot hold is queued: held before printing, never lost
                    why = str(exc) if str(exc).startswith(name) else f"{name}: {exc}"
                    return self._refuse(pfd, preset, name, why, sig)
                except FileChanged:
                    self.seen.pop(key, None)     # written to while copied: look again
                    return
                except OSError as exc:           # a read error, the spool disk full, ...
                    self.seen.pop(key, None)
                    self._warn_once(f"{preset}/{shown(name)}", f"{preset}: cannot queue "
                                    f"{name} ({exc.strerror or exc}); trying again")
                    return
        finally:
            os.close(fd)
        self._warn_once(f"{preset}/{shown(name)}", None)
        self.seen.pop(key, None)
        self.taken[key] = _ident(st)
        log.info("hot folder %s: %s is job %s", preset, name, job["id"])
        self.srv.notify()


def _ident(st) -> tuple:
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


class FileChanged(Exception):
    """The file changed while it was copied to the spool (the copy is deleted)."""


def _check_same(fd: int, before) -> None:
    """After the copy: the file is still as it was when it was found complete."""
    now = os.fstat(fd)
    if (now.st_size, now.st_mtime_ns, now.st_ino, now.st_nlink) != \
            (before.st_size, before.st_mtime_ns, before.st_ino, before.st_nlink):
        raise FileChanged()
