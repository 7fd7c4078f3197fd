"""docs/protocol.md: codecs, framing, reliability, and the byte-exact examples."""

import re
import struct
from pathlib import Path

import numpy as np
import pytest

from wideprint.device_sim.endpoints import in_process
from wideprint.device_sim.faults import Faults
from wideprint.device_sim.printer import Printer
from wideprint.driver import protocol as P
from wideprint.driver.device import Device
from wideprint.driver.link import CommandLink, DeviceError, LinkError

DOC = Path(__file__).resolve().parent.parent / "docs" / "protocol.md"


def doc_examples() -> dict[str, tuple[str, bytes]]:
    text = DOC.read_text()
    block = re.search(r"```frames\n(.*?)```", text, re.S).group(1)
    out = {}
    for line in block.strip().splitlines():
        name, direction, hexes = (part.strip() for part in line.split("|"))
        out[name] = (direction, bytes.fromhex(hexes))
    return out


EX = doc_examples()


def test_crc16_check_value():
    assert P.crc16_ccitt(b"123456789") == 0x29B1


def test_doc_examples_match_the_codec():
    assert EX["IDENTIFY, SEQ 0"][1] == P.Frame(0, P.Kind.COMMAND, P.Op.IDENTIFY).encode()
    assert EX["GET_STATUS, SEQ 1"][1] == P.Frame(1, P.Kind.COMMAND, P.Op.GET_STATUS).encode()
    assert EX["WRITE_REG DIR := 1, SEQ 2"][1] == P.Frame(
        2, P.Kind.COMMAND, P.Op.WRITE_REG, struct.pack("<HH", P.REG_DIR, 1)).encode()
    assert EX["FEED 2909 steps, SEQ 5"][1] == P.Frame(
        5, P.Kind.COMMAND, P.Op.FEED, struct.pack(P.FEED_FMT, 2909, 0, 4000, 40000)).encode()
    assert EX["SET_LINE pass 7, SEQ 6"][1] == P.Frame(
        6, P.Kind.COMMAND, P.Op.SET_LINE,
        struct.pack(P.SET_LINE_FMT, 7, 1, 300, 1740, 2600, 15590, 47244)).encode()
    bits = np.zeros((1, 1, 128), np.uint8)
    bits[0, 0, [1, 64]] = 1
    assert EX["DATA block"][1] == P.encode_block(3, 0, 0x01, P.nozzles_to_words(bits))
    assert EX["REPORT"][1] == P.Report(0, 1, 3, 5, 80, (64,) * 8).encode()


def test_emulator_answers_the_doc_examples_byte_for_byte():
    """The emulated DSP, fed the documented host bytes, sends the documented answers."""
    ser, _ = in_process(Printer())
    pairs = [("handshake request", "handshake reply"),
             ("IDENTIFY, SEQ 0", "IDENTIFY response"),
             ("GET_STATUS, SEQ 1", "GET_STATUS response"),
             ("WRITE_REG DIR := 1, SEQ 2", "WRITE_REG echo"),
             ("READ_REG STATUS, SEQ 3", "READ_REG answer 0x0011"),
             ("PING with a damaged CRC", "NAK (CRC)")]
    for request, reply in pairs:
        assert EX[request][0] == "host->dsp" and EX[reply][0] == "dsp->host"
        ser.write(EX[request][1])
        assert ser.read(1000) == EX[reply][1], request


def test_driver_connect_sends_the_documented_frames():
    """Decode the emulator's view of the wire while the real driver connects."""
    printer = Printer()
    ser, data = in_process(printer)
    from wideprint.rip.profile import load_profile
    dev = Device(CommandLink(ser), data, load_profile(), emulator=printer)
    dev.connect()
    dev.link.status()
    rx = b"".join(bytes.fromhex(e["hex"]) for e in printer.events if e["event"] == "serial_rx")
    expected = (EX["handshake request"][1] + EX["IDENTIFY, SEQ 0"][1]
                + EX["GET_STATUS, SEQ 1"][1])
    assert rx == expected
    frames = P.FrameDecoder().feed(rx[1:])
    assert [(f.seq, f.kind, f.op) for f in frames] == [
        (0, P.Kind.COMMAND, P.Op.IDENTIFY), (1, P.Kind.COMMAND, P.Op.GET_STATUS)]


def test_decoder_finds_a_frame_after_garbage_and_a_false_sync():
    good = P.Frame(9, P.Kind.RESPONSE, P.Op.PING, b"\x00abc").encode()
    junk = bytes([0x13, P.SYNC, 0x05, 0x77, 0x7E, 0x00])   # a SYNC whose frame is garbage
    dec = P.FrameDecoder()
    frames = dec.feed(junk + good)
    assert [f.payload for f in frames] == [b"\x00abc"]
    assert dec.bad >= 1


def test_decoder_handles_split_delivery():
    frame = P.Frame(1, P.Kind.COMMAND, P.Op.PING, bytes(range(40))).encode()
    dec = P.FrameDecoder()
    got = []
    for i in range(len(frame)):
        got += dec.feed(frame[i:i + 1])
    assert len(got) == 1 and got[0].payload == bytes(range(40))


def test_every_single_bit_flip_is_caught():
    frame = P.Frame(3, P.Kind.COMMAND, P.Op.FEED, struct.pack(P.FEED_FMT, 100, 0, 4000, 40000)).encode()
    for i in range(1, len(frame)):          # not the SYNC byte: then there is no frame at all
        for bit in range(8):
            bad = bytearray(frame)
            bad[i] ^= 1 << bit
            dec = P.FrameDecoder()
            frames = dec.feed(bytes(bad))
            assert frames == [] or frames[0].encode() == frame


def test_retransmission_is_not_executed_twice():
    printer = Printer()
    ser, _ = in_process(printer)
    link = CommandLink(ser)
    link.handshake()
    link.command(P.Op.ENABLE, b"\x01")
    link.command(P.Op.HOME)
    feed = P.Frame(link.seq, P.Kind.COMMAND, P.Op.FEED,
                   struct.pack(P.FEED_FMT, 1000, 0, 4000, 40000)).encode()
    ser.write(feed)
    first = ser.read(100)
    ser.write(feed)                          # the host did not see the answer: same SEQ again
    again = ser.read(100)
    assert first == again
    assert printer.paper_steps == 1000
    assert any(e["event"] == "retransmission" for e in printer.events)


def test_three_failed_tries_raise_a_link_error():
    printer = Printer(faults=Faults(serial_byte_error=1.0))    # every byte corrupted
    ser, _ = in_process(printer)
    link = CommandLink(ser)
    with pytest.raises(LinkError):
        link.command(P.Op.PING, b"x")
    assert link.retries == 2                 # 3 tries in all


def test_refusals_carry_the_result_code():
    ser, _ = in_process(Printer())
    link = CommandLink(ser)
    link.handshake()
    with pytest.raises(DeviceError, match="NOT_ENABLED"):
        link.command(P.Op.HOME)
    with pytest.raises(DeviceError, match="UNKNOWN_OPCODE"):
        link.command(0x7F)


def test_nozzle_word_bit_order():
    bits = np.zeros(128, np.uint8)
    bits[[1, 16, 17, 126]] = 1
    words = P.nozzles_to_words(bits)
    assert words.tolist() == [0x0002, 0x0003, 0, 0, 0, 0, 0, 0x4000]
    assert np.array_equal(P.words_to_nozzles(words), bits)


def test_block_crc_and_header_checks():
    words = np.arange(2 * 3 * 8, dtype=np.uint16).reshape(2, 3, 8)
    blk = P.encode_block(5, 48, 0b101, words)
    dec = P.BlockDecoder()
    (b,) = dec.feed(blk)
    assert (b.pass_id, b.first_fire, b.head_mask, b.fires) == (5, 48, 0b101, 3)
    assert np.array_equal(b.words, words)
    bad = bytearray(blk)
    bad[30] ^= 0x40
    with pytest.raises(P.BlockError, match="CRC"):
        P.BlockDecoder().feed(bytes(bad))
    with pytest.raises(ValueError):
        P.encode_block(5, 0, 0b111, words)     # 3 heads in the mask, 2 parts


def test_status_roundtrip():
    st = P.Status(0, 0x1F, 4, -120, 15000, 123456, 7, 99, 4, 2, 7, 1801, 1, tuple(range(8)))
    assert P.Status.decode(st.encode()) == st
