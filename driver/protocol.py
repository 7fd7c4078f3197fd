"""The wire protocol shared by the host driver and the emulator (docs/protocol.md).

Only constants and pure codecs live here: frames of the command channel (section 2),
blocks and reports of the data channel (section 3).  Neither side keeps state in this
module; the host's retry logic is in driver/link.py and the device's in device_sim/dsp.py.
"""

from __future__ import annotations

import binascii
import enum
import struct
import zlib
from dataclasses import dataclass

import numpy as np

PROTOCOL_VERSION = (1, 0)

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


# STATUS flags (GET_STATUS, section 2.5)
FLAG_ENABLED = 1 << 0
FLAG_HOMED = 1 << 1
FLAG_HEADS_CONFIGURED = 1 << 2
FLAG_PAPER_MEASURED = 1 << 3
FLAG_LINE_DONE = 1 << 4
FLAG_FEED_DONE = 1 << 5
FLAG_JOB_OPEN = 1 << 6
FLAG_FAULT = 1 << 7

# -- section 2.6: FPGA registers in the DSP's I/O space (A15 = 1, A5..A0) ----------------
REG_STATUS = 0x8000       # read: D0 DIR, D1 DPI(600), D2 WE_EN, D3 DPI(300), D4 FIFO empty,
                          #       D5 underrun, D6 heads configured, D7 firing
REG_DIR = 0x8001          # 0x0001 forward, 0x0000 reverse
REG_DPI = 0x8002          # 0x0000 150 dpi, 0x0001 600 dpi (seed), 0x0002 300 dpi (extension)
REG_WE_EN = 0x8003        # 0x0001 print enable
REG_PASS_LO = 0x8004
REG_PASS_HI = 0x8005
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

FIFO_EMPTY = 1 << 0
FIFO_ALMOST_EMPTY = 1 << 1
FIFO_FULL = 1 << 2
FIFO_WR_COUNT_SHIFT = 3   # bits 3..4: WR_COUNT[1:0], the level in quarters of the depth
FIFO_DREQ = 1 << 5        # DMA request: room for one more block

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


# -- CRCs --------------------------------------------------------------------------------
def crc16_ccitt(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (section 2.2): poly 0x1021, init 0xFFFF, no reflection, no final
    xor; check("123456789") == 0x29B1.  binascii's CRC-CCITT is this CRC given init 0xFFFF."""
    return binascii.crc_hqx(data, crc)


def crc32(data) -> int:
    """CRC-32/ISO-HDLC (zlib.crc32), as used by the data channel."""
    return zlib.crc32(data) & 0xFFFFFFFF


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


# -- command payloads (section 2.5) ------------------------------------------------------
IDENTIFY_FMT = "<BBH16sBBHIBHBH"   # see docs/protocol.md 2.5 IDENTIFY
STATUS_FMT = "<BHBiiiIIBBIiB8H"    # see docs/protocol.md 2.5 GET_STATUS
SET_LINE_FMT = "<IBHiIII"          # pass, dir, dpi, fire_start, fire_count, speed, accel
FEED_FMT = "<iBII"                 # steps, profile, max steps/s, accel steps/s^2
JOB_BEGIN_FMT = "<IiIIHIi"         # job, x0 counts, width cols, height rows, dpi, row nm, y0 rows
PAPER_FMT = "<Bii"                 # present, left counts, right counts
HEAD_STATUS_FMT = "<hHB"           # per head: temp 0.1 C, piezo 0.1 V, flags


@dataclass(frozen=True)
class Status:
    result: int
    flags: int
    motion: int
    carriage: int          # encoder counts (x4)
    speed: int             # counts per second, signed
    paper_steps: int       # feed steps made since power-up
    pass_id: int
    fires_done: int
    fault: int
    fault_head: int
    fault_pass: int
    fault_column: int
    ring_free: int
    fifo: tuple[int, ...]

    @classmethod
    def decode(cls, payload: bytes) -> "Status":
        v = struct.unpack(STATUS_FMT, payload)
        return cls(*v[:13], fifo=tuple(v[13:]))

    def encode(self) -> bytes:
        return struct.pack(STATUS_FMT, self.result, self.flags, self.motion, self.carriage,
                           self.speed, self.paper_steps, self.pass_id, self.fires_done,
                           self.fault, self.fault_head, self.fault_pass, self.fault_column,
                           self.ring_free, *self.fifo)


# -- data channel (section 3) --------------------------------------------------------------
BLOCK_MAGIC = b"WPD1"
REPORT_MAGIC = b"WPR1"
BLOCK_HEADER = struct.Struct("<4sBBHIII")   # magic, type, head mask, fires, pass, first fire, words
BLOCK_DATA = 0x01
BLOCK_FLUSH = 0x02
REPORT = struct.Struct("<4sBBHIII8H")        # magic, type, flags, ring free, pass, blocks, fires, fifo[8]
REPORT_TYPE = 0x81
REPORT_UNDERRUN = 1 << 0
REPORT_DATA_ERROR = 1 << 1
REPORT_PASS_DONE = 1 << 2
REPORT_FLUSHED = 1 << 3     # the answer to a FLUSH block: `blocks` = where to resume
WORDS_PER_FIRE = 8          # 128 nozzles / 16-bit FIFO words
MAX_BLOCK_WORDS = 65536


def encode_block(pass_id: int, first_fire: int, head_mask: int, words: np.ndarray,
                 kind: int = BLOCK_DATA) -> bytes:
    """words: uint16 (heads_in_mask, fires, 8), fire order, one part per head (ascending)."""
    words = np.ascontiguousarray(words, dtype="<u2")
    parts, fires = (words.shape[0], words.shape[1]) if words.size else (0, 0)
    if parts != bin(head_mask).count("1") and kind == BLOCK_DATA:
        raise ValueError("one part per head in the mask")
    header = BLOCK_HEADER.pack(BLOCK_MAGIC, kind, head_mask, fires, pass_id, first_fire,
                               words.size)
    payload = words.tobytes()
    return header + payload + crc32(header + payload).to_bytes(4, "little")


@dataclass
class Block:
    kind: int
    head_mask: int
    fires: int
    pass_id: int
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
        self._buf += data
        out: list[Block] = []
        buf = self._buf
        while len(buf) >= BLOCK_HEADER.size:
            if buf[:4] != BLOCK_MAGIC:
                nxt = buf.find(BLOCK_MAGIC, 1)
                del buf[: nxt if nxt > 0 else len(buf) - 3]
                raise BlockError("data channel out of sync (no block magic)")
            magic, kind, mask, fires, pass_id, first, nwords = BLOCK_HEADER.unpack_from(buf)
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
                raise BlockError(f"block CRC error (pass {pass_id}, fire {first})")
            words = np.frombuffer(bytes(buf[BLOCK_HEADER.size:total - 4]), dtype="<u2")
            out.append(Block(kind, mask, fires, pass_id, first,
                             words.reshape(parts, fires, WORDS_PER_FIRE) if nwords else
                             np.zeros((0, 0, WORDS_PER_FIRE), np.uint16)))
            del buf[:total]
        return out


@dataclass(frozen=True)
class Report:
    flags: int
    ring_free: int
    pass_id: int
    blocks: int
    fires_done: int
    fifo: tuple[int, ...]

    def encode(self) -> bytes:
        body = REPORT.pack(REPORT_MAGIC, REPORT_TYPE, self.flags, self.ring_free, self.pass_id,
                           self.blocks, self.fires_done, *self.fifo)
        return body + crc32(body).to_bytes(4, "little")


class ReportDecoder:
    SIZE = REPORT.size + 4

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Report]:
        self._buf += data
        out = []
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
