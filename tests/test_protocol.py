"""docs/protocol.md: the command table, codecs, framing, reliability, and the byte-exact
examples (every opcode's, against both the codec and the emulator)."""

import ast
import random
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wideprint.device_sim import dsp
from wideprint.device_sim.endpoints import in_process
from wideprint.device_sim.faults import Faults
from wideprint.device_sim.printer import Printer
from wideprint.driver import protocol as P
from wideprint.driver.device import Device
from wideprint.driver.link import CommandLink, DeviceError, LinkError

DOC = Path(__file__).resolve().parent.parent / "docs" / "protocol.md"


def _block(kind: str) -> list[list[str]]:
    block = re.search(rf"```{kind}\n(.*?)```", DOC.read_text(), re.S).group(1)
    return [[part.strip() for part in line.split("|", 2)] for line in block.strip().splitlines()]


def doc_frames() -> list[tuple[str, str, bytes]]:
    """The `frames` block in order: (name, direction, bytes)."""
    return [(name, direction, bytes.fromhex(hexes)) for name, direction, hexes in _block("frames")]


def doc_fields() -> dict[str, dict]:
    """The `fields` block: name -> the payload's fields (`-`: none)."""
    out = {}
    for name, text in _block("fields"):
        call = ast.parse(f"f({'' if text == '-' else text})", mode="eval").body
        out[name] = {kw.arg: ast.literal_eval(kw.value) for kw in call.keywords}
    return out


FRAMES = doc_frames()
EX = {name: (direction, data) for name, direction, data in FRAMES}
FIELDS = doc_fields()


def command_frames():
    """Every example that is a valid command or response frame, with its decoded frame."""
    for name, direction, data in FRAMES:
        if direction not in ("host->dsp", "dsp->host") or data[:1] != bytes((P.SYNC,)):
            continue
        frames = P.FrameDecoder().feed(data)
        if frames and frames[0].kind != P.Kind.NAK:
            assert frames[0].encode() == data, name
            yield name, frames[0]


def _crc16_reference(data: bytes) -> int:
    """Bit by bit, as section 2.2 defines it."""
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_crc16_check_value():
    assert P.crc16_ccitt(b"123456789") == 0x29B1
    rng = random.Random(1)
    for n in (0, 1, 2, 7, 64, 257):
        data = bytes(rng.randrange(256) for _ in range(n))
        assert P.crc16_ccitt(data) == _crc16_reference(data)


# -- the command table -------------------------------------------------------------------------
def test_every_opcode_is_declared_handled_and_documented():
    """A new opcode fails here until it has a declaration, a DSP handler, a row in the
    section 2.5 table and a request and response example in section 5."""
    ops = set(P.Op)
    assert set(P.COMMANDS) == ops
    assert set(dsp._HANDLERS) == ops
    requests = {f.op for _, f in command_frames() if f.kind == P.Kind.COMMAND}
    responses = {f.op for _, f in command_frames() if f.kind == P.Kind.RESPONSE}
    assert requests == ops, f"no request example: {sorted(o.name for o in ops - requests)}"
    assert responses == ops, f"no response example: {sorted(o.name for o in ops - responses)}"
    assert set(doc_layouts()) == {op.name for op in ops}


def doc_layouts() -> dict[str, tuple[str, str]]:
    """Section 2.5's table: name -> (request cell, response cell)."""
    text = DOC.read_text()
    table = text[text.index("| op | name | command payload"):]
    rows = {}
    for line in table.splitlines()[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[1]] = (cells[2], cells[3])
    return rows


def _spec(cell: str) -> str:
    """A cell's layout: its leading `code`, or '' for '-'."""
    if cell.startswith("-"):
        return ""
    m = re.match(r"`([^`]*)`", cell)
    assert m, f"no layout in {cell!r}"
    return m.group(1)


def test_the_doc_table_has_the_declared_layouts():
    for name, (request, response) in doc_layouts().items():
        cmd = P.COMMANDS[P.Op[name]]
        assert _spec(request) == cmd.request.spec, name
        if cmd.echo:
            assert response.startswith("echo"), name
        else:
            assert _spec(response) == cmd.response.spec, name


def test_echoed_commands():
    """Section 2.3: these answers repeat the command's payload and the host checks it."""
    assert {op for op, c in P.COMMANDS.items() if c.echo} == {
        P.Op.SET_BAUD, P.Op.ENABLE, P.Op.SET_LINE, P.Op.FEED, P.Op.WRITE_REG,
        P.Op.HEAD_CONFIG_LOAD, P.Op.JOB_BEGIN, P.Op.JOB_END, P.Op.PING,
        P.Op.SPIT, P.Op.PURGE, P.Op.CAP}


def test_layouts_decode_and_encode():
    rec = P.decode_request(P.Op.HEAD_CONFIG_DATA, bytes([0x90, 0x01, 0x21, 0xF0]))
    assert rec == (400, (1, 2, 0, 15)) and rec.first == 400
    assert P.encode_request(P.Op.HEAD_CONFIG_DATA, first=400, digits=[1, 2, 0, 15]) == \
        bytes([0x90, 0x01, 0x21, 0xF0])
    heads = P.decode_response(P.Op.HEAD_STATUS, bytes.fromhex("5e0190010108009001 02"))
    assert heads.heads == ((350, 400, 1), (8, 400, 2)) and heads.heads[1].flags == 2
    assert P.encode_response(P.Op.HEAD_STATUS, heads=[(350, 400, 1), dict(
        temperature=8, piezo=400, flags=2)]) == bytes.fromhex("5e019001010800900102")
    assert P.decode_response(P.Op.HEAD_STATUS, b"").heads == ()
    ident = P.COMMANDS[P.Op.IDENTIFY].response
    assert ident.decode(ident.encode(**dict(P.decode_response(
        P.Op.IDENTIFY, EX["IDENTIFY response"][1][6:-2])._asdict()))).serial == "WP3400-EMU-0001"
    assert P.decode_request(P.Op.PING, b"") == (b"",)


def test_layout_errors():
    with pytest.raises(P.BadLength):
        P.decode_request(P.Op.SET_LINE, bytes(22))
    with pytest.raises(P.BadLength):
        P.decode_request(P.Op.HOME, b"\x00")
    with pytest.raises(P.BadLength):
        P.decode_request(P.Op.HEAD_CONFIG_DATA, b"\x00")          # no digit index
    with pytest.raises(P.BadLength):
        P.decode_response(P.Op.HEAD_STATUS, bytes(6))               # not whole records
    with pytest.raises(P.BadLength):
        P.Status.decode(b"")
    with pytest.raises(P.LayoutError):
        P.encode_request(P.Op.WRITE_REG, addr=0x10000, value=0)      # out of range
    with pytest.raises(P.LayoutError):
        P.encode_request(P.Op.WRITE_REG, addr=0x8001)                # a field missing
    with pytest.raises(P.LayoutError):
        P.encode_request(P.Op.JOB_END, job=1, jobs=2)                # an unknown field
    with pytest.raises(P.LayoutError):
        P.Status(*range(13), fifo=(0,) * 7).encode()                # 7 FIFO levels, not 8
    with pytest.raises(P.LayoutError):
        P.encode_request(P.Op.HEAD_CONFIG_DATA, first=0, digits=[16])
    with pytest.raises(ValueError):
        P.Layout("a:u8 rest:bytes b:u8", "Bad")                     # a tail must be last
    with pytest.raises(ValueError):
        P.Layout("a:u24", "Bad")


def _fixed_layouts():
    for cmd in P.COMMANDS.values():
        for lay in (cmd.request, cmd.response):
            if lay.tail is None and all(k != "ascii" for _, k, _ in lay.fields) and lay.size:
                yield lay


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_fixed_layouts_are_bijective(data):
    """Any payload of the right length decodes, and encodes back to the same bytes."""
    lay = data.draw(st.sampled_from(list(_fixed_layouts())))
    raw = data.draw(st.binary(min_size=lay.size, max_size=lay.size))
    rec = lay.decode(raw)
    assert lay.encode(**rec._asdict()) == raw
    assert lay.decode(lay.encode_values(rec)) == rec


# -- section 5: every example, against the codec and the emulator --------------------------------
def test_doc_examples_match_the_codec():
    """Encoding the documented fields gives exactly the documented frame; decoding the
    frame gives exactly the documented fields."""
    named = dict(command_frames())
    assert set(named) == set(FIELDS), "every command/response example needs a fields line"
    for name, frame in named.items():
        fields = FIELDS[name]
        if frame.kind == P.Kind.COMMAND:
            assert P.decode_request(frame.op, frame.payload)._asdict() == fields, name
            payload = P.encode_request(frame.op, **fields)
        else:
            assert frame.payload[0] == P.Result.OK, name
            assert P.decode_response(frame.op, frame.payload[1:])._asdict() == fields, name
            payload = bytes((P.Result.OK,)) + P.encode_response(frame.op, **fields)
        assert P.Frame(frame.seq, frame.kind, frame.op, payload).encode() == EX[name][1], name
    assert EX["NAK (CRC)"][1] == P.Frame(0, P.Kind.NAK, 0, b"\x01").encode()
    bits = np.zeros((1, 1, 128), np.uint8)
    bits[0, 0, [1, 64]] = 1
    assert EX["DATA block"][1] == P.encode_block(3, 0, 0x01, P.nozzles_to_words(bits))
    assert EX["REPORT"][1] == P.Report(0, 1, 3, 5, 80, (64,) * 8).encode()
    assert P.Status.decode(EX["GET_STATUS response"][1][5:-2]) == P.Status(
        0, 0, 0, 0, 0, 0, 0, 0, 0, 0xFF, 0, 0, 2, (0,) * 8)


def _send_rest_of_config(ser, held: int) -> None:
    """The HEAD_CONFIG_DATA frames the doc leaves out: the configuration after its first
    `held` digits (docs/protocol.md 5)."""
    from wideprint.rip.profile import load_profile
    digits = load_profile().head_config_digits()
    for i, first in enumerate(range(held, len(digits), 400)):
        ser.write(P.Frame(0x80 + i, P.Kind.COMMAND, P.Op.HEAD_CONFIG_DATA, P.encode_request(
            P.Op.HEAD_CONFIG_DATA, first=first, digits=digits[first:first + 400])).encode())
        assert ser.read(1000)[5] == P.Result.OK


def test_emulator_answers_the_doc_examples_byte_for_byte():
    """The emulated DSP, fed the documented host bytes in order, sends the documented
    answers (its idle time not counted, its power-up number 1, as in the doc: sections 2.9,
    2.10)."""
    ser, _ = in_process(Printer(faults=Faults(idle_time_scale=0, boot=1)))
    lines = [ln for ln in FRAMES if ln[1] in ("host->dsp", "dsp->host")]
    held = 0
    for (name, direction, data), (reply, rdir, expected) in zip(lines[::2], lines[1::2]):
        assert (direction, rdir) == ("host->dsp", "dsp->host"), name
        if data[:1] == bytes((P.SYNC,)) and data[4:5] == bytes((P.Op.HEAD_CONFIG_LOAD,)):
            _send_rest_of_config(ser, held)
        ser.write(data)
        got = ser.read(1000)
        assert got.hex(" ") == expected.hex(" "), f"{name} -> {reply}"
        if reply in FIELDS and "held" in FIELDS[reply]:
            held = FIELDS[reply]["held"]
    assert len(lines) % 2 == 0


def test_a_wrong_length_is_bad_length_for_every_opcode():
    """Once a command passes its refusal checks (2.4) a payload that does not fit its
    layout is answered BAD_LENGTH, and nothing is executed."""
    printer = Printer()
    ser, data = in_process(printer)
    link = CommandLink(ser)
    dev = Device(link, data, printer.profile, emulator=printer)
    dev.connect()
    dev.load_head_config()
    link.call(P.Op.ENABLE, on=1)
    link.command(P.Op.HOME)
    for op, cmd in P.COMMANDS.items():
        lay = cmd.request
        wrong = [bytes(lay.size + 1)] if lay.tail is None else []
        if lay.size:
            wrong.append(bytes(lay.size - 1))
        for payload in wrong:
            with pytest.raises(DeviceError, match="BAD_LENGTH"):
                link.command(op, payload)
    assert printer.fault == P.Fault.NONE and printer.paper_steps == 0


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
    frame = P.Frame(3, P.Kind.COMMAND, P.Op.FEED, P.encode_request(
        P.Op.FEED, steps=100, profile=0, max_rate=4000, accel=40000)).encode()
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
    link.call(P.Op.ENABLE, on=1)
    link.command(P.Op.HOME)
    feed = P.Frame(link.seq, P.Kind.COMMAND, P.Op.FEED, P.encode_request(
        P.Op.FEED, steps=1000, profile=0, max_rate=4000, accel=40000)).encode()
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
    assert (b.stroke, b.first_fire, b.head_mask, b.fires) == (5, 48, 0b101, 3)
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
