"""The live media of an emulated printer, for the print server's clients (docs/server.md,
"Live media"): what has landed on the paper of the job printing, as a picture of at most
LIVE_MAX_PX on its longer side, area-averaged (every dot counts, nothing aliases), at the
job's true physical aspect (the device grid is anisotropic: columns at the dpi mode, rows
at the profile's row pitch).

The emulator (device_sim) keeps only a window of media rows near the heads; `LivePrinter`
hands that window to the `LiveMedia` before rows leave it and at the job's end, so nothing
printed between two looks is missed.  Memory: the picture, plus one window's rendering.
Only app/ composes the emulator (docs/architecture.md): the server asks app/devices.py for
a device with a LiveMedia, never for the emulator itself.
"""

from __future__ import annotations

import threading

import numpy as np

LIVE_MAX_PX = 1024


class LiveMedia:
    def __init__(self, max_px: int = LIVE_MAX_PX):
        self.max_px = max_px
        self.lock = threading.Lock()
        self.version = 0               # +1 at each change: clients fetch only on a change
        self.job: int | None = None
        self.canvas: np.ndarray | None = None
        self._shape = (0, 0)           # the job's media (rows, columns)
        self._fy = self._fx = 1.0      # picture pixels per media row / column
        self.poll = None               # the printer's capture: rows landed since its last flush

    def begin(self, job: int, width: int, height: int, dpi: int, row_nm: int) -> None:
        """A job's media begins: a blank picture of its physical aspect."""
        w_mm = width * 25.4 / dpi
        h_mm = height * row_nm * 1e-6
        # one scale both ways (the true aspect), never more pixels than dots either way
        s = min(self.max_px / max(w_mm, h_mm, 1e-9), width / max(w_mm, 1e-9),
                height / max(h_mm, 1e-9))
        pw = max(1, int(round(w_mm * s)))
        ph = max(1, int(round(h_mm * s)))
        with self.lock:
            self.job = job
            self._shape = (height, width)
            self._fy, self._fx = ph / height, pw / width
            self.canvas = np.full((ph, pw, 3), 255, np.uint8)
            self.version += 1

    def push(self, first: int, rows: np.ndarray) -> None:
        """Media rows first.. (h, width, 4) 0/1 dots: their part of the picture redrawn,
        area-averaged (rows that share a picture row with rows outside the window get the
        window's share only: they are redrawn whole as the window moves on)."""
        import cv2
        from ..rip.planes import render_rgb
        if self.canvas is None or not rows.size:
            return
        H, W = self._shape
        n = min(rows.shape[0], H - first)
        if n <= 0:
            return
        y0 = int(first * self._fy)
        y1 = max(y0 + 1, int(np.ceil((first + n) * self._fy)))
        y1 = min(y1, self.canvas.shape[0])
        rgb = render_rgb(np.ascontiguousarray(rows[:n, :W]))
        part = cv2.resize(rgb, (self.canvas.shape[1], y1 - y0), interpolation=cv2.INTER_AREA)
        with self.lock:
            self.canvas[y0:y1] = part.reshape(y1 - y0, self.canvas.shape[1], 3)
            self.version += 1

    def png(self) -> bytes | None:
        import cv2
        poll = self.poll
        if poll is not None:
            try:
                poll()                 # a copy of the window; a race shows a row a moment late
            except Exception:  # noqa: BLE001 - a picture is never worth a failed request
                pass
        with self.lock:
            if self.canvas is None:
                return None
            img = self.canvas[:, :, ::-1].copy()
        ok, buf = cv2.imencode(".png", img)
        return buf.tobytes() if ok else None


def live_printer_class():
    """device_sim's Printer that hands its media window to `self.live` (a LiveMedia)."""
    from ..device_sim.printer import Printer

    class LivePrinter(Printer):
        live: LiveMedia | None = None

        def _capture(self) -> None:
            live, media = self.live, self.media
            if live is not None and media is not None and live.job == self._live_job:
                first, rows = media.snapshot(1)
                live.push(first, rows)

        def job_begin(self, job, x0, width, height, dpi, row_nm, y0) -> None:
            super().job_begin(job, x0, width, height, dpi, row_nm, y0)
            self._live_job = job
            if self.live is not None:
                self.live.begin(job, width, height, dpi, row_nm)
                self.live.poll = self._capture

        def before_media_flush(self) -> None:
            super().before_media_flush()
            self._capture()

        def before_job_end(self) -> None:
            super().before_job_end()
            self._capture()

    LivePrinter._live_job = None
    return LivePrinter
