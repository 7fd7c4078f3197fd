"""Hot folders: one folder per preset; a completely written file becomes a job and moves
to done/ or failed/ when the job ends (docs/server.md, "Hot folders")."""

from __future__ import annotations

import logging
import os
import stat
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from .config import IGNORED_SUFFIXES, _unique
from .validate import Invalid, validate_name

if TYPE_CHECKING:
    from .core import PrintServer

log = logging.getLogger("wideprint.server")


# -- hot folders ------------------------------------------------------------------------------
def open_for_writing(path: str) -> bool:
    """Whether any process we can see has this file open for writing (Linux /proc)."""
    try:
        target = os.stat(path)
    except OSError:
        return False
    proc = Path("/proc")
    if not proc.is_dir():
        return False
    for pid in os.listdir(proc):
        if not pid.isdigit():
            continue
        fd_dir = f"/proc/{pid}/fd"
        try:
            fds = os.listdir(fd_dir)
        except OSError:
            continue
        for fd in fds:
            try:
                st = os.stat(f"{fd_dir}/{fd}")
            except OSError:
                continue
            if st.st_ino != target.st_ino or st.st_dev != target.st_dev:
                continue
            try:
                with open(f"/proc/{pid}/fdinfo/{fd}") as f:
                    for line in f:
                        if line.startswith("flags:"):
                            flags = int(line.split()[1], 8)
                            if flags & os.O_ACCMODE in (os.O_WRONLY, os.O_RDWR):
                                return True
            except (OSError, ValueError):
                continue
    return False


class HotFolders(threading.Thread):
    """ROOT/PRESET/ for every preset.  A file becomes a job once complete: the same size
    and modification time on two scans in a row and open for writing by nobody.  Dotfiles
    and partial names (*.part, *.tmp, ...) are ignored, folders are left alone; symlinks,
    non-regular files (FIFOs, sockets, devices), oversize and unreadable files go straight
    to failed/ with NAME.reason.txt."""

    def __init__(self, server: "PrintServer", root: Path):
        super().__init__(name="wideprint-hot-folders", daemon=True)
        self.srv = server
        self.root = root
        self.seen: dict[str, tuple] = {}
        self.stopping = threading.Event()
        self.lock = threading.Lock()
        self.made: set[str] = set()
        self.make_folders(server.presets)

    def make_folders(self, presets) -> None:
        """ROOT/PRESET/{done,failed}/ for presets that have none yet (start-up, and
        presets added to the file later).  A removed preset's folder is left as it is."""
        for preset in set(presets) - self.made:
            for sub in ("", "done", "failed"):
                (self.root / preset / sub).mkdir(parents=True, exist_ok=True)
            self.made.add(preset)

    def run(self) -> None:
        while not self.stopping.wait(self.srv.config.scan_interval):
            try:
                self.scan_once()
            except Exception:  # noqa: BLE001 - the scanner must keep going
                log.exception("hot folder scan")

    @staticmethod
    def ignored(name: str) -> bool:
        low = name.lower()
        return name.startswith(".") or low.endswith(IGNORED_SUFFIXES) or name.startswith("~$")

    def scan_once(self) -> None:
        presets = self.srv.presets             # re-read first if the file changed
        with self.lock:
            self.make_folders(presets)
            active = self.srv.spool.active_hot_paths()
            present = set()
            for preset, settings in presets.items():
                folder = self.root / preset
                try:
                    entries = list(os.scandir(folder))
                except OSError as exc:
                    log.warning("hot folder %s: %s", folder, exc)
                    continue
                for e in entries:
                    if self.ignored(e.name):
                        continue
                    path = os.path.join(folder, e.name)
                    if path in active:
                        continue
                    try:
                        st = os.lstat(path)
                    except OSError:
                        continue
                    if stat.S_ISDIR(st.st_mode):
                        continue                       # done/, failed/, a folder being copied
                    present.add(path)
                    self._consider(preset, settings, folder, e.name, path, st)
            for gone in set(self.seen) - present:
                del self.seen[gone]

    def _consider(self, preset: str, settings: dict, folder: Path, name: str, path: str,
                  st) -> None:
        if stat.S_ISLNK(st.st_mode):
            target = os.path.realpath(path)
            inside = target.startswith(str(folder.resolve()) + os.sep)
            return self._refuse(folder, name, f"{name} is a symbolic link to {target}"
                                + ("" if inside else ", outside the hot folder")
                                + ": links are not followed; copy the file itself")
        if not stat.S_ISREG(st.st_mode):
            kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                    else "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode)
                    else "not a regular file")
            return self._refuse(folder, name, f"{name} is {kind}: only regular files are printed")
        limit = self.srv.config.max_file_bytes
        if st.st_size > limit:
            return self._refuse(folder, name, f"{name} is {st.st_size} bytes, above the "
                                f"{limit}-byte limit")
        sig = (st.st_size, st.st_mtime_ns, st.st_ino)
        if self.seen.get(path) != sig:
            self.seen[path] = sig                   # new or still changing: look again
            return
        if open_for_writing(path):
            return                                  # stable but still open: a slow writer
        del self.seen[path]
        if st.st_size == 0:
            return self._refuse(folder, name, f"{name} is empty")
        try:
            validate_name(name)
        except Invalid as exc:
            return self._refuse(folder, name, str(exc))
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError as exc:
            return self._refuse(folder, name, f"{name}: cannot open ({exc.strerror})")
        try:
            fst = os.fstat(fd)
            if not stat.S_ISREG(fst.st_mode) or fst.st_ino != st.st_ino:
                return self._refuse(folder, name, f"{name} changed while being read")
            with os.fdopen(fd, "rb", closefd=False) as f:
                try:
                    spool_path, size, digest = self.srv.spool_copy(f, name, fst.st_size)
                except Invalid as exc:
                    return self._refuse(folder, name, str(exc))
        finally:
            os.close(fd)
        job, _ = self.srv.spool.add_job(name=name, source=f"hot:{preset}", spool_path=spool_path,
                                        size=size, sha256=digest,
                                        settings=dict(settings), preset=preset,
                                        client="hot-folder", hot_path=path)
        log.info("hot folder %s: %s is job %s", preset, name, job["id"])
        self.srv.worker.notify()

    def _refuse(self, folder: Path, name: str, reason: str) -> None:
        log.warning("hot folder: %s", reason)
        self.seen.pop(os.path.join(folder, name), None)
        self.move(folder / name, folder / "failed", reason)

    @staticmethod
    def move(src: Path, dest_dir: Path, reason: str | None = None) -> Path | None:
        dest_dir.mkdir(exist_ok=True)
        dest = _unique(dest_dir / src.name)
        try:
            os.rename(src, dest)                    # the link/FIFO itself, never its target
        except OSError as exc:
            log.warning("cannot move %s to %s: %s", src, dest_dir, exc)
            return None
        if reason is not None:
            (dest_dir / (dest.name + ".reason.txt")).write_text(reason.rstrip() + "\n")
        return dest
