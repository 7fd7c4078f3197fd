"""The DSP's serial command interpreter (docs/protocol.md section 2).

Byte stream in, byte stream out: the 5AH/55H handshake, frames with CRC16, NAK on damaged
frames, at-most-once execution (a retransmitted SEQ gets the remembered response), and the
command set.  Motion itself is in printer.py / line.py; this module decodes and checks.
"""

from __future__ import annotations

import struct

from ..driver import protocol as P

FIRMWARE_VERSION = 0x0100
SERIAL_NUMBER = b"WP3400-EMU-0001"


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
        try:
            payload = self.execute(frame.op, frame.payload)
        except struct.error:
            payload = bytes((P.Result.BAD_LENGTH,))
        response = P.Frame(frame.seq, P.Kind.RESPONSE, frame.op, payload).encode()
        self.last_seq, self.last_response = frame.seq, response
        self.printer.log("command", seq=frame.seq, op=P.op_name(frame.op),
                         payload=frame.payload.hex(), result=payload[0])
        return response

    # -- the command set (docs/protocol.md 2.5) ---------------------------------------------
    def execute(self, op: int, payload: bytes) -> bytes:
        pr = self.printer
        ok = bytes((P.Result.OK,))

        def res(code: P.Result) -> bytes:
            return bytes((code,))

        def need_empty() -> None:
            if payload:
                raise struct.error("no payload expected")

        if op not in P.Op._value2member_map_:
            return res(P.Result.UNKNOWN_OPCODE)
        if op == P.Op.IDENTIFY:
            need_empty()
            prof = pr.profile
            modes = sum(1 << i for i, d in enumerate((150, 300, 600)) if d in prof.dpi_modes)
            return ok + struct.pack(P.IDENTIFY_FMT, *P.PROTOCOL_VERSION, FIRMWARE_VERSION,
                                    SERIAL_NUMBER, pr.n_heads, prof.nozzles, pr.fpga.fifo_words,
                                    pr.fpga.pass_buffer_words, pr.fpga.ring_blocks,
                                    prof.block_fires, modes, prof.counts_per_inch)
        if op == P.Op.PING:
            return ok + payload
        if op == P.Op.GET_STATUS:
            need_empty()
            return pr.status().encode()
        if op == P.Op.READ_REG:
            (addr,) = struct.unpack("<H", payload)
            value = pr.fpga.read_reg(addr)
            if value is None:
                return res(P.Result.BAD_ARGUMENT)
            return ok + struct.pack("<HH", addr, value)
        if op == P.Op.HEAD_STATUS:
            need_empty()
            body = b"".join(struct.pack(P.HEAD_STATUS_FMT, int(round(h.temperature_c * 10)),
                                        int(round(h.piezo_v * 10)),
                                        int(h.configured) | int(h.overtemp) << 1 |
                                        int(bool(h.dead)) << 2) for h in pr.heads)
            return ok + body
        if op == P.Op.CLEAR_FAULT:
            need_empty()
            cleared = pr.fault
            pr.clear_fault()
            return ok + bytes((cleared,))
        if op == P.Op.ESTOP:
            need_empty()
            pr.raise_fault(P.Fault.ESTOP)
            pr.enabled = False
            return ok
        if op == P.Op.STOP:
            need_empty()
            pr.stop_motion()
            return ok
        if op == P.Op.SET_BAUD:
            (baud,) = struct.unpack("<I", payload)
            if baud not in P.SUPPORTED_BAUDS:
                return res(P.Result.BAD_ARGUMENT)
            pr.baud = baud
            return ok + payload
        if op == P.Op.HEAD_CONFIG_DATA:
            (first,) = struct.unpack_from("<H", payload)
            digits = [d for b in payload[2:] for d in (b & 0x0F, b >> 4)]
            if first == 0:
                self.config_digits = []
            if first != len(self.config_digits) or first + len(digits) > 1022:
                return res(P.Result.BAD_ARGUMENT)
            self.config_digits += digits
            return ok + struct.pack("<H", len(self.config_digits))
        if op == P.Op.HEAD_CONFIG_LOAD:
            count, crc = struct.unpack("<HI", payload)
            digits = self.config_digits[:count]
            if len(digits) != count or P.crc32(P.pack_digits(digits)) != crc:
                return res(P.Result.CONFIG_CRC)
            if pr.busy():
                return res(P.Result.BUSY)
            pr.load_head_config(digits)
            return ok + payload

        # everything below moves or arms something: refused while a fault is latched
        if pr.fault != P.Fault.NONE:
            return res(P.Result.FAULT_ACTIVE)
        if op == P.Op.WRITE_REG:
            addr, value = struct.unpack("<HH", payload)
            if addr == P.REG_WE_EN and value == 1 and not pr.heads_configured():
                pr.raise_fault(P.Fault.HEAD_CONFIG)
                return res(P.Result.HEADS_NOT_CONFIGURED)
            if not pr.fpga.write_reg(addr, value):
                return res(P.Result.BAD_ARGUMENT)
            pr.log("register", addr=f"{addr:04X}", value=value)
            return ok + payload
        if op == P.Op.ENABLE:
            (on,) = struct.unpack("<B", payload)
            if on not in (0, 1):
                return res(P.Result.BAD_ARGUMENT)
            pr.enabled = bool(on)
            return ok + payload
        if op == P.Op.JOB_BEGIN:
            fields = struct.unpack(P.JOB_BEGIN_FMT, payload)
            pr.job_begin(*fields)
            return ok + payload
        if op == P.Op.JOB_END:
            (job,) = struct.unpack("<I", payload)
            pr.job_end(job)
            return ok + payload
        # motion commands
        if not pr.enabled:
            return res(P.Result.NOT_ENABLED)
        if pr.busy():
            return res(P.Result.BUSY)
        if op == P.Op.HOME:
            need_empty()
            pr.home()
            return ok
        if not pr.homed:
            return res(P.Result.NOT_HOMED)
        if op == P.Op.MEASURE_PAPER:
            need_empty()
            pr.measure_paper()
            return ok
        if op == P.Op.GET_PAPER:
            need_empty()
            return ok + struct.pack(P.PAPER_FMT, int(pr.paper_present()), *pr.paper_edges)
        if op == P.Op.PARK:
            need_empty()
            return res(pr.park())
        if op == P.Op.FEED:
            steps, profile, vmax, acc = struct.unpack(P.FEED_FMT, payload)
            if profile not in (0, 1) or vmax == 0 or acc == 0:
                return res(P.Result.BAD_ARGUMENT)
            code = pr.feed(steps, profile, vmax, acc)
            return bytes((code,)) + (payload if code == P.Result.OK else b"")
        if op == P.Op.SET_LINE:
            fields = struct.unpack(P.SET_LINE_FMT, payload)
            code = pr.set_line(*fields)
            return bytes((code,)) + (payload if code == P.Result.OK else b"")
        if op == P.Op.START_LINE:
            need_empty()
            code = pr.start_line()
            return bytes((code,)) + (struct.pack("<I", pr.fpga.pass_id) if code == P.Result.OK else b"")
        return res(P.Result.UNKNOWN_OPCODE)
