"""Cut files: HP-GL/2 for vinyl and contour cutters, DXF for flatbed and other cutting
software (docs/cut.md, "Cut files").  Writers and readers (the tests, the GUI's overlay and
a shop's checks read a file back with the same frame).

Frame of both: the printed sheet of rip/cut.py, millimetres, origin at the sheet's first
printed row and left edge; `x` across the media to the right (as it comes out of the
printer, printed side up), `y` along the feed (the direction the media leaves the printer).

* HP-GL/2 (`.plt`, `.hpgl`): plotter units of 0.025 mm (40 per mm, what vinyl cutters
  read); the plotter's X is the sheet's `y` (along the media, as a roll cutter's X axis is)
  and its Y the sheet's `x`.  That pair is a right-handed plotter frame seen from above, so
  the cut is not mirrored.  `IN;` `SP1;` then `PU x,y;` `PD x,y,...;` per path, `SP0;` at
  the end.  The registration marks' centres are `CO` comments (HP-GL/2's comment
  instruction, ignored by cutters), never drawn: a cutter must not cut its marks.
* DXF (`.dxf`, R2000, `$INSUNITS` 4 = mm) through ezdxf: every path an LWPOLYLINE on layer
  `CUT` (closed paths with the closed flag), every mark its square outline on layer
  `REGMARKS` plus a POINT at its centre.  DXF's y points up: DXF `(x, -y)`, so the drawing
  looks as the print does with its first row at the top.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from typing import Iterable

import numpy as np

from .cut import CHORD_MM, CutJob, cut_job

__all__ = ["UNITS_PER_MM", "CUT_FORMATS", "cut_format", "write_cut_file", "write_hpgl",
           "write_dxf", "read_cut_file", "read_hpgl", "parse_hpgl", "read_dxf", "write_job_cut",
           "SERVER_CUT_FILES", "server_cut_path", "write_cut_files"]

UNITS_PER_MM = 40                      # HP-GL plotter units (0.025 mm)
CUT_FORMATS = {".plt": "hpgl", ".hpgl": "hpgl", ".hpg": "hpgl", ".dxf": "dxf"}
CUT_LAYER, MARK_LAYER = "CUT", "REGMARKS"


def cut_format(path: str) -> str:
    """'hpgl' or 'dxf' from a cut file's name (ValueError for anything else)."""
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in CUT_FORMATS:
        raise ValueError(f"--cut-out {path}: the cut file must end in .plt, .hpgl or .dxf "
                         f"(HP-GL/2 or DXF), not {ext or 'nothing'!r}")
    return CUT_FORMATS[ext]


def write_cut_file(path: str, job: CutJob) -> str:
    """Write `job` in the format its name says; returns the format."""
    fmt = cut_format(path)
    (write_hpgl if fmt == "hpgl" else write_dxf)(path, job)
    return fmt


# -- HP-GL/2 -------------------------------------------------------------------------------
def _pu(p: np.ndarray) -> np.ndarray:
    """Sheet millimetres (x across, y along) -> plotter units (X along, Y across)."""
    return np.rint(np.asarray(p)[:, ::-1] * UNITS_PER_MM).astype(np.int64)


def write_hpgl(path: str, job: CutJob) -> None:
    out = ["IN;", f'CO"wideprint cut file: sheet {job.width_mm:.3f} x {job.height_mm:.3f} mm, '
           f'X along the feed, Y across, 40 units/mm, origin first printed row, left edge";']
    for place, x, y in job.marks:
        out.append(f'CO"REGMARK {place} {job.mark_mm:.3f} {y * UNITS_PER_MM:.1f},{x * UNITS_PER_MM:.1f}";')
    out.append("SP1;")
    for cp in job.paths:
        q = _pu(cp.points)
        keep = np.ones(len(q), bool)
        keep[1:] = np.any(q[1:] != q[:-1], axis=1)     # repeated points after rounding
        q = q[keep]
        if len(q) < 2:
            continue
        out.append(f"PU{q[0, 0]},{q[0, 1]};")
        out.append("PD" + ",".join(f"{a},{b}" for a, b in q[1:]) + ";")
    out += ["PU;", "SP0;"]
    with open(path, "w", newline="\n") as f:
        f.write("\n".join(out) + "\n")


def read_hpgl(path: str) -> tuple[list[np.ndarray], list[tuple[str, float, float]]]:
    """The pen-down polylines of an HP-GL/2 file (sheet millimetres) and the REGMARK
    comments (place, x mm, y mm)."""
    with open(path) as f:
        return parse_hpgl(f.read())


def parse_hpgl(text: str) -> tuple[list[np.ndarray], list[tuple[str, float, float]]]:
    """read_hpgl of the file's text."""
    marks = [(m.group(1), float(m.group(3)) / UNITS_PER_MM, float(m.group(2)) / UNITS_PER_MM)
             for m in re.finditer(r'CO"REGMARK (\S+) \S+ (-?[\d.]+),(-?[\d.]+)"', text)]
    text = re.sub(r'CO"[^"]*";?', "", text)
    lines: list[list] = []
    pos, down = (0.0, 0.0), False
    cur: list = []
    for cmd, args in re.findall(r"([A-Z]{2})([^A-Z;]*)", text):
        nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", args)]
        pts = list(zip(nums[::2], nums[1::2]))
        if cmd in ("PU", "PD"):
            d = cmd == "PD"
            if d and not down:
                cur = [pos]
            if not d and down and len(cur) > 1:
                lines.append(cur)
            down = d
            for p in pts:
                pos = p
                if down:
                    cur.append(p)
    if down and len(cur) > 1:
        lines.append(cur)
    return ([np.array(line, np.float64)[:, ::-1] / UNITS_PER_MM for line in lines], marks)


# -- DXF -----------------------------------------------------------------------------------
def write_dxf(path: str, job: CutJob) -> None:
    import ezdxf
    doc = ezdxf.new("R2000")
    doc.units = 4                                      # millimetres ($INSUNITS)
    doc.header["$MEASUREMENT"] = 1
    doc.layers.add(CUT_LAYER, color=6)
    doc.layers.add(MARK_LAYER, color=7)
    msp = doc.modelspace()
    for cp in job.paths:
        pts = [(float(x), -float(y)) for x, y in cp.points]
        if cp.closed and len(pts) > 2 and np.allclose(pts[0], pts[-1]):
            pts = pts[:-1]
        msp.add_lwpolyline(pts, close=cp.closed, dxfattribs={"layer": CUT_LAYER})
    h = job.mark_mm / 2
    for _place, x, y in job.marks:
        msp.add_lwpolyline([(x - h, -y + h), (x + h, -y + h), (x + h, -y - h), (x - h, -y - h)],
                           close=True, dxfattribs={"layer": MARK_LAYER})
        msp.add_point((x, -y), dxfattribs={"layer": MARK_LAYER})
    doc.saveas(path)


def read_dxf(path: str) -> tuple[list[np.ndarray], list[tuple[str, float, float]]]:
    """The CUT layer's polylines (sheet millimetres, a closed one ending on its start) and
    the REGMARKS centres (place '', x mm, y mm)."""
    import ezdxf
    from ezdxf.entities import LWPolyline
    doc = ezdxf.readfile(path)
    msp = doc.modelspace()
    lines = []
    for e in msp.query(f'LWPOLYLINE[layer=="{CUT_LAYER}"]'):
        if not isinstance(e, LWPolyline):
            continue
        p = np.array([(x, -y) for x, y in e.get_points("xy")], np.float64)
        if e.closed:
            p = np.vstack([p, p[:1]])
        lines.append(p)
    marks = [("", float(e.dxf.location.x), -float(e.dxf.location.y))
             for e in msp.query(f'POINT[layer=="{MARK_LAYER}"]')]
    return lines, marks


def read_cut_file(path: str) -> tuple[list[np.ndarray], list[tuple[str, float, float]]]:
    return (read_hpgl if cut_format(path) == "hpgl" else read_dxf)(path)


# -- a job's cut files (rip/cut.py extracts, this module writes) ---------------------------

def write_job_cut(path: str, rip, settings, profile, patterns: Iterable[str] | None = None) -> dict:
    """The cut file of a RipJob (rip/pipeline.py) at `path` (.plt/.hpgl: HP-GL/2, .dxf:
    DXF); returns the report's `cut` entry: file, format, paths, length, marks."""
    plan = rip.layout.plan if getattr(rip, "layout", None) is not None else None
    files = [rip.path, *getattr(rip, "more", ())]
    job = cut_job(files if plan is not None else rip.path, settings, profile, patterns, plan)
    fmt = write_cut_file(path, job)
    length = sum(float(np.hypot(*np.diff(p.points, axis=0).T).sum()) for p in job.paths)
    return dict(file=path, format=fmt, paths=len(job.paths), length_mm=round(length, 3),
                marks=len(job.marks), width_mm=round(job.width_mm, 3), height_mm=round(job.height_mm, 3),
                names=sorted({p.name for p in job.paths}), chord_mm=CHORD_MM)


#: the cut files a print server keeps for a job (docs/cut.md, "Through the print server")
SERVER_CUT_FILES = ("cut.plt", "cut.dxf")


def server_cut_path(state_dir, job_id: int, name: str) -> str:
    """Where the print server keeps a job's cut file `name` (one of SERVER_CUT_FILES)."""
    return os.path.join(os.fspath(state_dir), "cut", f"{int(job_id)}-{name}")


def write_cut_files(state_dir, job_id: int, rip, settings, profile) -> dict:
    """A server job's cut files, HP-GL/2 and DXF, from one extraction; the `cut` report.
    `rip` is the job's RipJob, or its list of files (they are laid out as it would be)."""
    if isinstance(rip, (list, tuple)):
        from .layout import plan_layout, wants_layout
        files = [os.fspath(f) for f in rip]
        plan = plan_layout(files, settings, profile) if wants_layout(settings.placement, files[1:]) else None
    else:
        plan = rip.layout.plan if getattr(rip, "layout", None) is not None else None
        files = [rip.path, *getattr(rip, "more", ())]
    job = cut_job(files if plan is not None else files[0], settings, profile, None, plan)
    folder = os.path.join(os.fspath(state_dir), "cut")
    os.makedirs(folder, exist_ok=True)
    for name in SERVER_CUT_FILES:
        # written aside under a name of its own (the worker and an API request may write
        # the same job's file at once), then renamed into place
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{int(job_id)}-", suffix=os.path.splitext(name)[1])
        os.close(fd)
        try:
            write_cut_file(tmp, job)
            os.replace(tmp, server_cut_path(state_dir, job_id, name))
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    return dict(paths=len(job.paths), marks=len(job.marks), files=list(SERVER_CUT_FILES))
