"""Layouts on the roll: step-and-repeat, nesting, tiling, marks and labels (docs/layout.md).

One layout is one printed job.  ``plan_layout()`` works out, from the items' placed sizes
only, where every item (a file placed on the device grid, maybe turned or cut to a tile)
goes on the *sheet* (the job's image area, in device dots), with the frame around it for
marks and the label.  ``LayoutJob`` composes the sheet's halftone band by band: each item
is ripped by its own ``RipJob`` (so it prints the same dots as when ripped alone) and its
rows are pasted where the plan says; marks and text are drawn as solid dots in the frames.
Memory is bounded by the band and the items side by side in it, never by the number of
items or the sheet's length (docs/layout.md, "Composing in bands").
"""

from __future__ import annotations

import math
import os
from collections import Counter
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import Any, Callable, Iterator

import numpy as np

from .printable import PrintableJob
from .place import _reband
from .settings import MM_PER_INCH, SETTINGS, RipSettings, _round

__all__ = ["LAYOUT_FIELDS", "Item", "Slot", "Mark", "Plan", "LayoutJob", "wants_layout",
           "item_settings", "plan_layout", "printed_size", "nest_sheets"]

#: the layout settings (placement fields that say how things go on the roll)
LAYOUT_FIELDS = tuple(s.name for s in SETTINGS if s.section == "layout")
_DEFAULTS = {s.name: s.default for s in SETTINGS if s.section == "layout"}

# the frame around an image (docs/layout.md, "The model"), millimetres
MARK_OFFSET_MM = 2.0      # from the image corner to a crop mark
MARK_LENGTH_MM = 5.0      # a crop mark's length; a registration target's diameter
MARK_LINE_MM = 0.25       # line width of marks and ticks
LABEL_GAP_MM = 1.5        # between the marks (or the image) and the label
LABEL_MM = 3.0            # the label line's height, descenders included

K = (3,)                  # crop marks, ticks, text: black
ALL_INKS = (0, 1, 2, 3)   # registration targets: the registration colour


def wants_layout(placement, more=()) -> bool:
    """Whether the settings (or several files) make a layout rather than a plain job."""
    p = placement
    return bool(more) or p.nest or p.repeat_across > 1 or p.repeat_along > 1 \
        or p.tile_width_mm is not None or p.tile_height_mm is not None \
        or p.marks != "none" or p.label


def item_settings(settings: RipSettings, turn: bool = False) -> RipSettings:
    """The settings an item is ripped with: the job's, the layout fields reset (an item is
    a plain job), turned 90 degrees clockwise more for a turned nested item."""
    pl = settings.placement
    rotate = (pl.rotate + 90) % 360 if turn else pl.rotate
    return replace(settings, placement=replace(pl, **_DEFAULTS, rotate=rotate))


# -- geometry --------------------------------------------------------------------------------
class _Grid:
    """Millimetres to device dots, each axis on its own (columns at dpi, rows at row_um)."""

    def __init__(self, dpi: int, row_um: float):
        self.dpi, self.row_um = int(dpi), float(row_um)

    def cols(self, mm: float) -> int:
        return _round(float(mm) / MM_PER_INCH * self.dpi)

    def rows(self, mm: float) -> int:
        return _round(float(mm) * 1000.0 / self.row_um)

    def mm_x(self, cols: int) -> float:
        return cols * MM_PER_INCH / self.dpi

    def mm_y(self, rows: int) -> float:
        return rows * self.row_um / 1000.0


@dataclass(frozen=True)
class Item:
    """One thing to print: a file as placed alone, maybe turned (nesting) or cut (a tile)."""
    path: str
    width: int                       # device columns
    height: int                      # device rows
    turn: bool = False               # turned 90 degrees clockwise more than its placement
    crop: tuple | None = None        # (x0, y0, x1, y1) of the placed image: a tile

    @property
    def key(self) -> tuple:
        return (self.path, self.turn, self.crop)


@dataclass
class Slot:
    """An item on the sheet: its image's top-left dot at (x, y) and the frame around it."""
    item: Item
    x: int
    y: int
    mx: int = 0                      # frame columns left and right (marks)
    my: int = 0                      # frame rows above and below (marks)
    label_rows: int = 0              # below the lower frame
    label: str = ""                  # the text under the image ("": none)
    joins: tuple = ()                # tiles: ("x", local column) / ("y", local row) ticks

    @property
    def box(self) -> tuple[int, int, int, int]:
        """(x, y, width, height) of the slot's box: image plus frame plus label."""
        return (self.x - self.mx, self.y - self.my, self.item.width + 2 * self.mx,
                self.item.height + 2 * self.my + self.label_rows)


@dataclass
class Mark:
    """A rectangle of the sheet drawn in `inks` (1 drop a dot): solid, or where the mask
    made by `draw` is set."""
    x: int
    y: int
    w: int
    h: int
    inks: tuple
    kind: str                        # crop | target | join | label
    draw: Callable[[], np.ndarray] | None = None
    _mask: np.ndarray | None = field(default=None, repr=False)

    def mask(self) -> np.ndarray | None:
        if self.draw is not None and self._mask is None:
            self._mask = self.draw()
        return self._mask


@dataclass
class Plan:
    """Where everything goes: the sheet's size in dots and its slots."""
    width: int
    height: int
    slots: list
    mode: str                        # single | repeat | nest | tile
    grid: _Grid
    marks_kind: str = "none"
    report: dict = field(default_factory=dict)
    cut_marks: Any = None            # marks "cut": the cutter's MarkLayout (rip/regmarks.py)

    @property
    def width_mm(self) -> float:
        return self.grid.mm_x(self.width)

    @property
    def height_mm(self) -> float:
        return self.grid.mm_y(self.height)

    def marks(self) -> Iterator[Mark]:
        """Every mark of the sheet (for a preview; masks are made only when asked)."""
        for s in self.slots:
            yield from self.slot_marks(s)

    def slot_marks(self, s: Slot) -> list[Mark]:
        """The marks in a slot's frame (docs/layout.md, "Marks and the label")."""
        g, it = self.grid, s.item
        x, y, w, h = s.x, s.y, it.width, it.height
        tc, tr = max(1, g.cols(MARK_LINE_MM)), max(1, g.rows(MARK_LINE_MM))
        ox, oy = g.cols(MARK_OFFSET_MM), g.rows(MARK_OFFSET_MM)
        lx, ly = g.cols(MARK_LENGTH_MM), g.rows(MARK_LENGTH_MM)
        out: list[Mark] = []
        if self.marks_kind in ("crop", "registration"):
            for yy in (y, y + h - tr):               # the top and bottom edges, continued
                out += [Mark(x - ox - lx, yy, lx, tr, K, "crop"), Mark(x + w + ox, yy, lx, tr, K, "crop")]
            for xx in (x, x + w - tc):               # the left and right edges, continued
                out += [Mark(xx, y - oy - ly, tc, ly, K, "crop"), Mark(xx, y + h + oy, tc, ly, K, "crop")]
        if self.marks_kind == "registration":
            draw = _target_drawer(lx, ly, tc)
            cx, cy = x + w // 2 - lx // 2, y + h // 2 - ly // 2
            for mx, my in ((cx, y - oy - ly), (cx, y + h + oy), (x - ox - lx, cy), (x + w + ox, cy)):
                out.append(Mark(mx, my, lx, ly, ALL_INKS, "target", draw))
        if self.marks_kind == "cut":                 # squares a contour cutter finds (docs/cut.md)
            out += [Mark(mx, my, mw, mh, K, "cut")
                    for mx, my, mw, mh, _ in self.cut_marks.rects(x, y, w, h, g.cols, g.rows)]
        for axis, at in s.joins:                     # tiles: where the neighbour's edge goes
            if axis == "x":
                c = x + min(max(at, 0), w - tc)
                out += [Mark(c, y - oy - ly, tc, ly, K, "join"), Mark(c, y + h + oy, tc, ly, K, "join")]
            else:
                r = y + min(max(at, 0), h - tr)
                out += [Mark(x - ox - lx, r, lx, tr, K, "join"), Mark(x + w + ox, r, lx, tr, K, "join")]
        if s.label:
            rows = g.rows(LABEL_MM)
            top = y + h + s.my + g.rows(LABEL_GAP_MM)
            avail = x + w + s.mx - x                # to the box's right edge
            text = _ascii(s.label)
            cols = min(avail, _text_width(text, rows, g))
            if cols > 0 and rows > 0:
                out.append(Mark(x, top, cols, rows, K, "label",
                                lambda t=text, c=cols, r=rows: _text_mask(t, c, r, g)))
        return out


def _spans(total: int, size: int, overlap: int) -> list[tuple[int, int]]:
    """Tiles of at most `size` covering [0, total) with `overlap` shared between neighbours,
    all as equal as the grid allows (docs/layout.md, "tiling")."""
    if total <= size:
        return [(0, total)]
    if size - overlap < 1:
        raise ValueError(f"placement: the tile overlap ({overlap} dots) leaves nothing of the "
                         f"tile ({size} dots)")
    n = -(-(total - overlap) // (size - overlap))
    t = -(-(total + (n - 1) * overlap) // n)
    step = t - overlap
    return [(i * step, min(i * step + t, total)) for i in range(n)]


def _probe(path: str, settings: RipSettings, profile, turn: bool) -> tuple[int, int]:
    """The placed size (columns, rows) of a file as an item, without ripping it."""
    from .inputs import open_source
    rs = item_settings(settings, turn)
    rs.check(profile)
    src = open_source(path, rs, profile)
    try:
        return int(src.width), int(src.height)
    finally:
        src.close()


def _paper_mm(settings: RipSettings, profile, paper_mm: float | None) -> float:
    return float(paper_mm) if paper_mm else float(profile.paper.default_width_mm)


def _avail_cols(settings: RipSettings, profile, paper_mm: float | None, g: _Grid) -> int:
    """Columns to nest or lay tiles into: nest_width_mm, else the paper less the side margins."""
    pl = settings.placement
    if pl.nest_width_mm is not None:
        mm = float(pl.nest_width_mm)
    else:
        margin = float(profile.paper.margin_mm if pl.margin_mm is None else pl.margin_mm)
        mm = _paper_mm(settings, profile, paper_mm) - 2 * margin
    return max(0, int(math.floor(mm / MM_PER_INCH * g.dpi + 1e-9)))


def plan_layout(paths, settings: RipSettings, profile, paper_mm: float | None = None,
                when: datetime | None = None, sizes: dict | None = None,
                names: dict | None = None) -> Plan:
    """The layout of `paths` under `settings` (geometry only: files are opened to learn
    their placed size, nothing is ripped).  `paper_mm`: the measured paper width, when
    known (nesting and tiles pack into it less the margins).  `sizes` caches the placed
    sizes by (path, turned) between calls.  ValueError names what cannot be laid out."""
    pl = settings.placement
    pl.check()
    paths = [os.fspath(p) for p in ([paths] if isinstance(paths, (str, os.PathLike)) else paths)]
    if not paths:
        raise ValueError("layout: no files")
    if len(paths) > 1 and not pl.nest:
        raise ValueError(f"layout: {len(paths)} files in one job need nest (--nest)")
    g = _Grid(settings.dpi, profile.row_um)
    sizes = {} if sizes is None else sizes
    when = when or datetime.now()

    def size(path: str, turn: bool = False) -> tuple[int, int]:
        if (path, turn) not in sizes:
            sizes[(path, turn)] = _probe(path, settings, profile, turn)
        return sizes[(path, turn)]

    tiles = pl.tile_width_mm is not None or pl.tile_height_mm is not None
    zone = pl.marks != "none" or (tiles and pl.join_marks)
    mx = g.cols(MARK_OFFSET_MM) + g.cols(MARK_LENGTH_MM) if zone else 0
    my = g.rows(MARK_OFFSET_MM) + g.rows(MARK_LENGTH_MM) if zone else 0
    cut_marks = None
    if pl.marks == "cut":                            # the cutter's marks set the frame
        from .regmarks import MarkLayout
        cut_marks = MarkLayout(spacing_mm=pl.cut_mark_spacing_mm)
        cx, cy = cut_marks.frame(g.cols, g.rows)
        mx, my = (max(mx, cx), max(my, cy)) if tiles and pl.join_marks else (cx, cy)
    lr = g.rows(LABEL_GAP_MM + LABEL_MM) if (pl.label or tiles) else 0
    gx, gy = g.cols(pl.gap_mm), g.rows(pl.gap_mm)

    def box_wh(w: int, h: int) -> tuple[int, int]:
        return w + 2 * mx, h + 2 * my + lr

    def label(path: str, w: int, h: int, extra: str = "") -> str:
        if not pl.label:
            return extra
        shown = (names or {}).get(path) or os.path.basename(path)     # the job's own name
        text = (f"{shown}  {when:%Y-%m-%d %H:%M}  {settings.dpi} dpi "
                f"{settings.passes} pass{'es' if settings.passes > 1 else ''} {settings.dither}  "
                f"{g.mm_x(w):.0f} x {g.mm_y(h):.0f} mm")
        return f"{extra}  {text}" if extra else text

    slots: list[Slot] = []

    def put(item: Item, bx: int, by: int, text: str = "", joins: tuple = ()) -> None:
        slots.append(Slot(item, bx + mx, by + my, mx, my, lr, text, joins))

    avail = None
    shelves = 0
    if tiles:
        mode = "tile"
        path = paths[0]
        W, H = size(path)
        avail = _avail_cols(settings, profile, paper_mm, g)
        tw = g.cols(pl.tile_width_mm) if pl.tile_width_mm is not None else W
        th = g.rows(pl.tile_height_mm) if pl.tile_height_mm is not None else H
        xs = _spans(W, tw, g.cols(pl.tile_overlap_mm))
        ys = _spans(H, th, g.rows(pl.tile_overlap_mm))
        n = len(xs) * len(ys)
        x = y = shelf_h = 0
        shelves = 1
        for r, (y0, y1) in enumerate(ys):
            for c, (x0, x1) in enumerate(xs):
                item = Item(path, x1 - x0, y1 - y0, crop=(x0, y0, x1, y1))
                bw, bh = box_wh(item.width, item.height)
                if bw > avail:
                    raise ValueError(f"layout: a tile is {g.mm_x(bw):.0f} mm wide with its frame, more "
                                     f"than the {g.mm_x(avail):.0f} mm of paper to print on; choose a "
                                     f"smaller tile width")
                if x and x + bw > avail:              # next shelf, tiles stay in reading order
                    x, y, shelf_h, shelves = 0, y + shelf_h + gy, 0, shelves + 1
                joins = []
                if pl.join_marks:
                    if c + 1 < len(xs):
                        joins.append(("x", xs[c + 1][0] - x0))
                    if c > 0:
                        joins.append(("x", xs[c - 1][1] - x0))
                    if r + 1 < len(ys):
                        joins.append(("y", ys[r + 1][0] - y0))
                    if r > 0:
                        joins.append(("y", ys[r - 1][1] - y0))
                number = f"tile {r * len(xs) + c + 1}/{n} r{r + 1} c{c + 1}"
                put(item, x, y, label(path, item.width, item.height, number), tuple(joins))
                x += bw + gx
                shelf_h = max(shelf_h, bh)
    elif pl.nest:
        mode = "nest"
        avail = _avail_cols(settings, profile, paper_mm, g)
        shelves = _nest(paths, pl, size, box_wh, avail, gx, gy, g, put, label)
    elif pl.repeat_across > 1 or pl.repeat_along > 1:
        mode = "repeat"
        path = paths[0]
        w, h = size(path)
        bw, bh = box_wh(w, h)
        item = Item(path, w, h)
        n = pl.repeat_across * pl.repeat_along
        for j in range(pl.repeat_along):
            for i in range(pl.repeat_across):
                put(item, i * (bw + gx), j * (bh + gy),
                    label(path, w, h, f"copy {j * pl.repeat_across + i + 1}/{n}" if pl.label else ""))
        shelves = pl.repeat_along
    else:
        mode = "single"
        w, h = size(paths[0])
        put(Item(paths[0], w, h), 0, 0, label(paths[0], w, h))
        shelves = 1
    width = max(s.box[0] + s.box[2] for s in slots)
    height = max(s.box[1] + s.box[3] for s in slots)
    plan = Plan(width, height, slots, mode, g, pl.marks, cut_marks=cut_marks)
    plan.report = _report(plan, paths, sizes, box_wh, gy, avail, shelves, when,
                          _paper_mm(settings, profile, paper_mm))
    return plan


def _nest(paths, pl, size, box_wh, avail, gx, gy, g, put, label) -> int:
    """First-fit decreasing height on shelves, items turned when allowed (docs/layout.md,
    "nesting"); calls put() for every item; returns the number of shelves."""
    entries = []                                   # [(path, copy, [(bh, bw, turn, w, h)])]
    for path in paths:
        orients = []
        for turn in ((False, True) if pl.nest_rotate else (False,)):
            w, h = size(path, turn)
            bw, bh = box_wh(w, h)
            if bw <= avail:
                orients.append((bh, bw, turn, w, h))
        if not orients:
            w, h = size(path)
            raise ValueError(f"layout: {path} is {g.mm_x(box_wh(w, h)[0]):.0f} mm wide"
                             f"{' (turned or not)' if pl.nest_rotate else ''}, more than the "
                             f"{g.mm_x(avail):.0f} mm to nest into")
        for copy in range(pl.nest_copies):
            entries.append((path, copy, orients))
    first = {id(e): min(e[2]) for e in entries}    # the lowest box that fits
    order = sorted(entries, key=lambda e: -first[id(e)][0])
    shelves: list[list[int]] = []                  # [y, height, next x]
    for path, copy, orients in order:
        spot = None
        for sh in shelves:
            fits = [o for o in orients if o[0] <= sh[1] and sh[2] + o[1] <= avail]
            if fits:
                spot = sh, max(fits)               # the tallest that fits fills the shelf best
                break
        if spot is None:
            o = min(orients)
            top = shelves[-1][0] + shelves[-1][1] + gy if shelves else 0
            shelves.append([top, o[0], 0])
            spot = shelves[-1], o
        sh, (bh, bw, turn, w, h) = spot
        extra = f"copy {copy + 1}/{pl.nest_copies}" if pl.label and pl.nest_copies > 1 else ""
        put(Item(path, w, h, turn=turn), sh[2], sh[0], label(path, w, h, extra))
        sh[2] += bw + gx
    return len(shelves)


def _report(plan: Plan, paths, sizes, box_wh, gy, avail, shelves, when, paper_mm) -> dict:
    """The layout's figures for the job report: its size, and the media saved against the
    same boxes printed one after another, unturned (docs/layout.md)."""
    g = plan.grid
    seq = 0
    for s in plan.slots:
        it = s.item
        w, h = sizes[(it.path, False)] if it.turn else (it.width, it.height)
        seq += box_wh(w, h)[1]
    seq += gy * (len(plan.slots) - 1)
    seq_mm, length_mm = g.mm_y(seq), plan.height_mm
    saved = seq_mm - length_mm
    return dict(mode=plan.mode, files=len(dict.fromkeys(paths)), items=len(plan.slots),
                shelves=shelves, turned=sum(1 for s in plan.slots if s.item.turn),
                width_dots=plan.width, height_rows=plan.height,
                width_mm=round(plan.width_mm, 1), length_mm=round(length_mm, 1),
                nest_width_mm=None if avail is None else round(g.mm_x(avail), 1),
                sequential_length_mm=round(seq_mm, 1), saved_mm=round(saved, 1),
                saved_percent=round(100.0 * saved / seq_mm, 1) if seq_mm > 0 else 0.0,
                saved_m2=round(saved * paper_mm / 1e6, 3), paper_width_mm=round(paper_mm, 1),
                made=when.strftime("%Y-%m-%d %H:%M:%S"))


def layout_line(lay: dict) -> str:
    """The layout's figures in a line (`print` output, a server job's message); for a nest,
    the media saved."""
    line = (f"layout {lay['mode']}: {lay['items']} item{'s' if lay['items'] != 1 else ''} on "
            f"{lay['width_mm']:.0f} x {lay['length_mm']:.0f} mm")
    if lay["mode"] == "nest":
        line += (f", {lay['saved_mm']:.0f} mm of media saved ({lay['saved_percent']:.1f} %, "
                 f"{lay['saved_m2']:.2f} m2) against {lay['sequential_length_mm']:.0f} mm one "
                 f"after another")
    return line


def printed_size(paths, settings: RipSettings, profile, paper_mm: float | None = None
                 ) -> tuple[int, int, float, float]:
    """(width_dots, height_rows, width_mm, height_mm) the job prints, the whole layout when
    the settings make one (for estimates: nothing is ripped)."""
    plan = plan_layout(paths, settings, profile, paper_mm)
    return plan.width, plan.height, plan.width_mm, plan.height_mm


def nest_sheets(paths, settings: RipSettings, profile, paper_mm: float | None = None
                ) -> tuple[list[list[str]], list[str], dict[str, str]]:
    """The nest start rule (docs/layout.md, "Nesting: when to start"): (complete sheets,
    files still waiting, {file: why it cannot be nested}).  Files are taken in order; a
    sheet is complete when it holds nest_count files or its packed length reaches
    nest_length_mm; without either rule nothing is complete and every file waits (the
    caller prints them together, or waits for more)."""
    from .load import ImageError
    pl = settings.placement
    sizes: dict = {}
    failed: dict[str, str] = {}
    sheets: list[list[str]] = []
    cur: list[str] = []
    for p in (os.fspath(p) for p in paths):
        try:
            plan_layout([*cur, p], settings, profile, paper_mm, sizes=sizes)
        except (ImageError, ValueError, OSError) as exc:
            failed[p] = str(exc)
            continue
        cur.append(p)
        full = pl.nest_count is not None and len(cur) >= pl.nest_count
        if not full and pl.nest_length_mm is not None:
            full = plan_layout(cur, settings, profile, paper_mm, sizes=sizes).height_mm \
                >= float(pl.nest_length_mm)
        if full:
            sheets.append(cur)
            cur = []
    return sheets, cur, failed


# -- drawing -------------------------------------------------------------------------------
def _ascii(text: str) -> str:
    return "".join(c if 32 <= ord(c) < 127 else "?" for c in text)


_FONT = 0                  # cv2.FONT_HERSHEY_SIMPLEX


def _font_metrics(rows: int, g: _Grid) -> tuple[int, float, int, int]:
    """(line height in square pixels at the dpi, font scale, stroke thickness, baseline)."""
    import cv2
    side = max(1, _round(g.mm_y(rows) / MM_PER_INCH * g.dpi))
    (_, above), below = cv2.getTextSize("Hg", _FONT, 1.0, 1)
    thick = max(1, _round(side * 0.08))
    scale = max(0.05, (side - thick - 1) / (above + below))
    base = min(side - 1, _round(above * scale) + thick // 2 + 1)
    return side, scale, thick, base


def _text_width(text: str, rows: int, g: _Grid) -> int:
    """Columns the text needs at the label's height."""
    import cv2
    if not text or rows < 1:
        return 0
    side, scale, thick, _ = _font_metrics(rows, g)
    (w, _), _ = cv2.getTextSize(text, _FONT, scale, thick)
    return w + 2 * thick + 1


def _text_mask(text: str, cols: int, rows: int, g: _Grid) -> np.ndarray:
    """(rows, cols) bool: the text in the Hershey simplex stroke font, drawn at the dpi's
    square pixels, then resampled (nearest) to the row pitch (docs/layout.md)."""
    import cv2
    side, scale, thick, base = _font_metrics(rows, g)
    canvas = np.zeros((side, cols), np.uint8)
    cv2.putText(canvas, text, (thick, base), _FONT, scale, 1, thick, cv2.LINE_8)
    return cv2.resize(canvas, (cols, rows), interpolation=cv2.INTER_NEAREST).astype(bool)


def _target_drawer(cols: int, rows: int, thick: int) -> Callable[[], np.ndarray]:
    def draw() -> np.ndarray:
        """A registration target: circle and cross, drawn square, resampled to rows."""
        import cv2
        side = cols
        canvas = np.zeros((side, side), np.uint8)
        c = side // 2
        cv2.circle(canvas, (c, c), max(1, (side - 1) // 2 - thick // 2 - 1), 1, thick, cv2.LINE_8)
        canvas[:, c - thick // 2: c - thick // 2 + thick] = 1
        canvas[c - thick // 2: c - thick // 2 + thick, :] = 1
        return cv2.resize(canvas, (cols, rows), interpolation=cv2.INTER_NEAREST).astype(bool)
    return draw


# -- composing -------------------------------------------------------------------------------
class _Crop:
    """A rectangle of a placed source (a tile): the ImageSource duck type RipJob uses."""

    def __init__(self, source, crop: tuple[int, int, int, int]):
        self.source, self.crop = source, crop
        x0, y0, x1, y1 = crop
        self.width, self.height = x1 - x0, y1 - y0
        for name in ("path", "channels", "colorspace", "depth", "dtype", "icc", "format", "xres", "yres"):
            setattr(self, name, getattr(source, name, None))
        # what the RIP must know of the content (rip/inputs.py); never the parent's packed_bands
        self.separated = getattr(source, "separated", False)
        self.prescreened = getattr(source, "prescreened", False)

    def bands(self, rows: int = 256) -> Iterator[np.ndarray]:
        return _reband(self._rows(rows), rows)

    def _rows(self, rows: int) -> Iterator[np.ndarray]:
        x0, y0, x1, y1 = self.crop
        it = iter(self.source.bands(rows))
        r = 0
        try:
            for band in it:
                a, b = max(r, y0), min(r + band.shape[0], y1)
                if a < b:
                    yield band[a - r:b - r, x0:x1]
                r += band.shape[0]
                if r >= y1:
                    break
        finally:
            close = getattr(it, "close", None)
            if close:
                close()

    def close(self) -> None:
        self.source.close()


class _Run:
    """An item's halftone rows from its first row on, handed out band by band."""

    def __init__(self, job, y: int):
        self.job = job
        self.it = iter(job.halftone_bands())
        self.pos = y                     # the sheet row of the next row to hand out
        self.end = y + job.height
        self.pending: list[np.ndarray] = []
        self.have = 0
        self.last: tuple | None = None   # (a, b, rows): shared by the slots of the run

    def rows(self, a: int, b: int) -> np.ndarray:
        if self.last is not None and self.last[:2] == (a, b):
            return self.last[2]
        if a != self.pos:
            raise RuntimeError(f"layout: item rows asked out of order ({a}, expected {self.pos})")
        n = b - a
        while self.have < n:
            band = next(self.it, None)
            if band is None:
                raise RuntimeError(f"layout: {self.job.path} gave {self.have} rows fewer than its "
                                   f"{self.job.height}")
            self.pending.append(band)
            self.have += band.shape[0]
        block = np.concatenate(self.pending, axis=0) if len(self.pending) > 1 else self.pending[0]
        out, rest = block[:n], block[n:]
        self.pending, self.have = ([rest] if rest.shape[0] else []), rest.shape[0]
        self.pos = b
        self.last = (a, b, out)
        return out

    def close(self) -> None:
        close = getattr(self.it, "close", None)
        if close:
            close()


class LayoutJob(PrintableJob):
    """Several placed items on one sheet, composed in bands (docs/layout.md).  The
    PrintableJob of a layout: `RipJob` makes one when the settings ask for a layout, and is
    its `make_job`, the factory of each item's job."""

    def __init__(self, paths, settings: RipSettings, profile, paper_mm: float | None = None,
                 when: datetime | None = None, names=(), *,
                 make_job: Callable[..., Any]):
        # make_job(path, settings, profile): the job of one item - a `RipJob` (its source is
        # cropped here, its dead-row compensation left to the sheet), handed in by
        # RipJob itself, so that this module does not import rip/pipeline.py (no circle)
        self.make_job = make_job
        self.paths = [os.fspath(p) for p in paths]
        self.path = self.paths[0]
        self.settings, self.profile = settings, profile
        # names: what the labels call the files (a print server's spooled copies have
        # names of their own; the label shows the job's file name)
        self.plan = plan_layout(self.paths, settings, profile, paper_mm, when,
                                names=dict(zip(self.paths, names)) if names else None)
        self.width, self.height = self.plan.width, self.plan.height
        self._free: dict[tuple, list] = {}        # item key -> open RipJobs not in a run
        self._runs_left: Counter = Counter()      # item key -> runs still to come
        self._open: list = []

    @property
    def report(self) -> dict:
        return dict(self.plan.report)

    @property
    def ink_limit(self) -> float | None:
        """--ink-limit, else the profile's (each item applies its own rule: docs/color.md)."""
        s = self.settings.ink_limit
        return s if s is not None else self.profile.color.ink_limit_percent

    def _job(self, item: Item):
        free = self._free.get(item.key)
        if free:
            return free.pop()
        job = self.make_job(item.path, item_settings(self.settings, item.turn), self.profile)
        job.compensate_dead = False          # the sheet's rows are compensated, not the item's
        self._open.append(job)
        if item.crop is not None:
            job.source = _Crop(job.source, item.crop)
            job.width, job.height = job.source.width, job.source.height
        if (job.width, job.height) != (item.width, item.height):
            raise RuntimeError(f"layout: {item.path} is {job.width} x {job.height} dots, the plan "
                               f"said {item.width} x {item.height}")
        return job

    def _done(self, item: Item, job) -> None:
        self._runs_left[item.key] -= 1
        if self._runs_left[item.key] > 0:
            self._free.setdefault(item.key, []).append(job)
        else:
            job.close()
            self._open.remove(job)

    def halftone_bands(self) -> Iterator[np.ndarray]:
        """The sheet top to bottom, (h, width, 4) uint8 0/1 bands of band_rows rows."""
        # a run per item and first row (copies side by side share it)
        self._runs_left = Counter(key for key, _ in {(s.item.key, s.y) for s in self.plan.slots})
        rows, W, H = int(self.settings.band_rows), self.width, self.height
        slots = sorted(self.plan.slots, key=lambda s: (s.box[1], s.x))
        nxt, active, runs = 0, [], {}
        try:
            for r0 in range(0, H, rows):
                r1 = min(H, r0 + rows)
                band = np.zeros((r1 - r0, W, 4), np.uint8)
                while nxt < len(slots) and slots[nxt].box[1] < r1:
                    active.append((slots[nxt], self.plan.slot_marks(slots[nxt])))
                    nxt += 1
                for s, marks in active:
                    it = s.item
                    a, b = max(r0, s.y), min(r1, s.y + it.height)
                    if a < b:
                        key = (it.key, s.y)
                        if key not in runs:
                            runs[key] = (_Run(self._job(it), s.y), it)
                        band[a - r0:b - r0, s.x:s.x + it.width] = runs[key][0].rows(a, b)
                    for m in marks:
                        _draw(band, r0, r1, m)
                for key in [k for k, (run, _) in runs.items() if run.end <= r1]:
                    run, it = runs.pop(key)
                    run.close()
                    self._done(it, run.job)
                active = [(s, m) for s, m in active if s.box[1] + s.box[3] > r1]
                yield band
        finally:
            for run, _ in runs.values():
                run.close()

    def close(self) -> None:
        for job in self._open:
            job.close()
        self._open, self._free = [], {}


def _draw(band: np.ndarray, r0: int, r1: int, m: Mark) -> None:
    a, b = max(r0, m.y), min(r1, m.y + m.h)
    x0, x1 = max(0, m.x), min(band.shape[1], m.x + m.w)
    if a >= b or x0 >= x1:
        return
    mask = m.mask()
    for c in m.inks:
        if mask is None:
            band[a - r0:b - r0, x0:x1, c] = 1
        else:
            band[a - r0:b - r0, x0:x1, c] |= mask[a - m.y:b - m.y, x0 - m.x:x1 - m.x]
