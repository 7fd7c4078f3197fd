"""Previews and estimates of queued jobs for the server's clients (docs/server.md,
"Previews and estimates"): `GET /v1/jobs/ID/preview` (JSON: size, strokes, time and ink per
copy and for all copies) and `GET /v1/jobs/ID/preview.png` (the preview halftone, true
physical aspect).  Both come from one app.jobpreview.compute_preview of the spooled file
with the job's settings and its printer's profile; the result is cached in memory per
(job, file, settings, profile) and a small thumbnail is kept on disk (thumbs/ID.png), so
the history still shows one after the spool copy is gone.

Previews are made one at a time (a semaphore): they read the whole file once, reduced, and
must not starve the printers' RIPs.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from collections import OrderedDict
from pathlib import Path

from .validate import Invalid, job_rip_settings

log = logging.getLogger("wideprint.server")

PREVIEW_PX = (32, 1600)        # the sizes a client may ask for (longer side, pixels)
THUMB_PX = 128                 # the thumbnail kept on disk
CACHE_ENTRIES = 32


class Previews:
    def __init__(self, server):
        self.srv = server
        self.dir = Path(server.state_dir) / "thumbs"
        self.dir.mkdir(exist_ok=True)
        self._lock = threading.Lock()
        self._one = threading.Semaphore(1)
        self._cache: OrderedDict = OrderedDict()

    def _profile(self, job: dict):
        name = job.get("printed_on") or job.get("printer")
        return self.srv.profiles.get(name) or self.srv.profile

    def _key(self, job: dict, px: int) -> tuple:
        prof = self._profile(job)
        return (job["id"], job["sha256"], json.dumps(job["settings"], sort_keys=True),
                prof.path, job["copies"], px)

    def thumbnail_path(self, job_id: int) -> Path:
        return self.dir / f"{int(job_id)}.png"

    def get(self, job: dict, px: int = THUMB_PX):
        """The PreviewData of `job` at `px` pixels on its longer side (cached); Invalid
        (422) with the file's own problem when it cannot be read."""
        from ...rip.load import ImageError
        from ..jobpreview import compute_preview
        key = self._key(job, px)
        with self._lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                return hit
        path = job.get("spool_path")
        if not path or not os.path.exists(path):
            raise Invalid(f"job {job['id']}: its file is no longer spooled (no preview)", 410)
        with self._one:
            try:
                rs, profile = job_rip_settings(job["settings"], self._profile(job),
                                               self.srv.state_dir)
                pd = compute_preview(path, rs, profile,
                                     copies=job["copies"], max_px=px)
            except (ImageError, ValueError, OSError) as exc:
                raise Invalid(str(exc).replace(path, job["name"]), 422) from None
        with self._lock:
            self._cache[key] = pd
            while len(self._cache) > CACHE_ENTRIES:
                self._cache.popitem(last=False)
        # the estimate resolved the document's spot colours as its RIP will: on the record of
        # a job still waiting (its RIP's own list replaces them; docs/spot.md)
        self.srv.spool.set_spots(job["id"], pd.spots, waiting_only=True)
        if px == THUMB_PX and not self.thumbnail_path(job["id"]).exists():
            try:
                self._write_png(self.thumbnail_path(job["id"]), pd)
            except OSError as exc:
                log.warning("job %s: cannot keep its thumbnail: %s", job["id"], exc)
        return pd

    @staticmethod
    def png_bytes(pd) -> bytes:
        import cv2
        from ...rip.planes import render_rgb
        rgb = render_rgb(pd.dots)
        ok, buf = cv2.imencode(".png", rgb[:, :, ::-1])
        if not ok:
            raise OSError("PNG encoding failed")
        return buf.tobytes()

    def _write_png(self, path: Path, pd) -> None:
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(self.png_bytes(pd))
        os.replace(tmp, path)

    def png(self, job: dict, px: int) -> bytes:
        """The preview picture; a finished job's kept thumbnail when its file is gone."""
        thumb = self.thumbnail_path(job["id"])
        if px == THUMB_PX and thumb.exists() and job["state"] in ("done", "failed", "cancelled"):
            return thumb.read_bytes()
        try:
            return self.png_bytes(self.get(job, px))
        except Invalid as exc:
            if exc.status == 410 and thumb.exists():
                return thumb.read_bytes()
            raise

    def proof_png(self, job: dict, px: int) -> bytes:
        """The job's soft proof as PNG (docs/color.md "Soft proof"): the file through its
        media's profile with the gamut warning, at most `px` on its longer side."""
        from ...rip.load import ImageError
        from ..jobpreview import proof_job
        from ..softproof import png_bytes
        path = job.get("spool_path")
        if not path or not os.path.exists(path):
            raise Invalid(f"job {job['id']}: its file is no longer spooled (no proof)", 410)
        with self._one:
            try:
                rs, profile = job_rip_settings(job["settings"], self._profile(job),
                                               self.srv.state_dir)
                return png_bytes(proof_job(path, rs, profile, max_px=px))
            except (ImageError, ValueError, OSError) as exc:
                raise Invalid(str(exc).replace(path, job["name"]), 422) from None

    def info(self, job: dict, px: int = THUMB_PX) -> dict:
        """Size, strokes, and the estimate per copy and for all copies (docs/server.md)."""
        pd = self.get(job, px)
        e = pd.estimate
        copies = max(1, int(job["copies"]))
        per_ink = [ml / copies for ml in e.ink_ml]
        per_copy = dict(time_s=e.time_s / copies, area_m2=e.area_m2, ink_ml=per_ink,
                        ink_total_ml=sum(per_ink), drops=e.drops)
        all_copies = dict(time_s=e.time_s, area_m2=e.area_m2 * copies, ink_ml=list(e.ink_ml),
                          ink_total_ml=e.total_ink_ml)
        return dict(job=job["id"], width_dots=pd.width_dots, height_rows=pd.height_rows,
                    width_mm=pd.width_mm, height_mm=pd.height_mm, dpi=pd.dpi,
                    strokes=pd.total_strokes, stroke_s=e.stroke_s, source=pd.source_desc,
                    exact=pd.exact, warnings=list(pd.warnings), copies=copies,
                    out_of_gamut=pd.out_of_gamut, spots=pd.spots,
                    per_copy=per_copy, all_copies=all_copies,
                    preview_px=[int(pd.dots.shape[1]), int(pd.dots.shape[0])])

    def forget(self, job_id: int) -> None:
        with self._lock:
            for k in [k for k in self._cache if k[0] == job_id]:
                del self._cache[k]
