"""The printer profile (resources/printers/*.toml) and the device grid it defines.

Everything geometric comes from the profile; docs/geometry.md explains the grid:
columns at the dpi mode's pitch (encoder counts / k), rows at half the nozzle pitch
(two heads per colour staggered by half a pitch), nozzles 0 and 127 never fire.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomlkit

RESOURCES = Path(__file__).resolve().parent.parent / "resources"
DEFAULT_PROFILE = RESOURCES / "printers" / "default.toml"
COLORS = ("C", "M", "Y", "K")


class ProfileError(ValueError):
    pass


@dataclass(frozen=True)
class Head:
    index: int
    name: str
    color: str
    x_counts: int      # scan-direction offset from the carriage reference, encoder counts
    y_rows: int        # feed-direction offset of nozzle 0 from swath slot 0, rows

    @property
    def channel(self) -> int:
        return COLORS.index(self.color)


@dataclass(frozen=True)
class Profile:
    path: str
    name: str
    raw: dict = field(repr=False, compare=False)
    heads: tuple[Head, ...]
    nozzles: int
    dead_end_nozzles: tuple[int, ...]
    dead_nozzles: frozenset[tuple[int, int]]          # (head index, nozzle)
    nozzle_pitch_um: float
    counts_per_inch: int
    dpi_modes: tuple[int, ...]
    bidir_offset_columns: dict[int, int]
    max_fire_hz: float
    drop_volume_pl: float
    fifo_words: int
    pass_buffer_words: int
    ring_blocks: int
    block_fires: int
    print_width_mm: float

    # -- the device grid --------------------------------------------------------------
    @property
    def row_um(self) -> float:
        """Row pitch in the feed direction: nozzle pitch / heads per colour."""
        return self.nozzle_pitch_um / self.heads_per_color

    @property
    def row_nm(self) -> int:
        return int(round(self.row_um * 1000))

    @property
    def heads_per_color(self) -> int:
        return len(self.heads) // len(COLORS)

    @property
    def swath_rows(self) -> int:
        """Rows spanned by one colour's heads in one pass (slots 0 .. swath_rows-1)."""
        return max(h.y_rows for h in self.heads) + (self.nozzles - 1) * self.heads_per_color + 1

    def k(self, dpi: int) -> int:
        """Encoder counts per column at a dpi mode."""
        if dpi not in self.dpi_modes:
            raise ProfileError(f"{self.path}: dpi {dpi} is not one of {list(self.dpi_modes)}")
        return self.counts_per_inch // dpi

    def heads_of(self, color: str) -> list[Head]:
        return [h for h in self.heads if h.color == color]

    def slot_table(self, include_dead: bool = True) -> np.ndarray:
        """(4, swath_rows, 2) int: for each colour and swath slot, (head index, nozzle) that
        prints it, or (-1, -1) where no live nozzle sits (dead-end nozzles, and the profile's
        dead nozzles unless include_dead is False)."""
        table = np.full((len(COLORS), self.swath_rows, 2), -1, dtype=np.int64)
        for head in self.heads:
            for nozzle in range(self.nozzles):
                if nozzle in self.dead_end_nozzles or (
                        include_dead and (head.index, nozzle) in self.dead_nozzles):
                    continue
                slot = head.y_rows + nozzle * self.heads_per_color
                if table[head.channel, slot, 0] >= 0:
                    raise ProfileError(f"{self.path}: heads {head.name} and "
                                       f"{self.heads[table[head.channel, slot, 0]].name} "
                                       f"print the same row")
                table[head.channel, slot] = (head.index, nozzle)
        return table

    def usable_slots(self) -> tuple[int, int]:
        """The longest run of slots [first, last+1) that every colour can print with all
        nozzles alive; dead nozzles inside it are the pass planner's business."""
        ok = (self.slot_table(include_dead=False)[:, :, 0] >= 0).all(axis=0)
        best, start = (0, 0), None
        for slot, good in enumerate(list(ok) + [False]):
            if good and start is None:
                start = slot
            elif not good and start is not None:
                best = max(best, (start, slot), key=lambda r: r[1] - r[0])
                start = None
        if best[1] <= best[0]:
            raise ProfileError(f"{self.path}: no row that every colour can print")
        return best

    # -- feed ---------------------------------------------------------------------------
    @property
    def feed_um_per_step(self) -> float:
        f = self.raw["feed"]
        return 2 * math.pi * f["roller_radius_mm"] * 1000 / (f["steps_per_rev"] * f["gear_ratio"])

    def feed_steps_for_rows(self, rows_total: int) -> int:
        """Cumulative feed steps that put the paper `rows_total` rows from its start.
        Rounded from the absolute target each time, so the error never accumulates."""
        return int(round(rows_total * self.row_um / self.feed_um_per_step))

    # -- carriage ---------------------------------------------------------------------------
    def speed_counts_s(self, dpi: int) -> int:
        mm_s = float(self.raw["carriage"]["speed_mm_s"][str(dpi)])
        max_by_head = self.max_fire_hz * 25.4 / dpi
        mm_s = min(mm_s, float(self.raw["carriage"]["max_speed_mm_s"]), max_by_head * 0.99)
        return int(mm_s / 25.4 * self.counts_per_inch)

    def accel_counts_s2(self) -> int:
        return int(float(self.raw["carriage"]["accel_mm_s2"]) / 25.4 * self.counts_per_inch)

    @property
    def rail_counts(self) -> int:
        return int(self.raw["carriage"]["rail_counts"])

    def head_config_path(self) -> Path:
        return RESOURCES / self.raw["head"]["config_file"]

    def head_config_digits(self) -> list[int]:
        """The head configuration file (docs/head-config.md): hex digits, whitespace and
        '#' comments ignored."""
        path = self.head_config_path()
        digits = []
        for line in path.read_text().splitlines():
            for ch in line.split("#", 1)[0]:
                if not ch.isspace():
                    try:
                        digits.append(int(ch, 16))
                    except ValueError:
                        raise ProfileError(f"{path}: {ch!r} is not a hex digit") from None
        return digits


def load_profile(path: str | Path | None = None) -> Profile:
    path = Path(path) if path else DEFAULT_PROFILE
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ProfileError(f"{path}: printer profile not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{path}: not a valid TOML printer profile ({exc})") from None
    try:
        enc, head, layout, fpga = raw["encoder"], raw["head"], raw["layout"], raw["fpga"]
        counts = int(enc["lines_per_inch"]) * int(enc["quadrature"])
        heads = tuple(Head(i, h["name"], h["color"], int(h["x_counts"]), int(h["y_rows"]))
                      for i, h in enumerate(layout["heads"]))
        names = {h.name: h.index for h in heads}
        dead = frozenset((names[d["head"]], int(d["nozzle"])) for d in layout.get("dead_nozzles", []))
        dpi_modes = tuple(int(d) for d in enc["dpi_modes"])
        prof = Profile(
            path=str(path), name=raw["printer"]["name"], raw=raw, heads=heads,
            nozzles=int(head["nozzles"]),
            dead_end_nozzles=tuple(int(n) for n in head["dead_end_nozzles"]),
            dead_nozzles=dead, nozzle_pitch_um=float(head["nozzle_pitch_um"]),
            counts_per_inch=counts, dpi_modes=dpi_modes,
            bidir_offset_columns={int(k): int(v) for k, v in layout["bidir_offset_columns"].items()},
            max_fire_hz=float(head["max_fire_hz"]), drop_volume_pl=float(head["drop_volume_pl"]),
            fifo_words=int(fpga["fifo_words"]), pass_buffer_words=int(fpga["pass_buffer_words"]),
            ring_blocks=int(fpga["dma_ring_blocks"]), block_fires=int(fpga["block_fires"]),
            print_width_mm=float(raw["printer"]["print_width_mm"]),
        )
    except KeyError as exc:
        raise ProfileError(f"{path}: missing key {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ProfileError(f"{path}: bad value ({exc})") from None
    _validate(prof)
    return prof


def _validate(p: Profile) -> None:
    if sorted(h.color for h in p.heads) != sorted(COLORS * (len(p.heads) // len(COLORS))) \
            or len(p.heads) % len(COLORS):
        raise ProfileError(f"{p.path}: heads must be {len(COLORS)} colours x the same count")
    if len(p.heads) > 8:
        raise ProfileError(f"{p.path}: the FPGA has 8 head channels")
    if p.nozzles != 128:
        raise ProfileError(f"{p.path}: an XJ128 has 128 nozzles")
    kmax = max(p.counts_per_inch // d for d in p.dpi_modes)
    for d in p.dpi_modes:
        if p.counts_per_inch % d:
            raise ProfileError(f"{p.path}: dpi {d} does not divide {p.counts_per_inch} counts/inch")
    for h in p.heads:
        if h.x_counts % kmax:
            raise ProfileError(f"{p.path}: head {h.name} x offset {h.x_counts} counts is not a "
                               f"multiple of {kmax} (whole columns at {min(p.dpi_modes)} dpi)")
    if p.fifo_words % 8 or p.block_fires * 8 > p.fifo_words + p.pass_buffer_words:
        raise ProfileError(f"{p.path}: a data block ({p.block_fires} fires) must fit the FIFO")
    p.slot_table()  # raises on overlapping rows
    if p.feed_um_per_step > p.row_um / 2:
        raise ProfileError(f"{p.path}: a feed step ({p.feed_um_per_step:.1f} um) is coarser "
                           f"than half a row ({p.row_um / 2:.1f} um)")


def save_calibration(path: str | Path, bidir_offset_columns: dict[int, int] | None = None,
                     head_x_counts: dict[str, int] | None = None,
                     dead_nozzles=None) -> Profile:
    """Write calibration results into a profile file, keeping its comments and layout
    (tomlkit edits the document in place), and return the reloaded profile, which
    validates them; a result that does not load leaves the file as it was.

    bidir_offset_columns: {dpi: columns}, the whole table.  head_x_counts: {head: counts}.
    dead_nozzles: the complete new list of dead nozzles, as (head name, nozzle) pairs or
    {"head": ..., "nozzle": ...} tables (None leaves the list alone, an empty list clears
    it); written as `dead_nozzles = [{ head = "M1", nozzle = 57 }, ...]` in [layout]."""
    path = Path(path)
    try:
        doc = tomlkit.parse(path.read_text())
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read the printer profile ({exc.strerror or exc})") from None
    except tomlkit.exceptions.ParseError as exc:
        raise ProfileError(f"{path}: not a valid TOML printer profile ({exc})") from None
    layout = doc.get("layout")
    if layout is None:
        raise ProfileError(f"{path}: no [layout] table to update")
    if bidir_offset_columns is not None:
        table = layout.get("bidir_offset_columns")
        if table is None:
            raise ProfileError(f"{path}: no bidir_offset_columns to update")
        new = {str(int(k)): int(v) for k, v in sorted(bidir_offset_columns.items())}
        for key in [k for k in table if k not in new]:
            del table[key]
        table.update(new)
    for name, counts in (head_x_counts or {}).items():
        heads = [h for h in layout.get("heads", []) if h.get("name") == name]
        if len(heads) != 1:
            raise ProfileError(f"{path}: no head {name!r} to update")
        heads[0]["x_counts"] = int(counts)
    if dead_nozzles is not None:
        dead = _dead_nozzle_list(path, dead_nozzles)
        items = [f'{{ head = "{h}", nozzle = {z} }}' for h, z in dead]
        value = ("[" + ", ".join(items) + "]" if len(items) <= 4 else       # one a line if many
                 "[\n" + "".join(f"  {it},\n" for it in items) + "]")
        layout["dead_nozzles"] = tomlkit.parse(f"v = {value}")["v"]
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(tomlkit.dumps(doc))
    try:
        load_profile(tmp)
    except ProfileError:
        tmp.unlink()
        raise
    tmp.replace(path)
    return load_profile(path)


def _dead_nozzle_list(path: Path, entries) -> list[tuple[str, int]]:
    """Checked, de-duplicated and sorted (head order, nozzle) dead nozzles."""
    prof = load_profile(path)
    index = {h.name: h.index for h in prof.heads}
    out = set()
    for e in entries:
        head, nozzle = (e["head"], e["nozzle"]) if isinstance(e, dict) else e
        if head not in index:
            raise ProfileError(f"{path}: no head {head!r} (heads: {', '.join(index)})")
        nozzle = int(nozzle)
        if not 1 <= nozzle <= prof.nozzles - 2:
            raise ProfileError(f"{path}: dead nozzle {head}:{nozzle}: nozzles are 1..{prof.nozzles - 2} "
                               f"(0 and {prof.nozzles - 1} never fire)")
        out.add((head, nozzle))
    return sorted(out, key=lambda hn: (index[hn[0]], hn[1]))
