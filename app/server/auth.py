"""Who is asking, and what they may do (docs/server.md "Users and roles").

Two roles, as CUPS has them:

- **operator**: the holder of the server's `token` file (the one token before issue 31,
  so every existing client keeps working).  Everything: every job, the queue, the
  printers, presets, shutdown.  A client with the operator token names the person it acts
  for in `X-Wideprint-User` (the CUPS backend: the CUPS job's user; the IPP bridge: the
  IPP requesting-user-name; the CLI: the OS user); jobs it submits belong to that name.
- **user**: the holder of a user token, `STATE/users/NAME` (0600, made by the operator
  with `wideprint users add NAME`).  Submits jobs (they belong to NAME whatever the
  request says), reads the queue, the printers and the accounting, and cancels, holds,
  releases, requeues, moves or edits **its own** jobs only.  Anything else: 403 with the
  reason.

Job owners are kept in the server's database, table `job_owners` (job id, owner), written
when the job is queued.  A job with no owner (queued before issue 31, from a hot folder,
or by an operator client that named nobody) is the operator's alone.
"""

from __future__ import annotations

import hmac
import logging
import os
import re
import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

from ..safe_text import add_secret, forget_secret, safe
from .config import TokenError, read_token_file

log = logging.getLogger("wideprint.server")

USERS_DIR = "users"
USER_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.@+-]{0,63}$")   # a users/ file's name
MAX_CLAIMED = 100                       # X-Wideprint-User: characters at most
OPERATOR, USER = "operator", "user"
RESCAN_S = 2.0                          # users/ is looked at again at most this often


@dataclass(frozen=True)
class Identity:
    """Who a request comes from: `name` (None: an operator client that named nobody)
    and `role` (operator or user)."""
    name: str | None
    role: str

    @property
    def operator(self) -> bool:
        return self.role == OPERATOR

    def shown(self) -> str:
        who = safe(self.name) if self.name else "the operator"
        return f"{who} ({self.role})" if self.name else who


def check_user_name(name: str) -> str:
    """A name for `users add`: it names a file in users/, so a plain word (ValueError)."""
    if not isinstance(name, str) or not USER_NAME.match(name) or name.endswith(".tmp"):
        raise ValueError(f"user name {name!r}: 1-64 letters, digits, '_', '.', '@', '+' or "
                         f"'-', starting with a letter, digit or '_'")
    return name


def claimed_name(value: str) -> str:
    """The X-Wideprint-User header: a name, percent-encoded UTF-8 (so any name travels in
    an HTTP header); ValueError for one that is empty, too long, not UTF-8 or holds
    control, invisible or reordering characters."""
    try:
        name = unquote(value, errors="strict")
    except UnicodeDecodeError:
        raise ValueError("X-Wideprint-User is not percent-encoded UTF-8") from None
    name = name.strip()
    if not name or len(name) > MAX_CLAIMED:
        raise ValueError(f"X-Wideprint-User must be 1 to {MAX_CLAIMED} characters")
    if safe(name) != name:
        raise ValueError(f"X-Wideprint-User {safe(name)[:60]!r} holds control or invisible "
                         f"characters")
    return name


class Users:
    """The user tokens of `STATE/users/`: one file a user, its name the user's, its content
    the token (checked like the operator's token; a bad file is skipped with a warning,
    never fatal).  Re-read when the folder changes (and at most every RESCAN_S)."""

    def __init__(self, state_dir: str | os.PathLike, operator_token: str | None = None):
        self.dir = Path(state_dir) / USERS_DIR
        self.operator_token = operator_token
        self._tokens: dict[str, str] = {}          # name -> token
        self._seen: tuple | None = None
        self._checked = 0.0
        self._warned: set = set()
        self._lock = threading.Lock()

    def _scan(self) -> None:
        try:
            st = os.stat(self.dir)
            seen = (st.st_ino, st.st_mtime_ns)
        except FileNotFoundError:
            seen = None
        now = time.monotonic()
        if seen == self._seen and now - self._checked < RESCAN_S:
            return
        self._seen, self._checked = seen, now
        tokens: dict[str, str] = {}
        if seen is not None:
            try:
                names = sorted(os.listdir(self.dir))
            except OSError as exc:
                log.warning("cannot read the users folder %s: %s", self.dir, exc.strerror)
                names = []
            for name in names:
                if not USER_NAME.match(name) or name.endswith(".tmp"):
                    continue
                path = self.dir / name
                try:
                    tokens[name] = read_token_file(path)
                except FileNotFoundError:
                    continue
                except TokenError as exc:
                    key = (name, str(exc))
                    if key not in self._warned:
                        self._warned.add(key)
                        log.warning("user %s is refused: %s", name, exc)
        by_token: dict[str, list[str]] = {}
        for name, tok in tokens.items():
            by_token.setdefault(tok, []).append(name)
        for tok, names in by_token.items():
            if len(names) > 1 or tok == self.operator_token:
                for name in names:
                    tokens.pop(name, None)
                key = ("dup", tuple(names))
                if key not in self._warned:
                    self._warned.add(key)
                    log.warning("users %s are refused: their token is not theirs alone (make "
                                "new ones: wideprint users add NAME --replace)", ", ".join(names))
        for tok in set(self._tokens.values()) - set(tokens.values()):
            forget_secret(tok)
        for tok in tokens.values():
            add_secret(tok)
        self._tokens = tokens

    def lookup(self, token: str) -> str | None:
        """The user whose token this is (constant time for each token compared)."""
        with self._lock:
            self._scan()
            found = None
            for name, tok in self._tokens.items():
                if hmac.compare_digest(token.encode(), tok.encode()):
                    found = name
            return found

    def names(self) -> list[str]:
        with self._lock:
            self._scan()
            return sorted(self._tokens)


# -- job owners ---------------------------------------------------------------------------------
OWNERS_TABLE = ("CREATE TABLE IF NOT EXISTS job_owners (job_id INTEGER PRIMARY KEY, "
                "owner TEXT NOT NULL)")


class Owners:
    """Who each job belongs to: the table `job_owners` in the server's database (the same
    file as the queue, so the two are lost, restored or rebuilt together)."""

    def __init__(self, spool):
        self.spool = spool
        self._ready = False

    def _table(self) -> None:
        if not self._ready:
            with self.spool.tx() as c:
                c.execute(OWNERS_TABLE)
            self._ready = True

    def set(self, job_id: int, owner: str | None) -> None:
        if owner is None:
            return
        self._table()
        with self.spool.tx() as c:
            c.execute("INSERT OR REPLACE INTO job_owners (job_id, owner) VALUES (?, ?)",
                      (job_id, owner))

    def _read(self, sql: str, args: tuple) -> list:
        """A read that never writes: no table yet (no owner recorded) is no rows."""
        try:
            return self.spool.db.execute(sql, args).fetchall()
        except sqlite3.OperationalError as exc:
            if "no such table" in str(exc):
                return []
            raise

    def get(self, job_id: int) -> str | None:
        rows = self._read("SELECT owner FROM job_owners WHERE job_id=?", (job_id,))
        return rows[0][0] if rows else None

    def of(self, jobs: list[dict]) -> dict[int, str]:
        """The owners of these jobs (those that have one)."""
        if not jobs:
            return {}
        ids = [j["id"] for j in jobs]
        rows = self._read("SELECT job_id, owner FROM job_owners WHERE job_id BETWEEN ? AND ?",
                          (min(ids), max(ids)))
        wanted = set(ids)
        return {r[0]: r[1] for r in rows if r[0] in wanted}


def may_act(who: Identity, owner: str | None) -> bool:
    """Whether `who` may cancel, hold, release, requeue, move or edit a job of `owner`."""
    return who.operator or (owner is not None and who.name == owner)


# -- the operator's commands (`wideprint users ...`: straight on the state directory) ----------
def add_user(state_dir: str | os.PathLike, name: str, replace: bool = False) -> tuple[Path, str]:
    """Make user NAME's token, `STATE/users/NAME` (0600, written whole); FileExistsError if
    the user has one and not `replace`.  The running server takes it at its next request."""
    from .config import new_token, write_token_file
    check_user_name(name)
    d = Path(state_dir) / USERS_DIR
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    token = new_token()
    write_token_file(d / name, token, replace=replace)
    return d / name, token


def remove_user(state_dir: str | os.PathLike, name: str) -> bool:
    """User NAME's token deleted (False: there was none): refused from the next request."""
    check_user_name(name)
    try:
        os.unlink(Path(state_dir) / USERS_DIR / name)
    except FileNotFoundError:
        return False
    return True


def list_users(state_dir: str | os.PathLike) -> list[str]:
    d = Path(state_dir) / USERS_DIR
    try:
        return sorted(n for n in os.listdir(d) if USER_NAME.match(n) and not n.endswith(".tmp"))
    except FileNotFoundError:
        return []
