"""One print line in the emulator: the carriage sweeps, the encoder triggers fires, the
FPGA feeds each fire from the head FIFOs, and drops land on the media.

Event-driven and vectorised: the fire times come from the motion profile in closed form;
the DMA ring and FIFOs are stepped once per data block (not per fire): block b may enter
the FIFOs when its host buffer was ready and the FIFOs had room.  A block that is late for
its first fire is a starvation (docs/protocol.md 2.7):
- with the starve guard (profile `fpga.starve_guard`, default on) the FPGA stops firing
  at that column, the DSP brakes, and when the FIFOs are full again (or hold the rest of
  the line) it backs up and re-runs the line from that column: the stroke completes with
  every dot in place, only later;
- without it, it is the seed's FIFO underrun: a fault with head, stroke and column.
"""

from __future__ import annotations

from bisect import bisect_right

import numpy as np

from ..driver import protocol as P
from .head import serial_order
from .motion import ramp_counts
from .servo import ServoMove


# nozzles 0 and 127 (word 0 bit 0, word 7 bit 15; docs/protocol.md 4.3): data there is HEAD_DATA
_EDGE_NOZZLES = np.array([0x0001, 0, 0, 0, 0, 0, 0, 0x8000], np.uint16)


class LineRun:
    def __init__(self, printer, move: ServoMove, t_start: float, speed: float, accel: float):
        fpga = printer.fpga
        self.printer = printer
        self.stroke = fpga.stroke
        self.forward = fpga.forward
        self.k = printer.profile.counts_per_inch // fpga.dpi
        self.first = fpga.fire_start
        self.n = fpga.fire_count
        self.speed, self.accel = speed, accel
        i = np.arange(self.n)
        self.columns = self.first + i if self.forward else self.first + self.n - 1 - i
        self.end = move.end
        self.t_fire = np.full(self.n, np.inf)
        self._segment(0, move, t_start)
        self.stop_index = self.n           # fires at or after it are never made
        self.stop_fault = P.Fault.NONE
        self.stop_head = 0xFF
        self.done = False
        self.paused_at: int | None = None  # starved: next fire index, carriage braking/stopped
        self.pauses = 0
        self.fault = P.Fault.NONE
        self.min_level: int | None = None
        self._pending: list[tuple[int, int, np.ndarray]] = []   # fired, not yet landed
        self._pending_fires = 0
        self._plan_stops()

    def _segment(self, i0: int, move: ServoMove, t_start: float) -> None:
        """Fires i0.. happen on this move."""
        self.move, self.t_seg = move, t_start
        self.t_fire[i0:] = t_start + move.time_at(self.columns[i0:] * self.k)
        # the same times as a list, for the per-block search (bisect holds the GIL: a numpy
        # search of the whole line lets other threads take it for milliseconds)
        self._t_list = self.t_fire.tolist()

    # -- faults known when the line starts ----------------------------------------------------
    def _stop_at(self, index: int, fault: P.Fault, head: int = 0xFF) -> None:
        if index < self.stop_index:
            self.stop_index, self.stop_fault, self.stop_head = index, fault, head

    def _plan_stops(self) -> None:
        pr, inj = self.printer, self.printer.faults
        pos = self.columns * self.k
        if inj.limit_at is not None:
            hit = np.flatnonzero(pos >= inj.limit_at)
            if hit.size and self.forward:
                self._stop_at(int(hit[0]), P.Fault.LIMIT_RIGHT)
        if inj.encoder_glitch_at is not None:
            hit = np.flatnonzero((pos >= inj.encoder_glitch_at) if self.forward
                                 else (pos <= inj.encoder_glitch_at))
            if hit.size:
                self._stop_at(int(hit[0]), P.Fault.ENCODER)
        for name, stroke in list(inj.overtemp):
            if stroke == self.stroke:
                # the head overheats once, half-way through this line; cleared, it has
                # cooled (Printer.clear_fault), so the stroke resumed after it runs through
                inj.overtemp.remove((name, stroke))
                self._stop_at(self.n // 2, P.Fault.HEAD_OVERTEMP, pr.head_index(name))
        if self.n > 1:
            period = np.diff(self.t_fire)
            fast = np.flatnonzero(period < 1.0 / pr.profile.max_fire_hz)
            if fast.size:
                self._stop_at(int(fast[0]) + 1, P.Fault.OVERSPEED, 0)

    # -- progress -------------------------------------------------------------------------
    def advance(self, link_alive: bool) -> bool:
        """Run as far as the data allows.  Returns True when the line has ended
        (done or faulted), False when it waits for data from the host."""
        pr, fpga = self.printer, self.printer.fpga
        cap = fpga.capacity_fires
        self._drain_fifo()          # blocks preloaded before the line started
        while not self.done:
            if self.paused_at is not None:
                if not self._try_resume(cap):
                    return False
                continue
            if fpga.loaded_fires >= min(self.n, self.stop_index):
                if self.stop_index < self.n:
                    self._end(self.stop_index, self.stop_fault, self.stop_head)
                else:
                    self._end(self.n, P.Fault.NONE)
                return True
            first = fpga.loaded_fires
            if not fpga.ring:
                if link_alive:
                    return False
                # nothing more can come for now: the line starves at `first`
                if not self._starve(first, P.Fault.DATA_LINK_LOST):
                    return True
                continue
            rb = fpga.ring[0]
            room_idx = first + rb.block.fires - cap - 1     # this fire must be made first
            t_list = self._t_list
            room_t = t_list[room_idx] if room_idx >= 0 else -np.inf
            load_t = max(room_t, rb.ready_s + pr.dma_time(rb.block))
            if first < self.n and load_t > t_list[first] and first < self.stop_index:
                if not self._starve(first, P.Fault.FIFO_UNDERRUN):
                    return True
                continue
            consumed = bisect_right(t_list, load_t, 0, first)
            level = first - consumed
            self.min_level = level if self.min_level is None else min(self.min_level, level)
            fpga.fired = consumed            # the line has run up to this block's DMA
            pr.time = max(pr.time, load_t)
            fpga.move_next()
            pr.on_block_moved(load_t)
            self._drain_fifo()
        return True

    def _starve(self, index: int, fault: P.Fault) -> bool:
        """The FIFOs ran dry before fire `index`.  Returns False if that ended the line."""
        pr = self.printer
        if not pr.starve_guard:
            self._end(index, fault, 0)
            return False
        # firing stops at `index`; the carriage brakes from wherever it is
        t = self.t_fire[index]
        pos = self.move.position_at(t - self.t_seg)
        v = abs(self.move.speed_at(t - self.t_seg))
        sign = 1 if self.forward else -1
        stop = pos + sign * v * v / (2 * self.accel)
        self.paused_at = index
        self.pauses += 1
        self.printer.fpga.fired = index
        pr.carriage_park_at(stop, t + v / self.accel)
        pr.log("starved", stroke=self.stroke, fire=int(index), column=int(self.columns[index]),
               cause=fault.name)
        return True

    def _try_resume(self, cap: int) -> bool:
        """Back up and re-run the line from the paused column once the FIFOs are full
        (or hold the rest of the line)."""
        pr, fpga = self.printer, self.printer.fpga
        i = self.paused_at
        t = pr.time
        while fpga.ring and fpga.fifo_level_fires() + fpga.ring[0].block.fires <= cap:
            rb = fpga.ring[0]
            t = max(t, rb.ready_s + pr.dma_time(rb.block))
            fpga.move_next()
            pr.on_block_moved(t)
        remaining = min(self.n, self.stop_index) - i
        have = fpga.loaded_fires - i
        if have < min(remaining, cap - (cap % max(1, pr.profile.block_fires))):
            return False
        pr.time = max(pr.time, t)
        sign = 1 if self.forward else -1
        ramp = ramp_counts(self.speed, self.accel, self.k)
        start = float(self.columns[i] * self.k - sign * ramp)
        pr.move_carriage_to(start)
        move = ServoMove(pr.servo, start, self.end, self.speed, self.accel)
        self._segment(i, move, pr.time)
        self.paused_at = None
        pr.log("resumed", stroke=self.stroke, fire=int(i), column=int(self.columns[i]))
        self._drain_fifo()
        return True

    def _drain_fifo(self) -> None:
        """Fire the blocks in the FIFOs.  Drops are placed by position, so a block's fires
        can be placed as soon as it is certain they happen (its data arrived in time)."""
        if self.paused_at is not None:
            return
        fifo = self.printer.fpga.fifo
        while fifo:
            block = fifo.popleft()
            self._fire_block(block, block.first_fire)

    LAND_BATCH = 8192   # fires landed per batch: one unpack and one scatter per head

    def _fire_block(self, block: P.Block, first: int) -> None:
        last = min(first + block.fires, self.stop_index)
        count = last - first
        if count <= 0:
            return
        words = block.words[:, :count]
        # both edge nozzles of every fire looked at in one operation, the culprit only if set
        if np.count_nonzero(words & _EDGE_NOZZLES):
            bad = (words[:, :, 0] & 0x0001) | (words[:, :, 7] & 0x8000)
            part, fire = np.argwhere(bad)[np.argmin(np.argwhere(bad)[:, 1])]
            mask_heads = [h for h in range(self.printer.n_heads) if block.head_mask >> h & 1]
            self._stop_at(first + int(fire), P.Fault.HEAD_DATA, mask_heads[int(part)])
            count = int(fire)
            words = words[:, :count]
            if count == 0:
                return
        # the carriage's speed at each fire, for the physical model's drops (docs/physical.md)
        vel = None if self.printer.scanner is None else \
            self.move.speeds_at(self.t_fire[first:first + count] - self.t_seg)
        self._pending.append((first, block.head_mask, words, vel))
        self._pending_fires += count
        if self._pending_fires >= self.LAND_BATCH:
            self.land_pending()

    def land_pending(self) -> None:
        """Drops are placed by position, not time, so fired blocks are landed in batches."""
        if not self._pending:
            return
        pr = self.printer
        by_mask: dict[int, list] = {}
        for first, mask, words, vel in self._pending:
            by_mask.setdefault(mask, []).append((first, words, vel))
        self._pending, self._pending_fires = [], 0
        for mask, items in by_mask.items():
            idx = np.concatenate([np.arange(f, f + w.shape[1]) for f, w, _ in items])
            words = np.concatenate([w for _, w, _ in items], axis=1)
            vel = None if items[0][2] is None else np.concatenate([v for _, _, v in items])
            cols = self.columns[idx]
            heads = [h for h in range(pr.n_heads) if mask >> h & 1]
            for part, h in enumerate(heads):
                pr.land_drops(h, cols, words[part], self.forward, vel, self.speed)
            if pr.record_latched and len(heads) == pr.n_heads:
                pr.latched.setdefault(self.stroke, []).append((int(idx[0]), words))
            if pr.vcd is not None:
                self._waveform(idx, words, heads)

    def _waveform(self, idx: np.ndarray, words: np.ndarray, heads: list[int]) -> None:
        """Head-interface and encoder signals for the fires of the VCD window."""
        from .vcd import add_encoder, add_fire
        pr = self.printer
        stroke, head, first, count = pr.vcd_window
        if stroke != self.stroke or head not in heads:
            return
        sel = np.flatnonzero((idx >= first) & (idx < first + count))
        if sel.size == 0:
            return
        period = int(1e9 / pr.profile.max_fire_hz)
        part = heads.index(head)
        name = pr.profile.heads[head].name
        for i in sel:
            bits = serial_order(P.words_to_nozzles(words[part, i]))
            add_fire(pr.vcd, name, int(self.t_fire[idx[i]] * 1e9), bits, self.forward, period)
        c0, c1 = int(self.columns[idx[sel[0]]]) * self.k, int(self.columns[idx[sel[-1]]]) * self.k
        step = 1 if c1 >= c0 else -1
        # from the count before the first fire's: its trigger edge is in the trace
        counts = np.arange(c0 - step, c1 + step, step)
        times = self.t_seg + self.move.time_at(counts)
        add_encoder(pr.vcd, counts, (times * 1e9).astype(np.int64))

    def _end(self, fired: int, fault: P.Fault, head: int = 0xFF) -> None:
        pr = self.printer
        self.land_pending()
        self.done = True
        self.fault = fault
        pr.fpga.fired = fired
        if fault == P.Fault.NONE:
            pr.carriage_stop(self.move.final, self.t_seg + self.move.duration)
        else:
            t = self.t_fire[fired] if fired < self.n else self.t_seg + self.move.duration
            pos = self.move.position_at(t - self.t_seg)
            column = int(self.columns[fired]) if fired < self.n else int(self.columns[-1])
            pr.raise_fault(fault, head=head, stroke=self.stroke, column=column)
            pr.carriage_stop(pos, t)
        tr = self.move.traj
        pr.log("line", stroke=self.stroke, forward=self.forward, first_column=int(self.first),
               fires=int(self.n), fired=int(fired), fault=fault.name, pauses=self.pauses,
               min_fifo_words=None if self.min_level is None else self.min_level * P.WORDS_PER_FIRE,
               # the servo's run (docs/motion.md): what the thesis' test line measures
               max_following_error=round(float(tr.max_following_error), 3),
               final_error=round(float(self.move.final - self.move.end), 3),
               peak_current_a=round(float(tr.peak_current), 4),
               servo_period_s=pr.servo.period_s)
