"""Fault injection for the emulator: `--inject KIND=VALUE` on the command line, or
`Faults.parse([...])` from tests.  Each fault is reported the way the real device would
report it (docs/emulator.md lists them)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

KINDS = {
    "serial-ber": "bit error rate on the serial line, both directions (e.g. 1e-4)",
    "serial-byte-error": "probability that a serial byte is corrupted, both directions",
    "serial-drop": "probability that a serial byte is lost",
    "data-drop-after": "the data link drops after this many data blocks (the host may reconnect)",
    "data-stall": "extra host latency in seconds added to every DMA refill",
    "host-jitter": "host DMA refill latency model: ideal | typical | loaded",
    "dead-nozzle": "HEAD:NOZZLE that never drops, e.g. M1:57 (repeatable)",
    "limit-at": "the right limit switch trips at this encoder count",
    "paper-length-mm": "length of paper left on the roll",
    "paper-width-mm": "width of the loaded sheet",
    "overtemp": "HEAD:STROKE: the head overheats during this stroke, e.g. K2:3",
    "fifo-words": "FIFO depth per head (words) instead of the profile's",
    "encoder-glitch-at": "an impossible A/B transition at this encoder count",
    "starve-guard": "0: a starved FIFO is the seed's underrun fault; 1: pause and resume the line",
    "bidir-error": "reverse-stroke drops land this many columns off (misaligned machine)",
    "head-error": "HEAD:COUNTS: this head sits COUNTS encoder counts off its profile position",
    "seed": "random seed for the injected faults",
}


@dataclass
class Faults:
    serial_ber: float = 0.0
    serial_byte_error: float = 0.0
    serial_drop: float = 0.0
    data_drop_after: int | None = None
    data_stall: float = 0.0
    host_jitter: str = "ideal"
    dead_nozzle: list = field(default_factory=list)      # [(head name, nozzle)]
    limit_at: int | None = None
    paper_length_mm: float | None = None
    paper_width_mm: float | None = None
    overtemp: list = field(default_factory=list)         # [(head name, stroke)]
    fifo_words: int | None = None
    encoder_glitch_at: int | None = None
    starve_guard: int | None = None
    bidir_error: int = 0
    head_error: list = field(default_factory=list)       # [(head name, counts)]
    seed: int = 1

    @classmethod
    def parse(cls, items: list[str] | None) -> "Faults":
        f = cls()
        names = {fl.name: fl for fl in fields(cls)}
        for item in items or []:
            if "=" not in item:
                raise ValueError(f"--inject {item!r}: expected KIND=VALUE; kinds: {', '.join(KINDS)}")
            kind, value = item.split("=", 1)
            attr = kind.strip().replace("-", "_")
            if attr not in names:
                raise ValueError(f"--inject {kind!r}: unknown fault; kinds: {', '.join(KINDS)}")
            try:
                if attr in ("dead_nozzle", "overtemp", "head_error"):
                    head, num = value.split(":")
                    getattr(f, attr).append((head.strip(), int(num)))
                elif attr == "host_jitter":
                    if value not in ("ideal", "typical", "loaded"):
                        raise ValueError(value)
                    f.host_jitter = value
                elif attr in ("data_drop_after", "limit_at", "fifo_words", "encoder_glitch_at",
                              "seed", "starve_guard", "bidir_error"):
                    setattr(f, attr, int(float(value)))
                else:
                    setattr(f, attr, float(value))
            except ValueError:
                raise ValueError(f"--inject {kind}={value}: bad value ({KINDS[kind.strip()]})") from None
        return f
