"""Rewrite the byte-exact session of docs/protocol.md section 5 after a protocol change.

The host's frames are kept as written (their names say what each is), renumbered in
order of SEQ, re-encoded from their `fields` lines; each answer is what the emulator
sends back (tests/test_protocol.py then checks both directions).  New host frames are
added to the doc by hand (a name and a fields line; the bytes may be left as `-`), then:

    .venv/bin/python tools/protocol_examples.py          # rewrites docs/protocol.md
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT.parent))

from wideprint.device_sim.endpoints import in_process  # noqa: E402
from wideprint.device_sim.faults import Faults  # noqa: E402
from wideprint.device_sim.printer import Printer  # noqa: E402
from wideprint.driver import protocol as P  # noqa: E402
from wideprint.rip.profile import load_profile  # noqa: E402

DOC = ROOT / "docs" / "protocol.md"


def _rows(text: str, kind: str) -> list[list[str]]:
    block = re.search(rf"```{kind}\n(.*?)```", text, re.S).group(1)
    return [[part.strip() for part in line.split("|", 2)] for line in block.strip().splitlines()]


def _fields(text: str) -> dict:
    out = {}
    for name, body in _rows(text, "fields"):
        call = ast.parse(f"f({'' if body == '-' else body})", mode="eval").body
        out[name] = {kw.arg: ast.literal_eval(kw.value) for kw in call.keywords}
    return out


def main() -> None:
    text = DOC.read_text()
    frames = _rows(text, "frames")
    fields_rows = _rows(text, "fields")
    fields = _fields(text.replace("| ?\n", "| -\n"))
    ser, _ = in_process(Printer(faults=Faults(idle_time_scale=0)))   # idle time: docs 2.9
    digits = load_profile().head_config_digits()
    out, answers, held, answer = [], {}, 0, None
    for name, direction, hexes in frames:
        if direction == "host->dsp":
            if name in fields and "SEQ" in name:         # a command, encoded from its fields
                op = P.Op[re.match(r"[A-Z_]+", name).group(0)]
                seq = int(re.search(r"SEQ (\d+)", name).group(1))
                data = P.Frame(seq, P.Kind.COMMAND, op, P.encode_request(op, **fields[name])).encode()
            else:                                        # the handshake, a damaged frame
                data = bytes.fromhex(hexes)
            if data[4:5] == bytes((P.Op.HEAD_CONFIG_LOAD,)):
                for i, first in enumerate(range(held, len(digits), 400)):
                    ser.write(P.Frame(0x80 + i, P.Kind.COMMAND, P.Op.HEAD_CONFIG_DATA,
                                      P.encode_request(P.Op.HEAD_CONFIG_DATA, first=first,
                                                       digits=digits[first:first + 400])).encode())
                    ser.read(1000)
            ser.write(data)
            answer = ser.read(1000)
            out.append((name, direction, data.hex(" ").upper()))
        elif direction == "dsp->host":
            out.append((name, direction, answer.hex(" ").upper()))
            dec = P.FrameDecoder().feed(answer)
            if dec and dec[0].kind == P.Kind.RESPONSE and dec[0].payload[:1] == b"\x00":
                f = P.decode_response(dec[0].op, dec[0].payload[1:])._asdict()
                held = f.get("held", held)
                answers[name] = f
        else:
            out.append((name, direction, hexes))         # the data channel: as written
    w = max(len(n) for n, _, _ in out) + 1
    wd = max(len(d) for _, d, _ in out) + 1
    block = "\n".join(f"{n:<{w}}| {d:<{wd}}| {h}".rstrip() for n, d, h in out) + "\n"
    flines = []
    for name, body in fields_rows:
        if body == "?":                                  # a new answer: filled in
            f = answers[name]
            body = ", ".join(f"{k}={v!r}" for k, v in f.items()) or "-"
        flines.append(f"{name:<{w}}| {body}")
    text = re.sub(r"```frames\n.*?```", lambda m: "```frames\n" + block + "```", text, flags=re.S)
    text = re.sub(r"```fields\n.*?```", lambda m: "```fields\n" + "\n".join(flines) + "\n```",
                  text, flags=re.S)
    DOC.write_text(text)


if __name__ == "__main__":
    main()
