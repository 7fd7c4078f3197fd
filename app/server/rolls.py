"""The roll loaded on each printer (docs/server.md "Rolls"): its media (a media library name,
app/medialib.py), its width (the printer's paper sensor), its length (entered, or read from
the roll's label) and what is left of it - every copy's paper feed comes off it in the
transaction that records the copy (Spool._add_print), test prints' too.

A job the roll cannot hold is refused at submission and, when the roll ran down since,
held before its first stroke (worker.py), never half printed: the operator loads a new roll
or releases it with the override.
"""

from __future__ import annotations

import re
import time

from .validate import Invalid

ROLL_KEYS = {"media", "length_m", "label", "remaining_m", "width_mm", "spare_m"}
# a roll's label as its barcode or the operator reads it: `media=vinyl-300 length=50m`
# (length in m, or mm with the unit), separated by blanks, ';' or ','
LABEL_FIELD = re.compile(r"^(media|length|width)=(\S+)$")

# a job the worker held because the roll could not hold it says so in its message
# (worker.py _next_job); the roll's warning keeps counting it until a new roll is loaded
ROLL_HELD = "held before printing; load a new roll"
#: the roll left, over what the jobs waiting need, below which the printer warns (m)
WARN_SPARE_M = 1.0


def _metres(text, what: str, example: str) -> float:
    """'50', '50m', '50000mm', '50.5 m' -> metres; Invalid naming `what` otherwise."""
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*(m|mm|cm)?\s*", str(text))
    if not m:
        raise Invalid(f"{what} {text!r}: expected metres, e.g. {example}")
    return float(m.group(1)) * {"m": 1.0, None: 1.0, "cm": 0.01, "mm": 0.001}[m.group(2)]


def parse_length_m(text: str, what: str = "length") -> float:
    """'50', '50m', '50000mm', '50.5 m' -> metres; Invalid otherwise."""
    v = _metres(text, what, "50 or 50m or 50000mm")
    if not 0 < v <= 10_000:
        raise Invalid(f"{what} {text!r}: a roll is 0..10,000 m long")
    return v


def parse_label(label: str) -> dict:
    """The fields of a roll's label: {media, length_m, width_mm} (those it has)."""
    out: dict = {}
    for part in re.split(r"[\s;,]+", label.strip()):
        if not part:
            continue
        m = LABEL_FIELD.match(part)
        if not m:
            raise Invalid(f"roll label: {part!r} is not media=NAME, length=M or width=MM")
        key, value = m.groups()
        if key == "media":
            out["media"] = value
        elif key == "length":
            out["length_m"] = parse_length_m(value)
        else:
            out["width_mm"] = parse_length_m(value + ("" if value.endswith("m") else "mm"),
                                             "width") * 1000
    return out


def parse_spare_m(value) -> float:
    """The warning's spare for a roll (docs/server.md "Rolls: the warning"): metres, 0..1000
    (a number, or text as for a length: '3', '3m', '500mm'); Invalid otherwise."""
    if isinstance(value, bool):
        raise Invalid("spare_m: metres, 0..1000")
    v = float(value) if isinstance(value, (int, float)) else \
        _metres(value, "spare", "3 or 3m or 500mm")
    if not 0 <= v <= 1000:
        raise Invalid(f"spare {value!r}: 0..1,000 m")
    return v


def _roll_dict(row) -> dict | None:
    if row is None:
        return None
    d = dict(row)
    d["remaining_m"] = None if d["remaining_mm"] is None else round(d["remaining_mm"] / 1000, 3)
    d["length_m"] = None if d["length_mm"] is None else round(d["length_mm"] / 1000, 3)
    d["spare_m"] = WARN_SPARE_M if d.get("spare_mm") is None else round(d["spare_mm"] / 1000, 3)
    return d


class Rolls:
    """The rolls table of the queue's database (spool.py's schema)."""

    def __init__(self, spool, library=None):
        self.spool, self.library = spool, library      # the server's media library folder

    def get(self, printer: str) -> dict | None:
        return _roll_dict(self.spool.db.execute("SELECT * FROM rolls WHERE printer=?",
                                                (printer,)).fetchone())

    def load(self, printer: str, body: dict, width_mm: float | None) -> dict:
        """A new roll on `printer` (the API's body: media, length_m or label, width_mm when
        the printer has not measured it); its remaining length is its length."""
        if not isinstance(body, dict) or set(body) - ROLL_KEYS:
            raise Invalid(f"expected an object with some of {', '.join(sorted(ROLL_KEYS))}")
        label = body.get("label") or ""
        if not isinstance(label, str) or len(label) > 200:
            raise Invalid("label must be a string of at most 200 characters")
        fields = parse_label(label) if label else {}
        media = body.get("media", fields.get("media"))
        if not isinstance(media, str) or not media:
            raise Invalid("media is required (a name from the media library: wideprint media list)")
        from ..medialib import check_name, find
        try:
            find(check_name(media), self.library)
        except (ValueError, KeyError, FileNotFoundError, OSError) as exc:
            raise Invalid(f"media {media!r}: {exc}") from None
        length = body.get("length_m", fields.get("length_m"))
        if length is not None:
            length = parse_length_m(length)
        width = body.get("width_mm", fields.get("width_mm", width_mm))
        if width is not None and (isinstance(width, bool) or not isinstance(width, (int, float))
                                  or not 10 <= width <= 5000):
            raise Invalid("width_mm must be a number of 10..5000")
        mm = None if length is None else length * 1000
        spare = body.get("spare_m")
        spare_mm = None if spare is None else parse_spare_m(spare) * 1000
        with self.spool.tx() as c:
            c.execute("INSERT OR REPLACE INTO rolls (printer, media, width_mm, length_mm, "
                      "remaining_mm, loaded, label, spare_mm) VALUES (?,?,?,?,?,?,?,?)",
                      (printer, media, width, mm, mm, time.time(), label, spare_mm))
        return self.get(printer)  # type: ignore[return-value]

    def set_remaining(self, printer: str, remaining_m=None, spare_m=None) -> dict:
        """The operator measured what is left (a roll taken off and put back), and/or set
        the warning's spare for this roll."""
        with self.spool.tx() as c:
            n = c.execute("SELECT COUNT(*) FROM rolls WHERE printer=?", (printer,)).fetchone()[0]
            if not n:
                raise Invalid(f"printer {printer}: no roll loaded (load one first)", 409)
            if remaining_m is not None:
                mm = parse_length_m(remaining_m, "remaining") * 1000
                c.execute("UPDATE rolls SET remaining_mm=?, length_mm=MAX(COALESCE(length_mm, 0), "
                          "?) WHERE printer=?", (mm, mm, printer))
            if spare_m is not None:
                c.execute("UPDATE rolls SET spare_mm=? WHERE printer=?",
                          (parse_spare_m(spare_m) * 1000, printer))
        return self.get(printer)  # type: ignore[return-value]

    def unload(self, printer: str) -> None:
        with self.spool.tx() as c:
            c.execute("DELETE FROM rolls WHERE printer=?", (printer,))

    def measured(self, printer: str, width_mm: float) -> None:
        """The paper sensor's width, kept with the roll."""
        with self.spool.tx() as c:
            c.execute("UPDATE rolls SET width_mm=? WHERE printer=?", (round(width_mm, 2), printer))

    def used(self, printer: str, paper_mm: float) -> None:
        """Paper fed outside a job (a test print)."""
        if paper_mm > 0:
            with self.spool.tx() as c:
                c.execute("UPDATE rolls SET remaining_mm=MAX(0, remaining_mm - ?) WHERE "
                          "printer=? AND remaining_mm IS NOT NULL", (paper_mm, printer))


def paper_per_copy_mm(profile, height_mm: float, top_mm: float = 0.0) -> float:
    """The paper one copy feeds (docs/server.md "Rolls"): the blank `top_mm` before its
    image (placement), the image's length and the swath fed out past the heads after it
    (driver/job.py, "feed the last rows out")."""
    swath = profile.swath_rows * profile.row_um / 1000.0
    return float(top_mm) + height_mm + swath


def short_of_roll(roll: dict | None, need_mm: float) -> str:
    """Why the roll cannot hold `need_mm` of paper ('' when it can, or nobody knows)."""
    if roll is None or roll.get("remaining_mm") is None:
        return ""
    left = float(roll["remaining_mm"])
    if need_mm <= left:
        return ""
    return (f"needs {need_mm / 1000:,.2f} m of paper, the {roll['media']} roll has "
            f"{left / 1000:,.2f} m left")



def roll_warning(roll: dict | None, waiting: list[tuple[dict, float]],
                 spare_m: float | None = None) -> dict | None:
    """The printer's warning before a job runs off the roll (docs/server.md "Rolls: the
    warning"): `waiting` is each job the printer will take, in the order it takes them,
    with the paper it needs (mm; the printing job's copies left first).  A warning - not a
    fault, nothing stops - when the roll left is less than what they need plus `spare_m`
    (None: the roll's own spare, `spare_mm`, else WARN_SPARE_M):
    {kind: "media-low", message, remaining_m, need_m, job, name} where job/name is the
    first job the roll cannot hold (None when all fit and only the spare is short).  None
    when the roll's length is not known or it holds them with the spare."""
    if roll is None or roll.get("remaining_mm") is None:
        return None
    if spare_m is None:
        spare_m = WARN_SPARE_M if roll.get("spare_mm") is None else roll["spare_mm"] / 1000
    left = float(roll["remaining_mm"])
    need = sum(mm for _, mm in waiting)
    if left >= need + spare_m * 1000:
        return None
    short, total = None, 0.0
    for job, mm in waiting:
        total += mm
        if total > left:
            short = job
            break
    media = roll.get("media") or "the"
    text = (f"roll low: {left / 1000:,.2f} m of {media} left"
            + (f", the {len(waiting)} job{'s' if len(waiting) != 1 else ''} waiting need "
               f"{need / 1000:,.2f} m" if waiting else ""))
    if short is not None:
        text += (f"; {short['name']} (job {short['id']}) will not fit: load a new roll "
                 f"before it prints, or it is held")
    else:
        text += f" (less than {spare_m:g} m to spare): have a new roll ready"
    return dict(kind="media-low", message=text, remaining_m=round(left / 1000, 3),
                need_m=round(need / 1000, 3), job=None if short is None else short["id"],
                name=None if short is None else short["name"])
