"""The DSP's serial command interpreter (docs/protocol.md section 2).

Byte stream in, byte stream out: the 5AH/55H handshake, frames with CRC16, NAK on damaged
frames, at-most-once execution (a retransmitted SEQ gets the remembered response), and the
command set: one handler per opcode, payloads decoded and encoded from the declarations in
driver/protocol.py.  Motion itself is in printer.py / line.py; this module decodes and checks.
"""

from __future__ import annotations

from typing import Callable

from ..driver import protocol as P

FIRMWARE_VERSION = 0x0100
SERIAL_NUMBER = b"WP3400-EMU-0001"

# Refusals checked before a command runs, each level adding to the one before (2.4):
FREE = 0         # always executed
ARMS = 1         # FAULT_ACTIVE while a fault is latched
MOVES = 2        # ... NOT_ENABLED, BUSY while a line runs
NEEDS_HOME = 3   # ... NOT_HOMED

_HANDLERS: dict[int, tuple[Callable, int]] = {}


def handles(op: P.Op, gate: int = FREE):
    """Register a Dsp method as the handler of `op` (Klipper's DECL_COMMAND, device side)."""
    def register(fn):
        _HANDLERS[op] = (fn, gate)
        return fn
    return register


class Dsp:
    def __init__(self, printer):
        self.printer = printer
        self.decoder = P.FrameDecoder()
        self.last_seq: int | None = None
        self.last_response: bytes | None = None
        self.config_digits: list[int] = []

    # -- bytes in, bytes out ----------------------------------------------------------------
    def receive(self, data: bytes, gap: bool = False) -> bytes:
        """`gap`: the line was idle for longer than the inter-frame timeout (20 character
        times, docs/protocol.md 2.2) before these bytes, so a frame still incomplete from
        before is dropped (and NAKed) rather than glued to new bytes."""
        out = bytearray()
        if gap and self.decoder.pending():
            self.decoder.reset()
            out += P.Frame(0, P.Kind.NAK, 0, b"\x03").encode()
            self.printer.log("nak", reason="timeout")
        # the handshake byte is answered only between frames (docs/protocol.md 2.1)
        if self.decoder.pending() == 0:
            sync = data.find(P.SYNC)
            between = data if sync < 0 else data[:sync]
            for _ in range(between.count(P.HANDSHAKE_REQUEST)):
                out.append(P.HANDSHAKE_REPLY)
                self.printer.log("handshake")
        bad_before = self.decoder.bad
        frames = self.decoder.feed(data)
        for _ in range(self.decoder.bad - bad_before):
            out += P.Frame(0, P.Kind.NAK, 0, b"\x01").encode()
            self.printer.log("nak")
        for frame in frames:
            out += self.handle(frame)
        return bytes(out)

    def handle(self, frame: P.Frame) -> bytes:
        if frame.kind != P.Kind.COMMAND:
            return b""
        if frame.seq == self.last_seq and self.last_response is not None:
            self.printer.log("retransmission", seq=frame.seq, op=frame.op)
            return self.last_response
        payload = self.execute(frame.op, frame.payload)
        response = P.Frame(frame.seq, P.Kind.RESPONSE, frame.op, payload).encode()
        self.last_seq, self.last_response = frame.seq, response
        self.printer.log("command", seq=frame.seq, op=P.op_name(frame.op),
                         payload=frame.payload.hex(), result=payload[0])
        return response

    # -- the command set (docs/protocol.md 2.5) ---------------------------------------------
    def execute(self, op: int, payload: bytes) -> bytes:
        """One command's response payload: refusals in the order below, then the request
        decoded from its declaration (driver/protocol.py), the handler, and the response
        encoded from its declaration (data only with OK; an echo repeats the request)."""
        entry = _HANDLERS.get(op)
        if entry is None:
            return bytes((P.Result.UNKNOWN_OPCODE,))
        handler, gate = entry
        refused = self._refusal(gate)
        if refused is not None:
            return bytes((refused,))
        try:
            request = P.decode_request(op, payload)
        except P.BadLength:
            return bytes((P.Result.BAD_LENGTH,))
        fields = request._asdict()
        out = handler(self, **fields)
        if isinstance(out, dict):
            return bytes((P.Result.OK,)) + P.encode_response(op, **out)
        if isinstance(out, tuple):
            return bytes((P.Result.OK,)) + P.COMMANDS[op].response.encode_values(out)
        if out != P.Result.OK:
            return bytes((out,))
        echo = P.COMMANDS[op].echo
        return bytes((P.Result.OK,)) + P.encode_response(op, **(fields if echo else {}))

    def _refusal(self, gate: int) -> P.Result | None:
        pr = self.printer
        if gate >= ARMS and pr.fault != P.Fault.NONE:
            return P.Result.FAULT_ACTIVE
        if gate >= MOVES:
            if not pr.enabled:
                return P.Result.NOT_ENABLED
            if pr.busy():
                return P.Result.BUSY
        if gate >= NEEDS_HOME and not pr.homed:
            return P.Result.NOT_HOMED
        return None

    # Handlers get the request's declared fields by name and return a Result (with OK an
    # echoed command echoes, others answer their empty layout) or the response fields: a
    # dict by name or a tuple in declared order.
    @handles(P.Op.IDENTIFY)
    def identify(self):
        pr = self.printer
        prof = pr.profile
        major, minor = P.PROTOCOL_VERSION
        modes = sum(1 << i for i, d in enumerate((150, 300, 600)) if d in prof.dpi_modes)
        return dict(proto_major=major, proto_minor=minor, firmware=FIRMWARE_VERSION,
                    serial=SERIAL_NUMBER, heads=pr.n_heads, nozzles=prof.nozzles,
                    fifo_words=pr.fpga.fifo_words, pass_buffer_words=pr.fpga.pass_buffer_words,
                    ring_blocks=pr.fpga.ring_blocks, block_fires=prof.block_fires,
                    dpi_mask=modes, counts_per_inch=prof.counts_per_inch)

    @handles(P.Op.PING)
    def ping(self, data):
        return P.Result.OK

    @handles(P.Op.GET_STATUS)
    def get_status(self):
        return self.printer.status().response_values()

    @handles(P.Op.READ_REG)
    def read_reg(self, addr):
        value = self.printer.fpga.read_reg(addr)
        if value is None:
            return P.Result.BAD_ARGUMENT
        return dict(addr=addr, value=value)

    @handles(P.Op.HEAD_STATUS)
    def head_status(self):
        return dict(heads=[(int(round(h.temperature_c * 10)), int(round(h.piezo_v * 10)),
                            int(h.configured) | int(h.overtemp) << 1 | int(bool(h.dead)) << 2)
                           for h in self.printer.heads])

    @handles(P.Op.CLEAR_FAULT)
    def clear_fault(self):
        cleared = self.printer.fault
        self.printer.clear_fault()
        return dict(fault=cleared)

    @handles(P.Op.ESTOP)
    def estop(self):
        self.printer.raise_fault(P.Fault.ESTOP)
        self.printer.enabled = False
        return P.Result.OK

    @handles(P.Op.STOP)
    def stop(self):
        self.printer.stop_motion()
        return P.Result.OK

    @handles(P.Op.SET_BAUD)
    def set_baud(self, baud):
        if baud not in P.SUPPORTED_BAUDS:
            return P.Result.BAD_ARGUMENT
        self.printer.baud = baud
        return P.Result.OK

    @handles(P.Op.HEAD_CONFIG_DATA)
    def head_config_data(self, first, digits):
        # digits from `first` on are (re)written: a host resending a chunk whose answer it
        # lost, after a reconnect, gets the same result (docs/protocol.md 2.5)
        if first > len(self.config_digits) or first + len(digits) > 1022:
            return P.Result.BAD_ARGUMENT
        self.config_digits[first:] = digits
        return dict(held=len(self.config_digits))

    @handles(P.Op.HEAD_CONFIG_LOAD)
    def head_config_load(self, count, crc):
        pr = self.printer
        digits = self.config_digits[:count]
        if len(digits) != count or P.crc32(P.pack_digits(digits)) != crc:
            return P.Result.CONFIG_CRC
        if pr.busy():
            return P.Result.BUSY
        pr.load_head_config(digits)
        return P.Result.OK

    # everything below moves or arms something: refused while a fault is latched
    @handles(P.Op.WRITE_REG, ARMS)
    def write_reg(self, addr, value):
        pr = self.printer
        if addr == P.REG_WE_EN and value == 1 and not pr.heads_configured():
            pr.raise_fault(P.Fault.HEAD_CONFIG)
            return P.Result.HEADS_NOT_CONFIGURED
        if not pr.fpga.write_reg(addr, value):
            return P.Result.BAD_ARGUMENT
        pr.log("register", addr=f"{addr:04X}", value=value)
        return P.Result.OK

    @handles(P.Op.ENABLE, ARMS)
    def enable(self, on):
        if on not in (0, 1):
            return P.Result.BAD_ARGUMENT
        self.printer.enabled = bool(on)
        return P.Result.OK

    @handles(P.Op.JOB_BEGIN, ARMS)
    def job_begin(self, job, x0, width, height, dpi, row_nm, y0):
        self.printer.job_begin(job, x0, width, height, dpi, row_nm, y0)
        return P.Result.OK

    @handles(P.Op.JOB_END, ARMS)
    def job_end(self, job):
        self.printer.job_end(job)
        return P.Result.OK

    # motion commands: also refused when not enabled or busy
    @handles(P.Op.HOME, MOVES)
    def home(self):
        if self.printer.service.capped:
            return P.Result.BAD_STATE
        self.printer.home()
        return P.Result.OK

    # and when not homed
    @handles(P.Op.MEASURE_PAPER, NEEDS_HOME)
    def measure_paper(self):
        if self.printer.service.capped:
            return P.Result.BAD_STATE
        self.printer.measure_paper()
        return P.Result.OK

    @handles(P.Op.GET_PAPER, NEEDS_HOME)
    def get_paper(self):
        left, right = self.printer.paper_edges
        return dict(present=int(self.printer.paper_present()), left=left, right=right)

    @handles(P.Op.PARK, NEEDS_HOME)
    def park(self):
        return self.printer.park()

    @handles(P.Op.FEED, NEEDS_HOME)
    def feed(self, steps, profile, max_rate, accel):
        if profile not in (0, 1) or max_rate == 0 or accel == 0:
            return P.Result.BAD_ARGUMENT
        return self.printer.feed(steps, profile, max_rate, accel)

    @handles(P.Op.SET_LINE, NEEDS_HOME)
    def set_line(self, stroke, direction, dpi, fire_start, fire_count, speed, accel):
        return self.printer.set_line(stroke, direction, dpi, fire_start, fire_count, speed, accel)

    @handles(P.Op.START_LINE, NEEDS_HOME)
    def start_line(self):
        if self.printer.service.capped:
            return P.Result.BAD_STATE
        code = self.printer.start_line()
        return dict(stroke=self.printer.fpga.stroke) if code == P.Result.OK else code

    # head care (section 2.9)
    @handles(P.Op.SPIT, NEEDS_HOME)
    def spit(self, drops, heads):
        return self.printer.spit(drops, heads)

    @handles(P.Op.PURGE, NEEDS_HOME)
    def purge(self, ms, heads):
        return self.printer.purge(ms, heads)

    @handles(P.Op.CAP, MOVES)
    def cap(self, on):
        if on and not self.printer.homed:    # capping moves to the park position
            return P.Result.NOT_HOMED
        return self.printer.cap(on)

    @handles(P.Op.SERVICE_STATUS)
    def service_status(self):
        return self.printer.service.status()

    @handles(P.Op.JOB_STATUS)
    def job_status(self):
        """The printer's account of its job (docs/protocol.md 2.10); answered whatever the
        printer's state, a latched fault included: it moves nothing."""
        return dict(boot=self.printer.boot, **self.printer.job_account)
