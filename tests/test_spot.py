"""Spot colours (docs/spot.md, issue 35): named colour libraries in CxF3 and text, their
resolution per media, a PDF's Separation colours printed with their recipes and measured
on the emulator's spectrophotometer, a cut colour that never prints, the swatch book."""

import json
from pathlib import Path

import numpy as np
import pikepdf
import pytest

from support.printcut import BRAND, CUT_Y_PT, H_PT, PT, RECTS, W_PT, make_pdf
from wideprint.app.cli import main
from wideprint.device_sim.spectral import delta_e2000 as de2000_spectral
from wideprint.device_sim.spectro import measure_patches
from wideprint.rip import spot
from wideprint.rip.color import DEFAULT_OUTPUT_ICC
from wideprint.rip.inputs import open_source
from wideprint.rip.planes import read_planes
from wideprint.rip.profile import load_profile
from wideprint.rip.settings import RipSettings
from wideprint.rip.spot_pdf import spot_names

ROOT = Path(__file__).resolve().parent.parent

# a CxF3 file as X-Rite's tools write it (namespace prefix, a spectral-only object too)
XRITE_CXF = b"""<?xml version="1.0" encoding="UTF-8"?>
<cc:CxF xmlns:cc="http://colorexchangeformat.com/CxF3-core">
 <cc:Resources>
  <cc:ObjectCollection>
   <cc:Object ObjectType="Standard" Name="Brand Red" Id="o1">
    <cc:ColorValues>
     <cc:ColorCIELab ColorSpecification="CS1"><cc:L>48</cc:L><cc:A>62</cc:A><cc:B>38</cc:B></cc:ColorCIELab>
    </cc:ColorValues>
   </cc:Object>
   <cc:Object ObjectType="Standard" Name="Only Spectral" Id="o2">
    <cc:ColorValues>
     <cc:ReflectanceSpectrum ColorSpecification="CS1" StartWL="400">0.1 0.2</cc:ReflectanceSpectrum>
    </cc:ColorValues>
   </cc:Object>
  </cc:ObjectCollection>
  <cc:ColorSpecificationCollection>
   <cc:ColorSpecification Id="CS1">
    <cc:TristimulusSpec><cc:Illuminant>D50</cc:Illuminant><cc:Observer>2_Degree</cc:Observer>
    <cc:Method>E308</cc:Method></cc:TristimulusSpec>
   </cc:ColorSpecification>
  </cc:ColorSpecificationCollection>
 </cc:Resources>
</cc:CxF>
"""


@pytest.fixture
def spots_dir(tmp_path, monkeypatch):
    d = tmp_path / "spots"
    monkeypatch.setenv("WIDEPRINT_SPOT_DIR", str(d))
    return d


def _brand_library(folder) -> spot.SpotBook:
    book = spot.SpotBook(folder)
    book.add([spot.Spot(n, lab) for n, lab in BRAND.items()], "brand")
    return book


# -- the files ------------------------------------------------------------------------------
def test_text_list_round_trip_and_refusals():
    text = "# brand book\nBrand Red: 48 62 38\n\nPANTONE 485 C: 50.1, 65.2, 45.7\n"
    got = spot.parse_text(text)
    assert [(s.name, s.lab) for s in got] == [("Brand Red", (48.0, 62.0, 38.0)),
                                               ("PANTONE 485 C", (50.1, 65.2, 45.7))]
    again = spot.parse_text(spot.write_text(got))
    assert [(s.name, s.lab) for s in again] == [(s.name, s.lab) for s in got]
    with pytest.raises(ValueError, match=r"text:2: not 'NAME: L a b'"):
        spot.parse_text("A: 1 2 3\nno colon here\n")
    with pytest.raises(ValueError, match="out of range"):
        spot.parse_text("X: 120 0 0")
    with pytest.raises(ValueError, match="cut colour name"):
        spot.parse_text("CutContour: 50 0 0")


def test_cxf3_round_trip_the_xrite_structure_and_d50_only():
    warnings: list[str] = []
    got = spot.parse_cxf3(XRITE_CXF, "x.cxf", warnings)
    assert [(s.name, s.lab) for s in got] == [("Brand Red", (48.0, 62.0, 38.0))]
    assert any("Only Spectral" in w for w in warnings)
    mine = [spot.Spot(n, lab) for n, lab in BRAND.items()]
    data = spot.write_cxf3(mine, "brand")
    assert b"http://colorexchangeformat.com/CxF3-core" in data and b"<cc:Illuminant>D50" in data
    back = spot.parse_cxf3(data)
    assert [(s.name, s.lab) for s in back] == [(s.name, s.lab) for s in mine]
    d65 = XRITE_CXF.replace(b">D50<", b">D65<")
    with pytest.raises(ValueError, match="D65"):
        spot.parse_cxf3(d65)
    # an object with a D65 and a D50 Lab: the D50 one is taken
    both = XRITE_CXF.replace(
        b'<cc:ColorCIELab ColorSpecification="CS1">',
        b'<cc:ColorCIELab ColorSpecification="CS65"><cc:L>1</cc:L><cc:A>2</cc:A><cc:B>3</cc:B></cc:ColorCIELab>'
        b'<cc:ColorCIELab ColorSpecification="CS1">').replace(
        b'<cc:ColorSpecificationCollection>',
        b'<cc:ColorSpecificationCollection><cc:ColorSpecification Id="CS65"><cc:TristimulusSpec>'
        b'<cc:Illuminant>D65</cc:Illuminant><cc:Observer>10_Degree</cc:Observer></cc:TristimulusSpec>'
        b'</cc:ColorSpecification>')
    assert [s.lab for s in spot.parse_cxf3(both)] == [(48.0, 62.0, 38.0)]


def test_cli_import_export_round_trip_and_name_matching(spots_dir, tmp_path, capsys):
    src = tmp_path / "brand.cxf"
    src.write_bytes(XRITE_CXF)
    assert main(["spot", "import", str(src)]) == 0
    txt = tmp_path / "more.txt"
    txt.write_text("Brand Teal: 55 -35 -12\n")
    assert main(["spot", "import", str(txt), "--library", "brand"]) == 0
    assert main(["spot", "import", str(txt), "--library", "other"]) == 2      # a clash
    assert "already in library 'brand'" in capsys.readouterr().err
    out_cxf, out_txt = tmp_path / "out.cxf", tmp_path / "out.txt"
    assert main(["spot", "export", "brand", "-o", str(out_cxf)]) == 0
    assert main(["spot", "export", "brand", "-o", str(out_txt)]) == 0
    assert {s.name: s.lab for s in spot.read_file(out_cxf)} == BRAND
    assert {s.name: s.lab for s in spot.read_file(out_txt)} == BRAND
    book = spot.SpotBook()
    assert book.find("brand_red").lab == BRAND["Brand Red"]          # case, '_' and blanks fold
    assert book.find("BRAND   TEAL").name == "Brand Teal"
    capsys.readouterr()
    assert main(["spot", "list", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [c["name"] for c in listed[0]["colours"]] == ["Brand Red", "Brand Teal"]
    assert main(["spot", "remove", "Brand Teal"]) == 0
    assert book.find("Brand Teal") is None


def test_resolution_through_the_media_profile_reports_the_gamut(spots_dir):
    book = _brand_library(spots_dir)
    book.add([spot.Spot("Too Blue", (30.0, 40.0, -95.0))], "brand")
    red = book.resolve("brand red", "vinyl-300", DEFAULT_OUTPUT_ICC)
    assert red.resolved == "library" and red.in_gamut and red.de2000 < 1.0
    back = spot.cmyk_to_lab(np.array([red.cmyk]), DEFAULT_OUTPUT_ICC)
    assert spot.delta_e2000(back, np.array([BRAND["Brand Red"]]))[0] == pytest.approx(red.de2000, abs=1e-3)
    blue = book.resolve("Too Blue", "vinyl-300", DEFAULT_OUTPUT_ICC)
    assert blue.resolved == "library" and not blue.in_gamut and blue.de2000 > 5
    assert book.resolve("Unknown 1", "vinyl-300", DEFAULT_OUTPUT_ICC).resolved == "alternate"
    assert book.resolve("Thru-cut", "vinyl-300", DEFAULT_OUTPUT_ICC).resolved == "cut"
    book.save_recipe("vinyl-300", "Brand Red", [0.0, 0.9, 0.7, 0.05], de2000=0.7, source="swatch")
    saved = book.resolve("BRAND RED", "vinyl-300", DEFAULT_OUTPUT_ICC)
    assert saved.resolved == "recipe" and saved.cmyk == (0.0, 0.9, 0.7, 0.05)
    assert book.resolve("Brand Red", "other-media", DEFAULT_OUTPUT_ICC).resolved == "library"


def test_spot_colour_math_agrees_with_the_emulators_de2000():
    rng = np.random.default_rng(3)
    a = np.column_stack([rng.uniform(5, 95, 50), rng.uniform(-80, 80, 50), rng.uniform(-80, 80, 50)])
    b = a + rng.normal(0, 4, a.shape)
    # libvips computes in float32; one pair sits near the hue mean's branch (0.007 apart)
    np.testing.assert_allclose(spot.delta_e2000(a, b), de2000_spectral(a, b), atol=0.01)


def _raster(path, settings=None) -> tuple[np.ndarray, list]:
    src = open_source(str(path), settings or RipSettings(), load_profile(None))
    try:
        return np.concatenate(list(src.bands(256))), src.spots
    finally:
        src.close()


def _rows(img, y_pt) -> slice:
    """The raster rows of page height y_pt (from the bottom)."""
    h = img.shape[0]
    r = int(round((H_PT - y_pt) / H_PT * h))
    return slice(r - 3, r + 4)


def test_pdf_spots_print_their_recipes_and_others_their_alternate(spots_dir, tmp_path):
    pdf = make_pdf(tmp_path / "spots.pdf")
    assert spot_names(str(pdf)).names == {"Brand Red": "separation", "Brand Teal": "separation",
                                          "Other Green": "separation", "CutContour": "cut"}
    plain, plain_spots = _raster(pdf)                 # empty library: alternates
    assert [s["resolved"] for s in plain_spots] == ["alternate"] * 3 + ["cut"]
    book = _brand_library(spots_dir)
    img, spots = _raster(pdf)
    by = {s["name"]: s for s in spots}
    assert by["Brand Red"]["resolved"] == by["Brand Teal"]["resolved"] == "library"
    assert by["Other Green"]["resolved"] == "alternate" and by["CutContour"]["resolved"] == "cut"
    h, w = img.shape[:2]
    for name, (x, y, rw, rh) in RECTS.items():
        cx, cy = int((x + rw / 2) / W_PT * w), int((H_PT - y - rh / 2) / H_PT * h)
        got = img[cy, cx]
        if name in BRAND:
            want = np.round(np.array(book.resolve(name, "vinyl-300", DEFAULT_OUTPUT_ICC).cmyk) * 255)
            assert np.abs(got.astype(int) - want).max() <= 1, name
            assert np.abs(got.astype(int) - plain[cy, cx]).max() > 20     # not the alternate
        else:                                          # the alternate, as today
            assert list(got) == [179, 0, 255, 0]
            assert np.array_equal(plain[cy - 20:cy + 20, cx - 20:cx + 20], img[cy - 20:cy + 20, cx - 20:cx + 20])
    # with the media's profile as the output profile the recipe is given in an ICCBased space
    # of that very profile: Ghostscript links it as the identity, so the same inks print
    icc_img, _ = _raster(pdf, RipSettings(output_icc=DEFAULT_OUTPUT_ICC))
    for name, (x, y, rw, rh) in RECTS.items():
        if name in BRAND:
            cx, cy = int((x + rw / 2) / W_PT * w), int((H_PT - y - rh / 2) / H_PT * h)
            assert np.array_equal(icc_img[cy, cx], img[cy, cx]), name


def test_a_document_without_library_or_cut_colours_is_not_rewritten(spots_dir, tmp_path):
    _brand_library(spots_dir)
    pdf = pikepdf.new()
    page = pdf.add_blank_page(page_size=(72, 72))
    page.Resources = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(CS0=pikepdf.Array([
        pikepdf.Name.Separation, pikepdf.Name("/Gold"), pikepdf.Name.DeviceCMYK,
        pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0], C1=[0, 0.2, 0.8, 0.1], N=1)])))
    page.Contents = pdf.make_stream(b"/CS0 cs 0.5 scn 10 10 52 52 re f")
    path = tmp_path / "gold.pdf"
    pdf.save(path)
    src = open_source(str(path), RipSettings(), load_profile(None))
    try:
        assert src.spot_plan.path == str(path) and src.spot_plan.folder is None
        assert src.spots[0]["name"] == "Gold" and src.spots[0]["resolved"] == "alternate"
        img = np.concatenate(list(src.bands(256)))
    finally:
        src.close()
    half = np.array([0, 0.2, 0.8, 0.1]) * 0.5 * 255             # half a tint of the alternate
    assert np.abs(img[img.shape[0] // 2, img.shape[1] // 2] - half).max() <= 0.5


def test_a_cut_line_neither_prints_nor_knocks_out(spots_dir, tmp_path):
    img, _ = _raster(make_pdf(tmp_path / "spots.pdf"))
    h, w = img.shape[:2]
    x0, x1 = int(25 / W_PT * w), int(190 / W_PT * w)
    over_paper = img[_rows(img, CUT_Y_PT + 70), x0:x1]      # above the background: blank paper
    assert over_paper.max() == 0
    # over the background and the spots: what lies under prints, the line does not
    under = img[_rows(img, CUT_Y_PT), x0:x1]
    above = img[_rows(img, CUT_Y_PT + 12), x0:x1]
    assert np.array_equal(under, above)


def test_printed_spots_measure_within_2_de2000_and_the_cut_line_drops_nothing(spots_dir, tmp_path, capsys):
    """The issue's must-show: on the emulator through the default media (vinyl-300), the
    spectrophotometer reads each library spot within ΔE2000 2 of its Lab; no drop lands
    under the 3 mm CutContour line; the report lists every spot and how it printed."""
    _brand_library(spots_dir)
    pdf = make_pdf(tmp_path / "spots.pdf")
    media, lab, report = tmp_path / "m.tif", tmp_path / "lab.tif", tmp_path / "r.json"
    assert main(["print", str(pdf), "--media-out", str(media), "--spectro-out", str(lab),
                 "--report", str(report)]) == 0
    said = capsys.readouterr().out
    assert "spots: Brand Red (library, ΔE 0." in said and "CutContour (cut: not printed)" in said
    rep = json.loads(report.read_text())[0]
    by = {s["name"]: s for s in rep["spots"]}
    assert {n: by[n]["resolved"] for n in by} == {"Brand Red": "library", "Brand Teal": "library",
                                                  "Other Green": "alternate", "CutContour": "cut"}
    rects = [(x * PT + 2, (H_PT - y - rh) * PT + 2, (x + rw) * PT - 2, (H_PT - y - rh) * PT + 10)
             for name, (x, y, rw, rh) in RECTS.items() if name in BRAND]
    measured = measure_patches(str(lab), rects, inset_mm=1.0)
    de = de2000_spectral(measured, np.array(list(BRAND.values())))
    assert de.max() <= 2.0, (measured, de)
    drops = read_planes(media)
    h = drops.shape[0]
    r = int(round((H_PT - CUT_Y_PT - 70) / H_PT * h))
    half = int(np.ceil(1.5 / 25.4 * 370.53)) + 2        # 1.5 mm each side, and a row more
    x0, x1 = int(22 / W_PT * drops.shape[1]), int(194 / W_PT * drops.shape[1])
    assert drops[r - half:r + half + 1, x0:x1].sum() == 0
    assert drops[:, x0:x1].sum() > 0                     # the rest of the page printed


def test_swatch_book_round_trip(spots_dir, capsys):
    """swatch -> measure -> pick -> recipe stored -> ΔE reported -> the job prints it."""
    _brand_library(spots_dir)
    assert main(["spot", "swatch", "Brand Red", "--json"]) == 0
    sw = json.loads(capsys.readouterr().out)
    assert sw["patches"] == 45 and sw["best_de2000"] <= sw["centre_de2000"] <= 2.0
    book = spot.SpotBook()
    data = book.swatch("vinyl-300", "Brand Red")
    lab = np.array([p["lab"] for p in data["patches"]])
    assert np.ptp(lab[:, 0]) > 4                 # the lightness steps printed apart
    assert main(["spot", "pick", "Brand Red", "--json"]) == 0
    picked = json.loads(capsys.readouterr().out)
    assert picked["de2000"] == sw["best_de2000"] and picked["patch"] == sw["best_patch"]
    rec = book.recipe("vinyl-300", "brand red")
    assert rec["cmyk"] == sw["best_cmyk"] and rec["source"] == "swatch"
    res = book.resolve("Brand Red", "vinyl-300", DEFAULT_OUTPUT_ICC)
    assert res.resolved == "recipe" and res.de2000 == picked["de2000"]
    assert main(["spot", "pick", "Brand Red", "--patch", "3"]) == 0
    assert "patch 3 stored" in capsys.readouterr().out
    assert main(["spot", "forget", "Brand Red"]) == 0
    assert book.resolve("Brand Red", "vinyl-300", DEFAULT_OUTPUT_ICC).resolved == "library"


def test_devicen_mixes_library_recipes_and_process_inks(spots_dir, tmp_path):
    """A DeviceN of a library colour and Black prints the recipe plus the black tint; one
    with a colorant in no library prints the library colour's recipe plus what its
    alternate prints for that colorant alone over tint 0 (this alternate is black at any
    tint: nothing; docs/spot.md "A DeviceN that mixes", tests/test_spot_devicen.py)."""
    book = _brand_library(spots_dir)
    pdf = pikepdf.new()
    page = pdf.add_blank_page(page_size=(144, 72))
    fn = pdf.make_stream(b"{ pop pop 0 0 0 1 }")          # the designer's alternate: black
    fn.FunctionType, fn.Domain, fn.Range = 4, [0, 1, 0, 1], [0, 1] * 4

    def devicen(*names):
        return pikepdf.Array([pikepdf.Name.DeviceN, pikepdf.Array([pikepdf.Name("/" + n) for n in names]),
                              pikepdf.Name.DeviceCMYK, fn])
    page.Resources = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(
        D0=devicen("Brand Red", "Black"), D1=devicen("Brand Teal", "Unknown X")))
    page.Contents = pdf.make_stream(b"/D0 cs 1 0.5 scn 0 0 72 72 re f /D1 cs 1 1 scn 72 0 72 72 re f")
    path = tmp_path / "devicen.pdf"
    pdf.save(path)
    img, spots = _raster(path)
    assert {s["name"]: s["resolved"] for s in spots} == {"Brand Red": "library", "Brand Teal": "library",
                                                         "Unknown X": "alternate"}
    h, w = img.shape[:2]
    red = np.array(book.resolve("Brand Red", "vinyl-300", DEFAULT_OUTPUT_ICC).cmyk) + [0, 0, 0, 0.5]
    assert np.abs(img[h // 2, w // 4] - red * 255).max() <= 1
    teal = np.array(book.resolve("Brand Teal", "vinyl-300", DEFAULT_OUTPUT_ICC).cmyk)
    assert np.abs(img[h // 2, 3 * w // 4] - teal * 255).max() <= 1


def test_postscript_spots_go_the_same_way(spots_dir, tmp_path):
    book = _brand_library(spots_dir)
    ps = tmp_path / "spots.ps"
    ps.write_text("%!PS-Adobe-3.0\n<< /PageSize [216 144] >> setpagedevice\n"
                  "0.2 0.2 0.2 0.2 setcmykcolor 0 0 216 144 rectfill\n"
                  "[/Separation (Brand Red) /DeviceCMYK {dup 0 exch 0.5 mul 0}] setcolorspace 1 setcolor "
                  "10 10 60 124 rectfill\n"
                  "[/Separation /CutContour /DeviceCMYK {0 exch 0 0}] setcolorspace 1 setcolor "
                  "8.5 setlinewidth 30 72 moveto 186 72 lineto stroke\nshowpage\n")
    img, spots = _raster(ps)
    assert {s["name"]: s["resolved"] for s in spots} == {"Brand Red": "library", "CutContour": "cut"}
    h, w = img.shape[:2]
    want = np.round(np.array(book.resolve("Brand Red", "vinyl-300", DEFAULT_OUTPUT_ICC).cmyk) * 255)
    assert np.abs(img[h // 2, int(40 / 216 * w)].astype(int) - want).max() <= 1
    assert (img[h // 2 - 10: h // 2 + 10, int(100 / 216 * w):int(180 / 216 * w)] == 51).all()


def test_cut_colour_in_forms_text_and_fill_and_stroke(spots_dir, tmp_path):
    """A form's cut stroke and fill, text shown in a cut colour (its advance kept) and the
    stroke half of a fill-and-stroke (`B`) print nothing; what else they hold prints."""
    pdf = pikepdf.new()
    page = pdf.add_blank_page(page_size=(216, 144))
    fn = pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0], C1=[0, 1, 0, 0], N=1)
    cut = pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/Thru-cut"), pikepdf.Name.DeviceCMYK, fn])
    form = pikepdf.Stream(pdf, b"/C CS 1 SCN 6 w 10 10 m 100 10 l S /C cs 1 scn 10 30 50 20 re f "
                               b"0 0 1 0 k 10 60 20 20 re B")
    form.Type, form.Subtype, form.BBox = pikepdf.Name.XObject, pikepdf.Name.Form, [0, 0, 216, 144]
    form.Resources = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(C=cut))
    font = pikepdf.Dictionary(Type=pikepdf.Name.Font, Subtype=pikepdf.Name.Type1, BaseFont=pikepdf.Name.Helvetica)
    page.Resources = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(C=cut), Font=pikepdf.Dictionary(F1=font),
                                        XObject=pikepdf.Dictionary(F0=pdf.make_indirect(form)))
    page.Contents = pdf.make_stream(b"0.5 0 0 0 k 100 70 116 50 re f q /F0 Do Q "
                                    b"BT /F1 40 Tf /C cs 1 scn 110 80 Td (CUT) Tj 0 0 0 1 k (K) Tj ET")
    path = tmp_path / "cut.pdf"
    pdf.save(path)
    img, spots = _raster(path)
    assert [(s["name"], s["resolved"]) for s in spots] == [("Thru-cut", "cut")]
    assert (img[..., 1] == 0).all()                       # the cut colour's magenta nowhere
    h, w = img.shape[:2]
    y_rows = np.nonzero(img[..., 2].any(axis=1))[0]        # B's fill kept, its cut stroke not
    assert len(y_rows) == pytest.approx(20 / 144 * h, abs=2)
    # the cut text leaves the cyan under it as it is, and "K" prints after its advance
    # (Helvetica C, U, T at 40 pt: 82.2 pt; K starts 3 pt in), also through the media's profile
    for im in (img, _raster(path, RipSettings(output_icc=DEFAULT_OUTPUT_ICC))[0]):
        under = im[int((144 - 118) / 144 * h):int((144 - 72) / 144 * h), int(112 / 216 * w):int(190 / 216 * w)]
        assert (under == under[0, 0]).all() and under[0, 0, 0] > 100
        assert np.nonzero(im[..., 3].any(axis=0))[0].min() == pytest.approx((110 + 82.2 + 3) / 216 * w, abs=3)


def test_a_program_setting_its_spot_at_every_object_probes_each_name_once(tmp_path):
    """Illustrator's PostScript sets the colour space at every object: the probe names each
    spot once, so the page sizes (in the probe's first 64 KiB of output) are still read."""
    from wideprint.rip.ghostscript import probe
    ps = tmp_path / "many.ps"
    ps.write_text("%!PS\n<< /PageSize [216 144] >> setpagedevice\n"
                  + "[/Separation (Brand Red) /DeviceCMYK {dup 0 exch 0.5 mul 0}] setcolorspace 0.5 setcolor "
                    "10 10 60 124 rectfill\n" * 2000          # 90 KB of output if each were said
                  + "[/DeviceN [/Cyan /Spot2] /DeviceCMYK {pop 0 0 0}] setcolorspace 1 1 setcolor "
                    "80 10 20 20 rectfill\nshowpage\n")
    seen: dict[str, str] = {}
    pages, _ = probe(str(ps), "ps", "crop", spots=seen)
    assert [(p.width_pt, p.height_pt) for p in pages] == [(216.0, 144.0)]
    assert seen == {"Brand Red": "separation", "Cyan": "devicen", "Spot2": "devicen"}
