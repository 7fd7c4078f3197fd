"""The command channel, host side (docs/protocol.md section 2): handshake, framing,
stop-and-wait with at most 3 tries per frame (seed 004), parameter echo checks."""

from __future__ import annotations

import logging
import struct
import threading
import time

from . import protocol as P

log = logging.getLogger("wideprint.link")

# commands whose response must echo the command payload (docs/protocol.md 2.3)
ECHOED = {P.Op.SET_LINE, P.Op.FEED, P.Op.WRITE_REG, P.Op.JOB_BEGIN, P.Op.JOB_END,
          P.Op.ENABLE, P.Op.SET_BAUD, P.Op.HEAD_CONFIG_LOAD}


class LinkError(ConnectionError):
    """The command channel failed: 3 tries of one frame, no handshake, or a bad echo."""


class DeviceError(RuntimeError):
    """The DSP refused a command with a result code."""

    def __init__(self, op: int, result: int):
        self.op, self.result = op, result
        try:
            rname = P.Result(result).name
        except ValueError:
            rname = f"result 0x{result:02X}"
        super().__init__(f"printer refused {P.op_name(op)}: {rname}")


class CommandLink:
    def __init__(self, port, response_timeout: float = 0.25, tries: int = P.MAX_TRIES):
        self.port = port
        self.timeout = response_timeout
        self.tries = tries
        self.seq = 0
        self.decoder = P.FrameDecoder()
        self.retries = 0          # retransmissions made (telemetry)
        self.frames = 0
        self._lock = threading.RLock()   # one command at a time, from any thread (ESTOP)
        # an in-process device answers synchronously: no answer now means none is coming
        self.synchronous = bool(getattr(port, "synchronous", False))

    def _frame_time(self, nbytes: int) -> float:
        baud = getattr(self.port, "baudrate", P.DEFAULT_BAUD) or P.DEFAULT_BAUD
        return nbytes * 10 / baud

    def handshake(self) -> None:
        with self._lock:
            self._handshake()

    def _handshake(self) -> None:
        for _ in range(self.tries):
            self.port.reset_input_buffer()
            self.port.write(bytes((P.HANDSHAKE_REQUEST,)))
            deadline = time.monotonic() + self.timeout
            while True:
                data = self.port.read(max(1, getattr(self.port, "in_waiting", 0)))
                if P.HANDSHAKE_REPLY in data:
                    self.decoder.reset()
                    return
                if (self.synchronous and not data) or time.monotonic() > deadline:
                    break
        raise LinkError(f"no printer answered the handshake on {getattr(self.port, 'port', self.port)}")

    def command(self, op: P.Op, payload: bytes = b"") -> bytes:
        """Send one command, return the response data after the result byte."""
        with self._lock:
            return self._command(op, payload)

    def _command(self, op: P.Op, payload: bytes) -> bytes:
        frame = P.Frame(self.seq, P.Kind.COMMAND, op, payload).encode()
        seq = self.seq
        self.seq = (self.seq + 1) & 0xFF
        self.frames += 1
        for attempt in range(self.tries):
            if attempt:
                self.retries += 1
            self.port.write(frame)
            resp = self._await(seq, op, len(frame))
            if resp is None:
                continue
            result, data = resp.payload[0], resp.payload[1:]
            if result != P.Result.OK:
                raise DeviceError(op, result)
            if op in ECHOED and data[:len(payload)] != payload:
                raise LinkError(f"{P.op_name(op)}: the printer echoed different parameters")
            return data
        raise LinkError(f"{P.op_name(op)}: no valid answer after {self.tries} tries")

    def _await(self, seq: int, op: int, sent: int) -> P.Frame | None:
        deadline = time.monotonic() + self.timeout + self._frame_time(sent + 64)
        bad0 = self.decoder.bad
        while True:
            waiting = getattr(self.port, "in_waiting", 0)
            data = self.port.read(max(1, waiting))
            for fr in self.decoder.feed(data):
                if fr.kind == P.Kind.NAK:
                    return None
                if fr.kind == P.Kind.RESPONSE and fr.seq == seq and fr.op == op and fr.payload:
                    return fr
            if self.decoder.bad != bad0:
                # a damaged answer: retransmit now rather than wait out the timeout
                self.decoder.reset()
                return None
            if self.synchronous and not data:
                self.decoder.reset()
                return None
            if time.monotonic() > deadline:
                self.decoder.reset()
                return None

    # -- typed helpers ----------------------------------------------------------------------
    def identify(self) -> dict:
        v = struct.unpack(P.IDENTIFY_FMT, self.command(P.Op.IDENTIFY))
        keys = ("proto_major", "proto_minor", "firmware", "serial", "heads", "nozzles",
                "fifo_words", "pass_buffer_words", "ring_blocks", "block_fires", "dpi_mask",
                "counts_per_inch")
        info = dict(zip(keys, v))
        info["serial"] = info["serial"].rstrip(b"\0").decode("ascii", "replace")
        if info["proto_major"] != P.PROTOCOL_VERSION[0]:
            raise LinkError(f"printer speaks protocol {info['proto_major']}.{info['proto_minor']}, "
                            f"this host {P.PROTOCOL_VERSION[0]}.{P.PROTOCOL_VERSION[1]}")
        return info

    def status(self) -> P.Status:
        return P.Status.decode(bytes((P.Result.OK,)) + self.command(P.Op.GET_STATUS))

    def write_reg(self, addr: int, value: int) -> None:
        self.command(P.Op.WRITE_REG, struct.pack("<HH", addr, value))

    def read_reg(self, addr: int) -> int:
        a, v = struct.unpack("<HH", self.command(P.Op.READ_REG, struct.pack("<H", addr)))
        return v
