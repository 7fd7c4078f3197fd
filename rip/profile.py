"""The printer profile (resources/printers/*.toml) and the device grid it defines.

Everything geometric comes from the profile; docs/geometry.md explains the grid:
columns at the dpi mode's pitch (encoder counts / k), rows at half the nozzle pitch
(two heads per colour staggered by half a pitch), nozzles 0 and 127 never fire.

The file is read and checked once, by load_profile: one frozen dataclass per [section],
each key declared once below with its type, default and range (`_key`), so that a bad
value is refused at load with the file, the section, the key and the problem, and the
RIP, the driver and the emulator read typed attributes (profile.carriage.accel_mm_s2).
The table in docs/geometry.md ("The profile file") is spec_markdown()'s output.

This module imports nothing from wideprint: it is the printer description the RIP, the
driver and the emulator share.
"""

from __future__ import annotations

import difflib
import json
import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable

import numpy as np
import tomlkit

RESOURCES = Path(__file__).resolve().parent.parent / "resources"
DEFAULT_PROFILE = RESOURCES / "printers" / "default.toml"
COLORS = ("C", "M", "Y", "K")
INTENTS = ("perceptual", "relative", "saturation", "absolute")   # as rip/color/
FPGA_HEAD_CHANNELS = 8
WORDS_PER_FIRE = 8            # 128 nozzle bits in 16-bit FIFO words
FINE_STEPS = 64               # fine steps per column of the bidir offset (docs/calibration.md)


class ProfileError(ValueError):
    pass


_REQUIRED = object()          # a key without a default


# -- where a value sits, and how it is shown in a message ------------------------------------
def _show(v: Any, limit: int = 60) -> str:
    """A value as it would be written in TOML (strings quoted), shortened."""
    if isinstance(v, bool):
        s = "true" if v else "false"
    elif isinstance(v, str):
        s = json.dumps(v, ensure_ascii=False)
    elif isinstance(v, dict):
        s = "{ " + ", ".join(f"{k} = {_show(x)}" for k, x in v.items()) + " }" if v else "{}"
    elif isinstance(v, (list, tuple)):
        s = "[" + ", ".join(_show(x) for x in v) + "]"
    else:
        s = str(v)
    return s if len(s) <= limit else s[:limit - 3] + "..."


class _At:
    """File, [section] and key (dotted / indexed inside arrays and tables) of a value."""

    def __init__(self, path: Path | str, section: str, key: str = ""):
        self.path, self.section, self.key = path, section, key

    def sub(self, name: str) -> _At:
        return _At(self.path, self.section, f"{self.key}.{name}" if self.key else name)

    def item(self, i: int) -> _At:
        return _At(self.path, self.section, f"{self.key}[{i}]")

    def error(self, msg: str) -> ProfileError:
        where = f"[{self.section}] {self.key}" if self.key else f"[{self.section}]"
        return ProfileError(f"{self.path}: {where}: {msg}")

    def bad(self, spec: _Spec, v: Any) -> ProfileError:
        return self.error(f"must be {spec.what()}, not {_show(v)}")


class _Ctx:
    """The sections read so far (later sections are checked against earlier ones)."""

    def __init__(self, path: Path | str):
        self.path = path
        self.sections: dict[str, Any] = {}

    def __getattr__(self, name: str) -> Any:
        try:
            return self.sections[name]
        except KeyError:
            raise AttributeError(name) from None


# -- value specs: parse one TOML value into its typed form, or raise naming where it is -------
class _Spec:
    kind = ""                      # the type column of the spec table

    def what(self, plural: bool = False) -> str:   # "a number > 0": the message says "must be <what>"
        raise NotImplementedError

    def range(self) -> str:        # the range column of the spec table
        return ""

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        raise NotImplementedError


class _Num(_Spec):
    def __init__(self, integer: bool = False, *, gt: float | None = None, ge: float | None = None,
                 le: float | None = None, multiple: int | None = None,
                 choices: tuple[float, ...] | None = None) -> None:
        self.integer, self.gt, self.ge, self.le = integer, gt, ge, le
        self.multiple, self.choices = multiple, choices
        self.kind = "int" if integer else "float"

    def range(self) -> str:
        if self.choices:
            return ", ".join(str(c) for c in self.choices)
        if self.ge is not None and self.le is not None:
            parts = [f"{self.ge}..{self.le}"]
        else:
            low = f"> {self.gt}" if self.gt is not None else \
                f">= {self.ge}" if self.ge is not None else ""
            parts = [low, f"<= {self.le}" if self.le is not None else ""]
        parts.append(f"a multiple of {self.multiple}" if self.multiple else "")
        return " and ".join(p for p in parts if p)

    def what(self, plural: bool = False) -> str:
        if self.choices:
            return (str(self.choices[0]) if len(self.choices) == 1
                    else ("" if plural else "one of ") + self.range())
        noun = ("integers" if plural else "an integer") if self.integer else \
            ("numbers" if plural else "a number")
        r = self.range()
        if not r:
            return noun
        return f"{noun} in {r}" if r[0].isdigit() else f"{noun} {r}" if r[0] in "<>" \
            else f"{noun}, {r}"

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        ok = isinstance(v, int if self.integer else (int, float)) and not isinstance(v, bool)
        if not ok:
            raise at.bad(self, v)
        x = int(v) if self.integer else float(v)
        if not math.isfinite(x) \
                or self.choices and x not in self.choices \
                or self.gt is not None and not x > self.gt \
                or self.ge is not None and not x >= self.ge \
                or self.le is not None and not x <= self.le \
                or self.multiple and x % self.multiple:
            raise at.bad(self, v)
        return x


class _Str(_Spec):
    kind = "str"

    def __init__(self, choices: tuple[str, ...] | None = None) -> None:
        self.choices = choices

    def range(self) -> str:
        return ", ".join(json.dumps(c) for c in self.choices) if self.choices else "not empty"

    def what(self, plural: bool = False) -> str:
        if self.choices:
            return f"one of {self.range()}"
        return "non-empty strings" if plural else "a non-empty string"

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        if not isinstance(v, str) or not v.strip() or self.choices and v not in self.choices:
            raise at.bad(self, v)
        return v


class _Bool(_Spec):
    kind = "bool"

    def what(self, plural: bool = False) -> str:
        return "true or false"

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        if not isinstance(v, bool):
            raise at.bad(self, v)
        return v


class _List(_Spec):
    def __init__(self, item: _Spec, min_len: int = 0, distinct: bool = False) -> None:
        self.item, self.min_len, self.distinct = item, min_len, distinct
        self.kind = f"list of {item.kind}"

    def range(self) -> str:
        r = self.item.range()
        own = ", ".join(p for p in ("at least one" if self.min_len else "",
                                    "distinct" if self.distinct else "") if p)
        return "; ".join(p for p in (own, r and f"each {r}") if p)

    def what(self, plural: bool = False) -> str:
        return f"a {'non-empty ' if self.min_len else ''}list of {self.item.what(plural=True)}"

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        if not isinstance(v, list) or len(v) < self.min_len:
            raise at.bad(self, v)
        out = tuple(self.item.parse(x, at.item(i), ctx, got) for i, x in enumerate(v))
        if self.distinct:
            dup = next((x for i, x in enumerate(out) if x in out[:i]), None)
            if dup is not None:
                raise at.error(f"{_show(dup)} is listed twice")
        return out


class _DpiTable(_Spec):
    """{ dpi = value, ... } keyed by the [encoder] dpi modes; `fill` for modes not listed
    (None: every mode must be listed)."""

    def __init__(self, value: _Num, fill: Any = None) -> None:
        self.value, self.fill = value, fill
        self.kind = f"table dpi → {value.kind}"

    def range(self) -> str:
        r = self.value.range()
        return (f"each {r}; " if r else "") + ("every dpi mode" if self.fill is None
                                                else f"modes not listed: {self.fill}")

    def what(self, plural: bool = False) -> str:
        return f"a table {{ dpi = {self.value.what()}, ... }}"

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        if not isinstance(v, dict):
            raise at.bad(self, v)
        modes = ctx.encoder.dpi_modes
        out: dict[int, Any] = {}
        for key, x in v.items():
            if not (key.isdigit() and int(key) in modes):
                raise at.sub(key).error(
                    f"not a dpi mode ([encoder] dpi_modes: {', '.join(map(str, modes))})")
            out[int(key)] = self.value.parse(x, at.sub(key), ctx, got)
        for d in modes:
            if d not in out:
                if self.fill is None:
                    raise at.error(f"no value for dpi {d} (every dpi mode needs one)")
                out[d] = self.fill
        return {d: out[d] for d in sorted(out)}


def _read_keys(table: dict[str, Any], at: _At, keys: list[tuple[str, _Spec, Any]],
               ctx: _Ctx) -> dict[str, Any]:
    """Each key of `keys` (name, spec, default or _REQUIRED) parsed from the TOML table;
    an unknown key is an error naming the known ones."""
    names = [k for k, _, _ in keys]
    for k in table:
        if k not in names:
            near = difflib.get_close_matches(k, names, 1)
            raise at.sub(k).error(f"unknown key (known keys: {', '.join(names)})"
                                  + (f"; did you mean {near[0]}?" if near else ""))
    got: dict[str, Any] = {}
    for name, spec, default in keys:
        if name in table:
            got[name] = spec.parse(table[name], at.sub(name), ctx, got)
        elif default is _REQUIRED:
            raise at.sub(name).error(f"missing required key ({spec.what()})")
        else:   # defaults are TOML values, typed by the same spec
            got[name] = None if default is None else spec.parse(default, at.sub(name), ctx, got)
    return got


class _Table(_Spec):
    """An inline table with fixed keys, all required (a head, a dead nozzle)."""

    def __init__(self, keys: list[tuple[str, _Spec]],
                 make: Callable[[dict[str, Any], _At, _Ctx, dict[str, Any]], Any]) -> None:
        self.keys = [(k, s, _REQUIRED) for k, s in keys]
        self.make = make
        self.kind = "{ " + ", ".join(k for k, _ in keys) + " }"

    def what(self, plural: bool = False) -> str:
        return "tables " + self.kind if plural else "a table " + self.kind

    def range(self) -> str:
        return "; ".join(f"{k}: {s.range()}" for k, s, _ in self.keys if s.range())

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        if not isinstance(v, dict):
            raise at.bad(self, v)
        return self.make(_read_keys(v, at, self.keys, ctx), at, ctx, got)


class _Curve(_Spec):
    kind = "list of [in, out]"

    def range(self) -> str:
        return "0..255, in increasing, at least 2 points"

    def what(self, plural: bool = False) -> str:
        return "a list of at least 2 [in, out] points, numbers 0..255, in increasing"

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        if not isinstance(v, list) or len(v) < 2:
            raise at.bad(self, v)
        pts: list[tuple[Any, ...]] = []
        for i, p in enumerate(v):
            if not (isinstance(p, list) and len(p) == 2):
                raise at.item(i).error(f"must be an [in, out] pair, not {_show(p)}")
            pts.append(tuple(_Num(ge=0, le=255).parse(x, at.item(i), ctx, got) for x in p))
            if i and not pts[-1][0] > pts[-2][0]:
                raise at.item(i).error(f"in must increase: {_show(p)} follows {_show(v[i - 1])}")
        return tuple(pts)


def _key(spec: _Spec, default: Any = _REQUIRED, doc: str = "", shown: str | None = None) -> Any:
    """A profile key: its spec, its default as a TOML value (_REQUIRED: none; None: absent
    means `shown`) and what it is, for the spec table."""
    return field(metadata=dict(spec=spec, default=default, doc=doc, shown=shown))


# -- the sections ----------------------------------------------------------------------------
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


def _make_dead(v: dict[str, Any], at: _At, ctx: _Ctx, got: dict[str, Any]) -> tuple[int, int]:
    """(head index, nozzle) of a dead nozzle named by head name."""
    index = {h.name: h.index for h in got["heads"]}
    if v["head"] not in index:
        raise at.sub("head").error(f"no head {_show(v['head'])} (heads: {', '.join(index)})")
    head = ctx.head
    if v["nozzle"] >= head.nozzles or v["nozzle"] in head.dead_end_nozzles:
        raise at.sub("nozzle").error(
            f"must be a nozzle that fires, 0..{head.nozzles - 1} but not "
            f"{', '.join(map(str, head.dead_end_nozzles))} (dead_end_nozzles), not {v['nozzle']}")
    return index[v["head"]], v["nozzle"]


_HEAD = _Table([("name", _Str()), ("color", _Str(COLORS)), ("x_counts", _Num(True)),
                ("y_rows", _Num(True, ge=0))], lambda v, at, ctx, got: v)
_DEAD = _Table([("head", _Str()), ("nozzle", _Num(True, ge=0))], _make_dead)


class _Heads(_List):
    def __init__(self) -> None:
        super().__init__(_HEAD, min_len=1)

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        heads = tuple(Head(i, **h) for i, h in enumerate(super().parse(v, at, ctx, got)))
        seen: set[str] = set()
        for h in heads:
            if h.name in seen:
                raise at.item(h.index).sub("name").error(f"{_show(h.name)} is used by two heads")
            seen.add(h.name)
        return heads


class _HeadTable(_Spec):
    """{ HEAD = value, ... } keyed by head names of [layout] heads (read before it)."""

    def __init__(self, value: _Spec) -> None:
        self.value = value
        self.kind = f"table head → {value.kind}"

    def range(self) -> str:
        return "keys: head names; heads not listed: 0"

    def what(self, plural: bool = False) -> str:
        return f"a table {{ HEAD = {self.value.what()}, ... }}"

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        if not isinstance(v, dict):
            raise at.bad(self, v)
        names = [h.name for h in got["heads"]]
        out: dict[str, Any] = {}
        for key, x in v.items():
            if key not in names:
                raise at.sub(key).error(f"no head {_show(key)} (heads: {', '.join(names)})")
            out[key] = self.value.parse(x, at.sub(key), ctx, got)
        return out


class _NozzleTable(_HeadTable):
    """{ HEAD = [one value per nozzle], ... } for every head of [layout] heads, or none."""

    def __init__(self, each: _Num) -> None:
        super().__init__(_List(each))
        self.each = each

    def range(self) -> str:
        return f"every head or none; one value per nozzle, each {self.each.range()}"

    def what(self, plural: bool = False) -> str:
        return f"a table {{ HEAD = [one {self.each.what()} per nozzle], ... }}"


class _DeadNozzles(_List):
    def __init__(self) -> None:
        super().__init__(_DEAD)

    def parse(self, v: Any, at: _At, ctx: _Ctx, got: dict[str, Any]) -> Any:
        return frozenset(super().parse(v, at, ctx, got))


class _Section:
    def _check(self, at: _At, ctx: _Ctx) -> None:
        """Checks between keys, and against earlier sections."""


@dataclass(frozen=True, kw_only=True)
class PrinterSection(_Section):
    name: str = _key(_Str(), doc="shown to the operator and in reports")
    print_width_mm: float = _key(_Num(gt=0), doc="mm, the widest printable span")


@dataclass(frozen=True, kw_only=True)
class EncoderSection(_Section):
    lines_per_inch: int = _key(_Num(True, gt=0), doc="the linear encoder strip")
    quadrature: int = _key(_Num(True, choices=(1, 2, 4)), 4,
                           doc="edges counted per line (counts per inch = lines x quadrature)")
    dpi_modes: tuple[int, ...] = _key(_List(_Num(True, gt=0), min_len=1, distinct=True),
                                      doc="column pitches; each divides the counts per inch")

    @property
    def counts_per_inch(self) -> int:
        return self.lines_per_inch * self.quadrature

    def _check(self, at: _At, ctx: _Ctx) -> None:
        for i, d in enumerate(self.dpi_modes):
            if self.counts_per_inch % d:
                raise at.sub("dpi_modes").item(i).error(
                    f"{d} does not divide the {self.counts_per_inch} counts per inch "
                    f"(lines_per_inch {self.lines_per_inch} x quadrature {self.quadrature})")


@dataclass(frozen=True, kw_only=True)
class HeadSection(_Section):
    model: str = _key(_Str(), "XJ128-360", doc="informational")
    nozzles: int = _key(_Num(True, choices=(128,)), 128,
                        doc="an XJ128: a fire is 8 FIFO words of 16 bits")
    dead_end_nozzles: tuple[int, ...] = _key(_List(_Num(True, ge=0)), [0, 127],
                                             doc="never fire; each < nozzles")
    nozzle_pitch_um: float = _key(_Num(gt=0), doc="row pitch = nozzle pitch / heads per colour")
    drop_volume_pl: float = _key(_Num(gt=0), doc="ink estimates")
    max_fire_hz: float = _key(_Num(gt=0), doc="caps each dpi mode's speed at 99 %")
    phases: int = _key(_Num(True, ge=1), 3, doc="CYCLESTB phases (informational)")
    config_file: str = _key(_Str(), doc="path under resources/; the file must exist "
                            "(docs/head-config.md)")
    overtemp_c: float = _key(_Num(), 55.0, doc="°C: the carriage board drops WE_EN above")
    nominal_temp_c: float = _key(_Num(), 35.0, doc="°C, the emulated heads'; < overtemp_c")

    @property
    def config_path(self) -> Path:
        return RESOURCES / self.config_file

    def _check(self, at: _At, ctx: _Ctx) -> None:
        for i, n in enumerate(self.dead_end_nozzles):
            if n >= self.nozzles:
                raise at.sub("dead_end_nozzles").item(i).error(
                    f"must be a nozzle 0..{self.nozzles - 1}, not {n}")
        if not self.config_path.is_file():
            raise at.sub("config_file").error(f"no such file {self.config_path}")
        if not self.nominal_temp_c < self.overtemp_c:
            raise at.sub("nominal_temp_c").error(
                f"must be below overtemp_c ({self.overtemp_c}), not {self.nominal_temp_c}")


@dataclass(frozen=True, kw_only=True)
class LayoutSection(_Section):
    heads: tuple[Head, ...] = _key(_Heads(), doc="x_counts: encoder counts from the carriage "
                                   "reference, whole columns of the coarsest dpi mode; y_rows: "
                                   "rows from swath slot 0. At most 8 heads, the same number per "
                                   "colour, no two of a colour on one row, some row every colour "
                                   "prints")
    dead_nozzles: frozenset[tuple[int, int]] = _key(
        _DeadNozzles(), [], doc="head names; nozzles that fire otherwise. Loaded as "
        "(head index, nozzle); the stroke planner prints around them")
    bidir_offset_columns: dict[int, int] = _key(_DpiTable(_Num(True), fill=0), {},
                                                doc="columns reverse strokes are shifted by (bidir "
                                                "alignment)")
    bidir_fine_steps: dict[int, int] = _key(
        _DpiTable(_Num(True, ge=-(FINE_STEPS - 1), le=FINE_STEPS - 1), fill=0), {},
        doc=f"1/{FINE_STEPS} columns added to bidir_offset_columns (calibrate bidir; "
        "docs/calibration.md)")
    head_x_um: dict[str, float] = _key(_HeadTable(_Num(ge=-10000, le=10000)), {},
                                       doc="measured: the head sits this far right of x_counts; "
                                       "fired to match (calibrate heads)")
    head_y_um: dict[str, float] = _key(_HeadTable(_Num(ge=-10000, le=10000)), {},
                                       doc="measured: the head sits this far down the paper from "
                                       "y_rows; recorded, not applied (under a nozzle pitch)")
    nozzle_dy_um: dict[str, tuple[float, ...]] = _key(
        _NozzleTable(_Num(ge=-1000, le=1000)), {},
        doc="measured (calibrate nozzles, 1200 dpi scan): each nozzle's drops land this far "
        "down the paper from its row; the `hiding` pass mask plans with it (docs/quality.md)")
    nozzle_volume_pct: dict[str, tuple[float, ...]] = _key(
        _NozzleTable(_Num(ge=-100, le=200)), {},
        doc="measured with nozzle_dy_um: each nozzle's drop volume against its colour's "
        "median, %; -100: no drop (dead, or nozzles 0 and 127)")
    nozzles_measured: str | None = _key(_Str(), None, shown="none",
                                        doc="when nozzle_dy_um and nozzle_volume_pct were "
                                        "measured (UTC, ISO 8601)")

    @property
    def heads_per_color(self) -> int:
        return len(self.heads) // len(COLORS)

    def _check(self, at: _At, ctx: _Ctx) -> None:
        at_heads = at.sub("heads")
        if len(self.heads) > FPGA_HEAD_CHANNELS:
            raise at_heads.error(f"the FPGA has {FPGA_HEAD_CHANNELS} head channels, "
                                 f"not {len(self.heads)}")
        count = {c: sum(h.color == c for h in self.heads) for c in COLORS}
        if len(set(count.values())) != 1:
            raise at_heads.error("every colour needs the same number of heads, not "
                                 + ", ".join(f"{c}: {n}" for c, n in count.items()))
        kmax = max(ctx.encoder.counts_per_inch // d for d in ctx.encoder.dpi_modes)
        for h in self.heads:
            if h.x_counts % kmax:
                raise at_heads.item(h.index).sub("x_counts").error(
                    f"must be a multiple of {kmax} (whole columns at "
                    f"{min(ctx.encoder.dpi_modes)} dpi), not {h.x_counts}")
        hpc = self.heads_per_color
        live = set(range(ctx.head.nozzles)) - set(ctx.head.dead_end_nozzles)
        rows: dict[str, dict[int, str]] = {c: {} for c in COLORS}
        for h in self.heads:
            for n in live:
                other = rows[h.color].setdefault(h.y_rows + n * hpc, h.name)
                if other != h.name:
                    raise at_heads.error(f"heads {other} and {h.name} print the same row")
        if not set.intersection(*(set(r) for r in rows.values())):
            raise at_heads.error("no row that every colour can print (y_rows)")
        # the nozzles' measured errors come as a whole: every head, every nozzle, dated
        names = [h.name for h in self.heads]
        tables = (("nozzle_dy_um", self.nozzle_dy_um), ("nozzle_volume_pct", self.nozzle_volume_pct))
        if any(t for _, t in tables):
            for key, table in tables:
                missing = [n for n in names if n not in table]
                if missing:
                    raise at.sub(key).error(f"no values for head(s) {', '.join(missing)}: "
                                            "the nozzles are measured all at once (calibrate nozzles)")
                for name, values in table.items():
                    if len(values) != ctx.head.nozzles:
                        raise at.sub(key).sub(name).error(
                            f"{len(values)} values, the head has {ctx.head.nozzles} nozzles")
            if not self.nozzles_measured:
                raise at.sub("nozzles_measured").error(
                    "missing: when nozzle_dy_um and nozzle_volume_pct were measured")


@dataclass(frozen=True, kw_only=True)
class CarriageSection(_Section):
    rail_counts: int = _key(_Num(True, gt=0), doc="encoder counts between the limit switches")
    home_counts: int = _key(_Num(True, ge=0), 0, doc="<= rail_counts (informational)")
    park_counts: int = _key(_Num(True, ge=0), doc="over the capping station; <= rail_counts")
    max_speed_mm_s: float = _key(_Num(gt=0), doc="moves that do not print; caps speed_mm_s")
    accel_mm_s2: float = _key(_Num(gt=0), doc="every carriage move")
    speed_mm_s: dict[int, float] = _key(_DpiTable(_Num(gt=0)),
                                        doc="printing speed, capped by max_speed_mm_s "
                                        "and max_fire_hz")
    # the DC servo plant and loop, for the emulator (docs/motion.md)
    motor_ke: float = _key(_Num(gt=0), 0.0287, doc="servo: back-EMF constant, V s/rad")
    motor_kt: float | None = _key(_Num(gt=0), None, doc="servo: torque constant, N m/A",
                                  shown="= motor_ke")
    motor_r_ohm: float = _key(_Num(gt=0), 1.89, doc="servo: armature resistance")
    motor_l_h: float = _key(_Num(gt=0), 0.00156, doc="servo: armature inductance")
    supply_v: float = _key(_Num(gt=0), 19.1, doc="servo: L298 bridge supply")
    current_limit_a: float = _key(_Num(gt=0), 2.0, doc="servo: LM393 current cut")
    inertia_kg_m2: float = _key(_Num(gt=0), 0.0001,
                                doc="servo: at the motor shaft, carriage included")
    friction_nm: float = _key(_Num(ge=0), 0.0, doc="servo: Coulomb friction at the shaft")
    pulley_diameter_mm: float = _key(_Num(gt=0), 10.0, doc="servo: belt pulley")
    servo_period_s: float = _key(_Num(gt=0), 0.001,
                                 doc="servo: DSP loop period; the gains are tuned for it")
    kp: float = _key(_Num(gt=0), 32.0, doc="servo: the thesis' PI gain (informational)")
    ti_s: float = _key(_Num(ge=0), 1.32, doc="servo: integral time of the position error (0: none)")

    @property
    def torque_constant(self) -> float:
        return self.motor_ke if self.motor_kt is None else self.motor_kt

    def _check(self, at: _At, ctx: _Ctx) -> None:
        for key in ("home_counts", "park_counts"):
            if getattr(self, key) > self.rail_counts:
                raise at.sub(key).error(f"must be <= rail_counts ({self.rail_counts}), "
                                        f"not {getattr(self, key)}")


@dataclass(frozen=True, kw_only=True)
class FeedSection(_Section):
    steps_per_rev: int = _key(_Num(True, gt=0), doc="stepper (half-)steps per motor turn")
    gear_ratio: float = _key(_Num(gt=0), doc="motor turns per roller turn")
    roller_radius_mm: float = _key(_Num(gt=0), doc="a feed step must be <= half a row")
    max_steps_s: float = _key(_Num(gt=0), doc="feed speed")
    accel_steps_s2: float = _key(_Num(gt=0), doc="feed acceleration")
    profile: str = _key(_Str(("trapezoid", "sigmoid")), "trapezoid", doc="feed speed profile")
    travel_error_ppm: float = _key(_Num(ge=-50000, le=50000), 0.0,
                                   doc="measured: the paper travels this much further than its "
                                   "steps say; feeds are scaled to match (calibrate feed)")

    @property
    def um_per_step(self) -> float:
        return 2 * math.pi * self.roller_radius_mm * 1000 / (self.steps_per_rev * self.gear_ratio)

    def _check(self, at: _At, ctx: _Ctx) -> None:
        row_um = ctx.head.nozzle_pitch_um / ctx.layout.heads_per_color
        if self.um_per_step > row_um / 2:
            raise at.sub("steps_per_rev, gear_ratio, roller_radius_mm").error(
                f"a feed step ({self.um_per_step:.1f} um) is coarser than half a row "
                f"({row_um / 2:.1f} um)")


@dataclass(frozen=True, kw_only=True)
class FpgaSection(_Section):
    fifo_words: int = _key(_Num(True, gt=0, multiple=WORDS_PER_FIRE),
                           doc="FIFO depth per head, 16-bit words")
    almost_empty_words: int = _key(_Num(True, ge=0), 64, doc="the FIFO_FLAGS LOW level (programmable; the seed's ALMOST_EMPTY is one fire from empty); < fifo_words")
    pass_buffer_words: int = _key(_Num(True, ge=0), 0,
                                  doc="on-card pass buffer per head (0: FIFO only)")
    dma_ring_blocks: int = _key(_Num(True, ge=1), doc="DMA blocks the host may have in flight")
    block_fires: int = _key(_Num(True, ge=1), doc="fires per head per data block; its 8 "
                            "words a fire fit fifo_words + pass_buffer_words")
    starve_guard: bool = _key(_Bool(), True, doc="re-run a line from a dry FIFO (false: "
                              "an underrun is a fault)")

    def _check(self, at: _At, ctx: _Ctx) -> None:
        if self.almost_empty_words >= self.fifo_words:
            raise at.sub("almost_empty_words").error(
                f"must be below fifo_words ({self.fifo_words}), not {self.almost_empty_words}")
        room = self.fifo_words + self.pass_buffer_words
        if self.block_fires * WORDS_PER_FIRE > room:
            raise at.sub("block_fires").error(
                f"a data block of {self.block_fires} fires ({self.block_fires * WORDS_PER_FIRE} "
                f"words) must fit fifo_words + pass_buffer_words ({room} words)")


@dataclass(frozen=True, kw_only=True)
class LinkSection(_Section):
    baud: int = _key(_Num(True, gt=0), 57600, doc="serial command link; a device spec's "
                     "baud= overrides it")
    retries: int = _key(_Num(True, ge=1), 3, doc="tries per frame (informational: the link "
                       "makes the protocol's 3)")
    response_timeout_s: float = _key(_Num(gt=0), 0.25, doc="command link")


@dataclass(frozen=True, kw_only=True)
class PaperSection(_Section):
    default_width_mm: float = _key(_Num(gt=0), doc="the emulator's sheet; the GUI's "
                                    "until the paper is measured")
    margin_mm: float = _key(_Num(ge=0), 5.0, doc="side margins inside the measured edges "
                            "(a job's placement may override); 2 x < print_width_mm")

    def _check(self, at: _At, ctx: _Ctx) -> None:
        if 2 * self.margin_mm >= ctx.printer.print_width_mm:
            raise at.sub("margin_mm").error(
                f"two margins of {self.margin_mm} mm leave nothing of the "
                f"{ctx.printer.print_width_mm} mm print width")


@dataclass(frozen=True, kw_only=True)
class ColorSection(_Section):
    ink_limit_percent: float | None = _key(_Num(gt=0, le=400), None, shown="none",
                                           doc="for separations made from RGB or grey; "
                                           "none: no limit")
    intent: str = _key(_Str(INTENTS), "relative", doc="informational: jobs choose theirs")
    drop_budget: dict[int, float] = _key(_DpiTable(_Num(gt=0, le=1), fill=1.0), {},
                                         doc="linearisation per dpi mode: the fraction of "
                                         "each ink amount the mode prints, all passes "
                                         "together (docs/color.md); 1.0: as separated")


_IDENTITY = [[0, 0], [255, 255]]


@dataclass(frozen=True, kw_only=True)
class CurvesSection(_Section):
    C: tuple[tuple[float, float], ...] = _key(_Curve(), _IDENTITY,
                                              doc="linearisation: in -> out, interpolated")
    M: tuple[tuple[float, float], ...] = _key(_Curve(), _IDENTITY, doc="as C")
    Y: tuple[tuple[float, float], ...] = _key(_Curve(), _IDENTITY, doc="as C")
    K: tuple[tuple[float, float], ...] = _key(_Curve(), _IDENTITY, doc="as C")


@dataclass(frozen=True, kw_only=True)
class MaintenanceSection(_Section):
    """Head care (docs/protocol.md 2.9, docs/driver.md "Head care").  The ink's drying
    figures are what the emulator models; the schedule is what the host does."""
    open_time_s: float = _key(_Num(gt=0), 120.0, doc="ink: an uncapped nozzle idle this "
                              "long misfires (drying) until it has fired recovery_drops")
    recovery_drops: int = _key(_Num(True, ge=1), 40, doc="ink: misfires of a dried nozzle "
                               "before it drops again")
    clog_time_s: float = _key(_Num(gt=0), 1800.0, doc="ink: idle this long, a nozzle "
                              "clogs: only a purge opens it; > open_time_s")
    spit: bool = _key(_Bool(), True, doc="spit (keep-wet firing into the spittoon) before "
                      "strokes and while idle or paused; false: never (not for production)")
    spit_interval_s: float = _key(_Num(gt=0), 30.0, doc="spit a head before a stroke in "
                                  "which a nozzle idle this long would fire, and every this "
                                  "long while paused; + the longest stroke < open_time_s")
    spit_drops: int = _key(_Num(True, ge=1, le=10000), 200, doc="drops per nozzle per "
                           "spit; >= recovery_drops")
    spit_hz: float = _key(_Num(gt=0), 5000.0, doc="spit firing rate; <= [head] max_fire_hz")
    cap_after_s: float = _key(_Num(ge=0), 120.0, doc="an idle or paused printer parks and "
                              "caps after this long (0: never)")
    purge_ms: int = _key(_Num(True, ge=100, le=10000), 1500, doc="`printer purge` pump time")
    purge_ml: float = _key(_Num(ge=0), 0.8, doc="ink a purge costs per head and second "
                           "of pumping (accounting)")

    def _check(self, at: _At, ctx: _Ctx) -> None:
        if self.clog_time_s <= self.open_time_s:
            raise at.sub("clog_time_s").error(f"must be above open_time_s ({self.open_time_s})")
        if self.spit_drops < self.recovery_drops:
            raise at.sub("spit_drops").error(f"a spit of {self.spit_drops} drops does not "
                                             f"recover a dried nozzle ({self.recovery_drops})")
        if self.spit_hz > ctx.head.max_fire_hz:
            raise at.sub("spit_hz").error(f"above the head's max_fire_hz ({ctx.head.max_fire_hz})")
        c = ctx.carriage
        stroke_s = (c.rail_counts / ctx.encoder.counts_per_inch * 25.4
                    / min(c.speed_mm_s.values()) + 2 * min(c.speed_mm_s.values()) / c.accel_mm_s2)
        if self.spit and self.spit_interval_s + stroke_s >= self.open_time_s:
            raise at.sub("spit_interval_s").error(
                f"{self.spit_interval_s} s + the longest stroke ({stroke_s:.1f} s) must stay "
                f"below open_time_s ({self.open_time_s} s): a nozzle would dry mid-stroke")


@dataclass(frozen=True, kw_only=True)
class PhysicalSection(_Section):
    """The loaded media as the emulator's physical model sees it (docs/physical.md, "The
    colour of the print"): what its spectrophotometer and scanner measure."""
    media: str = _key(_Str(), "solvent-vinyl", doc="spectral data of the paper and inks: "
                      "resources/spectra/NAME.json")
    yule_nielsen_n: float = _key(_Num(ge=1, le=10), 1.7, doc="the media's optical dot gain "
                                 "(Yule-Nielsen n); 1: none")
    ink_limit_ml_m2: float = _key(_Num(gt=0), 20.0, doc="wet ink (ml/m2 = um of film) the "
                                  "media takes; more bleeds and adds no density")
    bleed_um: float = _key(_Num(ge=0, le=5000), 150.0, doc="the reach (Gaussian sigma) over "
                           "which ink beyond that limit spreads")

    def _check(self, at: _At, ctx: _Ctx) -> None:
        if not (RESOURCES / "spectra" / f"{self.media}.json").is_file():
            have = sorted(p.stem for p in (RESOURCES / "spectra").glob("*.json")
                          if not p.stem.startswith("cie"))
            raise at.sub("media").error(f"no spectral data {self.media!r} in "
                                        f"resources/spectra (have: {', '.join(have)})")


# the sections in file (and checking) order: later ones are checked against earlier ones
SECTIONS: dict[str, type] = {
    "printer": PrinterSection, "encoder": EncoderSection, "head": HeadSection,
    "layout": LayoutSection, "carriage": CarriageSection, "feed": FeedSection,
    "fpga": FpgaSection, "link": LinkSection, "paper": PaperSection,
    "color": ColorSection, "curves": CurvesSection, "maintenance": MaintenanceSection,
    "physical": PhysicalSection,
}


def _keys_of(cls: Any) -> list[tuple[str, _Spec, Any]]:
    return [(f.name, f.metadata["spec"], f.metadata["default"]) for f in fields(cls)]


def _read_section(name: str, cls: Any, doc: dict[str, Any], ctx: _Ctx) -> Any:
    at = _At(ctx.path, name)
    keys = _keys_of(cls)
    table = doc.get(name)
    if table is None:
        if any(d is _REQUIRED for _, _, d in keys):
            raise at.error("missing section (keys: " + ", ".join(k for k, _, _ in keys) + ")")
        table = {}
    elif not isinstance(table, dict):
        raise at.error(f"must be a table of keys, not {_show(table)}")
    section = cls(**_read_keys(table, at, keys, ctx))
    section._check(at, ctx)
    return section


@dataclass(frozen=True, kw_only=True)
class Profile:
    """A loaded profile: its sections as typed attributes, the flat names most code uses,
    and the device grid derived from them."""
    path: str
    printer: PrinterSection
    encoder: EncoderSection
    head: HeadSection
    layout: LayoutSection
    carriage: CarriageSection
    feed: FeedSection
    fpga: FpgaSection
    link: LinkSection
    paper: PaperSection
    color: ColorSection
    curves: CurvesSection
    maintenance: MaintenanceSection
    physical: PhysicalSection

    # -- the names most of the code uses ------------------------------------------------------
    @property
    def name(self) -> str:
        return self.printer.name

    @property
    def print_width_mm(self) -> float:
        return self.printer.print_width_mm

    @property
    def heads(self) -> tuple[Head, ...]:
        return self.layout.heads

    @property
    def dead_nozzles(self) -> frozenset[tuple[int, int]]:
        """(head index, nozzle)"""
        return self.layout.dead_nozzles

    @property
    def bidir_offset_columns(self) -> dict[int, int]:
        return self.layout.bidir_offset_columns

    def bidir_shift_columns(self, dpi: int) -> float:
        """Columns reverse strokes are shifted right by: whole plus fine steps."""
        return (self.layout.bidir_offset_columns.get(dpi, 0)
                + self.layout.bidir_fine_steps.get(dpi, 0) / FINE_STEPS)

    def fire_shift(self, dpi: int) -> tuple[np.ndarray, np.ndarray]:
        """How the calibration moves each head's drops (docs/calibration.md): per direction
        (0 forward, 1 reverse) and head, whole columns `n` (the planner's data shift, right)
        and the rest as a distance `f` >= 0 µm along the carriage's travel (the fire delay):
        S = -head_x_um (+ the bidir shift in reverse) = n col + f forward, n col - f reverse."""
        col_um = self.k(dpi) * 25_400.0 / self.counts_per_inch
        n = np.zeros((2, len(self.heads)), np.int64)
        f = np.zeros((2, len(self.heads)))
        for h in self.heads:
            for d in (0, 1):
                shift = -self.layout.head_x_um.get(h.name, 0.0) / col_um
                if d == 1:
                    shift += self.bidir_shift_columns(dpi)
                shift = round(shift * FINE_STEPS * 64) / (FINE_STEPS * 64)   # no float dust
                n[d, h.index] = math.floor(shift) if d == 0 else math.ceil(shift)
                f[d, h.index] = abs(shift - n[d, h.index]) * col_um
        return n, f

    @property
    def nozzles(self) -> int:
        return self.head.nozzles

    @property
    def dead_end_nozzles(self) -> tuple[int, ...]:
        return self.head.dead_end_nozzles

    @property
    def nozzle_pitch_um(self) -> float:
        return self.head.nozzle_pitch_um

    @property
    def max_fire_hz(self) -> float:
        return self.head.max_fire_hz

    @property
    def drop_volume_pl(self) -> float:
        return self.head.drop_volume_pl

    @property
    def counts_per_inch(self) -> int:
        return self.encoder.counts_per_inch

    @property
    def dpi_modes(self) -> tuple[int, ...]:
        return self.encoder.dpi_modes

    @property
    def fifo_words(self) -> int:
        return self.fpga.fifo_words

    @property
    def pass_buffer_words(self) -> int:
        return self.fpga.pass_buffer_words

    @property
    def ring_blocks(self) -> int:
        return self.fpga.dma_ring_blocks

    @property
    def block_fires(self) -> int:
        return self.fpga.block_fires

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
        return self.layout.heads_per_color

    @property
    def swath_rows(self) -> int:
        """Rows spanned by one colour's heads in one stroke (slots 0 .. swath_rows-1)."""
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
                if table[head.channel, slot, 0] >= 0:   # load_profile refuses this already
                    raise ProfileError(f"{self.path}: heads {head.name} and "
                                       f"{self.heads[table[head.channel, slot, 0]].name} "
                                       f"print the same row")
                table[head.channel, slot] = (head.index, nozzle)
        return table

    def usable_slots(self) -> tuple[int, int]:
        """The longest run of slots [first, last+1) that every colour can print with all
        nozzles alive; dead nozzles inside it are the stroke planner's business."""
        ok = np.asarray((self.slot_table(include_dead=False)[:, :, 0] >= 0).all(axis=0))
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
        return self.feed.um_per_step

    def feed_steps_for_rows(self, rows_total: int) -> int:
        """Cumulative feed steps that put the paper `rows_total` rows from its start.
        Rounded from the absolute target each time, so the error never accumulates; a
        measured travel error (calibrate feed) scales the steps to match."""
        return int(round(rows_total * self.row_um / self.feed_um_per_step
                         / (1.0 + self.feed.travel_error_ppm * 1e-6)))

    # -- carriage ---------------------------------------------------------------------------
    def speed_counts_s(self, dpi: int) -> int:
        c = self.carriage
        max_by_head = self.max_fire_hz * 25.4 / dpi
        mm_s = min(c.speed_mm_s[dpi], c.max_speed_mm_s, max_by_head * 0.99)
        return int(mm_s / 25.4 * self.counts_per_inch)

    def accel_counts_s2(self) -> int:
        return int(self.carriage.accel_mm_s2 / 25.4 * self.counts_per_inch)

    @property
    def rail_counts(self) -> int:
        return self.carriage.rail_counts

    def head_config_path(self) -> Path:
        return self.head.config_path

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
    """Read and check a printer profile (None: the built-in default.toml)."""
    path = Path(path) if path else DEFAULT_PROFILE
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ProfileError(f"{path}: printer profile not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"{path}: cannot read the printer profile ({exc})") from None
    return _parse(text, path)


def _parse(text: str, path: Path) -> Profile:
    """The profile in `text`; messages name `path`."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{path}: not a valid TOML printer profile ({exc})") from None
    for name in doc:
        if name not in SECTIONS:
            near = difflib.get_close_matches(name, list(SECTIONS), 1)
            raise ProfileError(f"{path}: [{name}]: unknown section (known sections: "
                               f"{', '.join(SECTIONS)})"
                               + (f"; did you mean [{near[0]}]?" if near else ""))
    ctx = _Ctx(path)
    for name, cls in SECTIONS.items():
        ctx.sections[name] = _read_section(name, cls, doc, ctx)
    return Profile(path=str(path), **ctx.sections)


def spec_markdown() -> str:
    """The profile's keys as a Markdown table (docs/geometry.md, "The profile file")."""
    rows = ["| key | type | default | range | notes |", "|---|---|---|---|---|"]
    for name, cls in SECTIONS.items():
        for f in fields(cls):
            spec, default, shown = (f.metadata[k] for k in ("spec", "default", "shown"))
            dflt = ("required" if default is _REQUIRED else shown if default is None
                    else f"`{_show(default)}`")
            rows.append(f"| `[{name}] {f.name}` | {spec.kind} | {dflt} | {spec.range()} "
                        f"| {f.metadata['doc']} |")
    return "\n".join(rows) + "\n"


def save_calibration(path: str | Path, bidir_offset_columns: dict[int, int] | None = None,
                     head_x_counts: dict[str, int] | None = None,
                     dead_nozzles: Any = None, *, bidir_fine_steps: dict[int, int] | None = None,
                     head_x_um: dict[str, float] | None = None,
                     head_y_um: dict[str, float] | None = None,
                     head_y_rows: dict[str, int] | None = None,
                     travel_error_ppm: float | None = None,
                     curves: dict[str, list[tuple[float, float]]] | None = None,
                     nozzle_errors: tuple[dict[str, Any], dict[str, Any], str] | None = None
                     ) -> Profile:
    """Write calibration results into a profile file, keeping its comments and layout
    (tomlkit edits the document in place), and return the reloaded profile, which
    validates them; a result that does not load leaves the file as it was.

    bidir_offset_columns: {dpi: columns}, the whole table.  head_x_counts: {head: counts}.
    dead_nozzles: the complete new list of dead nozzles, as (head name, nozzle) pairs or
    {"head": ..., "nozzle": ...} tables (None leaves the list alone, an empty list clears
    it); written as `dead_nozzles = [{ head = "M1", nozzle = 57 }, ...]` in [layout].
    From scans (docs/calibration.md): bidir_fine_steps {dpi: 64ths}, head_x_um and head_y_um
    {head: µm} (each the whole table), head_y_rows {head: rows}, [feed]
    travel_error_ppm, and [curves] {ink: [(in, out), ...]} (inks not given are kept).
    nozzle_errors: ({head: [µm per nozzle]}, {head: [% per nozzle]}, when), every head:
    [layout] nozzle_dy_um, nozzle_volume_pct (written as [layout.nozzle_dy_um] tables of
    arrays, 16 values a line) and nozzles_measured, replaced whole."""
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
    for key, values, conv in (("bidir_offset_columns", bidir_offset_columns, int),
                              ("bidir_fine_steps", bidir_fine_steps, int),
                              ("head_x_um", head_x_um, _um), ("head_y_um", head_y_um, _um)):
        if values is None:
            continue
        table = layout.get(key)
        if table is None:                # optional key: add it
            layout[key] = tomlkit.inline_table()
            table = layout[key]
        new = {str(k): conv(v) for k, v in sorted(values.items())}
        for old in [k for k in table if k not in new]:
            del table[old]
        table.update(new)
    for key, per_head in (("x_counts", head_x_counts), ("y_rows", head_y_rows)):
        for name, v in (per_head or {}).items():
            heads = [h for h in layout.get("heads", []) if h.get("name") == name]
            if len(heads) != 1:
                raise ProfileError(f"{path}: no head {name!r} to update")
            heads[0][key] = int(v)
    if travel_error_ppm is not None:
        feed = doc.get("feed")
        if feed is None:
            raise ProfileError(f"{path}: no [feed] table to update")
        feed["travel_error_ppm"] = _um(travel_error_ppm)
    if curves:
        table = doc.get("curves")
        if table is None:
            doc["curves"] = tomlkit.table()
            table = doc["curves"]
        for ink, pts in curves.items():
            table[ink] = tomlkit.parse(
                "v = [" + ", ".join(f"[{_um(a)}, {_um(b)}]" for a, b in pts) + "]")["v"]
    if dead_nozzles is not None:
        dead = _dead_nozzle_list(path, dead_nozzles)
        items = [f'{{ head = "{h}", nozzle = {z} }}' for h, z in dead]
        value = ("[" + ", ".join(items) + "]" if len(items) <= 4 else       # one a line if many
                 "[\n" + "".join(f"  {it},\n" for it in items) + "]")
        layout["dead_nozzles"] = tomlkit.parse(f"v = {value}")["v"]
    if nozzle_errors is not None:
        dy, volume, when = nozzle_errors
        layout["nozzles_measured"] = str(when)
        errors: dict[str, Any]
        for key, errors in (("nozzle_dy_um", dy), ("nozzle_volume_pct", volume)):
            nozzle_table = tomlkit.table()
            for name, per_nozzle in errors.items():
                vals = [f"{_um(x)}" for x in per_nozzle]
                lines = "".join("  " + ", ".join(vals[i:i + 16]) + ",\n"
                                for i in range(0, len(vals), 16))
                nozzle_table[str(name)] = tomlkit.parse(f"v = [\n{lines}]")["v"]
            if key in layout:
                del layout[key]
            layout[key] = nozzle_table
    text = tomlkit.dumps(doc)
    _parse(text, path)               # checked before the file changes, messages name it
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return load_profile(path)


def _um(v: float) -> float:
    """A measured length as written: to a hundredth (of a µm, or a ppm)."""
    return round(float(v), 2)


def _dead_nozzle_list(path: Path, entries: Any) -> list[tuple[str, int]]:
    """Checked, de-duplicated and sorted (head order, nozzle) dead nozzles."""
    prof = load_profile(path)
    index = {h.name: h.index for h in prof.heads}
    out: set[tuple[str, int]] = set()
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
