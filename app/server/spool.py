"""The print server's persistent queue (docs/server.md): jobs, their settings, state and
checkpoint, and the accounting of every print, in one SQLite database (WAL) in the state
directory; each queued job keeps a private copy of its file in `spool/` (failed and
cancelled jobs keep theirs for a while, so the operator can requeue them).

Every thread uses its own connection (`Spool.db`); state transitions run in
`BEGIN IMMEDIATE` transactions so two threads never both take the same job.  The database
is written with `synchronous=FULL`: a job whose submission was answered survives a crash
of the server and a power cut.
"""

from __future__ import annotations

import json
import os
import sqlite3
import threading
import time
from contextlib import contextmanager
from pathlib import Path

STATES = ("queued", "held", "printing", "done", "failed", "cancelled")
ACTIVE = ("queued", "held", "printing")
FINAL = ("done", "failed", "cancelled")
COLORS = ("c", "m", "y", "k")

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS jobs (
    id           INTEGER PRIMARY KEY AUTOINCREMENT,
    key          TEXT UNIQUE,                 -- client's idempotency key (retries are one job)
    name         TEXT NOT NULL,               -- file name as submitted (a plain name)
    source       TEXT NOT NULL,               -- api, hot:PRESET, cups
    client       TEXT,                        -- free client tag (user, host, CUPS user)
    spool_path   TEXT,                        -- the private copy (NULL once deleted)
    size         INTEGER NOT NULL,
    sha256       TEXT NOT NULL,
    preset       TEXT,
    settings     TEXT NOT NULL,               -- JSON: the effective RipSettings fields
    copies       INTEGER NOT NULL DEFAULT 1,
    copies_done  INTEGER NOT NULL DEFAULT 0,
    priority     INTEGER NOT NULL DEFAULT 0,  -- higher first
    state        TEXT NOT NULL CHECK (state IN ('queued','held','printing','done','failed','cancelled')),
    interrupted  INTEGER NOT NULL DEFAULT 0,  -- 1: it was printing when the server stopped
    message      TEXT NOT NULL DEFAULT '',
    hot_path     TEXT,                        -- hot-folder original, moved to done/ or failed/
    submitted    REAL NOT NULL,
    started      REAL,
    finished     REAL,
    copy_started REAL,                        -- start of the copy now printing
    strokes_total INTEGER NOT NULL DEFAULT 0, -- carriage strokes of the copy printing
    strokes_done INTEGER NOT NULL DEFAULT 0,
    checkpoint   TEXT,                        -- JSON: x0, paper0, next_stroke, epoch, copy
    attempt      INTEGER NOT NULL DEFAULT 1,  -- 1, then +1 each time the operator requeues it
    printer      TEXT,                        -- the printer asked for (NULL: any printer)
    printed_on   TEXT,                        -- the printer that took it (its checkpoint is that printer's)
    fault        TEXT NOT NULL DEFAULT '',    -- a printer fault stopped it: held until cleared
    nest_members TEXT,                        -- JSON [ids]: the jobs nested on this job's sheet
    nested_in    INTEGER,                     -- printed on that job's sheet (a nest member)
    force        INTEGER NOT NULL DEFAULT 0,  -- 1: the operator overrode the fit checks
    reprint_of   INTEGER,                     -- the archived job this one reprints
    rip_hold     INTEGER NOT NULL DEFAULT 0,  -- 1: RIP it while held (ripped.py)
    ripped       TEXT,                        -- JSON: its kept planes (path, key, size ...)
    spots        TEXT                         -- JSON: its spot colours as ripped (docs/spot.md)
);
CREATE INDEX IF NOT EXISTS jobs_queue ON jobs (state, interrupted, priority, id);
CREATE TABLE IF NOT EXISTS prints (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id         INTEGER NOT NULL REFERENCES jobs (id),
    copy           INTEGER NOT NULL,          -- 1-based
    file           TEXT NOT NULL,
    source         TEXT NOT NULL,
    preset         TEXT,
    settings       TEXT NOT NULL,
    started        REAL NOT NULL,
    ended          REAL NOT NULL,
    duration_s     REAL NOT NULL,
    strokes_total  INTEGER NOT NULL,
    strokes_printed INTEGER NOT NULL,
    drops_c INTEGER NOT NULL, drops_m INTEGER NOT NULL,
    drops_y INTEGER NOT NULL, drops_k INTEGER NOT NULL,
    ink_c_ml REAL NOT NULL, ink_m_ml REAL NOT NULL,
    ink_y_ml REAL NOT NULL, ink_k_ml REAL NOT NULL,
    width_dots     INTEGER NOT NULL,
    height_rows    INTEGER NOT NULL,
    area_m2        REAL NOT NULL,
    outcome        TEXT NOT NULL,             -- done, failed, cancelled, stopped, interrupted
    message        TEXT NOT NULL DEFAULT '',
    resumed        INTEGER NOT NULL DEFAULT 0,-- 1: finished after a server restart
    recoveries     INTEGER NOT NULL DEFAULT 0,
    retries        INTEGER NOT NULL DEFAULT 0,
    attempt        INTEGER NOT NULL DEFAULT 1,-- the job's attempt this copy belongs to
    printer        TEXT,                      -- the printer it printed on
    media          TEXT,                      -- the roll loaded on it then (rolls.py)
    paper_mm       REAL NOT NULL DEFAULT 0,   -- paper fed by the copy (taken off the roll)
    spots          TEXT                       -- JSON: the job's spot colours, as printed
);
CREATE INDEX IF NOT EXISTS prints_job ON prints (job_id);
CREATE TABLE IF NOT EXISTS rolls (
    printer        TEXT PRIMARY KEY,          -- the roll loaded on this printer (rolls.py)
    media          TEXT NOT NULL,             -- a media library name (app/medialib.py)
    width_mm       REAL,                      -- from the paper sensor (NULL: not measured yet)
    length_mm      REAL,                      -- as loaded (entered or from its label), NULL: unknown
    remaining_mm   REAL,                      -- length less every feed since (NULL: unknown)
    loaded         REAL NOT NULL,
    label          TEXT NOT NULL DEFAULT '',
    spare_mm       REAL                       -- the warning's spare (NULL: 1 m, rolls.py)
);
"""

SCHEMA_VERSION = "6"
# columns added since schema 1: (table, column, definition), added to older databases;
# schema 4: several printers (printer, printed_on), a fault stops a job (fault); schema 5:
# the server nests jobs on one sheet (nest_members on the sheet's job, nested_in on the others);
# schema 6: fit override and reprints (force, reprint_of), rolls (the rolls table; a print's
# printer, media and paper fed)
ADDED_COLUMNS = (("jobs", "attempt", "INTEGER NOT NULL DEFAULT 1"),
                 ("prints", "attempt", "INTEGER NOT NULL DEFAULT 1"),
                 ("jobs", "printer", "TEXT"),
                 ("jobs", "printed_on", "TEXT"),
                 ("jobs", "fault", "TEXT NOT NULL DEFAULT ''"),
                 ("jobs", "nest_members", "TEXT"),
                 ("jobs", "nested_in", "INTEGER"),
                 ("jobs", "force", "INTEGER NOT NULL DEFAULT 0"),
                 ("jobs", "reprint_of", "INTEGER"),
                 ("prints", "printer", "TEXT"),
                 ("prints", "media", "TEXT"),
                 ("prints", "paper_mm", "REAL NOT NULL DEFAULT 0"),
                 ("jobs", "rip_hold", "INTEGER NOT NULL DEFAULT 0"),
                 ("jobs", "ripped", "TEXT"),
                 ("jobs", "spots", "TEXT"),
                 ("prints", "spots", "TEXT"),
                 ("rolls", "spare_mm", "REAL"))
# columns renamed since: (table, old name, new name), renamed in older databases.  Schema 3:
# carriage movements are strokes; a pass is the weave's (docs/architecture.md, "Words")
RENAMED_COLUMNS = (("jobs", "passes_total", "strokes_total"),
                   ("jobs", "passes_done", "strokes_done"),
                   ("prints", "passes_total", "strokes_total"),
                   ("prints", "passes_printed", "strokes_printed"))


def disk_full(exc: BaseException) -> bool:
    """Whether an error is the state directory's disk (or quota) being full: SQLite's
    SQLITE_FULL, or ENOSPC/EDQUOT from a write.  Never a job's fault: the worker waits for
    space (docs/server.md "Full disks"), the API answers 507."""
    import errno
    if isinstance(exc, sqlite3.OperationalError):
        return "full" in str(exc).lower()
    return isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)


class SpoolError(Exception):
    """A request the queue refuses (the message says why); `status` is the HTTP code."""

    def __init__(self, message: str, status: int = 409):
        super().__init__(message)
        self.status = status


def _job_dict(row: sqlite3.Row) -> dict:
    d = dict(row)
    d["settings"] = json.loads(d["settings"])
    cp = d.pop("checkpoint")
    d["checkpoint"] = cp = json.loads(cp) if cp else None
    if cp is not None and "next_pass" in cp and "next_stroke" not in cp:
        cp["next_stroke"] = cp.pop("next_pass")      # saved by schema 2: the same number
    d["interrupted"] = bool(d["interrupted"])
    if d.get("ripped"):
        d["ripped"] = json.loads(d["ripped"])
    d["spots"] = json.loads(d["spots"]) if d.get("spots") else None
    return d


class Spool:
    def __init__(self, state_dir: str | os.PathLike):
        self.state_dir = Path(state_dir)
        self.state_dir.mkdir(parents=True, exist_ok=True)
        self.spool_dir = self.state_dir / "spool"
        self.spool_dir.mkdir(exist_ok=True)
        self.path = self.state_dir / "wideprint.db"
        self._local = threading.local()
        db = self.db
        db.execute("PRAGMA journal_mode=WAL")
        with self.tx() as c:
            for stmt in SCHEMA.split(";"):
                if stmt.strip():
                    c.execute(stmt)
            for table, column, definition in ADDED_COLUMNS:
                have = {r[1] for r in c.execute(f"PRAGMA table_info({table})")}
                if column not in have:
                    c.execute(f"ALTER TABLE {table} ADD COLUMN {column} {definition}")
            for table, old, new in RENAMED_COLUMNS:
                have = {r[1] for r in c.execute(f"PRAGMA table_info({table})")}
                if old in have and new not in have:
                    c.execute(f"ALTER TABLE {table} RENAME COLUMN {old} TO {new}")
            c.execute("INSERT OR REPLACE INTO meta VALUES ('schema', ?)", (SCHEMA_VERSION,))
            c.execute("INSERT OR IGNORE INTO meta VALUES ('printer_epoch', '0')")

    # -- connections and transactions ---------------------------------------------------
    @property
    def db(self) -> sqlite3.Connection:
        c = getattr(self._local, "conn", None)
        if c is None:
            c = sqlite3.connect(self.path, timeout=30, isolation_level=None,
                                check_same_thread=True)
            c.row_factory = sqlite3.Row
            c.execute("PRAGMA busy_timeout=30000")
            c.execute("PRAGMA synchronous=FULL")
            c.execute("PRAGMA foreign_keys=ON")
            self._local.conn = c
        return c

    @contextmanager
    def tx(self):
        """One write transaction (BEGIN IMMEDIATE: the write lock is taken at once)."""
        c = self.db
        c.execute("BEGIN IMMEDIATE")
        try:
            yield c
        except BaseException:
            c.execute("ROLLBACK")
            raise
        c.execute("COMMIT")

    def close(self) -> None:
        c = getattr(self._local, "conn", None)
        if c is not None:
            c.close()
            self._local.conn = None

    # -- meta ---------------------------------------------------------------------------
    @staticmethod
    def _epoch_key(printer: str | None) -> str:
        # the first printer keeps the key of the one-printer schema (its checkpoints stay valid)
        return "printer_epoch" if printer in (None, "", "main") else f"printer_epoch:{printer}"

    def _epoch(self, c, printer: str | None) -> int:
        key = self._epoch_key(printer)
        c.execute("INSERT OR IGNORE INTO meta VALUES (?, '0')", (key,))
        return int(c.execute("SELECT value FROM meta WHERE key=?", (key,)).fetchone()[0])

    def _bump_epoch(self, c, printer: str | None) -> int:
        epoch = self._epoch(c, printer) + 1
        c.execute("UPDATE meta SET value=? WHERE key=?", (str(epoch), self._epoch_key(printer)))
        return epoch

    def epoch(self, printer: str | None = None) -> int:
        """A printer's epoch: bumped whenever a job starts afresh on that printer; a
        checkpoint from an older epoch is stale (something else printed there since)."""
        with self.tx() as c:
            return self._epoch(c, printer)

    # -- jobs -----------------------------------------------------------------------------
    def add_job(self, *, name: str, source: str, spool_path: str, size: int, sha256: str,
                settings: dict, preset: str | None = None, copies: int = 1, priority: int = 0,
                hold: bool = False, key: str | None = None, client: str | None = None,
                hot_path: str | None = None, printer: str | None = None, force: int = 0,
                reprint_of: int | None = None, rip_hold: int = 0) -> tuple[dict, bool]:
        """Queue a job; returns (job, created).  With a key already used the existing job
        is returned (created False): a client's retry never makes a second job.  force: the
        operator overrode the fit checks (docs/server.md "Fit before it fails");
        reprint_of: the archived job this one prints again ("Archive and reprint")."""
        with self.tx() as c:
            if key is not None:
                row = c.execute("SELECT * FROM jobs WHERE key=?", (key,)).fetchone()
                if row is not None:
                    return _job_dict(row), False
            cur = c.execute(
                "INSERT INTO jobs (key, name, source, client, spool_path, size, sha256, preset,"
                " settings, copies, priority, state, hot_path, submitted, printer, force,"
                " reprint_of, rip_hold) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                (key, name, source, client, spool_path, size, sha256, preset,
                 json.dumps(settings, sort_keys=True), copies, priority,
                 "held" if hold or rip_hold else "queued", hot_path, time.time(), printer,
                 int(force), reprint_of, int(bool(rip_hold))))
            row = c.execute("SELECT * FROM jobs WHERE id=?", (cur.lastrowid,)).fetchone()
        return _job_dict(row), True

    def get(self, job_id: int) -> dict | None:
        row = self.db.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone()
        return _job_dict(row) if row else None

    def jobs(self, states: tuple[str, ...] | None = None, limit: int | None = None,
             after: int = 0, newest: bool = False) -> list[dict]:
        """Jobs in id order; newest: the last `limit` of them, newest first (the history)."""
        q, args = "SELECT * FROM jobs WHERE id > ?", [after]
        if states:
            q += f" AND state IN ({','.join('?' * len(states))})"
            args += list(states)
        q += " ORDER BY id DESC" if newest else " ORDER BY id"
        if limit:
            q += " LIMIT ?"
            args.append(limit)
        return [_job_dict(r) for r in self.db.execute(q, args)]

    def ended_mark(self) -> dict:
        """What changes whenever a job ends (or an ended one is deleted): the number of ended
        jobs and the newest end.  The event stream sends it as `ended`, so a front end's
        history follows even a job that came and went between two samples of `jobs`."""
        n, last, newest = self.db.execute(
            f"SELECT COUNT(*), MAX(finished), MAX(id) FROM jobs WHERE state IN "
            f"({','.join('?' * len(FINAL))})", FINAL).fetchone()
        return {"count": n, "finished": last, "last_id": newest}

    def counts(self) -> dict:
        out = {s: 0 for s in STATES}
        for state, n in self.db.execute("SELECT state, COUNT(*) FROM jobs GROUP BY state"):
            out[state] = n
        return out

    QUEUE_ORDER = "ORDER BY interrupted DESC, priority DESC, id ASC"

    def next_jobs(self, printer: str, limit: int = 16) -> list[dict]:
        """The first `limit` jobs `printer` may print, in the order next_job takes them (the
        worker skips "any" jobs its paper cannot hold: docs/server.md, "Several printers")."""
        rows = self.db.execute(
            "SELECT * FROM jobs WHERE state='queued' AND nested_in IS NULL "
            "AND (printer IS NULL OR printer=?) "
            "AND (interrupted=0 OR printed_on IS NULL OR printed_on=?) "
            f"{self.QUEUE_ORDER} LIMIT ?", (printer, printer, limit)).fetchall()
        return [_job_dict(r) for r in rows]

    def next_job(self, printer: str | None = None) -> dict | None:
        """The job a printer's worker prints next: one that printer was interrupted in
        first (the paper is in the middle of it), then by priority, then in submission order,
        among the jobs for this printer or for any; held jobs wait.  A job interrupted on
        another printer waits for that one (its checkpoint is that printer's)."""
        if printer is None:
            row = self.db.execute("SELECT * FROM jobs WHERE state='queued' AND nested_in IS NULL "
                                  f"{self.QUEUE_ORDER} LIMIT 1"
                                  ).fetchone()
            return _job_dict(row) if row else None
        jobs = self.next_jobs(printer, 1)
        return jobs[0] if jobs else None

    def queue_position(self) -> dict[int, int]:
        rows = self.db.execute("SELECT id FROM jobs WHERE state='queued' AND nested_in IS NULL "
                               f"{self.QUEUE_ORDER}")
        return {r[0]: i + 1 for i, r in enumerate(rows)}

    def claim(self, job_id: int, printer: str | None = None) -> dict | None:
        """queued -> printing on `printer`, for its worker.  Resumes an interrupted job whose
        checkpoint is still valid there (the same printer, nothing printed since);
        otherwise the job starts afresh and that printer's epoch moves on."""
        now = time.time()
        with self.tx() as c:
            row = c.execute("SELECT * FROM jobs WHERE id=? AND state='queued'", (job_id,)).fetchone()
            if row is None:
                return None
            job = _job_dict(row)
            epoch = self._epoch(c, printer)
            cp = job["checkpoint"]
            if cp is not None and (cp.get("epoch") != epoch or
                                   (job["printed_on"] or None) not in (None, printer)):
                cp = None                    # something else printed since: start over
            if cp is None:
                epoch = self._bump_epoch(c, printer)
                c.execute("UPDATE jobs SET checkpoint=NULL, strokes_done=0, copy_started=? "
                          "WHERE id=?", (now, job_id))
            c.execute("UPDATE jobs SET state='printing', started=COALESCE(started, ?), "
                      "copy_started=COALESCE(copy_started, ?), message='', printed_on=?, "
                      "fault='' WHERE id=?", (now, now, printer, job_id))
            row = c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone()
        job = _job_dict(row)
        job["epoch"] = epoch
        return job

    def nest(self, leader: int, members: list[int]) -> bool:
        """The queued jobs `members` go on job `leader`'s sheet (docs/server.md, "Nesting
        jobs"): the leader is claimed as usual; the members leave the queue, printing with
        it.  False when one of them is no longer queued (taken, cancelled, held)."""
        if not members:
            return True
        with self.tx() as c:
            marks = ",".join("?" * len(members))
            n = c.execute(f"SELECT COUNT(*) FROM jobs WHERE id IN ({marks}) AND state='queued' "
                          "AND nested_in IS NULL", members).fetchone()[0]
            if n != len(members):
                return False
            c.execute(f"UPDATE jobs SET state='printing', nested_in=?, started=?, "
                      f"message=? WHERE id IN ({marks})",
                      (leader, time.time(), f"nested on job {leader}'s sheet", *members))
            c.execute("UPDATE jobs SET nest_members=? WHERE id=?", (json.dumps(members), leader))
        return True

    def members(self, leader: dict) -> list[dict]:
        ids = json.loads(leader.get("nest_members") or "[]")
        return [j for j in (self.get(i) for i in ids) if j is not None]

    def save_checkpoint(self, job_id: int, checkpoint: dict, strokes_total: int) -> None:
        """After every stroke: where a restarted server resumes this job."""
        with self.tx() as c:
            c.execute("UPDATE jobs SET checkpoint=?, strokes_done=?, strokes_total=? WHERE id=?",
                      (json.dumps(checkpoint, sort_keys=True),
                       int(checkpoint.get("next_stroke", 0)), strokes_total, job_id))

    def copy_done(self, job_id: int, row: dict | None = None) -> dict:
        """One copy printed: its accounting row and the count in one transaction (a crash
        can leave neither or both: never a copy counted and printed again, docs/server.md
        "Crash recovery"); the next copy starts afresh."""
        with self.tx() as c:
            self._add_print(c, row)
            c.execute("UPDATE jobs SET copies_done=copies_done+1, checkpoint=NULL, "
                      "copy_started=NULL, interrupted=0 WHERE id=?", (job_id,))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def restart(self, job_id: int, message: str, row: dict | None, hold: bool) -> dict:
        """The printer could not confirm the job's checkpoint (docs/protocol.md 2.10): the
        copy's strokes on the sheet are accounted (`row`, outcome `interrupted`) and the
        job starts again from its first stroke — held for the operator, or queued at the
        head of the queue (`--on-crash reprint`); one transaction."""
        with self.tx() as c:
            self._add_print(c, row)
            c.execute("UPDATE jobs SET state=?, interrupted=?, checkpoint=NULL, strokes_done=0, "
                      "copy_started=NULL, message=? WHERE id=? AND state='printing'",
                      ("held" if hold else "queued", 0 if hold else 1, message, job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def start_copy(self, job_id: int) -> None:
        """A later copy starts: a fresh placement on the printer (new epoch)."""
        now = time.time()
        with self.tx() as c:
            row = c.execute("SELECT printed_on FROM jobs WHERE id=?", (job_id,)).fetchone()
            self._bump_epoch(c, row[0] if row else None)
            c.execute("UPDATE jobs SET copy_started=?, strokes_done=0 WHERE id=?", (now, job_id))

    def stop_for_fault(self, job_id: int, message: str, row: dict | None = None) -> dict:
        """A printer fault stopped the job: it is held, with its checkpoint and the fault,
        until the operator clears the fault (resume: back to the queue, where it goes on at
        its first unfinished stroke; or fail it).  docs/server.md, "Printer faults"."""
        with self.tx() as c:
            self._add_print(c, row)
            c.execute("UPDATE jobs SET state='held', interrupted=1, fault=?, message=? "
                      "WHERE id=? AND state='printing'", (message, message, job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def fault_stopped(self, printer: str | None) -> list[dict]:
        """The jobs a fault of `printer` stopped (normally one)."""
        rows = self.db.execute("SELECT * FROM jobs WHERE state='held' AND fault != '' AND "
                               "(printed_on IS ? OR printed_on = ?) ORDER BY id",
                               (printer, printer)).fetchall()
        return [_job_dict(r) for r in rows]

    def resume_after_fault(self, job_id: int) -> dict:
        """The fault is cleared: the stopped job goes back to the head of its printer's
        queue (interrupted), its checkpoint kept."""
        with self.tx() as c:
            c.execute("UPDATE jobs SET state='queued', fault='', message='' WHERE id=? AND "
                      "state='held' AND fault != ''", (job_id,))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def set_printer(self, job_id: int, printer: str | None) -> dict:
        """Move a job that has not started to another printer (None: any)."""
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            if job["state"] not in ("queued", "held") or job["interrupted"]:
                raise SpoolError(f"job {job_id} is {job['state']}"
                                 + (" part-way" if job["interrupted"] else "")
                                 + ": only a job not yet started can move to another printer")
            c.execute("UPDATE jobs SET printer=? WHERE id=?", (printer, job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def finish(self, job_id: int, state: str, message: str = "", keep_copy: bool = False,
               row: dict | None = None, copy_done: bool = False,
               members: dict[int, str] | None = None) -> dict:
        """The job ended, in one transaction with what ends with it: its last copy's
        accounting `row` (and, `copy_done`, that copy counted), and the jobs nested on its
        sheet (`members`: id -> message), which end in the same state.  keep_copy: the
        spool copies stay (a failed or cancelled job the operator may requeue); otherwise
        the caller deletes the files once this has committed."""
        assert state in FINAL
        now = time.time()
        with self.tx() as c:
            self._add_print(c, row)
            if copy_done:
                c.execute("UPDATE jobs SET copies_done=copies_done+1 WHERE id=?", (job_id,))
            for mid, msg in (members or {}).items():
                c.execute("UPDATE jobs SET state=?, message=?, finished=?, interrupted=0, "
                          "fault='', checkpoint=NULL, spool_path=CASE WHEN ? THEN spool_path "
                          "END WHERE id=? AND state NOT IN ('done','failed','cancelled')",
                          (state, msg, now, int(keep_copy), mid))
            c.execute("UPDATE jobs SET state=?, message=?, finished=?, interrupted=0, fault='', "
                      "checkpoint=NULL, copy_started=NULL, "
                      "spool_path=CASE WHEN ? THEN spool_path END WHERE id=?",
                      (state, message, now, int(keep_copy), job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def wait_for_printer(self, job_id: int, message: str) -> None:
        """The printer could not be reached: the job waits at the head of the queue with
        its checkpoint (the printer keeps its state), as after a crash."""
        with self.tx() as c:
            c.execute("UPDATE jobs SET state='queued', interrupted=1, message=? "
                      "WHERE id=? AND state='printing'", (message, job_id))

    def hold(self, job_id: int) -> dict:
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            if job["state"] == "held":
                return job
            if job["state"] != "queued":
                raise SpoolError(f"job {job_id} is {job['state']}: only a queued job can be held")
            c.execute("UPDATE jobs SET state='held' WHERE id=?", (job_id,))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def hold_for_roll(self, job_id: int, message: str) -> dict | None:
        """The loaded roll cannot hold the job (docs/server.md "Rolls"): queued -> held with
        the reason, before a stroke of it is printed; None when it is no longer queued."""
        with self.tx() as c:
            n = c.execute("UPDATE jobs SET state='held', message=? WHERE id=? AND "
                          "state='queued' AND interrupted=0", (message, job_id)).rowcount
            if not n:
                return None
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def rip_hold(self, job_id: int) -> dict:
        """RIP and hold (docs/server.md "RIP and hold"): a job not yet started is held and
        marked to be ripped ahead; its planes are kept for its release."""
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            started = job["interrupted"] or job["checkpoint"] is not None or job["fault"]
            if job["state"] not in ("queued", "held") or started:
                raise SpoolError(f"job {job_id} is {job['state']}"
                                 + (" part-way" if started and job["state"] != "printing" else "")
                                 + ": only a job not yet started can be ripped and held")
            if job["nest_members"] or (job["settings"].get("placement") or {}).get("nest"):
                raise SpoolError(f"job {job_id} is nested with others: its sheet is ripped "
                                 f"when it prints")
            c.execute("UPDATE jobs SET state='held', rip_hold=1 WHERE id=?", (job_id,))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def rip_hold_jobs(self) -> list[dict]:
        """The held jobs to rip ahead (ripped.py's Ripper), oldest first."""
        rows = self.db.execute("SELECT * FROM jobs WHERE state='held' AND rip_hold=1 AND "
                               "fault='' AND spool_path IS NOT NULL AND nested_in IS NULL "
                               "ORDER BY id").fetchall()
        return [_job_dict(r) for r in rows]

    def set_ripped(self, job_id: int, info: dict, spots: list | None = None) -> dict | None:
        """A job's kept planes recorded, with the spot colours that RIP printed (`spots`,
        kept as they were when None): the ones they replace ({} if none), or None when
        the job is no longer waiting (the caller deletes the new planes)."""
        with self.tx() as c:
            row = c.execute("SELECT ripped FROM jobs WHERE id=? AND state IN ('queued','held')",
                            (job_id,)).fetchone()
            if row is None:
                return None
            c.execute("UPDATE jobs SET ripped=? WHERE id=?", (json.dumps(info), job_id))
            if spots is not None:
                c.execute("UPDATE jobs SET spots=? WHERE id=?", (json.dumps(spots), job_id))
            return json.loads(row[0]) if row[0] else {}

    def set_spots(self, job_id: int, spots: list, waiting_only: bool = False) -> None:
        """The spot colours a job's RIP resolved (docs/spot.md "The job's report"): each
        name, how it resolved, its recipe and ΔE2000; recorded once the worker has ripped
        it, before its first stroke, and replaced by every later RIP of it.  waiting_only:
        the estimate's, kept only while the job waits (queued or held)."""
        with self.tx() as c:
            c.execute("UPDATE jobs SET spots=? WHERE id=?" + (" AND state IN ('queued','held')"
                                                              if waiting_only else ""),
                      (json.dumps(spots), job_id))

    def release(self, job_id: int, force: bool = False) -> dict:
        """held -> queued; force: the operator overrides the fit checks for it (a roll that
        holds more than the server knows, a job meant to run over the edge)."""
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            if job["state"] == "queued":
                return job
            if job["state"] != "held":
                raise SpoolError(f"job {job_id} is {job['state']}: only a held job can be released")
            if job["fault"]:
                raise SpoolError(f"job {job_id} was stopped by a printer fault ({job['fault']}): "
                                 f"clear the fault on printer {job['printed_on'] or 'main'} "
                                 f"to resume it or fail it")
            c.execute("UPDATE jobs SET state='queued', force=MAX(force, ?) WHERE id=?",
                      (int(force), job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def edit(self, job_id: int, *, settings: dict | None = None, copies: int | None = None,
             priority: int | None = None) -> dict:
        """Change a job that has not started: its settings (the whole effective mapping),
        copies, priority (docs/server.md, "Editing a job").  A job stopped part-way keeps
        the settings its printed strokes were made with."""
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            started = job["interrupted"] or job["checkpoint"] is not None or job["fault"]
            if job["state"] not in ("queued", "held") or (started and settings is not None):
                raise SpoolError(f"job {job_id} is {job['state']}"
                                 + (" part-way" if started and job["state"] != "printing" else "")
                                 + ": only a job not yet started can be edited")
            if copies is not None and copies < job["copies_done"]:
                raise SpoolError(f"job {job_id} has printed {job['copies_done']} copies already")
            sets, args = [], []
            for col, v in (("settings", None if settings is None else json.dumps(settings)),
                           ("copies", copies), ("priority", priority)):
                if v is not None:
                    sets.append(f"{col}=?")
                    args.append(v)
            if sets:
                c.execute(f"UPDATE jobs SET {', '.join(sets)} WHERE id=?", (*args, job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def set_priority(self, job_id: int, priority: int) -> dict:
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            if job["state"] not in ("queued", "held"):
                raise SpoolError(f"job {job_id} is {job['state']}: its priority no longer matters")
            c.execute("UPDATE jobs SET priority=? WHERE id=?", (priority, job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def cancel_waiting(self, job_id: int, keep_copy: bool = False) -> dict | None:
        """Cancel a queued or held job at once; returns None when it is printing (the
        worker cancels it at the printer).  keep_copy as for `finish`."""
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            if job["state"] == "printing":
                return None
            if job["state"] in FINAL:
                raise SpoolError(f"job {job_id} is already {job['state']}")
            c.execute("UPDATE jobs SET state='cancelled', message='cancelled by the operator', "
                      "finished=?, interrupted=0, fault='', checkpoint=NULL, "
                      "spool_path=CASE WHEN ? THEN spool_path END WHERE id=?",
                      (time.time(), int(keep_copy), job_id))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def requeue(self, job_id: int) -> dict:
        """The operator puts a failed or cancelled job back in the queue (docs/server.md,
        "Requeue"): a fresh print of its spooled copy, from its first stroke, with the same
        settings, preset, copies and priority, as attempt N+1.  Its `prints` rows stay."""
        with self.tx() as c:
            job = self._get_for_change(c, job_id)
            if job["state"] not in ("failed", "cancelled"):
                hint = (f"; reprint it (wideprint reprint {job_id})" if job["state"] == "done"
                        else "")
                raise SpoolError(f"job {job_id} is {job['state']}: only a failed or cancelled "
                                 f"job can be requeued{hint}")
            path = job["spool_path"]
            if path is None:
                raise SpoolError(f"job {job_id}: its spooled file is gone (copies of failed and "
                                 f"cancelled jobs are deleted after the server's --keep-failed "
                                 f"time); submit the file again", 410)
            try:
                size = os.stat(path).st_size
            except FileNotFoundError:
                raise SpoolError(f"job {job_id}: its spooled file is gone ({path} was deleted); "
                                 f"submit the file again", 410) from None
            if size != job["size"]:
                raise SpoolError(f"job {job_id}: its spooled file is damaged ({size} bytes, "
                                 f"{job['size']} submitted); submit the file again")
            # hot_path: the original already went to failed/ with the first attempt's reason;
            # the new attempt moves no hot-folder file (a new file of that name is a new job)
            c.execute("UPDATE jobs SET state='queued', attempt=attempt+1, message='', "
                      "nested_in=NULL, nest_members=NULL, "
                      "copies_done=0, strokes_done=0, strokes_total=0, checkpoint=NULL, "
                      "interrupted=0, started=NULL, finished=NULL, copy_started=NULL, "
                      "hot_path=NULL WHERE id=?", (job_id,))
            return _job_dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())

    def expire_archive(self, before: float, max_bytes: int | None) -> list[str]:
        """The archive's retention (docs/server.md "Archive and reprint"): done jobs keep
        their spool copy until `before`, and only the newest that fit in `max_bytes`
        together; the others forget it (no reprint).  Returns the paths to delete."""
        with self.tx() as c:
            rows = c.execute("SELECT id, spool_path, size, finished FROM jobs WHERE state='done' "
                             "AND spool_path IS NOT NULL ORDER BY finished DESC, id DESC").fetchall()
            gone, total = [], 0
            for r in rows:                   # newest first: the oldest go when over size
                if r["finished"] is None or r["finished"] < before or \
                        (max_bytes is not None and total + int(r["size"]) > max_bytes):
                    gone.append(r)
                else:
                    total += int(r["size"])
            c.executemany("UPDATE jobs SET spool_path=NULL WHERE id=?", [(r[0],) for r in gone])
        return [r[1] for r in gone]

    def expire_copies(self, before: float) -> list[str]:
        """Forget the spool copies of jobs that failed or were cancelled before `before`
        (they can no longer be requeued); returns the paths for the caller to delete."""
        with self.tx() as c:
            rows = c.execute("SELECT id, spool_path FROM jobs WHERE state IN ('failed','cancelled') "
                             "AND spool_path IS NOT NULL AND finished < ?", (before,)).fetchall()
            c.executemany("UPDATE jobs SET spool_path=NULL WHERE id=?", [(r[0],) for r in rows])
        return [r[1] for r in rows]

    @staticmethod
    def _get_for_change(c, job_id: int) -> dict:
        row = c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone()
        if row is None:
            raise SpoolError(f"no job {job_id}", 404)
        job = _job_dict(row)
        if job.get("nested_in") and job["state"] not in FINAL:
            raise SpoolError(f"job {job_id} prints on job {job['nested_in']}'s nested sheet: "
                             f"act on job {job['nested_in']}")
        return job

    def recover(self, on_crash: str) -> list[dict]:
        """At start-up: jobs left `printing` by a server that died.  `resume`: back to the
        head of the queue, resumed at their first unfinished stroke; `hold`: held for the
        operator (release resumes them if nothing else printed since)."""
        out = []
        with self.tx() as c:
            for row in c.execute("SELECT * FROM jobs WHERE state='printing'").fetchall():
                job = _job_dict(row)
                cp = job["checkpoint"] or {}
                at = f"stroke {cp['next_stroke']}" if "next_stroke" in cp else "the start"
                if on_crash == "hold":
                    msg = (f"interrupted (server stopped) before {at}; held: release to "
                           f"resume there, or cancel")
                    c.execute("UPDATE jobs SET state='held', interrupted=1, message=? WHERE id=?",
                              (msg, job["id"]))
                else:
                    msg = (f"interrupted (server stopped); resuming at {at} once the printer "
                           f"confirms the sheet holds the strokes before it")
                    c.execute("UPDATE jobs SET state='queued', interrupted=1, message=? WHERE id=?",
                              (msg, job["id"]))
                job["message"] = msg
                out.append(job)
        return out

    def active_hot_paths(self) -> set[str]:
        return {r[0] for r in self.db.execute(
            "SELECT hot_path FROM jobs WHERE hot_path IS NOT NULL AND state IN "
            "('queued','held','printing')")}

    def planes_in_use(self, archived: bool = False) -> set[str]:
        """The kept planes of the jobs still waiting or printing (RIP and hold); archived:
        and of the done jobs whose file the archive keeps."""
        out = set()
        for (info,) in self.db.execute("SELECT ripped FROM jobs WHERE ripped IS NOT NULL AND "
                                       "(state IN ('queued','held','printing') OR (? AND "
                                       "state='done' AND spool_path IS NOT NULL))",
                                       (int(archived),)):
            path = json.loads(info).get("path")
            if path:
                out.add(path)
        return out

    def spool_files_in_use(self) -> set[str]:
        return {r[0] for r in self.db.execute(
            "SELECT spool_path FROM jobs WHERE spool_path IS NOT NULL")}

    # -- accounting -------------------------------------------------------------------------
    def add_print(self, row: dict) -> None:
        with self.tx() as c:
            self._add_print(c, row)

    @staticmethod
    def _add_print(c, row: dict | None) -> None:
        """A copy's accounting row, inside the caller's transaction (the copy's state
        change commits with it)."""
        if row:
            c.execute(f"INSERT INTO prints ({', '.join(row)}) VALUES ({','.join('?' * len(row))})",
                      tuple(row.values()))
            if row.get("paper_mm") and row.get("printer"):
                # the paper this copy fed comes off the printer's roll in the same
                # transaction (docs/server.md "Rolls"): a crash keeps both or neither
                c.execute("UPDATE rolls SET remaining_mm=MAX(0, remaining_mm - ?) WHERE "
                          "printer=? AND remaining_mm IS NOT NULL",
                          (float(row["paper_mm"]), row["printer"]))

    def prints(self, job_id: int | None = None) -> list[dict]:
        if job_id is None:
            rows = self.db.execute("SELECT * FROM prints ORDER BY id")
        else:
            rows = self.db.execute("SELECT * FROM prints WHERE job_id=? ORDER BY id", (job_id,))
        out = [dict(r) for r in rows]
        for r in out:
            r["spots"] = json.loads(r["spots"]) if r.get("spots") else None
        return out
