"""The command channel, host side (docs/protocol.md section 2): handshake, framing,
stop-and-wait with at most 3 tries per frame (seed 004), parameter echo checks.  Payloads
are encoded and decoded from the declarations in driver/protocol.py (section 2.5)."""

from __future__ import annotations

import collections
import logging
import math
import threading
import time

from . import protocol as P

log = logging.getLogger("wideprint.link")


class LinkError(ConnectionError):
    """The command channel failed: 3 tries of one frame, no handshake, or a bad echo."""


class LineTooNoisy(LinkError):
    """The serial line damages so many frames that the protocol cannot work over it; the
    message gives the measured bit error rate (docs/driver.md, "A noisy serial line")."""


class LineQuality:
    """The measured bit error rate of the command channel (docs/driver.md, "A noisy serial
    line").  Every try of a frame is a trial over the bits it put on the line (request and
    answer, 10 bits a byte with start and stop bits) that succeeds with probability
    (1 - p)^bits, so p = -ln(share of tries that succeeded) / mean bits a try.  The share
    is smoothed ((ok + 1/2) / (tries + 1)) so that a run of failures gives a finite, large
    estimate rather than none.  The window forgets old tries, so a line that recovers (a
    connector re-seated) is seen to."""

    WINDOW = 400                # tries remembered

    def __init__(self) -> None:
        self._tries: collections.deque = collections.deque(maxlen=self.WINDOW)

    def record(self, bits: int, ok: bool) -> None:
        self._tries.append((bits, ok))

    def reset(self) -> None:
        self._tries.clear()

    @property
    def tries(self) -> int:
        return len(self._tries)

    def bit_error_rate(self) -> float:
        n = len(self._tries)
        if not n:
            return 0.0
        ok = sum(1 for _, good in self._tries if good)
        if ok == n:
            return 0.0
        mean_bits = sum(b for b, _ in self._tries) / n
        return -math.log((ok + 0.5) / (n + 1)) / mean_bits

    def frame_success(self, nbytes: int) -> float:
        """Probability that a frame of nbytes crosses the line intact."""
        return (1.0 - min(self.bit_error_rate(), 1.0)) ** (10 * nbytes)


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
        self.frames_ok = 0        # commands answered (progress, for the job's recovery)
        self.quality = LineQuality()
        self._answer_sizes: dict[int, int] = {}   # last answer frame size per opcode
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

    def call(self, op: P.Op, **fields):
        """Send one command encoded from its declaration, return the decoded response
        record (docs/protocol.md 2.5); an echo is checked against what was sent (2.3)."""
        data = self.command(op, P.encode_request(op, **fields))
        try:
            return P.decode_response(op, data)
        except P.BadLength as exc:
            raise LinkError(f"{P.op_name(op)}: malformed answer: {exc}") from None

    def command(self, op: P.Op, payload: bytes = b"") -> bytes:
        """Send one command as raw payload bytes, return the response data after the
        result byte (echo checked)."""
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
                self.quality.record(10 * (len(frame) + self._answer_bytes(op, payload)), False)
                continue
            answer = len(resp.payload) + P.FRAME_OVERHEAD
            self._answer_sizes[op] = answer
            self.quality.record(10 * (len(frame) + answer), True)
            self.frames_ok += 1
            result, data = resp.payload[0], resp.payload[1:]
            if result != P.Result.OK:
                raise DeviceError(op, result)
            cmd = P.COMMANDS.get(op)
            if cmd is not None and cmd.echo and data != payload:
                raise LinkError(f"{P.op_name(op)}: the printer echoed different parameters")
            return data
        raise LinkError(f"{P.op_name(op)}: no valid answer after {self.tries} tries")

    def _answer_bytes(self, op: int, payload: bytes) -> int:
        """The answer frame a try of `op` expects, for the line-quality estimate: the
        echo, the declared fixed layout, or the last answer seen."""
        if op in self._answer_sizes:
            return self._answer_sizes[op]
        cmd = P.COMMANDS.get(op)
        body = len(payload) if cmd is not None and cmd.echo else \
            (cmd.response.size if cmd is not None else 0)
        return P.FRAME_OVERHEAD + 1 + body

    def check_line(self, largest_frame: int = 64) -> None:
        """LineTooNoisy when the measured error rate leaves a frame of `largest_frame`
        bytes (a status answer and its request) less than a 1 in 20 chance per try:
        then 3 tries fail more often than not and no amount of reconnecting helps."""
        q = self.quality
        if q.tries >= 12 and q.frame_success(largest_frame) < 0.05:
            raise LineTooNoisy(
                f"the serial line is too noisy: measured bit error rate {q.bit_error_rate():.1e} "
                f"({1 - q.frame_success(largest_frame):.0%} of {largest_frame}-byte frames "
                f"damaged); check the cable and its screening, or lower the baud rate")

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

    # -- typed helpers: thin wrappers over call() ----------------------------------------
    def identify(self) -> dict:
        info = self.call(P.Op.IDENTIFY)._asdict()
        if info["proto_major"] != P.PROTOCOL_VERSION[0]:
            raise LinkError(f"printer speaks protocol {info['proto_major']}.{info['proto_minor']}, "
                            f"this host {P.PROTOCOL_VERSION[0]}.{P.PROTOCOL_VERSION[1]}")
        return info

    def status(self) -> P.Status:
        return P.Status(P.Result.OK, *self.call(P.Op.GET_STATUS))

    def write_reg(self, addr: int, value: int) -> None:
        self.call(P.Op.WRITE_REG, addr=addr, value=value)

    def read_reg(self, addr: int) -> int:
        return self.call(P.Op.READ_REG, addr=addr).value

    def head_status(self) -> tuple:
        """One record per head: temperature (0.1 °C), piezo (0.1 V), flags."""
        return self.call(P.Op.HEAD_STATUS).heads

    def paper(self):
        """GET_PAPER: (present, left, right), edges in encoder counts."""
        return self.call(P.Op.GET_PAPER)
