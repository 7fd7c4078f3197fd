"""The data channel, host side: a stroke's nozzle words cut into blocks and sent on DMA-ring
credit (docs/protocol.md section 3.2)."""

from __future__ import annotations

import threading
import time

import numpy as np

from . import protocol as P


class StreamError(ConnectionError):
    pass


def stroke_blocks(stroke: int, words: np.ndarray, block_fires: int, head_mask: int):
    """Yield (first_fire, encoded block) for a stroke's words (heads, fires, 8): the bytes
    of P.encode_block (docs/protocol.md 3.1), the whole blocks of the stroke made at once
    (one transposing copy, the headers as an array, a CRC each), the last partial one by
    encode_block itself."""
    parts, fires = words.shape[0], words.shape[1]
    whole = fires // block_fires if parts and block_fires > 0 else 0
    if whole:
        size = 2 * parts * block_fires * P.WORDS_PER_FIRE
        hdr = P.BLOCK_HEADER.size
        buf = np.empty((whole, hdr + size + 4), np.uint8)
        head = np.zeros(whole, np.dtype([("magic", "S4"), ("kind", "u1"), ("mask", "u1"),
                                         ("fires", "<u2"), ("stroke", "<u4"), ("first", "<u4"),
                                         ("words", "<u4")]))
        head["magic"], head["kind"], head["mask"] = P.BLOCK_MAGIC, P.BLOCK_DATA, head_mask
        head["fires"], head["stroke"] = block_fires, stroke
        head["first"] = np.arange(whole, dtype=np.uint32) * block_fires
        head["words"] = parts * block_fires * P.WORDS_PER_FIRE
        buf[:, :hdr] = head.view(np.uint8).reshape(whole, hdr)
        payload = buf[:, hdr:hdr + size].view("<u2").reshape(whole, parts, block_fires,
                                                              P.WORDS_PER_FIRE)
        payload[:] = words[:, :whole * block_fires].reshape(
            parts, whole, block_fires, P.WORDS_PER_FIRE).transpose(1, 0, 2, 3)
        crc = buf[:, hdr + size:].view("<u4")
        for b in range(whole):
            crc[b, 0] = P.crc32(buf[b, :hdr + size])
        for b in range(whole):
            yield b * block_fires, buf[b].tobytes()
    for first in range(whole * block_fires, fires, block_fires):
        yield first, P.encode_block(stroke, first, head_mask, words[:, first:first + block_fires])


class StrokeStreamer:
    """Sends one stroke's blocks, never more than `ring` ahead of the FPGA's reports."""

    def __init__(self, data, stroke: int, words: np.ndarray, block_fires: int, ring: int,
                 head_mask: int):
        self.data = data
        self.stroke = stroke
        self.blocks = list(stroke_blocks(stroke, words, block_fires, head_mask))
        self.ring = ring
        self.sent = 0
        self.acked = 0
        self.min_fifo_words: int | None = None
        self.decoder = P.ReportDecoder()
        self.error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def done(self) -> bool:
        return self.sent == len(self.blocks)

    def _recv(self, timeout: float) -> bytes:
        """The reports that arrived; a link that failed while reading them is a lost data
        link the job recovers from, as when sending (the PCI card finds a DMA abort here)."""
        try:
            return self.data.recv(timeout)
        except (ConnectionError, OSError) as exc:
            raise StreamError(f"stroke {self.stroke}: data link lost ({exc})") from exc

    def discard_stale(self) -> None:
        """Before SET_LINE of a new line: drop what waits on the data channel — reports of
        an earlier line, perhaps with the same stroke id (every job and copy starts at 0),
        which would count as this line's (docs/protocol.md 3.2)."""
        while self._recv(0.0):
            pass
        self.decoder = P.ReportDecoder()

    def _reports(self, timeout: float) -> None:
        for rep in self.decoder.feed(self._recv(timeout)):
            if rep.stroke != self.stroke or rep.blocks > self.sent:
                continue                 # another line's (more blocks than we sent: 3.2)
            self.acked = max(self.acked, rep.blocks)
            level = min(rep.fifo)
            self.min_fifo_words = level if self.min_fifo_words is None else min(self.min_fifo_words, level)

    def pump(self, timeout: float = 0.0) -> None:
        """Send every block the ring has room for; read the reports that arrived."""
        self._reports(0.0)
        while self.sent < len(self.blocks) and self.sent - self.acked < self.ring:
            try:
                self.data.send(self.blocks[self.sent][1])
            except (ConnectionError, OSError) as exc:
                raise StreamError(f"stroke {self.stroke}: data link lost ({exc})") from exc
            self.sent += 1
            self._reports(0.0)
        if self.sent < len(self.blocks) and timeout:
            self._reports(timeout)

    def resume(self, timeout: float = 5.0) -> None:
        """After a lost link: FLUSH the device's DMA ring and carry on from the first block
        that is not in its FIFOs (the FLUSHED report says which)."""
        self._stop.clear()
        try:
            self.data.send(P.encode_block(self.stroke, 0, 0, np.zeros((0, 0, 8), np.uint16),
                                          kind=P.BLOCK_FLUSH))
        except (ConnectionError, OSError) as exc:
            raise StreamError(f"stroke {self.stroke}: data link lost ({exc})") from exc
        deadline = time.monotonic() + timeout
        while True:
            for rep in self.decoder.feed(self._recv(0.02)):
                if rep.stroke == self.stroke and rep.flags & P.REPORT_FLUSHED:
                    self.sent = self.acked = rep.blocks
                    return
            if time.monotonic() > deadline:
                raise StreamError(f"stroke {self.stroke}: the printer did not answer the FLUSH")

    def preload(self, timeout: float = 5.0) -> None:
        """Fill the ring and the FIFOs before the carriage moves."""
        deadline = time.monotonic() + timeout
        while True:
            self.pump(0.01)
            if self.done or self.sent - self.acked >= self.ring:
                return
            if time.monotonic() > deadline:
                raise StreamError("the printer did not take the preload data")

    # -- the streaming thread: keeps the ring full while the main thread watches status ----
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f"stream-stroke-{self.stroke}",
                                        daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            while not self.done and not self._stop.is_set():
                self.pump(0.02)
        except BaseException as exc:  # handed to the job thread
            self.error = exc

    def wait(self, timeout: float) -> None:
        """Until the streaming thread has sent everything (or failed), at most `timeout`."""
        if self._thread is not None:
            self._thread.join(timeout)
        else:
            time.sleep(timeout)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
