"""The wire protocol shared by the host driver and the emulator (docs/protocol.md).

Only constants, the declaration of every command's payloads and pure codecs live here:
frames of the command channel (section 2), blocks and reports of the data channel
(section 3), the USB identity (section 1).  Neither side keeps state in this module; the
host's retry logic is in driver/link.py and the device's in device_sim/dsp.py.  This is the
seam between them: it imports nothing from wideprint (tests/test_layers.py).
"""

from __future__ import annotations

import binascii
import enum
import operator
import re
import struct
import zlib
from collections import namedtuple
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields
from typing import Any, NamedTuple

import numpy as np

PROTOCOL_VERSION = (1, 2)      # 1.1: head care, section 2.9; 1.2: JOB_STATUS, 2.10

# -- section 1: the data channel's USB function ----------------------------------------------
USB_VID = 0x1209      # pid.codes, the open-hardware vendor id
USB_PID = 0x5750      # "WP"
EP_OUT, EP_IN = 0x01, 0x81   # bulk OUT: data blocks; bulk IN: FPGA reports

# -- section 2.1: handshake and framing -------------------------------------------------
HANDSHAKE_REQUEST = 0x5A   # seed 004: host sends 5AH ...
HANDSHAKE_REPLY = 0x55     # ... the DSP answers 55H
SYNC = 0x7E
MAX_PAYLOAD = 250
FRAME_OVERHEAD = 7          # SYNC LEN SEQ KIND OP + CRC16
DEFAULT_BAUD = 57600
SUPPORTED_BAUDS = (57600, 115200, 230400, 460800, 921600)
MAX_TRIES = 3               # seed 004: three consecutive failures abandon and report


NO_STROKE = 0xFFFFFFFF      # GET_STATUS stroke id after JOB_BEGIN, before the job's first line
NO_JOB = 0xFFFFFFFF         # JOB_STATUS job id before the first JOB_BEGIN since power-up


class JobState(enum.IntEnum):
    """JOB_STATUS job_state (section 2.10)."""
    NONE = 0        # no job since power-up
    OPEN = 1        # JOB_BEGIN, no JOB_END yet
    ENDED = 2       # ended by JOB_END


class Kind(enum.IntEnum):
    COMMAND = 0x43   # 'C' host -> DSP
    RESPONSE = 0x52  # 'R' DSP -> host, same SEQ as the command it answers
    NAK = 0x4E       # 'N' DSP -> host: a damaged frame arrived, retransmit


class Op(enum.IntEnum):
    IDENTIFY = 0x01
    SET_BAUD = 0x02
    ENABLE = 0x03
    HOME = 0x04
    MEASURE_PAPER = 0x05
    GET_PAPER = 0x06
    SET_LINE = 0x07
    START_LINE = 0x08
    FEED = 0x09
    WRITE_REG = 0x0A
    READ_REG = 0x0B
    HEAD_CONFIG_DATA = 0x0C
    HEAD_CONFIG_LOAD = 0x0D
    HEAD_STATUS = 0x0E
    GET_STATUS = 0x0F
    STOP = 0x10
    ESTOP = 0x11
    CLEAR_FAULT = 0x12
    PARK = 0x13
    JOB_BEGIN = 0x14
    JOB_END = 0x15
    PING = 0x16
    SPIT = 0x17             # head care (section 2.9), protocol 1.1
    PURGE = 0x18
    CAP = 0x19
    SERVICE_STATUS = 0x1A
    JOB_STATUS = 0x1B       # the printer's account of its job (section 2.10), protocol 1.2


def op_name(op: int) -> str:
    try:
        return Op(op).name
    except ValueError:
        return f"0x{op:02X}"


class Result(enum.IntEnum):
    OK = 0x00
    UNKNOWN_OPCODE = 0x01
    BAD_LENGTH = 0x02
    BAD_ARGUMENT = 0x03
    BUSY = 0x04
    NOT_ENABLED = 0x05
    NOT_HOMED = 0x06
    HEADS_NOT_CONFIGURED = 0x07
    FAULT_ACTIVE = 0x08
    BAD_STATE = 0x09
    OUT_OF_RANGE = 0x0A
    CONFIG_CRC = 0x0B


class Fault(enum.IntEnum):
    NONE = 0x00
    LIMIT_LEFT = 0x01
    LIMIT_RIGHT = 0x02
    PAPER_OUT = 0x03
    FIFO_UNDERRUN = 0x04
    FIFO_OVERFLOW = 0x05
    HEAD_OVERTEMP = 0x06
    HEAD_DATA = 0x07
    OVERSPEED = 0x08
    OVERCURRENT = 0x09
    FOLLOWING_ERROR = 0x0A
    DATA_CRC = 0x0B
    DATA_SEQUENCE = 0x0C
    ESTOP = 0x0D
    HEAD_CONFIG = 0x0E
    DATA_LINK_LOST = 0x0F
    ENCODER = 0x10


FAULT_TEXT = {
    Fault.NONE: "no fault",
    Fault.LIMIT_LEFT: "carriage hit the left limit switch",
    Fault.LIMIT_RIGHT: "carriage hit the right limit switch",
    Fault.PAPER_OUT: "paper out",
    Fault.FIFO_UNDERRUN: "head FIFO underrun (print data arrived too late)",
    Fault.FIFO_OVERFLOW: "head FIFO overflow (more data than announced)",
    Fault.HEAD_OVERTEMP: "head over-temperature",
    Fault.HEAD_DATA: "print word sets nozzle 0 or 127",
    Fault.OVERSPEED: "fire rate above the head's maximum",
    Fault.OVERCURRENT: "carriage motor over-current",
    Fault.FOLLOWING_ERROR: "carriage following error",
    Fault.DATA_CRC: "data block CRC error",
    Fault.DATA_SEQUENCE: "data block out of sequence",
    Fault.ESTOP: "emergency stop",
    Fault.HEAD_CONFIG: "head configuration not loaded",
    Fault.DATA_LINK_LOST: "data link lost during a line",
    Fault.ENCODER: "encoder glitch (impossible quadrature transition)",
}


class Motion(enum.IntEnum):
    IDLE = 0
    HOMING = 1
    MEASURING = 2
    MOVING = 3      # positioning move, heads off
    PRINTING = 4    # a print line: ramp, fire span, ramp
    FEEDING = 5
    STOPPING = 6
    SERVICING = 7   # SPIT, PURGE or CAP at the service station (section 2.9)


# STATUS flags (GET_STATUS, section 2.5)
FLAG_ENABLED = 1 << 0
FLAG_HOMED = 1 << 1
FLAG_HEADS_CONFIGURED = 1 << 2
FLAG_PAPER_MEASURED = 1 << 3
FLAG_LINE_DONE = 1 << 4
FLAG_FEED_DONE = 1 << 5
FLAG_JOB_OPEN = 1 << 6
FLAG_FAULT = 1 << 7
FLAG_CAPPED = 1 << 8     # the caps are up (section 2.9)

# -- section 2.6: FPGA registers in the DSP's I/O space (A15 = 1, A5..A0) ----------------
REG_STATUS = 0x8000       # read: D0 DIR, D1 DPI(600), D2 WE_EN, D3 DPI(300), D4 FIFO empty,
                          #       D5 underrun, D6 heads configured, D7 firing
REG_DIR = 0x8001          # 0x0001 forward, 0x0000 reverse
REG_DPI = 0x8002          # 0x0000 150 dpi, 0x0001 600 dpi (seed), 0x0002 300 dpi (extension)
REG_WE_EN = 0x8003        # 0x0001 print enable
REG_STROKE_LO = 0x8004    # the stroke the FIFOs are loaded for (extension)
REG_STROKE_HI = 0x8005
REG_FIRE_START_LO = 0x8006
REG_FIRE_START_HI = 0x8007
REG_FIRE_COUNT_LO = 0x8008
REG_FIRE_COUNT_HI = 0x8009
REG_FIFO_FLUSH = 0x800A
REG_HEAD_MASK = 0x800B
REG_FIFO_LEVEL0 = 0x8010  # .. 0x8017, read only
REG_UNDERRUN = 0x8018     # read: bit h = head h underran
REG_CONFIG = 0x8019       # read: bit h = head h configured
REG_FIFO_FLAGS0 = 0x8020  # .. 0x8027, read only: the FIFO's flags (seed 4.2.2), see below
REG_FIRE_DELAY_FWD0 = 0x8028  # .. 0x802F: head h's fire delay in forward lines, FIRE_DELAY_HZ ticks
REG_FIRE_DELAY_REV0 = 0x8030  # .. 0x8037: the same in reverse lines (docs/calibration.md)
FIRE_DELAY_HZ = 7_500_000     # the FPGA clock the delays count

FIFO_EMPTY = 1 << 0
FIFO_ALMOST_EMPTY = 1 << 1  # the seed's: the next read (one fire's words) empties the FIFO
FIFO_FULL = 1 << 2
FIFO_WR_COUNT_SHIFT = 3   # bits 3..4: WR_COUNT[1:0], the level in quarters of the depth
FIFO_DREQ = 1 << 5        # DMA request: room for one more block
FIFO_LOW = 1 << 6         # extension: level <= the profile's almost_empty_words (programmable)

DPI_CODE = {150: 0x0000, 600: 0x0001, 300: 0x0002}
DPI_FROM_CODE = {v: k for k, v in DPI_CODE.items()}

STATUS_DIR = 1 << 0
STATUS_DPI600 = 1 << 1
STATUS_WE_EN = 1 << 2
STATUS_DPI300 = 1 << 3
STATUS_FIFO_EMPTY = 1 << 4
STATUS_UNDERRUN = 1 << 5
STATUS_CONFIGURED = 1 << 6
STATUS_FIRING = 1 << 7


def _record_type(typename: str, names: tuple[str, ...]) -> Any:
    """A layout's record: a namedtuple of its field names, made when the layout is declared."""
    return namedtuple(typename, names)


# -- CRCs --------------------------------------------------------------------------------
def crc16_ccitt(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (section 2.2): poly 0x1021, init 0xFFFF, no reflection, no final
    xor; check("123456789") == 0x29B1.  binascii's CRC-CCITT is this CRC given init 0xFFFF."""
    return binascii.crc_hqx(data, crc)


def crc32(data: bytes | bytearray | memoryview | np.ndarray) -> int:
    """CRC-32/ISO-HDLC (zlib.crc32), as used by the data channel."""
    # an ndarray is a buffer, which numpy's stubs do not say
    return zlib.crc32(data) & 0xFFFFFFFF  # type: ignore[arg-type]


# -- command-channel frames (section 2.2) ----------------------------------------------------
@dataclass(frozen=True)
class Frame:
    seq: int
    kind: Kind
    op: int
    payload: bytes = b""

    def encode(self) -> bytes:
        if len(self.payload) > MAX_PAYLOAD:
            raise ValueError(f"payload of {len(self.payload)} bytes exceeds {MAX_PAYLOAD}")
        body = bytes((len(self.payload), self.seq & 0xFF, int(self.kind), self.op & 0xFF)) + self.payload
        return bytes((SYNC,)) + body + crc16_ccitt(body).to_bytes(2, "big")


class FrameDecoder:
    """Byte-stream to frames.  Hunts for SYNC, checks LEN and CRC; on a bad frame it drops
    only the SYNC byte and hunts again, so a real frame hidden in garbage is still found.
    `bad` counts damaged frames (each one is a NAK on the device side)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.bad = 0

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        frames: list[Frame] = []
        buf = self._buf
        while True:
            start = buf.find(SYNC)
            if start < 0:
                buf.clear()
                break
            if start:
                del buf[:start]
            if len(buf) < 2:
                break
            length = buf[1]
            if length > MAX_PAYLOAD:
                self.bad += 1
                del buf[:1]
                continue
            total = length + FRAME_OVERHEAD
            if len(buf) < total:
                break
            body = bytes(buf[1:total - 2])
            crc = int.from_bytes(buf[total - 2:total], "big")
            kind = buf[3]
            if crc16_ccitt(body) != crc or kind not in Kind._value2member_map_:
                self.bad += 1
                del buf[:1]
                continue
            frames.append(Frame(seq=body[1], kind=Kind(kind), op=body[3], payload=body[4:]))
            del buf[:total]
        return frames

    def pending(self) -> int:
        return len(self._buf)

    def reset(self) -> None:
        self._buf.clear()


# -- command payloads (section 2.5): declared once, encoded and decoded from here by both sides --
# A layout is a list of `name:type` fields in wire order, little-endian (docs/protocol.md 2.5):
#   u8 u16 u32 i8 i16 i32    one integer          T[N]       N integers, a tuple
#   ascii[N]  N bytes of ASCII, NUL padded, a str
# and, as the last field only, the rest of the payload:
#   bytes     raw bytes      nibbles   hex digits two per byte, low nibble first, a tuple
#   {layout}[]  repeated records (e.g. one per head), a tuple of records
_SCALAR = {"u8": "B", "u16": "H", "u32": "I", "i8": "b", "i16": "h", "i32": "i"}
_FIELD = re.compile(r"\s*(\w+):(\{[^{}]*\}\[\]|\S+)")
_ARRAY = re.compile(r"(u8|u16|u32|i8|i16|i32|ascii)\[(\d+)\]")


class LayoutError(ValueError):
    """Fields that do not fit a declared layout (a missing or unknown field, a value out of
    its type's range)."""


class BadLength(LayoutError):
    """A payload whose length is wrong for its declared layout (the DSP answers BAD_LENGTH)."""


class Layout:
    """One declared payload layout: `decode(bytes) -> record`, `encode(**fields) -> bytes`.
    Records are namedtuples with the declared field names."""

    def __init__(self, spec: str, typename: str):
        self.spec = " ".join(spec.split())
        self.fields: list[tuple[str, str, int]] = []     # (name, kind, count)
        self.tail: str | None = None                      # "bytes" | "nibbles" | "group"
        self.group: Layout | None = None
        fmt = "<"
        pos = 0
        spec = spec.strip()
        while pos < len(spec):
            m = _FIELD.match(spec, pos)
            if not m:
                raise ValueError(f"layout {spec!r}: cannot parse at {spec[pos:]!r}")
            pos = m.end()
            name, typ = m.groups()
            if self.tail is not None:
                raise ValueError(f"layout {spec!r}: only the last field may take the rest")
            arr = _ARRAY.fullmatch(typ)
            if typ in _SCALAR:
                self.fields.append((name, "int", 1))
                fmt += _SCALAR[typ]
            elif arr and arr.group(1) == "ascii":
                self.fields.append((name, "ascii", int(arr.group(2))))
                fmt += arr.group(2) + "s"
            elif arr:
                self.fields.append((name, "array", int(arr.group(2))))
                fmt += _SCALAR[arr.group(1)] * int(arr.group(2))
            elif typ in ("bytes", "nibbles"):
                self.fields.append((name, typ, 0))
                self.tail = typ
            elif typ.startswith("{"):
                item = name[:-1] if name.endswith("s") else name     # heads -> Head
                self.group = Layout(typ[1:-3], item.title().replace("_", ""))
                if self.group.tail is not None or any(k != "int" for _, k, _ in self.group.fields):
                    raise ValueError(f"layout {spec!r}: a repeated record holds integers only")
                self.fields.append((name, "group", 0))
                self.tail = "group"
            else:
                raise ValueError(f"layout {spec!r}: unknown type {typ!r}")
        self.names = tuple(name for name, _, _ in self.fields)
        # a record type made at run time: typed as Any (mypy knows only declared NamedTuples)
        self.record: Any = _record_type(typename, self.names)
        self.struct = struct.Struct(fmt)
        self.size = self.struct.size        # of the fixed part; the tail adds to it
        self._keys = frozenset(self.names)
        self._plain = all(kind == "int" for _, kind, _ in self.fields)
        # decoding plan: runs of integers are sliced in one go
        self._plan: list[tuple[str, int, int]] = []
        i = 0
        for _, kind, count in self.fields:
            width = {"int": 1, "array": count, "ascii": 1}.get(kind, 0)
            if kind == "int" and self._plan and self._plan[-1][0] == "int":
                self._plan[-1] = ("int", self._plan[-1][1], i + 1)
            else:
                self._plan.append((kind, i, i + width))
            i += width

    def __repr__(self) -> str:
        return f"Layout({self.spec!r})"

    # -- bytes -> record -------------------------------------------------------------------
    def decode(self, data: bytes) -> Any:
        return self.record._make(self.decode_values(data))

    def decode_values(self, data: bytes) -> tuple[Any, ...] | list[Any]:
        """The field values in declaration order; BadLength when the length does not fit."""
        n = len(data)
        if self.tail is None:
            if n != self.size:
                raise BadLength(f"{n} bytes, {self.record.__name__} has {self.size}")
        elif n < self.size or (self.group is not None and (n - self.size) % self.group.size):
            raise BadLength(f"{n} bytes do not fit {self.record.__name__} ({self.spec})")
        values = self.struct.unpack_from(data)
        if self._plain:                     # the common case: integers only
            return values
        out: list[Any] = []
        for kind, i, j in self._plan:
            if kind == "int":
                out += values[i:j]
            elif kind == "array":
                out.append(values[i:j])
            elif kind == "ascii":
                out.append(values[i].rstrip(b"\0").decode("ascii", "replace"))
            elif kind == "bytes":
                out.append(bytes(data[self.size:]))
            elif kind == "nibbles":
                out.append(tuple(d for b in data[self.size:] for d in (b & 0x0F, b >> 4)))
            else:
                g = self.group
                assert g is not None          # kind "group": the layout has one
                out.append(tuple(map(g.record._make, g.struct.iter_unpack(data[self.size:]))))
        return out

    # -- fields -> bytes -------------------------------------------------------------------
    def encode(self, **values: Any) -> bytes:
        if values.keys() != self._keys:
            missing = [k for k in self.names if k not in values]
            extra = [k for k in values if k not in self._keys]
            raise LayoutError(f"{self.record.__name__}: missing {missing}, unknown {extra}")
        return self._pack([values[k] for k in self.names])

    def encode_values(self, values: Any) -> bytes:
        """Encode from values in declaration order (a record or a tuple)."""
        values = list(values)
        if len(values) != len(self.names):
            raise LayoutError(f"{self.record.__name__}: {len(values)} values for {self.names}")
        return self._pack(values)

    def _pack(self, values: list[Any]) -> bytes:
        tail = b""
        if not self._plain:
            flat: list[Any] = []
            for (name, kind, count), v in zip(self.fields, values):
                if kind == "int":
                    flat.append(v)
                elif kind == "array":
                    if len(v) != count:
                        raise LayoutError(f"{name}: {len(v)} values, the layout has {count}")
                    flat += v
                elif kind == "ascii":
                    raw = v.encode("ascii") if isinstance(v, str) else bytes(v)
                    if len(raw) > count:
                        raise LayoutError(f"{name}: {len(raw)} bytes, the layout has {count}")
                    flat.append(raw)
                elif kind == "bytes":
                    tail = bytes(v)
                elif kind == "nibbles":
                    if any(not 0 <= d <= 15 for d in v):
                        raise LayoutError(f"{name}: a digit is not 0..15")
                    tail = pack_digits(list(v))
                else:
                    g = self.group
                    assert g is not None      # kind "group": the layout has one
                    tail = b"".join(g.encode(**r) if isinstance(r, Mapping) else g.encode_values(r)
                                    for r in v)
            values = flat
        try:
            return self.struct.pack(*values) + tail
        except struct.error as exc:
            raise LayoutError(f"{self.record.__name__}: {exc}") from None


@dataclass(frozen=True)
class Command:
    """One opcode's declaration: its request layout, its response layout (the data after
    the result byte, sent only with result OK), and whether the response echoes the request
    (section 2.3: the host compares the echo with what it sent)."""
    op: Op
    request: Layout
    response: Layout
    echo: bool = False


COMMANDS: dict[int, Command] = {}


def decl(op: Op, request: str = "", response: str = "", echo: bool = False) -> Command:
    stem = "".join(w.title() for w in op.name.split("_"))
    if echo and response:
        raise ValueError(f"{op.name}: an echoed response has the request's layout")
    req = Layout(request, stem if echo else stem + "Request")
    cmd = Command(op, req, req if echo else Layout(response, stem + "Response"), echo)
    COMMANDS[op] = cmd
    return cmd


# The table (docs/protocol.md 2.5 has the same layouts with their meaning; tests check both).
decl(Op.IDENTIFY, response="proto_major:u8 proto_minor:u8 firmware:u16 serial:ascii[16] "
     "heads:u8 nozzles:u8 fifo_words:u16 pass_buffer_words:u32 ring_blocks:u8 block_fires:u16 "
     "dpi_mask:u8 counts_per_inch:u16")
decl(Op.SET_BAUD, request="baud:u32", echo=True)
decl(Op.ENABLE, request="on:u8", echo=True)
decl(Op.HOME)
decl(Op.MEASURE_PAPER)
decl(Op.GET_PAPER, response="present:u8 left:i32 right:i32")
decl(Op.SET_LINE, request="stroke:u32 direction:u8 dpi:u16 fire_start:i32 fire_count:u32 "
     "speed:u32 accel:u32", echo=True)
decl(Op.START_LINE, response="stroke:u32")
decl(Op.FEED, request="steps:i32 profile:u8 max_rate:u32 accel:u32", echo=True)
decl(Op.WRITE_REG, request="addr:u16 value:u16", echo=True)
decl(Op.READ_REG, request="addr:u16", response="addr:u16 value:u16")
decl(Op.HEAD_CONFIG_DATA, request="first:u16 digits:nibbles", response="held:u16")
decl(Op.HEAD_CONFIG_LOAD, request="count:u16 crc:u32", echo=True)
decl(Op.HEAD_STATUS, response="heads:{temperature:i16 piezo:u16 flags:u8}[]")
decl(Op.GET_STATUS, response="flags:u16 motion:u8 carriage:i32 speed:i32 paper_steps:i32 "
     "stroke:u32 fires_done:u32 fault:u8 fault_head:u8 fault_stroke:u32 fault_column:i32 "
     "ring_free:u8 fifo:u16[8]")
decl(Op.STOP)
decl(Op.ESTOP)
decl(Op.CLEAR_FAULT, response="fault:u8")
decl(Op.PARK)
decl(Op.JOB_BEGIN, request="job:u32 x0:i32 width:u32 height:u32 dpi:u16 row_nm:u32 y0:i32",
     echo=True)
decl(Op.JOB_END, request="job:u32", echo=True)
decl(Op.PING, request="data:bytes", echo=True)
decl(Op.SPIT, request="drops:u16 heads:u8", echo=True)
decl(Op.PURGE, request="ms:u16 heads:u8", echo=True)
decl(Op.CAP, request="on:u8", echo=True)
decl(Op.SERVICE_STATUS, response="capped:u8 wet_clock_ms:u32 spit_age_ms:u32[8]")
decl(Op.JOB_STATUS, response="boot:u32 job:u32 job_state:u8 lines_done:u32 last_stroke:u32")


def encode_request(op: int, **values: Any) -> bytes:
    return COMMANDS[op].request.encode(**values)


def decode_request(op: int, payload: bytes) -> Any:
    """Raises BadLength when the payload does not fit (section 2.4 BAD_LENGTH)."""
    return COMMANDS[op].request.decode(payload)


def encode_response(op: int, **values: Any) -> bytes:
    """The response data after the result byte (section 2.4)."""
    return COMMANDS[op].response.encode(**values)


def decode_response(op: int, data: bytes) -> Any:
    """`data`: the response payload after the result byte."""
    return COMMANDS[op].response.decode(data)


@dataclass(frozen=True)
class Status:
    """The GET_STATUS payload, result byte included: the result, then the fields declared
    for GET_STATUS's response (checked below)."""
    result: int
    flags: int
    motion: int
    carriage: int          # encoder counts (x4)
    speed: int             # counts per second, signed
    paper_steps: int       # feed steps made since power-up
    stroke: int            # the carriage stroke (print line) the FIFOs are loaded for
    fires_done: int
    fault: int
    fault_head: int
    fault_stroke: int
    fault_column: int
    ring_free: int
    fifo: tuple[int, ...]

    @classmethod
    def decode(cls, payload: bytes) -> "Status":
        if not payload:
            raise BadLength("an empty GET_STATUS payload")
        return cls(payload[0], *_STATUS.decode_values(payload[1:]))

    def response_values(self) -> tuple[Any, ...]:
        """The declared response fields in order (everything but the result byte)."""
        return _status_values(self)

    def encode(self) -> bytes:
        return bytes((self.result,)) + _STATUS.encode_values(_status_values(self))


_STATUS = COMMANDS[Op.GET_STATUS].response
_status_values = operator.attrgetter(*_STATUS.names)
if tuple(f.name for f in fields(Status)) != ("result", *_STATUS.names):
    raise TypeError("Status does not match the GET_STATUS declaration")


# -- data channel (section 3) --------------------------------------------------------------
BLOCK_MAGIC = b"WPD1"
REPORT_MAGIC = b"WPR1"
BLOCK_HEADER = struct.Struct("<4sBBHIII")   # magic, type, head mask, fires, stroke, first fire, words
BLOCK_DATA = 0x01
BLOCK_FLUSH = 0x02
REPORT = struct.Struct("<4sBBHIII8H")        # magic, type, flags, ring free, stroke, blocks, fires, fifo[8]
REPORT_TYPE = 0x81
REPORT_UNDERRUN = 1 << 0
REPORT_DATA_ERROR = 1 << 1
REPORT_STROKE_DONE = 1 << 2
REPORT_FLUSHED = 1 << 3     # the answer to a FLUSH block: `blocks` = where to resume
WORDS_PER_FIRE = 8          # 128 nozzles / 16-bit FIFO words
MAX_BLOCK_WORDS = 65536


def encode_block(stroke: int, first_fire: int, head_mask: int, words: np.ndarray,
                 kind: int = BLOCK_DATA) -> bytes:
    """words: uint16 (heads_in_mask, fires, 8), fire order, one part per head (ascending)."""
    words = np.ascontiguousarray(words, dtype="<u2")
    parts, fires = (words.shape[0], words.shape[1]) if words.size else (0, 0)
    if parts != bin(head_mask).count("1") and kind == BLOCK_DATA:
        raise ValueError("one part per head in the mask")
    header = BLOCK_HEADER.pack(BLOCK_MAGIC, kind, head_mask, fires, stroke, first_fire,
                               words.size)
    payload = words.tobytes()
    return header + payload + crc32(header + payload).to_bytes(4, "little")


@dataclass
class Block:
    kind: int
    head_mask: int
    fires: int
    stroke: int
    first_fire: int
    words: np.ndarray     # uint16 (parts, fires, 8)


class BlockError(ValueError):
    pass


class BlockDecoder:
    """Stream of bytes -> blocks.  A bad CRC or an impossible header raises BlockError
    after dropping the damaged bytes up to the next magic."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Block]:
        if not self._buf and type(data) is bytes:
            block = self._whole(data)
            if block is not None:
                return [block]
        self._buf += data
        out: list[Block] = []
        buf = self._buf
        while len(buf) >= BLOCK_HEADER.size:
            if buf[:4] != BLOCK_MAGIC:
                nxt = buf.find(BLOCK_MAGIC, 1)
                del buf[: nxt if nxt > 0 else len(buf) - 3]
                raise BlockError("data channel out of sync (no block magic)")
            magic, kind, mask, fires, stroke, first, nwords = BLOCK_HEADER.unpack_from(buf)
            parts = bin(mask).count("1")
            if nwords != parts * fires * WORDS_PER_FIRE or nwords > MAX_BLOCK_WORDS:
                del buf[:4]
                raise BlockError(f"block header word count {nwords} does not match "
                                 f"{parts} heads x {fires} fires")
            total = BLOCK_HEADER.size + 2 * nwords + 4
            if len(buf) < total:
                break
            crc = int.from_bytes(buf[total - 4:total], "little")
            if crc32(bytes(buf[:total - 4])) != crc:
                del buf[:total]
                raise BlockError(f"block CRC error (stroke {stroke}, fire {first})")
            words = np.frombuffer(bytes(buf[BLOCK_HEADER.size:total - 4]), dtype="<u2")
            out.append(Block(kind, mask, fires, stroke, first,
                             words.reshape(parts, fires, WORDS_PER_FIRE) if nwords else
                             np.zeros((0, 0, WORDS_PER_FIRE), np.uint16)))
            del buf[:total]
        return out

    @staticmethod
    def _whole(data: bytes) -> Block | None:
        """`data` is exactly one well-formed data block (how the host writes them): read in
        place, without the stream buffer's copies (the emulator decodes ~2,400 blocks a
        full-width stroke).  None: anything else, for the general path to handle."""
        if len(data) < BLOCK_HEADER.size + 4:
            return None
        magic, kind, mask, fires, stroke, first, nwords = BLOCK_HEADER.unpack_from(data)
        parts = bin(mask).count("1")
        total = BLOCK_HEADER.size + 2 * nwords + 4
        if magic != BLOCK_MAGIC or len(data) != total or nwords > MAX_BLOCK_WORDS or \
                nwords != parts * fires * WORDS_PER_FIRE or nwords == 0 or \
                zlib.crc32(memoryview(data)[:total - 4]) != int.from_bytes(data[total - 4:], "little"):
            return None
        words = np.frombuffer(data, dtype="<u2", count=nwords, offset=BLOCK_HEADER.size)
        return Block(kind, mask, fires, stroke, first, words.reshape(parts, fires, WORDS_PER_FIRE))


def encode_report(flags: int, ring_free: int, stroke: int, blocks: int, fires_done: int,
                  fifo: Iterable[int]) -> bytes:
    """One report (section 3.2): its fields in, its bytes out (the emulator's FPGA sends one
    a block, so without a Report object in between)."""
    body = REPORT.pack(REPORT_MAGIC, REPORT_TYPE, flags, ring_free, stroke, blocks, fires_done,
                       *fifo)
    return body + crc32(body).to_bytes(4, "little")


class Report(NamedTuple):
    """A decoded report (a tuple: the host decodes one a block)."""
    flags: int
    ring_free: int
    stroke: int
    blocks: int
    fires_done: int
    fifo: tuple[int, ...]

    def encode(self) -> bytes:
        return encode_report(*self)


class ReportDecoder:
    SIZE = REPORT.size + 4

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Report]:
        if not self._buf and type(data) is bytes and len(data) % self.SIZE == 0:
            # whole reports, nothing pending (the usual read): checked in place
            out, n = [], self.SIZE
            for off in range(0, len(data), n):
                if data[off:off + 4] != REPORT_MAGIC or zlib.crc32(
                        memoryview(data)[off:off + n - 4]) != int.from_bytes(data[off + n - 4:off + n], "little"):
                    break
                v = REPORT.unpack_from(data, off)
                out.append(Report(v[2], v[3], v[4], v[5], v[6], v[7:]))
            else:
                return out
            data = data[off:]               # the rest, from the first bad one: the general path
            pending = out
        else:
            pending = []
        self._buf += data
        out = pending
        while len(self._buf) >= self.SIZE:
            if self._buf[:4] != REPORT_MAGIC:
                nxt = self._buf.find(REPORT_MAGIC, 1)
                del self._buf[: nxt if nxt > 0 else len(self._buf) - 3]
                continue
            chunk = bytes(self._buf[:self.SIZE])
            del self._buf[:self.SIZE]
            if crc32(chunk[:-4]) != int.from_bytes(chunk[-4:], "little"):
                continue
            v = REPORT.unpack(chunk[:-4])
            out.append(Report(v[2], v[3], v[4], v[5], v[6], tuple(v[7:])))
        return out


# -- head configuration digits (section 2.5 HEAD_CONFIG_DATA) ----------------------------------
def pack_digits(digits: list[int]) -> bytes:
    """Hex digits two per byte, low nibble first (an odd last digit pads with 0)."""
    return bytes(digits[i] | ((digits[i + 1] << 4) if i + 1 < len(digits) else 0)
                 for i in range(0, len(digits), 2))


# -- 128-bit nozzle words (section 4.3) ------------------------------------------------------
def nozzles_to_words(bits: np.ndarray) -> np.ndarray:
    """bits: bool/uint8 (..., 128), index = nozzle -> uint16 (..., 8): word w bit i = nozzle 16w+i."""
    packed = np.packbits(np.asarray(bits, dtype=np.uint8), axis=-1, bitorder="little")
    return packed.view("<u2") if packed.flags.c_contiguous else np.ascontiguousarray(packed).view("<u2")


def words_to_nozzles(words: np.ndarray) -> np.ndarray:
    """uint16 (..., 8) -> uint8 (..., 128) nozzle bits."""
    w = np.ascontiguousarray(words, dtype="<u2")
    return np.unpackbits(w.view(np.uint8), axis=-1, bitorder="little")


# -- the PCI card: PLX PCI 9054 bridge + FPGA on its local bus (docs/pci.md) ----------------------
# Identity (docs/pci.md 1): the bridge's own IDs, the project's subsystem IDs.
PCI_VENDOR_PLX = 0x10B5
PCI_DEVICE_9054 = 0x9054
PCI_SUBVENDOR = USB_VID
PCI_SUBDEVICE = USB_PID
BAR_PLX = 0                     # the 9054's local configuration / runtime registers
BAR_FPGA = 2                    # local address space 0: the FPGA
# PCI configuration space
PCI_CFG_VENDOR = 0x00
PCI_CFG_COMMAND = 0x04
PCI_CFG_STATUS = 0x06
PCI_CFG_SUBVENDOR = 0x2C
PCI_CFG_SUBDEVICE = 0x2E
PCI_COMMAND_MEMORY = 1 << 1
PCI_COMMAND_MASTER = 1 << 2
PCI_STATUS_TARGET_ABORT = 1 << 12   # received target abort (W1C)
PCI_STATUS_MASTER_ABORT = 1 << 13   # received master abort (W1C)
# 9054 registers, BAR0 offsets (PCI 9054 data book; Linux drivers/comedi/drivers/plx9080.h)
PLX_INTCSR = 0x68
PLX_CNTRL = 0x6C
PLX_PCIHIDR = 0x70
PLX_PCIHIDR_9054 = 0x905410B5
PLX_DMAMODE0 = 0x80
PLX_DMAPADR0 = 0x84
PLX_DMALADR0 = 0x88
PLX_DMASIZ0 = 0x8C
PLX_DMADPR0 = 0x90
PLX_DMACSR0 = 0xA8              # 8 bits; 0xA9 is DMACSR1 (channel 1, unused: written 0)
INTCSR_PCI_IE = 1 << 8
INTCSR_ABORT_IE = 1 << 10
INTCSR_LOCAL_IE = 1 << 11
INTCSR_ABORT_ACTIVE = 1 << 14
INTCSR_LOCAL_ACTIVE = 1 << 15
INTCSR_DMA0_IE = 1 << 18
INTCSR_DMA0_ACTIVE = 1 << 21
INTCSR_ABORT_NOT_DMA0 = 1 << 25
INTCSR_HOST = INTCSR_PCI_IE | INTCSR_ABORT_IE | INTCSR_LOCAL_IE | INTCSR_DMA0_IE
DMAMODE_WIDTH32 = 3
DMAMODE_READY_IE = 1 << 6
DMAMODE_BURST = 1 << 8
DMAMODE_CHAIN = 1 << 9
DMAMODE_DONE_IE = 1 << 10
DMAMODE_LOCAL_CONST = 1 << 11
DMAMODE_DEMAND = 1 << 12
DMAMODE_CLEAR_COUNT = 1 << 16
DMAMODE_INT_PCI = 1 << 17
DMAMODE_BLOCK = (DMAMODE_WIDTH32 | DMAMODE_READY_IE | DMAMODE_BURST | DMAMODE_DONE_IE
                 | DMAMODE_LOCAL_CONST | DMAMODE_DEMAND | DMAMODE_CLEAR_COUNT | DMAMODE_INT_PCI)
DMAMODE_CHAINED = DMAMODE_BLOCK | DMAMODE_CHAIN               # 0x00031F43
DPR_PCI = 1 << 0                # the next descriptor is in PCI (host) memory
DPR_END = 1 << 1                # end of chain
DPR_TC_INT = 1 << 2             # interrupt when this descriptor is done
DPR_TO_PCI = 1 << 3             # direction local -> PCI (ours: 0, PCI -> local)
DPR_NEXT_MASK = 0xFFFFFFF0
DMASIZ_MASK = 0x7FFFFF
DMACSR_ENABLE = 1 << 0
DMACSR_START = 1 << 1
DMACSR_ABORT = 1 << 2
DMACSR_CLEAR_INT = 1 << 3
DMACSR_DONE = 1 << 4
# The FPGA, BAR2 offsets = local addresses (docs/pci.md 2)
FPGA_ID = 0x000
FPGA_ID_VALUE = 0x31435057      # "WPC1"
FPGA_VERSION = 0x004
FPGA_HEADS = 0x008
FPGA_FIFO_WORDS = 0x00C
FPGA_RING_SLOTS = 0x010
FPGA_CTRL = 0x020
FPGA_IRQ_STATUS = 0x024
FPGA_IRQ_MASK = 0x028
FPGA_REPORT_COUNT = 0x030
FPGA_REPORT_DATA = 0x034
FPGA_FIFO_LEVEL0 = 0x040
FPGA_FIFO_FLAGS0 = 0x060
FPGA_RING_FREE = 0x080
FPGA_STROKE = 0x084
FPGA_BLOCKS_MOVED = 0x088
FPGA_FIRES_DONE = 0x08C
FPGA_DATA = 0x1000              # the DMA's destination, at a constant local address
FPGA_BAR_SIZE = 0x2000
CTRL_DATA_RESET = 1 << 0
CTRL_IRQ_EN = 1 << 1
IRQ_REPORT = 1 << 0
IRQ_DREQ = 1 << 1
IRQ_FAULT = 1 << 2
DMA_DESC = struct.Struct("<IIII")   # PCI address, local address, size, next | DPR bits
DmaDesc = namedtuple("DmaDesc", "padr ladr size dpr")


def encode_dma_desc(padr: int, ladr: int, size: int, dpr: int) -> bytes:
    return DMA_DESC.pack(padr, ladr, size, dpr)


def decode_dma_desc(data: bytes | bytearray | memoryview) -> DmaDesc:
    return DmaDesc(*DMA_DESC.unpack(bytes(data[:DMA_DESC.size])))
