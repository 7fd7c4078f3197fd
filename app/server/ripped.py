"""RIP and hold (docs/server.md "RIP and hold"): a held job ripped ahead, its halftone planes
kept in the state directory (`ripped/ID-KEY.tif`, the planes format of docs/formats.md), so
that its release prints without ripping again.

`Ripper` (one thread, beside the printers' workers) rips the held jobs marked `rip_hold`
whose planes are missing or stale; `planes_job()` gives the worker a `PlanesJob` that
prints the kept planes when they are the job's as it is now.  The planes are the job's
for one key: the file's SHA-256, its settings and the printer profile's path and
modification time - an edit of the settings, a recalibrated profile or another printer's
profile makes them stale, and the job is ripped as usual.  They go when the job ends.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np

from ...rip.planes import iter_planes
from ...rip.printable import PrintableJob
from ...rip.swath import StrokePlanner, top_margin_rows
from .validate import job_rip_settings

log = logging.getLogger("wideprint.server")

RIPPED_DIR = "ripped"


def planes_key(job: dict, profile) -> str:
    """What the kept planes are the halftone of: the file, the settings, the profile."""
    try:
        mtime = os.stat(profile.path).st_mtime_ns if profile.path else 0
    except OSError:
        mtime = 0
    h = hashlib.sha256()
    h.update(json.dumps([job["sha256"], job["settings"], str(profile.path), mtime],
                        sort_keys=True).encode())
    return h.hexdigest()[:16]


class PlanesJob(PrintableJob):
    """A job printed from its kept planes: the same image area, halftone and stroke plan as
    the RipJob that wrote them (its planner's dead-row flag kept with them)."""

    def __init__(self, path: str, planes: str, settings, profile, dead_rows_empty: bool,
                 width: int, height: int):
        self.path, self.planes = path, planes
        self.settings, self.profile = settings, profile
        self.width, self.height = width, height
        self.dead_rows_empty = dead_rows_empty
        self.layout = None

    def planner(self) -> StrokePlanner:
        s = self.settings
        return StrokePlanner(self.profile, self.width, self.height, s.dpi, s.passes, s.bidir,
                             s.pass_mask, dead_rows_empty=self.dead_rows_empty,
                             top_rows=top_margin_rows(self.profile, s))

    def halftone_bands(self) -> Iterator[np.ndarray]:
        yield from iter_planes(self.planes)


def planes_job(job: dict, profile, settings, media_profile) -> PlanesJob | None:
    """The job's kept planes as a PlanesJob, when they are there and still the job's
    (`profile`: the printer's, for the key; `settings`, `media_profile`: what the job rips
    with, validate.job_rip_settings)."""
    info = job.get("ripped")
    if not info or info.get("error") or not info.get("path"):
        return None
    if info.get("key") != planes_key(job, profile) or not os.path.exists(info["path"]):
        return None
    return PlanesJob(job["spool_path"], info["path"], settings, media_profile,
                     bool(info["dead_rows_empty"]), int(info["width"]), int(info["height"]))


def rip_to_planes(job: dict, profile, state_dir: Path, out_dir: Path) -> dict:
    """Rip `job` once into the planes file, as the worker would rip it: {path, key, width,
    height, dead_rows_empty, rip_s, bytes, spots (the spot colours it resolved)}."""
    from ...rip.pipeline import RipJob
    key = planes_key(job, profile)
    out_dir.mkdir(exist_ok=True)
    final = out_dir / f"{job['id']}-{key}.tif"
    tmp = out_dir / f".{final.name}.part"
    t0 = time.monotonic()
    rs, media_profile = job_rip_settings(job["settings"], profile, state_dir)
    rip = RipJob(job["spool_path"], rs, media_profile, names=(job["name"],))
    try:
        from ...rip.spot_render import job_spots
        spots = job_spots(rip)
        rip.write_planes(tmp, "packed")
        dead = rip._dead_rows() is not None
        width, height = rip.width, rip.height
    finally:
        rip.close()
    with open(tmp, "rb+") as f:
        os.fsync(f.fileno())
    os.rename(tmp, final)
    return dict(path=str(final), key=key, width=width, height=height, dead_rows_empty=dead,
                rip_s=round(time.monotonic() - t0, 3), bytes=final.stat().st_size, spots=spots)


class Ripper(threading.Thread):
    """Rips the held jobs marked RIP-and-hold, one at a time, between the printers' RIPs."""

    def __init__(self, server):
        super().__init__(name="wideprint-ripper", daemon=True)
        self.srv = server
        self.wake = threading.Event()
        self.stopping = False
        self.dir = Path(server.state_dir) / RIPPED_DIR    # beside spool/, which holds files only

    def notify(self) -> None:
        self.wake.set()

    def stop(self) -> None:
        self.stopping = True
        self.wake.set()

    def _profile(self, job: dict):
        return self.srv.profiles.get(job.get("printer") or "") or self.srv.profile

    def run(self) -> None:
        while not self.stopping:
            self.wake.wait(2.0)
            self.wake.clear()
            try:
                for job in self.srv.spool.rip_hold_jobs():
                    if self.stopping:
                        return
                    self._rip(job)
            except Exception:  # noqa: BLE001 - a database hiccup must not end the ripper
                log.exception("RIP and hold")

    def _rip(self, job: dict) -> None:
        profile = self._profile(job)
        info = job.get("ripped")
        if info and info.get("key") == planes_key(job, profile) and (
                info.get("error") or os.path.exists(info["path"])):
            return                       # ready, or its file failed (it fails when printed)
        try:
            new = rip_to_planes(job, profile, self.srv.state_dir, self.dir)
        except Exception as exc:  # noqa: BLE001 - the file's own problem shows when it prints
            msg = str(exc).replace(job.get("spool_path") or "", job["name"])
            log.warning("job %s: RIP and hold: %s", job["id"], msg)
            self.srv.spool.set_ripped(job["id"], dict(error=msg, key=planes_key(job, profile),
                                                      path=""))
            return
        spots = new.pop("spots", None)        # on the job's record, with its planes
        old = self.srv.spool.set_ripped(job["id"], new, spots)
        if old is None:                  # the job ended or moved on meanwhile: not needed
            _remove(new["path"])
            return
        if old.get("path") and old["path"] != new["path"]:
            _remove(old["path"])
        log.info("job %s %s ripped and held: %.1f s, %.1f MB of planes", job["id"], job["name"],
                 new["rip_s"], new["bytes"] / 1e6)


def clean(state_dir: Path, in_use: set[str]) -> None:
    """Kept planes no waiting job owns any more go (checked with the spool's expiry)."""
    d = Path(state_dir) / RIPPED_DIR
    for p in d.iterdir() if d.is_dir() else ():
        if str(p) not in in_use and not p.name.startswith("."):
            _remove(str(p))


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    except OSError as exc:
        log.warning("cannot delete %s: %s", path, exc.strerror)
