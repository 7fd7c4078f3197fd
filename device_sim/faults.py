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
    "feed-noise": "random feed error: each feed travels a Gaussian error of this sigma further "
                  "(4um, 0.05row; the fixed part is feed-error; docs/physical.md \"The machine\")",
    "volume-spread": "per-nozzle drop volume spread, sigma (3%: each nozzle's drops 3 % larger or "
                     "smaller, for the whole job; seeded)",
    "direction-spread": "per-nozzle direction spread at the paper, sigma per axis (3um, or 3mrad "
                        "of angle over the head gap; seeded)",
    "head-density": "HEAD:+4%: this head's drops carry this much more ink (repeatable)",
    "head-density-spread": "head-to-head drop volume spread, sigma (2%; seeded)",
    "machine": "a whole machine's errors at once: perfect | typical | tired (docs/physical.md "
               "\"The machine\"); explicit kinds override its values",
    "skew": "the paper travels at this angle to the feed axis (0.2deg; positive: the print runs "
            "to the right down the sheet; docs/physical.md)",
    "seed": "random seed for the injected faults and the scanner's noise",
    "boot": "the power-up number JOB_STATUS reports (default: drawn at random at power-up; "
            "docs/protocol.md 2.10)",
}

UNITS = ("um", "mm", "col", "row")

#: the named machines of `--inject machine=` (docs/physical.md "The machine"): the errors a
#: well-kept and a worn printer of this make show; each value as `--inject` would take it
MACHINES: dict[str, dict[str, str]] = {
    "perfect": {},
    "typical": {"feed-noise": "3um", "volume-spread": "3%", "direction-spread": "3mrad",
                "head-density-spread": "2%"},
    "tired": {"feed-noise": "8um", "volume-spread": "8%", "direction-spread": "10mrad",
              "head-density-spread": "5%"},
}


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


HEAD_GAP_MM = 1.0          # nozzle plate to paper (decision, docs/physical.md; physical.py)


def _fraction(text: str) -> float:
    """'3%' or '0.03' -> 0.03; '+4%' -> 0.04."""
    t = text.strip()
    return float(t[:-1]) / 100 if t.endswith("%") else float(t)


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
    feed_noise: Length | None = None                     # sigma of the random feed error
    volume_spread: float = 0.0                           # sigma, fraction of the drop volume
    direction_spread: Length | None = None               # sigma per axis at the paper
    head_density: list = field(default_factory=list)     # [(head name, fraction)]
    head_density_spread: float = 0.0                     # sigma, fraction of the drop volume
    machine: str = "perfect"
    skew: float = 0.0                                    # degrees (docs/physical.md)
    seed: int = 1
    boot: int | None = None                              # power-up number (None: random)

    @property
    def machine_errors(self) -> bool:
        """Whether the machine's random errors (feed noise, nozzle and head spreads) are on."""
        return bool(self.feed_noise is not None and self.feed_noise.value
                    or self.volume_spread or self.direction_spread is not None
                    and self.direction_spread.value or self.head_density
                    or self.head_density_spread)

    @classmethod
    def parse(cls, items: list[str] | None) -> "Faults":
        f = cls()
        names = {fl.name: fl for fl in fields(cls)}
        items = list(items or [])
        machine = [i.split("=", 1)[1].strip() for i in items if i.split("=", 1)[0].strip() == "machine"]
        if machine:
            if machine[-1] not in MACHINES:
                raise ValueError(f"--inject machine={machine[-1]}: bad value (one of "
                                 f"{', '.join(MACHINES)})")
            given = {i.split("=", 1)[0].strip() for i in items}
            # the preset first, so that an explicit kind given with it wins
            items = [f"{k}={v}" for k, v in MACHINES[machine[-1]].items() if k not in given] + items
        for item in items:
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
                elif attr == "machine":
                    f.machine = value.strip()
                elif attr == "feed_noise":
                    f.feed_noise = Length.parse(value)
                    if f.feed_noise.unit == "col" or f.feed_noise.value < 0:
                        raise ValueError(value)
                elif attr == "direction_spread":
                    v = value.strip().lower()
                    # an angle: the drop's offset over the head gap (physical.HEAD_GAP_MM)
                    f.direction_spread = (Length(float(v[:-4]) * HEAD_GAP_MM) if v.endswith("mrad")
                                          else Length.parse(v))
                    if f.direction_spread.unit not in ("um", "mm") or f.direction_spread.value < 0:
                        raise ValueError(value)
                elif attr in ("volume_spread", "head_density_spread"):
                    setattr(f, attr, _fraction(value))
                    if not 0 <= getattr(f, attr) < 0.5:
                        raise ValueError(value)
                elif attr == "head_density":
                    head, amount = value.split(":")
                    frac = _fraction(amount)
                    if not -0.5 < frac < 1:
                        raise ValueError(value)
                    f.head_density.append((head.strip(), frac))
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
