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
    "bidir-error": "reverse-stroke drops land this far early: columns, or 0.3col, 25um",
    "head-error": "HEAD:COUNTS: this head sits COUNTS encoder counts off its profile position",
    "head-offset": "HEAD:x=20um,y=-10um: this head sits this far off its profile position",
    "feed-error": "the paper travels this much further per feed (15um), or by a fraction (0.1%)",
    "misdirect": "HEAD:NOZZLE:8um (along the feed) or HEAD:NOZZLE:x=5um,y=-3um (repeatable)",
    "dot-diameter": "diameter of a dot on the paper in the scan (e.g. 120um)",
    "dot-gain": "colour drift: every dot spreads this much wider on the paper (e.g. +8%: a "
                "new ink batch, a warmer platen; docs/media.md)",
    "scan-rotation": "scan: the sheet lies rotated by this many degrees on the glass",
    "scan-scale": "scan: the scanner's true resolution is this factor finer (e.g. 1.002)",
    "scan-offset": "scan: X,Y in mm: the sheet lies this far right/down on the glass",
    "scan-margin": "scan: mm of paper scanned around the image area (default 3; more for a "
                   "sheet turned or shifted on the glass)",
    "scan-noise": "scan: sensor noise, sigma in 8-bit levels (default 1.5)",
    "scan-blur": "scan: optics blur, Gaussian sigma (default 10um)",
    "scan-mode": "scan: rgb (default) or grey",
    "pci-desc-error": "PCI card: the N-th DMA descriptor fetch is a master abort (docs/pci.md 8)",
    "pci-dma-abort": "PCI card: the N-th block's DMA is aborted half-way (master abort)",
    "pci-irq-miss": "PCI card: each interrupt is lost with this probability",
    "pci-bus-stall": "PCI card: N:SECONDS: the N-th block's DMA is held off that long",
    "idle-time-scale": "head care: each second the printer stands idle counts this many on the "
                       "drying clock (a long pause in a short test, docs/emulator.md)",
    "dry-nozzle": "HEAD:NOZZLE that has dried (misfires until spat or purged; repeatable)",
    "clogged-nozzle": "HEAD:NOZZLE that has clogged (misfires until purged; repeatable)",
    "skew": "the paper travels at this angle to the feed axis (0.2deg; positive: the print runs "
            "to the right down the sheet; docs/physical.md)",
    "seed": "random seed for the injected faults and the scanner's noise",
    "boot": "the power-up number JOB_STATUS reports (default: drawn at random at power-up; "
            "docs/protocol.md 2.10)",
}

UNITS = ("um", "mm", "col", "row")


@dataclass(frozen=True)
class Length:
    """A length with its unit (docs/physical.md): um, mm, col (columns of the job's dpi
    mode) or row (rows of the job's row pitch)."""
    value: float
    unit: str = "um"

    @classmethod
    def parse(cls, text: str, default_unit: str = "um") -> "Length":
        t = text.strip().lower().replace("µm", "um")
        for unit in UNITS:
            if t.endswith(unit):
                return cls(float(t[:-len(unit)]), unit)
        return cls(float(t), default_unit)

    def um(self, col_um: float, row_um: float) -> float:
        return self.value * {"um": 1.0, "mm": 1000.0, "col": col_um, "row": row_um}[self.unit]


def _xy(text: str) -> tuple[Length, Length]:
    """'x=20um,y=-10um' (either part optional) -> (dx, dy)."""
    dx = dy = Length(0.0)
    for part in text.split(","):
        key, _, val = part.partition("=")
        if key.strip() == "x" and val:
            dx = Length.parse(val)
        elif key.strip() == "y" and val:
            dy = Length.parse(val)
        else:
            raise ValueError(part)
    return dx, dy


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
    bidir_error: float | Length = 0                      # a number: columns
    head_error: list = field(default_factory=list)       # [(head name, counts)]
    head_offset: list = field(default_factory=list)      # [(head name, Length x, Length y)]
    feed_error: Length | None = None                     # extra travel per feed
    feed_error_fraction: float = 0.0                     # of each feed's travel
    misdirect: list = field(default_factory=list)        # [(head name, nozzle, Length x, Length y)]
    dot_diameter: Length | None = None
    dot_gain: float = 0.0                                # fraction of the dot's diameter
    scan_rotation: float = 0.0                           # degrees
    scan_scale: float = 1.0
    scan_offset: tuple = (0.0, 0.0)                      # mm
    scan_margin: float = 3.0                             # mm around the image area
    scan_noise: float = 1.5                              # 8-bit levels
    scan_blur: Length = Length(10.0)
    scan_mode: str = "rgb"
    pci_desc_error: int | None = None
    pci_dma_abort: int | None = None
    pci_irq_miss: float = 0.0
    pci_bus_stall: tuple | None = None                   # (block number, seconds)
    idle_time_scale: float = 1.0
    dry_nozzle: list = field(default_factory=list)       # [(head name, nozzle)]
    clogged_nozzle: list = field(default_factory=list)   # [(head name, nozzle)]
    skew: float = 0.0                                    # degrees (docs/physical.md)
    seed: int = 1
    boot: int | None = None                              # power-up number (None: random)

    @classmethod
    def parse(cls, items: list[str] | None) -> "Faults":
        f = cls()
        names = {fl.name: fl for fl in fields(cls)}
        for item in items or []:
            if "=" not in item:
                raise ValueError(f"--inject {item!r}: expected KIND=VALUE; kinds: {', '.join(KINDS)}")
            kind, value = item.split("=", 1)
            attr = kind.strip().replace("-", "_")
            if attr not in names or kind.strip() not in KINDS:
                raise ValueError(f"--inject {kind!r}: unknown fault; kinds: {', '.join(KINDS)}")
            try:
                if attr in ("dead_nozzle", "overtemp", "head_error", "dry_nozzle", "clogged_nozzle"):
                    head, num = value.split(":")
                    getattr(f, attr).append((head.strip(), int(num)))
                elif attr == "host_jitter":
                    if value not in ("ideal", "typical", "loaded"):
                        raise ValueError(value)
                    f.host_jitter = value
                elif attr == "bidir_error":
                    f.bidir_error = Length.parse(value, "col")
                elif attr == "head_offset":
                    head, xy = value.split(":", 1)
                    f.head_offset.append((head.strip(), *_xy(xy)))
                elif attr == "feed_error":
                    if value.strip().endswith("%"):
                        f.feed_error_fraction = float(value.strip()[:-1]) / 100
                    else:
                        f.feed_error = Length.parse(value)
                        if f.feed_error.unit == "col":
                            raise ValueError(value)
                elif attr == "skew":
                    f.skew = float(value.strip().lower().removesuffix("deg").removesuffix("°"))
                    if not abs(f.skew) <= 5:
                        raise ValueError(value)
                elif attr == "misdirect":
                    head, nozzle, off = value.split(":", 2)
                    xy = _xy(off) if "=" in off else (Length(0.0), Length.parse(off))
                    f.misdirect.append((head.strip(), int(nozzle), *xy))
                elif attr in ("dot_diameter", "scan_blur"):
                    length = Length.parse(value)
                    if length.unit not in ("um", "mm") or length.value < 0:
                        raise ValueError(value)
                    setattr(f, attr, length)
                elif attr == "dot_gain":
                    v = value.strip()
                    f.dot_gain = float(v[:-1]) / 100 if v.endswith("%") else float(v)
                    if not -0.5 < f.dot_gain < 2:
                        raise ValueError(value)
                elif attr == "scan_offset":
                    x, y = value.lower().replace("mm", "").split(",")
                    f.scan_offset = (float(x), float(y))
                elif attr == "scan_mode":
                    if value not in ("rgb", "grey", "gray"):
                        raise ValueError(value)
                    f.scan_mode = "grey" if value == "gray" else value
                elif attr == "pci_bus_stall":
                    n, sec = value.split(":")
                    f.pci_bus_stall = (int(n), float(sec))
                elif attr in ("pci_desc_error", "pci_dma_abort", "data_drop_after", "limit_at", "fifo_words", "encoder_glitch_at",
                              "seed", "starve_guard", "boot"):
                    setattr(f, attr, int(float(value)))
                else:
                    setattr(f, attr, float(value))
            except ValueError:
                raise ValueError(f"--inject {kind}={value}: bad value ({KINDS[kind.strip()]})") from None
        return f
