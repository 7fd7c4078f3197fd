"""Print-and-cut documents for the tests (tests/test_spot*.py, tests/test_cut*.py,
tests/test_gui_spots.py; docs/spot.md, docs/cut.md): a PDF with two brand spot colours, a
spot in no library and CutContour lines, and where a document's cut paths and its K ink
land on the sheet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pikepdf

from wideprint.rip.profile import load_profile

PT = 25.4 / 72                                  # mm per point
ROW_UM = load_profile().row_um

# two brand colours inside vinyl-300's gamut, as a brand book gives them (D50, 2°)
BRAND = {"Brand Red": (48.0, 62.0, 38.0), "Brand Teal": (55.0, -35.0, -12.0)}


# -- a PDF with spots ---------------------------------------------------------------------------
W_PT, H_PT = 216, 144          # 3 x 2 in
# the spots' rectangles (x, y, w, h in points from the lower left), over a background that
# fills y 0..68; the CutContour lines, 3 mm wide, run x 20..196 at y 40 (over the
# background and the spots) and at y 110 (over blank paper)
RECTS = {"Brand Red": (10, 10, 60, 50), "Brand Teal": (78, 10, 60, 50), "Other Green": (146, 10, 60, 50)}
CUT_Y_PT = 40


def make_pdf(path: Path, cut_width_mm: float = 3.0) -> Path:
    """Two library spots (a Separation with a Lab alternate, one with a CMYK alternate), a
    spot in no library, and CutContour strokes 3 mm wide, over a 20 % CMYK background."""
    pdf = pikepdf.new()
    page = pdf.add_blank_page(page_size=(W_PT, H_PT))
    lab = pikepdf.Array([pikepdf.Name.Lab, pikepdf.Dictionary(WhitePoint=[0.9642, 1, 0.8249],
                                                               Range=[-128, 127, -128, 127])])

    def sep(name, alt, c0, c1):
        fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=c0, C1=c1, N=1)
        return pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/" + name), alt, fn])
    cmyk = pikepdf.Name.DeviceCMYK
    page.Resources = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(
        CS0=sep("Brand Red", lab, [100, 0, 0], [48, 62, 38]),
        CS1=sep("Brand Teal", cmyk, [0, 0, 0, 0], [0.8, 0, 0.3, 0]),     # the designer's guess
        CS2=sep("Other Green", cmyk, [0, 0, 0, 0], [0.7, 0, 1, 0]),
        CS3=sep("CutContour", cmyk, [0, 0, 0, 0], [0, 1, 0, 0])))
    w = cut_width_mm / PT
    body = [f"0.2 0.2 0.2 0.2 k 0 0 {W_PT} {H_PT - 76} re f"]        # background: lower part
    for i, (x, y, rw, rh) in enumerate(RECTS.values()):
        body.append(f"/CS{i} cs 1 scn {x} {y} {rw} {rh} re f")
    body.append(f"/CS3 CS 1 SCN {w:.4f} w 1 J 20 {CUT_Y_PT + 70} m 196 {CUT_Y_PT + 70} l S")
    body.append(f"/CS3 CS 1 SCN {w:.4f} w 20 {CUT_Y_PT} m 196 {CUT_Y_PT} l S")
    page.Contents = pdf.make_stream("\n".join(body).encode())
    pdf.save(path)
    return path


# -- where a document's cut paths and ink land (no printing: Ghostscript renders) -----------
def settings_for(dpi=300, **placement):
    from wideprint.rip.settings import Placement, RipSettings
    return RipSettings(dpi=dpi, placement=Placement(**placement))


def printed_box_mm(path: Path, st) -> tuple[float, float, float, float]:
    """The K ink's bounding box as Ghostscript renders the document for the job, mm."""
    from wideprint.rip.document import open_document
    from wideprint.rip.inputs import sniff_input
    with open_document(str(path), sniff_input(str(path)), st, load_profile()) as doc:
        k = np.concatenate(list(doc.bands(256)))[..., 3] > 127
    ys, xs = np.nonzero(k)
    col, row = 25.4 / st.dpi, ROW_UM / 1000
    return xs.min() * col, ys.min() * row, (xs.max() + 1) * col, (ys.max() + 1) * row


def cut_box_mm(path: Path, st) -> tuple[float, float, float, float]:
    from wideprint.rip.cut import cut_job
    job = cut_job(str(path), st, load_profile())
    pts = np.vstack([p.points for p in job.paths])
    return pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max()
