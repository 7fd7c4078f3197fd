"""Print and cut (issue 35, docs/cut.md): cut paths from a PDF's CutContour, the HP-GL/2 and
DXF cut files, the cutter's registration marks, and a camera cutter finding the marks on
the scan of a 3 m print with feed error and skew."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pikepdf
import pytest

from support.printcut import cut_box_mm, printed_box_mm, settings_for
from wideprint.app import api
from wideprint.rip.cutfile import read_dxf, read_hpgl
from wideprint.rip.cutnames import is_cut_name
from wideprint.rip.profile import load_profile

sys.path.insert(0, str(Path(__file__).parent / "support"))
import cutter  # noqa: E402

PT = 25.4 / 72.0                      # mm per point
ROW_UM = load_profile().row_um


def make_pdf(path: Path, w_pt: float, h_pt: float, content: str, cut_alt=(0, 1, 0, 0)) -> None:
    """A one-page PDF whose resource CS0 is a Separation named CutContour (alternate CMYK
    `cut_alt` at tint 1, as a designer's software writes it)."""
    pdf = pikepdf.new()
    fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0], C1=list(cut_alt), N=1)
    cs = pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/CutContour"), pikepdf.Name.DeviceCMYK,
                        pdf.make_indirect(fn)])
    form = pdf.make_stream(b"/CS0 CS 1 SCN 0.5 w 0 0 m 20 0 l 20 10 l S",
                           Type=pikepdf.Name.XObject, Subtype=pikepdf.Name.Form, BBox=[0, 0, 50, 50],
                           Resources=pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(CS0=cs)))
    res = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(CS0=cs), XObject=pikepdf.Dictionary(Fm0=form))
    page = pikepdf.Dictionary(Type=pikepdf.Name.Page, MediaBox=[0, 0, w_pt, h_pt], Resources=res,
                              Contents=pdf.make_stream(content.encode()))
    pdf.pages.append(pikepdf.Page(page))
    pdf.save(path)


def bezier(p0, p1, p2, p3, n=4000) -> np.ndarray:
    t = np.linspace(0, 1, n)[:, None]
    u = 1 - t
    return (u ** 3 * np.array(p0) + 3 * u * u * t * np.array(p1) + 3 * u * t * t * np.array(p2)
            + t ** 3 * np.array(p3))


def seg_dist(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Each point's distance to the polyline."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    best = np.full(len(points), np.inf)
    for i in range(0, len(points), 2000):
        p = points[i:i + 2000, None, :]
        t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-18), 0, 1)
        q = a + t[..., None] * d
        best[i:i + 2000] = np.sqrt(((p - q) ** 2).sum(-1)).min(axis=1)
    return best


def wideprint(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "wideprint.app.cli", *args], capture_output=True, text=True,
                          timeout=600)


# the decal: a K shape, and around it a CutContour with straight and curved parts (points)
H_PT = 200.0
CUT = [("m", (20, 20)), ("l", (140, 20)), ("c", (170, 20), (180, 60), (150, 90)),
       ("c", (120, 120), (60, 180), (30, 150)), ("l", (20, 20))]


def cut_ops() -> str:
    out = []
    for op, *pts in CUT:
        out.append(" ".join(f"{x} {y}" for x, y in pts) + f" {op}")
    return " ".join(out) + " h"


def true_path_mm(scale: float, x0_mm: float, y0_mm: float) -> np.ndarray:
    """The CutContour as the sheet should have it: points -> mm, y down from the page top."""
    pts, cur = [], None
    for op, *p in CUT:
        if op == "m":
            cur = p[0]
        elif op == "l":
            pts.append(np.linspace(cur, p[0], 2000))
            cur = p[0]
        else:
            pts.append(bezier(cur, *p))
            cur = p[-1]
    pdf = np.vstack(pts)
    return np.stack([x0_mm + pdf[:, 0] * PT * scale, y0_mm + (H_PT - pdf[:, 1]) * PT * scale], axis=1)


@pytest.fixture(scope="module")
def decal(tmp_path_factory):
    d = tmp_path_factory.mktemp("cut")
    pdf = d / "decal.pdf"
    # a 2 pt cut stroke whose alternate is magenta, as designers' files have it
    make_pdf(pdf, 200, H_PT, f"/CS0 CS 1 SCN 2 w {cut_ops()} S 0 0 0 1 k 50 50 60 40 re f\n"
             "q 1 0 0 1 150 150 cm /Fm0 Do Q\n")
    runs = {}
    for ext in ("plt", "dxf"):
        run = wideprint("print", str(pdf), "--dpi", "150", "--scale", "1.5", "--cut-out", str(d / f"decal.{ext}"),
                        "--media-out", str(d / f"media-{ext}.tif"), "--report", str(d / f"rep-{ext}.json"))
        assert run.returncode == 0, run.stderr
        runs[ext] = json.loads((d / f"rep-{ext}.json").read_text())[0]
    return d, runs


def frame_mm(dpi: int) -> tuple[float, float]:
    """The slot's frame for the cutter's marks (docs/cut.md): offset + side, on the grid."""
    cols = round(3.0 / 25.4 * dpi) * 2
    rows = round(3.0 * 1000 / ROW_UM) * 2
    return cols * 25.4 / dpi, rows * ROW_UM / 1000


def test_cut_names_are_the_conventional_ones():
    for name in ("CutContour", "cutcontour", "Thru-cut", "CutPath", "KissCut", "Die-line", "DieCut"):
        assert is_cut_name(name), name
    for name in ("Cyan", "PANTONE 485 C", "Brand Red", "Cutter"):
        assert not is_cut_name(name), name
    assert is_cut_name("Contour", ["contour"]) and not is_cut_name("CutContour", ["contour"])



def test_a_shop_sets_its_own_cut_names(monkeypatch):
    """$WIDEPRINT_CUT_NAMES replaces the list, or with a leading + adds to it; the render
    and the cut file ask the same function, so they agree."""
    monkeypatch.setenv("WIDEPRINT_CUT_NAMES", "Schnitt*, Konturschnitt")
    assert is_cut_name("Schnittkontur") and is_cut_name("KONTURSCHNITT") and not is_cut_name("CutContour")
    monkeypatch.setenv("WIDEPRINT_CUT_NAMES", "+Schnitt*")
    assert is_cut_name("Schnittkontur") and is_cut_name("CutContour")
    monkeypatch.delenv("WIDEPRINT_CUT_NAMES")
    assert not is_cut_name("Schnittkontur") and is_cut_name("CutContour")


@pytest.mark.parametrize("ext", ["plt", "dxf"])
def test_cut_file_path_equals_the_pdf_path_on_the_sheet(decal, ext):
    d, runs = decal
    lines, marks = (read_hpgl if ext == "plt" else read_dxf)(str(d / f"decal.{ext}"))
    assert runs[ext]["cut"]["paths"] == 2 and len(lines) == 2
    fx, fy = frame_mm(150)
    want = true_path_mm(1.5, fx, fy)
    main = max(lines, key=len)
    assert np.allclose(main[0], main[-1])                                 # closed
    there = seg_dist(main, want[::1])                    # the file's vertices on the true path
    back = seg_dist(want, main)                          # the true path on the file's polyline
    assert there.max() <= 0.05 and back.max() <= 0.05, (there.max(), back.max())
    assert len(main) > 30                                # the curves were flattened, not cut short
    # the form XObject's path, through its placement (cm) and the form's own resources
    form = min(lines, key=len)
    exp = np.array([[150, 150], [170, 150], [170, 160]], float)
    exp_mm = np.stack([fx + exp[:, 0] * PT * 1.5, fy + (H_PT - exp[:, 1]) * PT * 1.5], axis=1)
    assert np.abs(form - exp_mm).max() <= 0.05
    assert len(marks) == 4


def test_registration_marks_are_k_only_where_the_cut_file_says(decal):
    d, runs = decal
    media = api.read_planes(d / "media-plt.tif")
    _, marks = read_hpgl(str(d / "decal.plt"))
    dpi, col, row = 150, 25.4 / 150, ROW_UM / 1000
    fx, fy = frame_mm(dpi)
    w_mm, h_mm = 200 * PT * 1.5, H_PT * PT * 1.5
    place = {p: (x, y) for p, x, y in marks}
    # documented places: 3 mm squares, 3 mm clear of the graphic, at its corners
    for name, ex, ey in (("L0", fx - 4.5, fy - 4.5), ("R0", fx + w_mm + 4.5, fy - 4.5),
                      ("L1", fx - 4.5, fy + h_mm + 4.5), ("R1", fx + w_mm + 4.5, fy + h_mm + 4.5)):
        x, y = place[name]
        assert abs(x - ex) <= col and abs(y - ey) <= row, (name, x, y, ex, ey)
    # on the media: the K dots outside the graphic are exactly four squares at those centres
    gx0, gy0 = round(fx / col), round(fy / row)
    outside = media[..., 3].astype(bool)
    outside[gy0:gy0 + round(h_mm / row) + 1, gx0:gx0 + round(w_mm / col) + 1] = False
    n, _, stats, cents = cv2.connectedComponentsWithStats(outside.astype(np.uint8), connectivity=8)
    assert n - 1 == 4
    for (_x, _y, w, h, area), (cx, cy) in zip(stats[1:], cents[1:]):
        assert area == w * h and abs(w * col - 3.0) <= col and abs(h * row - 3.0) <= row
        mx, my = (cx + 0.5) * col, (cy + 0.5) * row
        assert min(np.hypot(mx - px, my - py) for px, py in place.values()) <= 0.5 * col
    # K only: no C, M or Y outside the graphic (the marks are not registration colour)
    cmy = media[..., :3].any(axis=2)
    cmy[gy0:gy0 + round(h_mm / row) + 1, gx0:gx0 + round(w_mm / col) + 1] = False
    assert not cmy.any()


def test_no_ink_under_the_cut_path_on_the_media(decal):
    """The cut line is never printed, whatever its stroke width (the render leaves cut
    colours out, docs/spot.md): no drop within 1 mm of the cut path, no magenta anywhere
    (the cut colour's alternate), and the K shape inside it printed."""
    d, _ = decal
    media = api.read_planes(d / "media-plt.tif")
    lines, _ = read_hpgl(str(d / "decal.plt"))
    col, row = 25.4 / 150, ROW_UM / 1000
    ink = media.any(axis=2)
    # the dots within 1 mm of the path (a point every 0.05 mm, the cells a 1 mm disc around it meets)
    dx, dy = np.meshgrid(np.arange(-7, 8) * col, np.arange(-15, 16) * row)
    disk = np.hypot(dx, dy) <= 1.0
    dx, dy = dx[disk], dy[disk]
    for line in lines:
        pts = cutter.resample(line, 0.05)
        cx = np.floor((pts[:, 0:1] + dx[None]) / col).astype(int)
        cy = np.floor((pts[:, 1:2] + dy[None]) / row).astype(int)
        ok = (cx >= 0) & (cx < ink.shape[1]) & (cy >= 0) & (cy < ink.shape[0])
        assert ok.all()                                  # the path is on the sheet
        assert not ink[cy, cx].any(), f"{int(ink[cy, cx].sum())} dots within 1 mm of the cut path"
    assert not media[..., 1].any()
    assert media[..., 3].sum() > 1000


W_MM, L_MM = 40.0, 3000.0


def long_contour() -> str:
    """A closed contour 3 m long: a straight side, the other of cubic waves, curved ends."""
    mm = 1 / PT
    p = [f"{5 * mm:.3f} {(L_MM - 5) * mm:.3f} m", f"{5 * mm:.3f} {5 * mm:.3f} l",
         f"{5 * mm:.3f} 0 {30 * mm:.3f} 0 {30 * mm:.3f} {10 * mm:.3f} c"]
    y, k = 10.0, 0
    while y + 250 <= L_MM - 10 + 1e-9:
        a = 6.0 if k % 2 == 0 else -6.0
        p.append(f"{(30 + a) * mm:.3f} {(y + 250 / 3) * mm:.3f} {(30 + a) * mm:.3f} "
                 f"{(y + 500 / 3) * mm:.3f} {30 * mm:.3f} {(y + 250) * mm:.3f} c")
        y, k = y + 250, k + 1
    p += [f"{30 * mm:.3f} {(L_MM - 10) * mm:.3f} l",
          f"{30 * mm:.3f} {L_MM * mm:.3f} {5 * mm:.3f} {L_MM * mm:.3f} {5 * mm:.3f} {(L_MM - 5) * mm:.3f} c h"]
    return " ".join(p)


def test_camera_cutter_finds_the_marks_and_cuts_on_the_printed_contour(tmp_path):
    """3 m print, 0.3 % feed error and 0.2 degree skew: the marks found on the scan correct
    the cut path onto the contour printed as a 0.4 mm K line (measured where the line is on
    the scan), within 0.25 mm everywhere; uncorrected it is millimetres off."""
    pdf = tmp_path / "banner.pdf"
    c = long_contour()
    # the cut line's alternate is no ink, so the scan shows only the K contour line
    make_pdf(pdf, W_MM / PT, L_MM / PT, f"/CS0 CS 1 SCN 0.3 w {c} S\n0 0 0 1 K {0.4 / PT:.4f} w {c} S\n",
             cut_alt=(0, 0, 0, 0))
    run = wideprint("print", str(pdf), "--dpi", "150", "--cut-out", str(tmp_path / "cut.plt"),
                    "--scan-out", str(tmp_path / "scan.tif"), "--scan-dpi", "200",
                    "--inject", "feed-error=0.3%", "--inject", "skew=0.2deg")
    assert run.returncode == 0, run.stderr
    lines, marks = read_hpgl(str(tmp_path / "cut.plt"))
    assert len(marks) == 16                              # 8 pairs: a pair at least every 500 mm
    dark, pix = cutter.load_scan(str(tmp_path / "scan.tif"))
    found = cutter.find_marks(dark, pix, marks, 3.0)
    path = cutter.resample(lines[0], 0.5)                # a point every 0.5 mm of the 6 m contour
    err = cutter.measure_on_print(dark, cutter.correct(path, found), pix)
    assert not np.isnan(err).any()                       # the printed line is under every point
    assert err.max() <= 0.25, err.max()
    # the injection is real: the first pair alone (no correction along the length) is far off
    first = cutter.Found(found.centres_px[:2], found.nominal_mm[:2], pix)
    end = path[path[:, 1] > L_MM - 100]
    sim, _ = cv2.estimateAffinePartial2D(first.nominal_mm[:, None].astype(np.float32),
                                         first.centres_px[:, None].astype(np.float32))
    naive = end @ sim[:, :2].T + sim[:, 2]
    corrected = cutter.correct(end, found)
    assert np.hypot(*(naive - corrected).T).max() * pix > 8.0      # 0.3 % of 3 m, 0.2 deg: ~9-10 mm


def test_print_server_keeps_the_cut_files_with_the_job(decal, print_server):
    """A job with placement marks cut: its HP-GL/2 and DXF cut files are fetched from the
    server's API, the same paths and marks as `wideprint print --cut-out` writes."""
    from wideprint.app.client import ApiError, Client
    d, _ = decal
    srv = print_server()
    c = Client(srv.state_dir)
    try:
        job = c.submit(d / "decal.pdf", settings={"dpi": 150, "placement": {"scale": 1.5, "marks": "cut"}})["job"]
        plain = c.submit(d / "decal.pdf", settings={"dpi": 150}, hold=True)["job"]
        held = c.submit(d / "decal.pdf", settings={"dpi": 150, "placement": {"scale": 1.5, "marks": "cut"}},
                        hold=True)["job"]
        early = d / "held.plt"                            # not ripped yet: made from its spooled file
        early.write_bytes(c.cut_file(held["id"], "plt"))
        assert early.read_bytes() == (d / "decal.plt").read_bytes()
        assert c.wait(job["id"], timeout=120)["state"] == "done"
        for ext, read in (("plt", read_hpgl), ("dxf", read_dxf)):
            got = d / f"server.{ext}"
            got.write_bytes(c.cut_file(job["id"], ext))
            lines, marks = read(str(got))
            want, want_marks = read(str(d / f"decal.{ext}"))
            assert len(lines) == len(want) == 2
            for a, b in zip(sorted(lines, key=len), sorted(want, key=len)):
                assert a.shape == b.shape and np.abs(a - b).max() < 1e-6
            assert np.allclose([m[1:] for m in marks], [m[1:] for m in want_marks])
        with pytest.raises(ApiError) as err:
            c.cut_file(plain["id"], "plt")
        assert err.value.status == 404 and "not a print-and-cut job" in str(err.value)
    finally:
        c.close()


# -- the extraction's graphics state, documents and layouts (no printing: Ghostscript renders;
# settings_for, printed_box_mm, cut_box_mm: tests/support/printcut.py) --
def test_devicen_tints_and_painting_operators(tmp_path):
    """A DeviceN with a cut component cuts only where that component's tint is above 0;
    `B` in the cut colour is one path; `n` paints nothing; a device colour after the spot
    ends it; q/Q restores the colour."""
    from wideprint.rip.cut import extract_pdf
    pdf = pikepdf.new()
    fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0], C1=[0, 1, 0, 0], N=1)
    fn4 = pdf.make_stream(b"{pop pop 0 0 0 0}", FunctionType=4, Domain=[0, 1, 0, 1], Range=[0, 1] * 4)
    res = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(
        CS0=pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/Thru-cut"), pikepdf.Name.DeviceCMYK, fn]),
        DN=pikepdf.Array([pikepdf.Name.DeviceN, pikepdf.Array([pikepdf.Name("/Spot1"), pikepdf.Name("/CutContour")]),
                          pikepdf.Name.DeviceCMYK, fn4])))
    content = ("/DN CS 1 0 SCN 0 0 m 10 0 l S "          # CutContour tint 0: not a cut
               "0.5 1 SCN 0 10 m 10 10 l S "             # tint 1: a cut
               "0 G q /CS0 cs 1 scn 0 20 m 10 20 l 10 30 l B Q "   # fill in the cut colour
               "0 30 m 10 30 l f "                       # fill restored by Q: not a cut
               "/CS0 CS 0 40 m 10 40 l n "               # n paints nothing
               "0 0 0 1 K 0 50 m 10 50 l S "             # a device colour: not a cut
               "/CS0 CS 0 SCN 0 60 m 10 60 l S")         # tint 0: not a cut
    page = pikepdf.Dictionary(Type=pikepdf.Name.Page, MediaBox=[0, 0, 100, 100], Resources=res,
                              Contents=pdf.make_stream(content.encode()))
    pdf.pages.append(pikepdf.Page(page))
    pdf.save(tmp_path / "dn.pdf")
    raws = extract_pdf(str(tmp_path / "dn.pdf"), 1)
    got = [(r.name, float(r.subpaths[0][0][1])) for r in raws]
    assert got == [("CutContour", 10.0), ("Thru-cut", 20.0)], got


@pytest.mark.parametrize("placement", [dict(rotate=90), dict(rotate=180, mirror=True, width_mm=123.4),
                                       dict(rotate=270, scale=1.7)])
def test_cut_path_lies_on_the_print_through_the_placement(tmp_path, placement):
    """A CutContour rectangle over a K rectangle of the same size: through every
    placement, the cut rectangle is where Ghostscript put the K one, within a dot."""
    pdf = tmp_path / "rect.pdf"
    make_pdf(pdf, 200, 150, "/CS0 CS 1 SCN 0.5 w 30 20 100 60 re S 0 0 0 1 k 30 20 100 60 re f\n")
    st = settings_for(dpi=150, **placement)
    got, want = cut_box_mm(pdf, st), printed_box_mm(pdf, st)
    assert np.abs(np.subtract(got, want)).max() <= 25.4 / 150 + 0.07, (got, want)   # a column or a row


def test_rotated_page_and_eps_go_through_ghostscript_as_printed(tmp_path):
    """/Rotate 90 and a page box (CropBox) as Ghostscript applies them; an EPS through
    pdfwrite with its BoundingBox as the page."""
    pdf = pikepdf.new()
    fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0], C1=[0, 1, 0, 0], N=1)
    res = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(
        CS0=pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/CutContour"), pikepdf.Name.DeviceCMYK, fn])))
    page = pikepdf.Dictionary(Type=pikepdf.Name.Page, MediaBox=[0, 0, 300, 200], CropBox=[20, 10, 260, 190],
                              Rotate=90, Resources=res, Contents=pdf.make_stream(
                                  b"/CS0 CS 1 SCN 0.5 w 60 40 120 50 re S 0 0 0 1 k 60 40 120 50 re f"))
    pdf.pages.append(pikepdf.Page(page))
    pdf.save(tmp_path / "rot.pdf")
    st = settings_for()
    got, want = cut_box_mm(tmp_path / "rot.pdf", st), printed_box_mm(tmp_path / "rot.pdf", st)
    assert np.abs(np.subtract(got, want)).max() <= 0.1, (got, want)
    eps = tmp_path / "shape.eps"
    eps.write_text("%!PS-Adobe-3.0 EPSF-3.0\n%%BoundingBox: 10 20 210 170\n"
                   "[/Separation /CutContour /DeviceCMYK {pop 0 1 0 0}] setcolorspace 1 setcolor\n"
                   "0.5 setlinewidth 40 50 moveto 150 50 lineto 150 130 170 150 40 130 curveto closepath stroke\n"
                   "/DeviceCMYK setcolorspace 0 0 0 1 setcolor\n"
                   "40 50 moveto 150 50 lineto 150 130 170 150 40 130 curveto closepath fill\nshowpage\n")
    got, want = cut_box_mm(eps, st), printed_box_mm(eps, st)
    assert np.abs(np.subtract(got, want)).max() <= 0.1, (got, want)


def test_layouts_carry_their_items_cut_paths_and_marks(tmp_path):
    """Step-and-repeat: every copy has its path and its marks, at its slot; nested items
    turned 90 degrees carry their turned paths; tiles cut only what lies on them."""
    from wideprint.rip.cut import cut_job
    from wideprint.rip.layout import plan_layout
    pdf = tmp_path / "label.pdf"
    make_pdf(pdf, 100, 80, "/CS0 CS 1 SCN 0.5 w 10 10 80 60 re S\n")
    prof = load_profile()
    alone = cut_job(str(pdf), settings_for(marks="cut"), prof,
                    plan=plan_layout([str(pdf)], settings_for(marks="cut"), prof))
    st = settings_for(marks="cut", repeat_across=3, repeat_along=2, gap_mm=4)
    plan = plan_layout([str(pdf)], st, prof)
    job = cut_job([str(pdf)], st, prof, plan=plan)
    assert len(job.paths) == 6 and len(job.marks) == 6 * len(alone.marks)
    g = plan.grid
    for s, p in zip(plan.slots, job.paths):
        shift = np.array([g.mm_x(s.x - plan.slots[0].x), g.mm_y(s.y - plan.slots[0].y)])
        assert np.abs(p.points - (alone.paths[0].points + shift)).max() < 1e-9
    # nesting with turns: a turned item's path is the file's printed alone at rotate 90, at its slot
    wide, small = tmp_path / "wide.pdf", tmp_path / "small.pdf"
    make_pdf(wide, 300 / PT, 60 / PT, "/CS0 CS 1 SCN 0.5 w 20 20 100 60 re S\n")
    make_pdf(small, 50 / PT, 40 / PT, "/CS0 CS 1 SCN 0.5 w 10 10 50 40 re S\n")
    nest = settings_for(dpi=150, nest=True, nest_rotate=True, nest_width_mm=200, marks="cut")
    nplan = plan_layout([str(wide), str(small)], nest, prof)
    njob = cut_job([str(wide), str(small)], nest, prof, plan=nplan)
    assert len(njob.paths) == 2 and len(njob.marks) == 8 and all(s.item.turn for s in nplan.slots)
    ng = nplan.grid
    for s, p in zip(nplan.slots, njob.paths):
        ref = cut_job(s.item.path, settings_for(dpi=150, rotate=90), prof).paths[0].points
        assert np.abs(p.points - (ref + [ng.mm_x(s.x), ng.mm_y(s.y)])).max() < 1e-9
    tiles = settings_for(tile_width_mm=20)
    tplan = plan_layout([str(pdf)], tiles, prof)
    tjob = cut_job([str(pdf)], tiles, prof, plan=tplan)
    assert len(tplan.slots) == 2 and len(tjob.paths) >= 2
    for p in tjob.paths:                    # each piece lies within its tile's slot
        assert any(g.mm_x(s.x) - 1e-6 <= p.points[:, 0].min() and p.points[:, 0].max()
                   <= g.mm_x(s.x + s.item.width) + 1e-6 for s in tplan.slots)


def test_gui_preview_draws_cut_lines_in_their_own_colour(qtbot):
    """The GUI's preview draws a print-and-cut job's cut lines over the picture, in the
    sheet's millimetres, in a colour no ink has; a message clears them."""
    from wideprint.app.gui.preview import CUT_COLOR, INK_COLORS, PreviewPanel
    panel = PreviewPanel()
    qtbot.addWidget(panel)
    panel.set_image(np.full((100, 200, 3), 255, np.uint8), 200.0, 100.0, "job")
    panel.set_cut_paths([np.array([[10.0, 5.0], [190.0, 5.0], [190.0, 95.0], [10.0, 5.0]]), np.zeros((1, 2))])
    r = panel.cut_item.sceneBoundingRect()
    assert abs(r.left() - (panel.margin_mm + 10)) < 0.01 and abs(r.top() - 5) < 0.01
    assert abs(r.width() - 180) < 0.01 and abs(r.height() - 90) < 0.01
    assert panel.cut_item.path().elementCount() == 4
    assert panel.cut_item.pen().color().name() == CUT_COLOR and CUT_COLOR not in INK_COLORS.values()
    panel.show_message("no job")
    assert panel.cut_item.path().isEmpty()


def test_pages_follow_each_other_with_their_cut_paths(tmp_path):
    """A two-page document prints its pages one after another along the roll: each page's
    cut path is on its own page's print (the page gap included)."""
    from wideprint.rip.cut import cut_job
    from wideprint.rip.document import open_document
    pdf = pikepdf.new()
    fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0], C1=[0, 1, 0, 0], N=1)
    cs = pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/CutContour"), pikepdf.Name.DeviceCMYK,
                        pdf.make_indirect(fn)])
    for rect, box in (("30 20 100 60", [0, 0, 200, 150]), ("50 40 60 50", [0, 0, 160, 120])):
        page = pikepdf.Dictionary(Type=pikepdf.Name.Page, MediaBox=box,
                                  Resources=pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(CS0=cs)),
                                  Contents=pdf.make_stream(f"/CS0 CS 1 SCN {rect} re S 0 0 0 1 k {rect} re f".encode()))
        pdf.pages.append(pikepdf.Page(page))
    pdf.save(tmp_path / "two.pdf")
    st = settings_for(dpi=150, page_gap_mm=12)
    with open_document(str(tmp_path / "two.pdf"), "pdf", st, load_profile()) as doc:
        k = (np.concatenate(list(doc.bands(256)))[..., 3] > 127).astype(np.uint8)
    n, _, stats, _ = cv2.connectedComponentsWithStats(k)
    col, row = 25.4 / 150, ROW_UM / 1000
    printed = sorted((x * col, y * row, (x + w) * col, (y + h) * row) for x, y, w, h, _ in stats[1:])
    job = cut_job(str(tmp_path / "two.pdf"), st, load_profile())
    cut = sorted((p.points[:, 0].min(), p.points[:, 1].min(), p.points[:, 0].max(), p.points[:, 1].max())
                 for p in job.paths)
    assert n - 1 == 2 and len(cut) == 2
    assert np.abs(np.subtract(cut, printed)).max() <= col + 0.01, (cut, printed)


def test_skew_turns_the_print_on_the_scan_and_leaves_the_media(tmp_path):
    """`--inject skew=1deg`: on the scan the print is turned by 1 degree, running to the
    right down the sheet (docs/physical.md "Skew"); the bit-exact media is the RIP's
    planes, as without skew."""
    pdf = tmp_path / "block.pdf"
    make_pdf(pdf, 120, 200, "0 0 0 1 k 10 10 100 180 re f\n")
    run = wideprint("print", str(pdf), "--dpi", "150", "--media-out", str(tmp_path / "media.tif"),
                    "--scan-out", str(tmp_path / "scan.tif"), "--scan-dpi", "200", "--inject", "skew=1deg")
    assert run.returncode == 0, run.stderr
    assert np.array_equal(api.read_planes(tmp_path / "media.tif"), api.rip(pdf, {"dpi": 150}))
    dark, _ = cutter.load_scan(str(tmp_path / "scan.tif"))
    rows = np.nonzero((dark > 0.5).sum(axis=1) > 50)[0]
    top, bottom = rows[5], rows[-6]                      # inside the block's height
    left = [np.argmax(dark[r] > 0.5) for r in range(top, bottom)]
    slope = np.degrees(np.arctan(np.polyfit(np.arange(top, bottom), left, 1)[0]))
    assert abs(slope - 1.0) < 0.05, slope               # the left edge runs right going down
