"""The emulated printer: DSP, FPGA, carriage board, heads, carriage, feed and media.

It sees only bytes: `serial_in()` takes command-channel bytes and returns the DSP's
answer, `data_in()` takes data-channel bytes and `data_out()` gives the FPGA's reports
(docs/protocol.md).  Simulated time advances with the motions; a print line advances as
far as its data allows (conservative co-simulation: the device never guesses bytes it has
not received, and host timing comes from the host-jitter model, docs/emulator.md).
"""

from __future__ import annotations

import json
import math
import os
import random
import time as wallclock
from collections import deque
from pathlib import Path
from typing import Callable

import numpy as np

from ..driver import protocol as P
from ..rip.profile import Profile, load_profile
from .dsp import Dsp
from .faults import Faults
from .fpga import Fpga
from .head import Head
from .line import LineRun
from .media import Media
from .motion import Trapezoid, ramp_counts
from .physical import JobGeometry, PhysicalModel, dot_diameter_um
from .servo import ServoMove, ServoParams
from .service import ServiceStation
from .stepper import feed_move

PCI_BYTES_S = 60e6           # effective PLX9054 DMA rate (33 MHz, 32 bit, with overhead)
HOME_SPEED_MM_S = 50.0
POWER_UP_POSITION = 23_456   # where the carriage happens to be at power-up (counts from the left switch)
SHEET_LEFT_MM = 320.0        # the emulator's sheet: left edge this far from the left switch
MEDIA_MARGIN_ROWS = 64       # media window rows beyond the swath (4.4 mm at 68.55 um a row)


class Printer:
    def __init__(self, profile: Profile | None = None, faults: Faults | None = None,
                 media_path: str | Callable[[int], str] | None = None,
                 event_log: str | Path | None = None, vcd_path: str | None = None,
                 vcd_window: tuple[int, int, int, int] = (0, 0, 0, 8),
                 record_latched: bool = False,
                 scan_path: str | Callable[[int], str | None] | None = None,
                 scan_dpi: float = 1200,
                 spectro_path: str | Callable[[int], str | None] | None = None,
                 spectro_dpi: float = 50, keep_events: int = 200_000):
        self.profile = profile or load_profile()
        self.faults = faults or Faults()
        prof = self.profile
        self.n_heads = len(prof.heads)
        self.fpga = Fpga(self.n_heads, self.faults.fifo_words or prof.fifo_words,
                         prof.pass_buffer_words, prof.ring_blocks,
                         prof.fpga.almost_empty_words,
                         prof.block_fires * P.WORDS_PER_FIRE)
        self.heads = [Head(h.index, h.name, temperature_c=prof.head.nominal_temp_c,
                           overtemp_c=prof.head.overtemp_c) for h in prof.heads]
        for name, nozzle in self.faults.dead_nozzle:
            self.heads[self.head_index(name)].dead.add(nozzle)
        # where drops really land, and the scan of each job (docs/physical.md)
        self.physical = PhysicalModel(prof, self.faults)
        self.geometry: JobGeometry | None = None
        self.scan_path, self.scan_dpi = scan_path, scan_dpi
        self.spectro_path, self.spectro_dpi = spectro_path, spectro_dpi
        self.scanner = None                  # the job's instruments (device_sim/spectro.py)
        self.scans: dict = {}                # scan path -> its closed Scanner
        self.paper_extra_nm = 0.0            # the paper's travel beyond its steps (feed-error)
        self._extra0 = 0.0                   # ... at the open job's JOB_BEGIN
        self._y_slack_nm = 0.0               # drops of the open job land this far above slot 0
        self.dsp = Dsp(self)
        self.servo = ServoParams.from_profile(self.profile)
        self.rng = random.Random(self.faults.seed)
        self.time = 0.0
        self.baud = P.DEFAULT_BAUD
        self.enabled = False
        self.homed = False
        self.fault = P.Fault.NONE
        self.fault_head, self.fault_stroke, self.fault_column = 0xFF, 0, 0
        self.position = float(POWER_UP_POSITION)    # carriage, counts from the left switch
        self.count_offset = POWER_UP_POSITION       # DSP counter = position - offset (0 at power-up)
        self.motion = P.Motion.IDLE
        self.line_done = False
        self.feed_done = False
        self.paper_steps = 0
        self.feed_state = 1                  # L297 translator state (1..8)
        self.vcd_feed = True
        self.paper_measured = False
        width = self.faults.paper_width_mm or prof.paper.default_width_mm
        left = SHEET_LEFT_MM / 25.4 * prof.counts_per_inch
        self.sheet = (left, left + width / 25.4 * prof.counts_per_inch)
        self.paper_edges = (0, 0)
        self.paper_left_steps = (None if self.faults.paper_length_mm is None else
                                 int(self.faults.paper_length_mm * 1000 / prof.feed_um_per_step))
        self.line_cfg: dict | None = None
        self.line: LineRun | None = None
        self.link_alive = True
        self.starve_guard = prof.fpga.starve_guard \
            if self.faults.starve_guard is None else bool(self.faults.starve_guard)
        self.block_decoder = P.BlockDecoder()
        self._data_out = bytearray()
        self._stroke_blocks_received = 0
        self._move_times: list[float] = []
        self.blocks_total = 0
        self.job: dict | None = None
        # the printer's account of its job (docs/protocol.md 2.10): what JOB_STATUS reports
        self.boot = self.faults.boot if self.faults.boot is not None else \
            int.from_bytes(os.urandom(4), "little") % 0xFFFFFFFF + 1
        self.job_account = dict(job=P.NO_JOB, job_state=P.JobState.NONE, lines_done=0,
                                last_stroke=P.NO_STROKE)
        self._line_counted = None            # the line run last counted in lines_done
        self.media: Media | None = None
        self.media_path = media_path
        self.jobs_done: dict[int, dict] = {}
        self.config_traces = []
        self._log_file = open(event_log, "w") if event_log else None
        # VCD of the head interface for (stroke, head, first fire, fires); see vcd.py
        self.vcd_path, self.vcd_window = vcd_path, vcd_window
        self.vcd = None
        if vcd_path:
            from .vcd import Vcd
            self.vcd = Vcd()
        # the 128-bit words each head latched, per stroke, in firing order (tests, --latched-out)
        self.record_latched = record_latched
        self.latched: dict[int, list] = {}
        # the last `keep_events` events for tests and reports (~500 B each): a command's
        # job keeps them all; a print server's emulator, which runs for days and is polled
        # while idle, keeps fewer (app/server/worker.py)
        self.events: deque = deque(maxlen=keep_events)
        # the service station and the ink's drying (docs/protocol.md 2.9)
        self.service = ServiceStation(self, self.n_heads, prof.nozzles, prof.maintenance,
                                      self.faults)
        self._wall_last: float | None = None     # when the host last spoke (idle time)

    # -- bookkeeping ------------------------------------------------------------------------
    def log(self, event: str, **fields) -> None:
        rec = {"t": round(self.time, 9), "event": event, **fields}
        self.events.append(rec)
        if self._log_file:
            self._log_file.write(json.dumps(rec) + "\n")

    def head_index(self, name: str) -> int:
        for h in self.profile.heads:
            if h.name == name:
                return h.index
        raise ValueError(f"no head named {name!r} (heads: {[h.name for h in self.profile.heads]})")

    def heads_configured(self) -> bool:
        return all(h.configured for h in self.heads)

    def busy(self) -> bool:
        return self.line is not None and not self.line.done

    def close(self) -> None:
        self._close_media()
        self._close_scan()
        if self.vcd is not None and self.vcd_path:
            self.vcd.write(self.vcd_path)
            self.vcd = None
        if self._log_file:
            self._log_file.close()
            self._log_file = None

    # -- serial line ----------------------------------------------------------------------
    def _noise(self, data: bytes) -> bytes:
        f = self.faults
        if not (f.serial_ber or f.serial_byte_error or f.serial_drop) or not data:
            return data
        out = bytearray()
        for b in data:
            if f.serial_drop and self.rng.random() < f.serial_drop:
                continue
            if f.serial_byte_error and self.rng.random() < f.serial_byte_error:
                b ^= 1 << self.rng.randrange(8)
            if f.serial_ber:
                for bit in range(8):
                    if self.rng.random() < f.serial_ber:
                        b ^= 1 << bit
            out.append(b)
        return bytes(out)

    def serial_in(self, data: bytes, gap: bool = True) -> bytes:
        """Bytes from the host; `gap` says the line was idle before them for longer than
        the DSP's inter-frame timeout."""
        now = wallclock.monotonic()
        if self._wall_last is not None and not self.busy() and self.motion == P.Motion.IDLE:
            self.service.idle(now - self._wall_last)    # the printer stood still meanwhile
        self._wall_last = now
        data = self._noise(data)
        self.log("serial_rx", hex=data.hex())
        return self._noise(self.dsp.receive(data, gap))

    # -- data channel -----------------------------------------------------------------------
    def data_in(self, data: bytes, delay_s: float = 0.0) -> None:
        """Data-channel bytes; `delay_s`: the bus held their DMA off that much longer
        than the host's refill latency (the PCI card's injected bus stall)."""
        try:
            blocks = self.block_decoder.feed(data)
        except P.BlockError as exc:
            self.log("data_error", error=str(exc))
            self.raise_fault(P.Fault.DATA_CRC, stroke=self.fpga.stroke)
            return
        for block in blocks:
            self.blocks_total += 1
            if block.kind == P.BLOCK_DATA:
                idx = self._stroke_blocks_received
                self._stroke_blocks_received += 1
                if idx < self.fpga.ring_blocks or idx - self.fpga.ring_blocks >= len(self._move_times):
                    ready = self.time
                else:
                    ready = self._move_times[idx - self.fpga.ring_blocks] + self.host_latency()
                ready += delay_s
            else:
                ready = self.time
            fault = self.fpga.accept(block, ready)
            if block.kind == P.BLOCK_FLUSH and fault == P.Fault.NONE:
                self._stroke_blocks_received = self.fpga.blocks_moved
                self._report(P.REPORT_FLUSHED)
            if fault != P.Fault.NONE:
                self.log("block_refused", stroke=block.stroke, first_fire=block.first_fire,
                         fault=fault.name)
                self.raise_fault(fault, stroke=block.stroke, column=block.first_fire)
            self.pump()
            if self.faults.data_drop_after is not None and \
                    self.blocks_total >= self.faults.data_drop_after:
                self.faults.data_drop_after = None      # one drop per injection
                self.data_link_lost()
                return

    def data_out(self) -> bytes:
        out = bytes(self._data_out)
        self._data_out.clear()
        return out

    def data_link_lost(self) -> None:
        self.log("data_link_lost")
        self.link_alive = False
        self.block_decoder = P.BlockDecoder()
        self.pump()

    def data_link_up(self) -> None:
        self.link_alive = True

    def host_latency(self) -> float:
        """Host DMA refill latency (docs/emulator.md): how long after a ring slot frees the
        host has the next block in it."""
        f = self.faults
        base = f.data_stall
        if f.host_jitter == "ideal":
            return base
        if f.host_jitter == "typical":
            lat = 150e-6 + self.rng.lognormvariate(math.log(300e-6), 0.8)
            if self.rng.random() < 1e-3:
                lat += self.rng.uniform(2e-3, 10e-3)
        else:  # loaded
            lat = 500e-6 + self.rng.lognormvariate(math.log(1.5e-3), 1.0)
            if self.rng.random() < 1e-2:
                lat += self.rng.uniform(5e-3, 30e-3)
        return base + lat

    def dma_time(self, block: P.Block) -> float:
        return (block.words.nbytes + P.BLOCK_HEADER.size + 4) / PCI_BYTES_S

    def on_block_moved(self, t: float) -> None:
        self._move_times.append(t)
        self._report(0)

    def _report(self, flags: int) -> None:
        f = self.fpga
        if f.underrun_mask:
            flags |= P.REPORT_UNDERRUN
        self._data_out += P.encode_report(flags, f.ring_free(), f.stroke, f.blocks_moved, f.fired,
                                          f.fifo_levels())

    def pump(self) -> None:
        """Let the line run as far as its data allows; move preloaded blocks into the FIFOs."""
        if self.line is not None and not self.line.done:
            ended = self.line.advance(self.link_alive)
            if ended:
                self.fpga.firing = False
                self._report(P.REPORT_STROKE_DONE if self.line.fault == P.Fault.NONE else 0)
            return
        while self.fpga.room_for_next() and self.fault == P.Fault.NONE:
            self.fpga.move_next()
            self._move_times.append(self.time)
            self._report(0)

    # -- faults -----------------------------------------------------------------------------
    def raise_fault(self, fault: P.Fault, head: int = 0xFF, stroke: int = 0,
                    column: int = 0) -> None:
        if self.fault != P.Fault.NONE:
            return
        self.fault, self.fault_head, self.fault_stroke, self.fault_column = fault, head, stroke, column
        if fault == P.Fault.FIFO_UNDERRUN and head != 0xFF:
            self.fpga.underrun_mask |= (1 << self.n_heads) - 1
        self.fpga.write_reg(P.REG_WE_EN, 0)
        if self.line is not None and not self.line.done:
            self.line.land_pending()
            self.line.done = True
            self.line.fault = fault
        self.motion = P.Motion.IDLE
        self.log("fault", fault=fault.name, head=head, stroke=stroke, column=column,
                 text=P.FAULT_TEXT[fault])

    def clear_fault(self) -> None:
        self.fault = P.Fault.NONE
        self.fault_head, self.fault_stroke, self.fault_column = 0xFF, 0, 0
        self.fpga.underrun_mask = 0
        for h in self.heads:
            h.temperature_c = min(h.temperature_c, h.overtemp_c - 5)

    # -- status -------------------------------------------------------------------------------
    def counter(self) -> int:
        return int(round(self.position)) - self.count_offset

    def status(self) -> P.Status:
        flags = 0
        for on, bit in ((self.enabled, P.FLAG_ENABLED), (self.homed, P.FLAG_HOMED),
                        (self.heads_configured(), P.FLAG_HEADS_CONFIGURED),
                        (self.paper_measured, P.FLAG_PAPER_MEASURED),
                        (self.line_done, P.FLAG_LINE_DONE), (self.feed_done, P.FLAG_FEED_DONE),
                        (self.job is not None, P.FLAG_JOB_OPEN),
                        (self.fault != P.Fault.NONE, P.FLAG_FAULT),
                        (self.service.capped, P.FLAG_CAPPED)):
            if on:
                flags |= bit
        motion = P.Motion.PRINTING if self.busy() else self.motion
        fires = self.fpga.fired
        return P.Status(P.Result.OK, flags, motion, self.counter(), 0, self.paper_steps,
                        self.fpga.stroke, fires, self.fault, self.fault_head, self.fault_stroke,
                        self.fault_column, self.fpga.ring_free(), self.fpga.fifo_levels())

    def paper_present(self) -> bool:
        return self.paper_left_steps is None or self.paper_left_steps > 0

    # -- motions ------------------------------------------------------------------------------
    def _mm_s(self, mm_s: float) -> float:
        return mm_s / 25.4 * self.profile.counts_per_inch

    def _move_to(self, target: float, speed: float | None = None) -> None:
        prof = self.profile
        v = speed or self._mm_s(prof.carriage.max_speed_mm_s)
        move = Trapezoid(self.position, target, v, prof.accel_counts_s2())
        self.time += move.duration
        self.position = float(target)

    def home(self) -> None:
        self._move_to(0.0, self._mm_s(HOME_SPEED_MM_S))
        self.count_offset = 0
        self.homed = True
        self.log("homed")

    def measure_paper(self) -> None:
        left, right = self.sheet
        self._move_to(min(self.profile.rail_counts, right + 600))
        self._move_to(max(0.0, left - 600))
        self.paper_edges = (int(math.ceil(left)) - self.count_offset,
                            int(math.floor(right)) - self.count_offset)
        self.paper_measured = True
        self.log("paper_measured", left=self.paper_edges[0], right=self.paper_edges[1])

    def park(self) -> P.Result:
        self._move_to(float(self.profile.carriage.park_counts) + self.count_offset)
        return P.Result.OK

    # -- the service station (docs/protocol.md 2.9) ---------------------------------------------
    def _masked(self, mask: int) -> list[int]:
        return [h for h in range(self.n_heads) if mask >> h & 1]

    def spit(self, drops: int, mask: int) -> P.Result:
        heads = self._masked(mask)
        if not 1 <= drops <= 10000 or not heads:
            return P.Result.BAD_ARGUMENT
        if self.service.capped:
            return P.Result.BAD_STATE
        self.park()
        printing = np.ones(self.profile.nozzles, bool)
        printing[list(self.profile.head.dead_end_nozzles)] = False
        self.service.spit(heads, drops, printing)
        return P.Result.OK

    def purge(self, ms: int, mask: int) -> P.Result:
        heads = self._masked(mask)
        if not 100 <= ms <= 10000 or not heads:
            return P.Result.BAD_ARGUMENT
        self.park()
        self.service.purge(heads, ms)
        return P.Result.OK

    def cap(self, on: int) -> P.Result:
        if on not in (0, 1):
            return P.Result.BAD_ARGUMENT
        if on:
            self.park()
        self.service.cap(bool(on))
        return P.Result.OK

    def feed(self, steps: int, profile: int, vmax: int, acc: int) -> P.Result:
        if not self.paper_present():
            self.raise_fault(P.Fault.PAPER_OUT)
            return P.Result.FAULT_ACTIVE
        made = steps
        if self.paper_left_steps is not None and steps > self.paper_left_steps:
            made = self.paper_left_steps
        run = feed_move(made, "sigmoid" if profile == 1 else "trapezoid", vmax, acc,
                        start_state=self.feed_state) if made else None
        if run is not None:
            if self.vcd is not None and self.vcd_feed:
                from .vcd import add_stepper
                add_stepper(self.vcd, ((self.time + run.step_times) * 1e9).astype(np.int64),
                            run.phases[:, :4])
                self.vcd_feed = False           # the first feed is enough to look at
            self.feed_state = run.end_state
            self.time += run.duration
        self.paper_steps += made
        row_um = self.job["row_nm"] / 1000 if self.job else self.profile.row_um
        self.paper_extra_nm += 1000 * self.physical.feed_error_um(
            made * self.profile.feed_um_per_step, row_um)
        if self.paper_left_steps is not None:
            self.paper_left_steps -= made
        self.feed_done = True
        self.log("feed", steps=made, paper_steps=self.paper_steps)
        if made != steps:
            self.raise_fault(P.Fault.PAPER_OUT)
        self._flush_media()
        return P.Result.OK

    def set_line(self, stroke: int, direction: int, dpi: int, first: int, count: int,
                 speed: int, accel: int) -> P.Result:
        prof = self.profile
        if direction not in (0, 1) or dpi not in prof.dpi_modes or count == 0 or speed == 0 \
                or accel == 0:
            return P.Result.BAD_ARGUMENT
        k = prof.counts_per_inch // dpi
        ramp = ramp_counts(speed, accel, k)
        lo = first * k - ramp + self.count_offset
        hi = (first + count - 1) * k + ramp + self.count_offset
        if lo < 0 or hi > prof.rail_counts:
            return P.Result.OUT_OF_RANGE
        fp = self.fpga
        fp.regs[P.REG_STROKE_LO], fp.regs[P.REG_STROKE_HI] = stroke & 0xFFFF, stroke >> 16
        u = first & 0xFFFFFFFF
        fp.regs[P.REG_FIRE_START_LO], fp.regs[P.REG_FIRE_START_HI] = u & 0xFFFF, u >> 16
        fp.regs[P.REG_FIRE_COUNT_LO], fp.regs[P.REG_FIRE_COUNT_HI] = count & 0xFFFF, count >> 16
        fp.flush()
        self._stroke_blocks_received = 0
        self._move_times = []
        self.line = None
        self.line_done = False
        self.line_cfg = dict(stroke=stroke, direction=direction, dpi=dpi, first=first,
                             count=count, speed=speed, accel=accel, lo=lo, hi=hi)
        self.log("set_line", **{k: v for k, v in self.line_cfg.items()})
        return P.Result.OK

    def start_line(self) -> P.Result:
        cfg = self.line_cfg
        fp = self.fpga
        if cfg is None or fp.stroke != cfg["stroke"]:
            return P.Result.BAD_STATE
        if fp.forward != (cfg["direction"] == 0) or fp.dpi != cfg["dpi"] or not fp.we_en:
            return P.Result.BAD_STATE
        if not self.heads_configured():
            return P.Result.HEADS_NOT_CONFIGURED
        start, end = (cfg["lo"], cfg["hi"]) if cfg["direction"] == 0 else (cfg["hi"], cfg["lo"])
        self._move_to(float(start))
        move = ServoMove(self.servo, start - self.count_offset, end - self.count_offset,
                         cfg["speed"], cfg["accel"])
        self.fpga.firing = True
        self.line_done = False
        self.motion = P.Motion.PRINTING
        self.line = LineRun(self, move, self.time, cfg["speed"], cfg["accel"])
        self.line_cfg = None       # a line runs once
        self.pump()
        return P.Result.OK

    def stop_motion(self) -> None:
        """STOP: heads off, a running line ends where it is (the carriage brakes)."""
        self.fpga.write_reg(P.REG_WE_EN, 0)
        line = self.line
        if line is not None and not line.done:
            line.land_pending()
            line.done = True
            self.fpga.firing = False
            self.motion = P.Motion.IDLE
            self.log("line", stroke=line.stroke, forward=line.forward,
                     first_column=int(line.first), fires=int(line.n), fired=int(self.fpga.fired),
                     fault="STOPPED", pauses=line.pauses, min_fifo_words=None)

    def carriage_park_at(self, counter_position: float, t: float) -> None:
        """The carriage braked to a stop inside a line (starved); the line stays active."""
        self.position = counter_position + self.count_offset
        self.time = max(self.time, t)

    def move_carriage_to(self, counter_position: float) -> None:
        self._move_to(counter_position + self.count_offset)

    def carriage_stop(self, counter_position: float, t: float) -> None:
        self.position = counter_position + self.count_offset
        self.time = max(self.time, t)
        self.motion = P.Motion.IDLE
        line = self.line
        if line is not None and line.fault == P.Fault.NONE:
            self.line_done = True
            if line is not self._line_counted and self.job is not None and \
                    self.fpga.fired == line.n:
                self._line_counted = line        # a whole line of the open job (2.10)
                self.job_account.update(lines_done=self.job_account["lines_done"] + 1,
                                        last_stroke=line.stroke)
        self.fpga.firing = False

    # -- heads and media ------------------------------------------------------------------------
    def load_head_config(self, digits: list[int]) -> None:
        t0 = int(self.time * 1e9)
        for h in self.heads:
            trace = h.load_config(digits, t0)
        self.config_traces.append(trace)
        if self.vcd is not None:
            from .vcd import add_config_load
            add_config_load(self.vcd, self.profile.heads[self.vcd_window[1]].name, trace.digits,
                            trace.dstb_rise_ns, trace.data_nconfig_rise_ns)
        self.fpga.configured_mask = (1 << self.n_heads) - 1
        self.time = trace.data_nconfig_rise_ns / 1e9
        self.log("head_config", digits=len(digits), first=digits[:5])

    def latched_words(self, stroke: int) -> np.ndarray:
        """(heads, fires, 8): what each head latched in a stroke, in firing order."""
        items = sorted(self.latched.get(stroke, []), key=lambda it: it[0])
        parts = [w for _, w in items]
        return np.concatenate(parts, axis=1) if parts else np.zeros((self.n_heads, 0, 8), np.uint16)

    def job_begin(self, job: int, x0: int, width: int, height: int, dpi: int, row_nm: int,
                  y0: int) -> None:
        if self.job is not None and self.job["job"] == job and (
                x0, width, height, dpi, row_nm, y0) == tuple(self.job[k] for k in (
                "x0", "width", "height", "dpi", "row_nm", "y0")):
            return                      # the host reconnected and said it again
        self._close_media()
        # a new job starts with no stroke of its own: an earlier job's last stroke (same
        # number, same fire count) must not look like this job's (docs/protocol.md JOB_BEGIN)
        self.line_done = False
        self.fpga.clear_stroke()
        self.fpga.clear_fire_delays()
        self._close_scan()
        self.job = dict(job=job, x0=x0, width=width, height=height, dpi=dpi, row_nm=row_nm,
                        y0=y0, paper0=self.paper_steps, k=self.profile.counts_per_inch // dpi)
        self.job_account = dict(job=job, job_state=P.JobState.OPEN, lines_done=0,
                                last_stroke=P.NO_STROKE)
        self._extra0 = self.paper_extra_nm
        path = self.media_path(job) if callable(self.media_path) else self.media_path
        geo = self.geometry = self.physical.job_geometry(x0, self.job["k"], y0, row_nm, width, height)
        # drops pushed up the paper (negative y offsets) land on rows this much above slot 0
        self._y_slack_nm = 1000 * max(0.0, -min(float(geo.static_dy_um(h).min())
                                                for h in range(self.n_heads)))
        # the window: the swath, what drops pushed up (slack) or down (a head's or nozzle's
        # y offset, the feed's error) may reach, and a margin; rows leave it at each feed
        self.media = Media(width, height, dpi, 25.4e6 / row_nm,
                           window_rows=self.profile.swath_rows + MEDIA_MARGIN_ROWS
                           + int(self._y_slack_nm // row_nm), path=path)
        scan = self.scan_path(job) if callable(self.scan_path) else self.scan_path
        spectro = self.spectro_path(job) if callable(self.spectro_path) else self.spectro_path
        if scan or spectro:
            from .spectro import open_instruments
            self.scanner = open_instruments(
                self.profile, self.faults, geo, dot_diameter_um(self.profile, self.faults),
                scan and (scan, self.scan_dpi), spectro and (spectro, self.spectro_dpi),
                slack_um=self._y_slack_nm / 1000, swath_um=self.profile.swath_rows * row_nm / 1000)
        self.log("job_begin", **self.job)

    def _close_media(self) -> str:
        """The open media file completed; '' or why it could not be written (a full disk):
        the emulator records the failure (event `media_error`, the job's `media_error`) and
        goes on — the printer itself is not wedged by its recorder's disk."""
        media = self.media
        if media is None:
            return ""
        try:
            media.close()
            return ""
        except (OSError, RuntimeError, ValueError) as exc:
            self.log("media_error", path=media.path, error=str(exc))
            return f"{media.path}: {exc}"

    def job_end(self, job: int) -> None:
        self.before_job_end()
        if self.media:
            error = self._close_media()
            cpi = self.profile.counts_per_inch
            stats = dict(drops=[int(d) for d in self.media.drops], stray=self.media.stray,
                         late=self.media.late, path=None if error else self.media.path,
                         media_error=error or None,
                         # where the image area sat: its left edge from the measured paper
                         # edge, and image row 0's paper position after JOB_BEGIN
                         left_mm=round((self.job["x0"] - self.paper_edges[0]) / cpi * 25.4, 3),
                         lead_mm=round(self.job["y0"] * self.job["row_nm"] / 1e6, 3))
            if self.scanner is not None:
                stats["scan"] = self.scanner.path
            self._close_scan()
            self.jobs_done[job] = stats
            self.log("job_end", job=job, **stats)
        if self.job is not None and self.job["job"] == job:
            self.job_account["job_state"] = P.JobState.ENDED
        self.media = None
        self.job = None

    def abandon_job(self) -> None:
        """The host gave up on the open job (it failed or was cancelled and will not be
        resumed): its media file is completed with what landed and blank paper after it,
        so what the printer did can be inspected (app/api.py)."""
        self._close_scan()
        if self.media:
            self._close_media()
            self.log("job_abandoned", job=self.job["job"] if self.job else None,
                     drops=[int(d) for d in self.media.drops])
        if self.job is not None:
            self.job_account["job_state"] = P.JobState.ENDED
        self.media = None
        self.job = None

    # -- hooks for live views (app/gui/workers.LivePrinter) --------------------------------
    def before_media_flush(self) -> None:
        """Called before rows the paper has carried past the heads are written out."""

    def before_job_end(self) -> None:
        """Called before the job's media is closed."""

    def _close_scan(self) -> None:
        if self.scanner is not None:
            self.scanner.close()
            for inst in getattr(self.scanner, "instruments", (self.scanner,)):
                self.log(getattr(inst, "event", "scan"), path=inst.path, dpi=inst.dpi,
                         drops=inst.drops, late=inst.late)
            self.scans[self.scanner.path] = self.scanner       # closed: its geometry, for tests
            self.scanner = None

    def paper_nm(self) -> float:
        """The paper's travel since JOB_BEGIN: its feed steps, plus the injected feed error."""
        return ((self.paper_steps - self.job["paper0"]) * self.profile.feed_um_per_step * 1000
                + self.paper_extra_nm - self._extra0)

    def _flush_media(self) -> None:
        if self.media and self.job:
            self.before_media_flush()
            paper_nm = self.paper_nm()
            self.media.flush_below(int(math.floor((paper_nm - self._y_slack_nm) / self.job["row_nm"]))
                                   - self.job["y0"])
            if self.scanner is not None:
                self.scanner.flush_below(paper_nm / 1000 - self.job["y0"] * self.job["row_nm"] / 1000)

    def land_drops(self, head: int, columns: np.ndarray, words: np.ndarray, forward: bool,
                   velocity: np.ndarray | None = None, line_speed: float = 0.0) -> None:
        """Drops of one head for fires at these trigger columns: words (fires, 8); the
        carriage's signed speed at each fire and the line's speed (counts/s) place them
        physically when a scan is made (docs/physical.md)."""
        prof, job = self.profile, self.job
        hd = self.heads[head]
        hd.fires += columns.size
        words = self.service.misfire(head, words)       # dried or clogged nozzles
        if hd.dead:
            words = words.copy()
            for z in hd.dead:                      # a dead nozzle never drops
                words[:, z >> 4] &= ~np.uint16(1 << (z & 15))
        if job is None or self.media is None:
            n = int(np.unpackbits(words.view(np.uint8)).sum())
            if n:
                self.log("drops_without_job", head=head, drops=n)
            return
        h = prof.heads[head]
        # where the drops really land.  The emulated machine is perfectly built unless a
        # misalignment is injected (docs/physical.md): reverse drops land `bidir-error`
        # early, a head sits `head-error` counts or `head-offset` off, a nozzle is
        # misdirected, the paper travels `feed-error` further.  The media holds each drop
        # in the cell of its static position.  The profile's calibration (bidir offset,
        # head x) is the RIP's business: a profile that matches the machine prints exactly.
        # A fire delay (FIRE_DELAY registers, docs/calibration.md) lands the drops v t
        # further along the travel: in the media by the line's nominal speed.
        paper_nm = self.paper_nm()
        delay = self.fpga.fire_delay_s(head, forward)
        shift = (1.0 if forward else -1.0) * line_speed * delay          # counts
        dcol, rows = self.geometry.grid(head, h.x_counts, self.physical.slots[head], forward,
                                        paper_nm, shift)
        self.media.land_words(h.channel, words, columns, rows, dcol)
        if self.scanner is not None and velocity is not None:
            x, y, size = self.physical.land(self.geometry, head, columns, words, forward,
                                            velocity, line_speed, paper_nm / 1000, delay,
                                            sizes=True)
            self.scanner.splat(h.channel, x, y, size)
