"""The state directory checked, and the queue rebuilt from the spool (docs/server.md "The
state directory: checked at start, `serve --check`").

The database is the queue's truth, the spool its files.  A database lost or damaged beside
a spool that still holds jobs' files is never "cleaned" (that would delete the shop's
work): the server refuses to start and says so, and `wideprint serve --check` reports
what it finds and, with `--repair` (the operator's consent), moves the damaged database
aside and queues every spooled file again, held, from the description written beside it
when it was queued (`UUID.ext.job.json`).
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import time
from pathlib import Path

DB_NAME = "wideprint.db"
INFO_DIR = "spool-info"        # spool/UUID.ext -> spool-info/UUID.ext.json
# what a job's description keeps (Spool.add_job's keywords), enough to queue it again
DESCRIPTION = ("name", "source", "client", "preset", "settings", "copies", "priority", "key",
               "printer", "hot_path", "size", "sha256")


class StateError(ValueError):
    """The state directory cannot be used as it is; the message says why and what to do."""


# -- the description beside each spool copy --------------------------------------------------
def sidecar(spool_path: str | os.PathLike) -> Path:
    """Where a spool copy's description is: beside the spool folder, so that spool/ holds
    the jobs' files only."""
    p = Path(spool_path)
    return p.parent.parent / INFO_DIR / f"{p.name}.json"


def write_description(spool_path: str | os.PathLike, fields: dict) -> None:
    """The job's description beside its spool copy, durable before the job row commits
    (written aside, fsync'd, renamed)."""
    d = {k: fields.get(k) for k in DESCRIPTION}
    d["submitted"] = time.time()
    path = sidecar(spool_path)
    path.parent.mkdir(mode=0o700, exist_ok=True)
    tmp = path.with_name(f".{path.name}.part")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(d, f, sort_keys=True)
        f.flush()
        os.fsync(f.fileno())
    os.rename(tmp, path)


def remove_copy(spool_path: str | os.PathLike) -> None:
    """A spool copy and its description go together."""
    for p in (Path(spool_path), sidecar(spool_path)):
        try:
            p.unlink()
        except FileNotFoundError:
            pass


def spool_files(spool_dir: Path) -> list[Path]:
    """The jobs' files in the spool (not descriptions, not partial writes)."""
    if not spool_dir.is_dir():
        return []
    return sorted(p for p in spool_dir.iterdir() if p.is_file() and not p.name.startswith("."))


# -- the database --------------------------------------------------------------------------------
def database_problem(state_dir: Path) -> str:
    """'' when the database is usable (or absent with an empty spool: a first start);
    otherwise what is wrong with it, in words naming the file."""
    db = Path(state_dir) / DB_NAME
    files = spool_files(Path(state_dir) / "spool")
    if not db.exists() or db.stat().st_size == 0:
        if not files:
            return ""
        what = "missing" if not db.exists() else "empty (0 bytes)"
        return (f"{db} is {what}, but {db.parent / 'spool'} holds {len(files)} job file(s): "
                f"the queue was lost")
    try:
        c = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30)
        try:
            rows = c.execute("PRAGMA quick_check").fetchall()
            tables = {r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        finally:
            c.close()
    except sqlite3.DatabaseError as exc:
        return f"{db} is not a usable database ({exc})"
    if [r[0] for r in rows] != ["ok"]:
        return f"{db} is damaged ({'; '.join(str(r[0]) for r in rows[:3])})"
    if "jobs" not in tables and files:
        return (f"{db} has no jobs table, but {db.parent / 'spool'} holds {len(files)} job "
                f"file(s): the queue was lost")
    return ""


def check_at_start(state_dir: Path) -> None:
    """Refuse to start on a lost or damaged queue (never clean the spool then)."""
    problem = database_problem(state_dir)
    if problem:
        raise StateError(f"{problem}. Nothing was changed. Run `wideprint serve --check "
                         f"--state-dir {state_dir}` to see what the spool holds, and add "
                         f"--repair to queue it again (held), or restore the database from a "
                         f"backup")


# -- serve --check ------------------------------------------------------------------------------
def file_digest(path: str | os.PathLike) -> str:
    """A spool copy's SHA-256, read a MiB at a time (the digest taken when it was queued)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def check(state_dir: Path) -> dict:
    """What the state directory holds: the database's problem (''), the jobs whose spool
    copy is missing or damaged, the spool files no job owns, with or without a
    description.  Reads only."""
    state_dir = Path(state_dir)
    spool_dir = state_dir / "spool"
    problem = database_problem(state_dir)
    out = dict(state_dir=str(state_dir), database=problem or "ok", jobs=0, active=0,
               missing=[], damaged=[], orphans=[], undescribed=[])
    used: set[str] = set()
    if not problem and (state_dir / DB_NAME).exists() and (state_dir / DB_NAME).stat().st_size:
        c = sqlite3.connect(f"file:{state_dir / DB_NAME}?mode=ro", uri=True, timeout=30)
        c.row_factory = sqlite3.Row
        try:
            try:
                rows = c.execute("SELECT id, name, state, spool_path, size, sha256 FROM jobs").fetchall()
            except sqlite3.OperationalError:
                rows = []
        finally:
            c.close()
        out["jobs"] = len(rows)
        for r in rows:
            if r["spool_path"]:
                used.add(r["spool_path"])
            if r["state"] not in ("queued", "held", "printing") or not r["spool_path"]:
                continue
            out["active"] += 1
            p = Path(r["spool_path"])
            if not p.exists():
                out["missing"].append(dict(id=r["id"], name=r["name"], path=str(p)))
            elif p.stat().st_size != r["size"] or file_digest(p) != r["sha256"]:
                out["damaged"].append(dict(id=r["id"], name=r["name"], path=str(p)))
    for p in spool_files(spool_dir):
        if str(p) in used:
            continue
        desc = _description(p)
        (out["orphans"] if desc is not None else out["undescribed"]).append(
            dict(path=str(p), name=(desc or {}).get("name"), size=p.stat().st_size))
    out["ok"] = not (problem or out["missing"] or out["damaged"])
    return out


def _description(path: Path) -> dict | None:
    try:
        d = json.loads(sidecar(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) and d.get("name") else None


def repair(state_dir: Path) -> dict:
    """With the operator's consent: a lost or damaged database is moved aside (never
    deleted) and a new one made; every spooled file with a description whose SHA-256
    still matches is queued again, held for the operator to look at and release.  A
    healthy database is left alone.  Returns the check before, plus `rebuilt` (job ids),
    `set_aside` (the old database's new name) and `skipped` (files not queued, why)."""
    from .spool import Spool
    state_dir = Path(state_dir)
    before = check(state_dir)
    result = dict(before, rebuilt=[], set_aside=None, skipped=[])
    if before["database"] == "ok":
        return result
    stamp = time.strftime("%Y%m%dT%H%M%S")
    db = state_dir / DB_NAME
    for suffix in ("", "-wal", "-shm"):
        p = Path(str(db) + suffix)
        if p.exists():
            aside = Path(f"{db}.lost-{stamp}{suffix}")
            os.rename(p, aside)
            if not suffix:
                result["set_aside"] = str(aside)
    sp = Spool(state_dir)
    try:
        for item in before["orphans"] + before["undescribed"]:
            p = Path(item["path"])
            desc = _description(p)
            if desc is None:
                result["skipped"].append(dict(path=str(p), why="no description beside it "
                                              "(spooled by an older version): submit it again"))
                continue
            if p.stat().st_size != desc.get("size") or file_digest(p) != desc.get("sha256"):
                result["skipped"].append(dict(path=str(p), why="its content is not the one "
                                              "queued (SHA-256 differs)"))
                continue
            fields = {k: desc.get(k) for k in ("name", "source", "client", "preset", "copies",
                                               "priority", "key", "printer")}
            fields["settings"] = desc.get("settings") or {}
            fields["copies"] = fields["copies"] or 1
            fields["priority"] = fields["priority"] or 0
            fields["source"] = fields["source"] or "api"
            job, _ = sp.add_job(spool_path=str(p), size=desc["size"], sha256=desc["sha256"],
                                hold=True, **fields)
            with sp.tx() as c:
                c.execute("UPDATE jobs SET message=? WHERE id=?",
                          ("rebuilt from the spool by `serve --check --repair` (its earlier "
                           "state and accounting were lost with the database): look at it and "
                           "release it", job["id"]))
            result["rebuilt"].append(job["id"])
    finally:
        sp.close()
    return result
