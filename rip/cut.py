"""Cut paths of a print job: the paths drawn in a cut spot colour, on the printed sheet
(docs/cut.md).

A PDF page's content stream is parsed with pikepdf (qpdf's tokenizer) and interpreted here
for the little a cut path needs: the current transformation matrix (`cm`, `q`/`Q`, form
XObjects with their `/Matrix`), path construction (`m l c v y h re`), painting (`S s f F f*
B B* b b* n`) and the stroke and fill colour spaces (`CS cs SC SCN sc scn`, `G g RG rg K k`)
with their Separation and DeviceN names.  A path stroked (or filled) while the stroke (or
fill) colour is a Separation or a DeviceN component whose name `rip.cutnames.is_cut_name`
calls a cut line, with a tint above 0, becomes a cut path.  PostScript and EPS are first
turned into PDF by Ghostscript's pdfwrite (which keeps paths and Separation spaces).

The path is then carried, as Bézier control points (affine maps keep Béziers), through the
same transforms the print went through: the page box and /Rotate /UserUnit as Ghostscript
renders them (docs/documents.md), the placement's scale, rotation and mirror
(docs/placement.md), the page's place in the document and the item's place on the
layout's sheet (docs/layout.md), to millimetres of the printed sheet; and flattened there,
so the chord error is stated on the media: at most `CHORD_MM` (0.01 mm).
"""

from __future__ import annotations

import math
import os
import subprocess
import tempfile
from dataclasses import dataclass, field
from decimal import Decimal
from typing import Iterable, Iterator

import numpy as np

from .cutnames import is_cut_name
from .settings import MM_PER_INCH

__all__ = ["CHORD_MM", "CutPath", "CutJob", "RawPath", "extract_pdf", "page_to_sheet",
           "flatten", "cut_job", "wants_cut_marks"]

#: the largest distance between a flattened polyline and its Bézier, millimetres of the media
CHORD_MM = 0.01


# -- the content stream --------------------------------------------------------------------
@dataclass
class RawPath:
    """One painted cut path in default user space (points): subpaths as a start point and
    segments ("L", (2,) end) / ("C", (3, 2) control points and end)."""
    name: str                                        # the spot colour's name
    subpaths: list = field(default_factory=list)     # [(start (2,), [segments], closed)]


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a @ b


def _matrix(a, b, c, d, e, f) -> np.ndarray:
    """A PDF matrix [a b c d e f] as a 3 x 3 acting on row vectors (x y 1)."""
    return np.array([[a, b, 0.0], [c, d, 0.0], [e, f, 1.0]], np.float64)


def _apply(m: np.ndarray, pts: np.ndarray) -> np.ndarray:
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    return pts @ m[:2, :2] + m[2, :2]


class _Colour:
    """The cut spot a colour space + colour selects ("" when it is not one)."""

    def __init__(self, names: tuple[str, ...] = (), tints: tuple[float, ...] = ()):
        self.names, self.tints = names, tints

    def cut_name(self, patterns) -> str:
        for i, n in enumerate(self.names):
            tint = self.tints[i] if i < len(self.tints) else 1.0
            if tint > 0 and is_cut_name(n, patterns):
                return n
        return ""


def _space_names(space) -> tuple[str, ...]:
    """Colorant names of a Separation or DeviceN colour space object ((), else)."""
    import pikepdf
    if isinstance(space, pikepdf.Array) and len(space) >= 2:
        family = str(space[0])
        if family == "/Separation":
            return (str(space[1]).lstrip("/"),)
        if family == "/DeviceN":
            return tuple(str(n).lstrip("/") for n in space[1])
    return ()


def _resolve_space(name, resources) -> tuple[str, ...]:
    try:
        spaces = resources.get("/ColorSpace") if resources is not None else None
        if spaces is not None and name in spaces:
            return _space_names(spaces[name])
    except (KeyError, TypeError, ValueError):
        pass
    return ()


def extract_pdf(path: str, page_number: int, patterns: Iterable[str] | None = None,
                text: list | None = None) -> list[RawPath]:
    """The cut paths of page `page_number` (1-based) of a PDF, in default user space;
    `text` (when given) gets the cut name of every text shown in a cut colour (its glyphs
    are no paths here: cut_job outlines them, docs/cut.md "Text in a cut colour")."""
    import pikepdf
    patterns = tuple(patterns) if patterns is not None else None
    out: list[RawPath] = []
    with pikepdf.open(path) as pdf:
        page = pdf.pages[page_number - 1]
        _run(page.obj, page.obj.get("/Resources"), np.eye(3), patterns, out, depth=0, text=text)
    return out


#: text render modes that fill, and that stroke (PDF 9.3.6)
_TEXT_FILLS, _TEXT_STROKES = (0, 2, 4, 6), (1, 2, 5, 6)


def _run(holder, resources, ctm0: np.ndarray, patterns, out: list[RawPath], depth: int,
         text: list | None = None) -> None:
    import pikepdf
    if depth > 12:                                   # forms calling forms: a cycle or an attack
        return
    stack: list[tuple] = []
    ctm = ctm0
    stroke, fill = _Colour(), _Colour()
    mode = 0                                         # the text render mode (Tr)
    sub: list = []                                   # subpaths being built
    cur: list | None = None                          # [start, segments, closed]
    point = np.zeros(2)

    def paint(colour: _Colour, fills: bool = False) -> None:
        name = colour.cut_name(patterns)
        if not name:
            return
        raw = RawPath(name)
        for start, segs, closed in sub:
            if not segs:
                continue
            # a fill closes every subpath (PDF 8.5.3.3): a filled shape is cut all round
            raw.subpaths.append((_apply(ctm, start)[0],
                                 [(k, _apply(ctm, v).reshape(-1, 2) if k == "C" else _apply(ctm, v)[0])
                                  for k, v in segs], closed or fills))
        if raw.subpaths:
            out.append(raw)

    try:
        ops = pikepdf.parse_content_stream(holder)
    except pikepdf.PdfError:
        return
    for ins in ops:
        if not isinstance(ins, pikepdf.ContentStreamInstruction):
            continue                                 # inline images
        operands, o = ins.operands, str(ins.operator)
        nums = [float(x) for x in operands if isinstance(x, (int, float, Decimal)) and not isinstance(x, bool)]
        if o == "q":
            stack.append((ctm, stroke, fill, mode))
        elif o == "Q":
            if stack:
                ctm, stroke, fill, mode = stack.pop()
        elif o == "Tr" and len(nums) == 1:
            mode = int(nums[0])
        elif o in ("Tj", "TJ", "'", '"') and text is not None:
            name = (fill.cut_name(patterns) if mode in _TEXT_FILLS else "") or \
                (stroke.cut_name(patterns) if mode in _TEXT_STROKES else "")
            if name:
                text.append(name)
        elif o == "cm" and len(nums) == 6:
            ctm = _mul(_matrix(*nums), ctm)
        elif o == "m" and len(nums) == 2:
            point = np.array(nums)
            cur = [point, [], False]
            sub.append(cur)
        elif o in ("l", "c", "v", "y") and cur is not None:
            if o == "l" and len(nums) == 2:
                cur[1].append(("L", np.array(nums)))
                point = np.array(nums)
            elif o == "c" and len(nums) == 6:
                cur[1].append(("C", np.array(nums).reshape(3, 2)))
                point = np.array(nums[4:])
            elif o == "v" and len(nums) == 4:
                cur[1].append(("C", np.array([point, nums[:2], nums[2:]], np.float64)))
                point = np.array(nums[2:])
            elif o == "y" and len(nums) == 4:
                cur[1].append(("C", np.array([nums[:2], nums[2:], nums[2:]], np.float64)))
                point = np.array(nums[2:])
        elif o == "h" and cur is not None:
            cur[2] = True
            point = cur[0]
        elif o == "re" and len(nums) == 4:
            x, y, w, h = nums
            cur = [np.array([x, y]), [("L", np.array([x + w, y])), ("L", np.array([x + w, y + h])),
                                      ("L", np.array([x, y + h]))], True]
            sub.append(cur)
            point = np.array([x, y])
        elif o in ("S", "s", "f", "F", "f*", "B", "B*", "b", "b*", "n"):
            if o in ("s", "b", "b*") and cur is not None:
                cur[2] = True
            if o in ("S", "s", "B", "B*", "b", "b*"):
                paint(stroke)
            if o in ("f", "F", "f*", "B", "B*", "b", "b*") and not (o[0] in "Bb" and stroke.cut_name(patterns)):
                paint(fill, fills=True)              # a B in the cut colour is one path, not two
            sub, cur = [], None
        elif o in ("CS", "cs") and operands:
            names = _resolve_space(operands[0], resources)
            col = _Colour(names, (1.0,) * len(names))   # a space's initial colour: tint 1
            if o == "CS":
                stroke = col
            else:
                fill = col
        elif o in ("SC", "SCN", "sc", "scn"):
            target = stroke if o in ("SC", "SCN") else fill
            if target.names:
                col = _Colour(target.names, tuple(nums))
                if o in ("SC", "SCN"):
                    stroke = col
                else:
                    fill = col
        elif o in ("G", "RG", "K"):
            stroke = _Colour()
        elif o in ("g", "rg", "k"):
            fill = _Colour()
        elif o == "Do" and operands:
            try:
                xobjs = resources.get("/XObject") if resources is not None else None
                xo = xobjs[operands[0]] if xobjs is not None else None
            except (KeyError, TypeError):
                xo = None
            if xo is not None and xo.get("/Subtype") == "/Form":
                m = xo.get("/Matrix")
                fm = _matrix(*[float(v) for v in m]) if m is not None else np.eye(3)
                _run(xo, xo.get("/Resources", resources), _mul(fm, ctm), patterns, out, depth + 1,
                     text)


def ps_to_pdf(path: str, fmt: str, directory: str) -> str:
    """A PostScript or EPS file as PDF (Ghostscript's pdfwrite keeps paths and spot colour
    spaces), in `directory`; EPS cropped to its BoundingBox as the print renders it."""
    out = os.path.join(directory, "cut.pdf")
    args = ["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pdfwrite",
            "-dCompressPages=false", f"-sOutputFile={out}"]
    if fmt == "eps":
        args.append("-dEPSCrop")
    args += ["-f", os.path.abspath(path)]
    run = subprocess.run(args, capture_output=True, timeout=300)
    if run.returncode != 0 or not os.path.exists(out):
        raise ValueError(f"{path}: Ghostscript could not read its cut paths: "
                         f"{run.stderr.decode(errors='replace').strip()[-300:]}")
    return out


def outline_text(pdf: str, page, directory: str):
    """Page `page` (a GsPage) of `pdf` with its text drawn as glyph outlines (Ghostscript's
    pdfwrite, -dNoOutputFonts: each glyph a filled or stroked path in the text's colour,
    spot colour spaces kept), cropped to the box the print renders (the page's box
    switches) and unrotated: (the new PDF, its GsPage with that box as its MediaBox), read
    the way a PostScript file's distilled page is."""
    from dataclasses import replace as _replace
    from .ghostscript import gs_path, probe
    out = os.path.join(directory, f"outlined-{page.number}.pdf")
    args = [gs_path(), "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pdfwrite",
            "-dNoOutputFonts", "-dCompressPages=false", "-dAutoRotatePages=/None",
            "-sColorConversionStrategy=LeaveColorUnchanged", f"-sPageList={page.number}",
            *page.flags, f"-sOutputFile={out}", "-f", os.path.abspath(pdf)]
    run = subprocess.run(args, capture_output=True, timeout=300)
    if run.returncode != 0 or not os.path.exists(out):
        raise ValueError(f"{pdf}: Ghostscript could not outline the text in a cut colour on page "
                         f"{page.number}: {run.stderr.decode(errors='replace').strip()[-300:]}")
    conv, _ = probe(out, "pdf", "media")
    return out, _replace(page, number=1, boxes=conv[0].boxes, box="media", rotate=conv[0].rotate,
                         flags=(), user_unit=conv[0].user_unit)


def _page_paths(pdf: str, page, patterns, directory: str):
    """(GsPage, cut paths) of a page: read from the file, or, when it shows text in a cut
    colour, from its copy with the text outlined (the outlines and every other cut path)."""
    text: list = []
    raws = extract_pdf(pdf, page.number, patterns, text)
    if text:
        outlined, opage = outline_text(pdf, page, directory)
        return opage, extract_pdf(outlined, 1, patterns)
    return page, raws


# -- page to sheet -------------------------------------------------------------------------
def _box(page) -> tuple[float, float, float, float]:
    """The page box Ghostscript renders, in default user space (rip/ghostscript.py)."""
    from .ghostscript import _BOX_KEYS, _intersect
    media = page.boxes.get("MediaBox", (0.0, 0.0, 612.0, 792.0))
    if page.box == "media":
        b = media
    else:
        b = _intersect(page.boxes[_BOX_KEYS[page.box]] if _BOX_KEYS[page.box] in page.boxes
                       else page.boxes["CropBox"], media)
    x0, x1 = sorted((b[0], b[2]))
    y0, y1 = sorted((b[1], b[3]))
    return x0, y0, x1, y1


def page_to_sheet(page, placement, raster: tuple[int, int, float, float], y_offset: float,
                  slot_xy: tuple[float, float], crop: tuple | None) -> np.ndarray:
    """The 3 x 3 affine map from a page's default user space (points) to sheet dots
    (columns, rows; continuous: the dot of column c spans [c, c + 1)).

    `raster` is (width, height, xres, yres) of the page as Ghostscript renders it in its own
    frame (rip/document.py page_geometry); `y_offset` the rows of the pages and gaps before
    it; `slot_xy` the item's top-left on the sheet, `crop` the tile's (x0, y0, x1, y1)."""
    bx0, by0, bx1, by1 = _box(page)
    uu = page.user_unit
    bw, bh = (bx1 - bx0) * uu, (by1 - by0) * uu
    # user space -> the page as viewed: top-left origin, y down, points (/UserUnit applied)
    m = _matrix(uu, 0, 0, -uu, -bx0 * uu, by1 * uu)
    rot = {0: _matrix(1, 0, 0, 1, 0, 0), 90: _matrix(0, 1, -1, 0, bh, 0),
           180: _matrix(-1, 0, 0, -1, bw, bh), 270: _matrix(0, -1, 1, 0, 0, bw)}[page.rotate]
    m = m @ rot
    pw, ph, xres, yres = raster
    m = m @ _matrix(xres / 72.0, 0, 0, yres / 72.0, 0, 0)       # -> the rendered raster's pixels
    turn = {0: _matrix(1, 0, 0, 1, 0, 0), 90: _matrix(0, 1, -1, 0, ph, 0),   # clockwise, whole pixels
            180: _matrix(-1, 0, 0, -1, pw, ph), 270: _matrix(0, -1, 1, 0, 0, pw)}[placement.rotate]
    m = m @ turn
    width = ph if placement.rotate in (90, 270) else pw
    if placement.mirror:
        m = m @ _matrix(-1, 0, 0, 1, width, 0)
    cx, cy = (crop[0], crop[1]) if crop else (0, 0)
    return m @ _matrix(1, 0, 0, 1, slot_xy[0] - cx, slot_xy[1] + y_offset - cy)


def _cubic_steps(ctrl: np.ndarray, tol: float) -> int:
    """Segments that keep a cubic within `tol` of its chords (Wang's formula)."""
    d = np.abs(ctrl[:-2] - 2 * ctrl[1:-1] + ctrl[2:]).max(initial=0.0)
    return max(1, int(math.ceil(math.sqrt(0.75 * d / tol)))) if d > 0 else 1


def flatten(start: np.ndarray, segs: list, closed: bool, tol: float = CHORD_MM) -> np.ndarray:
    """A subpath (already in millimetres) as a polyline whose chord error is at most `tol`."""
    pts = [np.asarray(start, np.float64)[None]]
    cur = np.asarray(start, np.float64)
    for kind, v in segs:
        if kind == "L":
            pts.append(np.asarray(v)[None])
            cur = np.asarray(v)
        else:
            ctrl = np.vstack([cur[None], v])
            n = _cubic_steps(ctrl, tol)
            t = (np.arange(1, n + 1) / n)[:, None]
            u = 1 - t
            pts.append(u ** 3 * ctrl[0] + 3 * u * u * t * ctrl[1] + 3 * u * t * t * ctrl[2] + t ** 3 * ctrl[3])
            cur = v[-1]
    p = np.vstack(pts)
    if closed and np.hypot(*(p[-1] - p[0])) > 1e-9:
        p = np.vstack([p, p[:1]])
    return p


@dataclass
class CutPath:
    """A polyline on the printed sheet, millimetres (docs/cut.md: x across from the print's
    left edge, y along the feed from its first row)."""
    points: np.ndarray
    closed: bool
    name: str


@dataclass
class CutJob:
    """A job's cut file content: the paths and the registration marks, sheet millimetres."""
    width_mm: float
    height_mm: float
    paths: list                                   # [CutPath]
    marks: list = field(default_factory=list)     # [(place, x mm, y mm)] centres
    mark_mm: float = 0.0                          # the marks' side


def _doc_pages(path: str, settings, profile, tmp: str) -> Iterator[tuple]:
    """(pdf path, GsPage, raster, y offset rows) of every printed page of a document."""
    from dataclasses import replace as _replace
    from .document import page_geometry, select_pages
    from .ghostscript import probe
    from .inputs import sniff_input
    pl = settings.placement
    fmt = sniff_input(path)
    if fmt not in ("pdf", "ps", "eps"):
        return
    pages, _ = probe(path, fmt, pl.page_box)
    chosen = select_pages(path, pages, pl.pages)
    pdf = path if fmt == "pdf" else ps_to_pdf(path, fmt, tmp)
    if fmt != "pdf":                              # the converted PDF's page: its MediaBox
        conv, _ = probe(pdf, "pdf", "media")
        chosen = [_replace(c, boxes=conv[c.number - 1].boxes, box="media", rotate=conv[c.number - 1].rotate)
                  for c in chosen]
    gap = int(round(float(pl.page_gap_mm) * 1000.0 / profile.row_um)) if len(chosen) > 1 else 0
    y = 0
    for page in chosen:
        raster = page_geometry(page, pl, settings.dpi, profile.row_um)
        yield pdf, page, raster, y
        h = raster[0] if pl.quarter_turn else raster[1]
        y += h + gap


def _clip_rect(p: np.ndarray, crop_mm: tuple | None) -> list[np.ndarray]:
    """A polyline kept where it lies in the rectangle (x0, y0, x1, y1): its runs of points
    inside (a tile cuts what lies on it; docs/cut.md)."""
    if crop_mm is None:
        return [p]
    x0, y0, x1, y1 = crop_mm
    inside = (p[:, 0] >= x0 - 1e-9) & (p[:, 0] <= x1 + 1e-9) & (p[:, 1] >= y0 - 1e-9) & (p[:, 1] <= y1 + 1e-9)
    out, run = [], []
    for q, ok in zip(p, inside):
        if ok:
            run.append(q)
        elif run:
            out.append(np.array(run))
            run = []
    if run:
        out.append(np.array(run))
    return [r for r in out if len(r) > 1]


def cut_job(paths, settings, profile, patterns: Iterable[str] | None = None, plan=None) -> CutJob:
    """The cut paths and marks of a job as `wideprint print` prints it: `paths` one file or
    a layout's files, `plan` the job's layout (rip/layout.py) when it has one."""
    from .layout import _Grid, item_settings
    if isinstance(paths, (str, os.PathLike)):
        paths = [os.fspath(paths)]
    g = _Grid(settings.dpi, profile.row_um)
    mm = np.diag([MM_PER_INCH / settings.dpi, profile.row_um / 1000.0, 1.0])
    if plan is not None:
        slots = [(s.item.path, s.x, s.y, s.item.turn, s.item.crop, s) for s in plan.slots]
        width, height = plan.width, plan.height
    else:
        from .layout import printed_size
        width, height = printed_size(paths[0], settings, profile)[:2]
        slots = [(paths[0], 0, 0, False, None, None)]
    cache: dict = {}
    out: list[CutPath] = []
    with tempfile.TemporaryDirectory(prefix="wideprint-cut-") as tmp:
        for path, sx, sy, turn, crop, _slot in slots:
            st = item_settings(settings, turn) if plan is not None else settings
            key = (path, turn)
            if key not in cache:
                sub = os.path.join(tmp, str(len(cache)))
                os.makedirs(sub)
                cache[key] = [(pdf, *_page_paths(pdf, page, patterns, sub), raster, y)
                              for pdf, page, raster, y in _doc_pages(path, st, profile, sub)]
            crop_mm = None
            if crop is not None:
                crop_mm = (g.mm_x(sx), g.mm_y(sy), g.mm_x(sx + crop[2] - crop[0]), g.mm_y(sy + crop[3] - crop[1]))
            for _pdf, page, raws, raster, y in cache[key]:
                m = page_to_sheet(page, st.placement, raster, y, (sx, sy), crop) @ mm
                for raw in raws:
                    for start, segs, closed in raw.subpaths:
                        pts = flatten(_apply(m, start)[0],
                                      [(k, _apply(m, v) if k == "C" else _apply(m, v)[0]) for k, v in segs],
                                      closed)
                        for piece in _clip_rect(pts, crop_mm):
                            out.append(CutPath(piece, closed and piece is pts, raw.name))
    marks: list = []
    mark_mm = 0.0
    if plan is not None and plan.cut_marks is not None:
        from .regmarks import centres_mm
        for k, s in enumerate(plan.slots):
            rects = plan.cut_marks.rects(s.x, s.y, s.item.width, s.item.height, g.cols, g.rows)
            marks += [(f"{k + 1}{place}" if len(plan.slots) > 1 else place, x, y)
                      for place, x, y in centres_mm(rects, g.mm_x, g.mm_y)]
        mark_mm = plan.cut_marks.size_mm
    return CutJob(g.mm_x(width), g.mm_y(height), out, marks, mark_mm)


def wants_cut_marks(settings):
    """The settings a job with a cut file prints with: the cutter's registration marks
    (`marks cut`) unless other marks were asked for (docs/cut.md)."""
    from dataclasses import replace as _replace
    pl = settings.placement
    if pl.marks != "none":
        return settings
    return _replace(settings, placement=_replace(pl, marks="cut"))
