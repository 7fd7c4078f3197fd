"""Text in a cut colour (docs/cut.md "Text in a cut colour"; issue 35): its glyph outlines
are cut paths, where Ghostscript draws the same text in ink, through a page box and a
/Rotate; the text itself never prints."""

from __future__ import annotations

import numpy as np
import pikepdf
from support.printcut import cut_box_mm, printed_box_mm, settings_for

from wideprint.rip.cut import cut_job
from wideprint.rip.document import open_document
from wideprint.rip.profile import load_profile

TEXT = b"BT /F1 72 Tf 40 50 Td (Wp) Tj ET"


def text_pdf(path, paint: bytes, mode: bytes = b"") -> None:
    """A page (CropBox and /Rotate 90, as Ghostscript applies them) with 'Wp' in Helvetica
    painted by `paint`, text render mode `mode`."""
    pdf = pikepdf.new()
    fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0], C1=[0, 1, 0, 0], N=1)
    res = pikepdf.Dictionary(
        ColorSpace=pikepdf.Dictionary(CS0=pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/CutContour"),
                                                         pikepdf.Name.DeviceCMYK, fn])),
        Font=pikepdf.Dictionary(F1=pikepdf.Dictionary(Type=pikepdf.Name.Font, Subtype=pikepdf.Name.Type1,
                                                      BaseFont=pikepdf.Name.Helvetica)))
    page = pikepdf.Dictionary(Type=pikepdf.Name.Page, MediaBox=[0, 0, 300, 200], CropBox=[20, 10, 260, 190],
                              Rotate=90, Resources=res,
                              Contents=pdf.make_stream(paint + b" " + mode + b" " + TEXT))
    pdf.pages.append(pikepdf.Page(page))
    pdf.save(path)


def test_text_in_a_cut_colour_is_cut_along_its_glyphs(tmp_path):
    cut, ink = tmp_path / "cut.pdf", tmp_path / "ink.pdf"
    text_pdf(cut, b"/CS0 cs 1 scn")
    text_pdf(ink, b"0 0 0 1 k")
    st = settings_for(dpi=300)
    job = cut_job(str(cut), st, load_profile())
    closed = [p for p in job.paths if p.closed]
    assert len(closed) >= 3 and all(p.name == "CutContour" for p in job.paths)   # W, and p's two contours
    got, want = cut_box_mm(cut, st), printed_box_mm(ink, st)
    assert np.abs(np.subtract(got, want)).max() <= 0.1, (got, want)
    with open_document(str(cut), "pdf", st, load_profile()) as doc:          # never printed
        assert sum(int(b.sum()) for b in doc.bands(256)) == 0
    # stroked text (render mode 1) in the cut colour: its outline's stroke is the cut path
    text_pdf(tmp_path / "stroked.pdf", b"/CS0 CS 1 SCN 0.2 w", b"1 Tr")
    assert cut_box_mm(tmp_path / "stroked.pdf", st) == got or \
        np.abs(np.subtract(cut_box_mm(tmp_path / "stroked.pdf", st), got)).max() <= 0.1
    # invisible text (mode 3) in the cut colour is not a cut line
    text_pdf(tmp_path / "hidden.pdf", b"/CS0 cs 1 scn", b"3 Tr")
    assert cut_job(str(tmp_path / "hidden.pdf"), st, load_profile()).paths == []
