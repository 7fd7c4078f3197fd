"""PDF, PostScript and EPS through Ghostscript (docs/documents.md): rendered straight onto
the device grid, printed on the emulator bit for bit like the same page rendered to a
TIFF, colour through the RIP's ICC path, page boxes, pages, placement, and hostile files
contained with Ghostscript's reason in plain words."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest
import tifffile

from support.images import ROOT  # noqa: F401
from wideprint.rip import ghostscript as G
from wideprint.rip.document import DocumentSource
from wideprint.rip.inputs import sniff_input
from wideprint.rip.load import ImageError
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes
from wideprint.rip.settings import Placement



@pytest.fixture(autouse=True)
def _ghostscript():
    """Ghostscript is a dependency of the product (resources/debian-packages.txt, installed
    by .ci/run): without it these tests fail, loudly, rather than skip."""
    if not any(os.access(os.path.join(p, "gs"), os.X_OK)
               for p in os.environ.get("PATH", "").split(os.pathsep)):
        pytest.fail("Ghostscript (gs) is not installed: apt-get install ghostscript "
                    "(.ci/run does)")

YPI = 25400 / 68.55                      # the default profile's rows per inch
RES = f"-r300x{YPI:.6f}"                 # the device grid at 300 dpi, as Ghostscript takes it
EXE = [sys.executable, "-m", "wideprint.app.cli"]

# shapes and text: CMYK, RGB and grey fills, hairlines, curves, a standard font and the
# document's own (Type 3) font.  Device colours are multiples of 0.2: x * 255 is a whole
# level, so no interpreter's rounding of a half level shows (PostScript's 0.1 K is 25,
# the PDF interpreter's 26)
PAGE = b"""
0.2 0.4 0.6 0.2 setcmykcolor 10 10 60 40 rectfill
1 0 0 setrgbcolor 80 10 moveto 140 10 lineto 110 60 lineto closepath fill
0.6 setgray 0.3 setlinewidth 5 70 moveto 139 95 lineto stroke
0 0.8 0.2 setrgbcolor newpath 40 80 18 0 360 arc fill
0 0 0 1 setcmykcolor /Times-Roman findfont 14 scalefont setfont 66 72 moveto (Wide 3.4) show
8 dict begin /FontType 3 def /FontMatrix [0.001 0 0 0.001 0 0] def /FontBBox [0 0 1000 1000] def
/Encoding 256 array def 0 1 255 { Encoding exch /.notdef put } for Encoding 65 /box put
/CharProcs 2 dict def CharProcs begin /.notdef {} def /box { 100 0 moveto 900 0 lineto 500 900 lineto
closepath fill } def end
/BuildGlyph { 1000 0 0 0 1000 1000 setcachedevice exch /CharProcs get exch get exec } def
/BuildChar { 1 index /Encoding get exch get 1 index /BuildGlyph get exec } def
currentdict end /WPTriangles exch definefont pop
0 0 1 0 setcmykcolor /WPTriangles findfont 12 scalefont setfont 100 90 moveto (AAA) show
"""


def write_ps(path, body: bytes = PAGE, size=(144, 108), pages: int = 1, eps: bool = False):
    w, h = size
    if eps:
        head = b"%%!PS-Adobe-3.0 EPSF-3.0\n%%%%BoundingBox: 0 0 %d %d\n%%%%EndComments\n" % (w, h)
        path.write_bytes(head + body + b"showpage\n")
        return path
    out = b"%!PS-Adobe-3.0\n"
    for i in range(pages):
        out += b"<< /PageSize [%d %d] >> setpagedevice\n" % (w, h) + body + b"showpage\n"
    path.write_bytes(out)
    return path


def make_pdf(ps, pdf):
    """ps2pdf, fonts embedded (prepress settings: even the standard 14)."""
    subprocess.run(["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pdfwrite", "-dCompatibilityLevel=1.4",
                    "-dPDFSETTINGS=/prepress", f"-sOutputFile={pdf}", str(ps)], check=True, capture_output=True)
    return pdf


def colour_flags(intent: int = 1):
    """The RIP's default ICC set-up (rip/color/), spelt out for a plain Ghostscript run."""
    cmyk, srgb = G.builtin_profile("cmyk"), G.builtin_profile("srgb")
    return [f"-sDefaultRGBProfile={srgb}", f"-sDefaultCMYKProfile={cmyk}", f"-sOutputICCProfile={cmyk}",
            f"-dRenderIntent={intent}", "-dOverrideRI", "-dBlackPtComp=0"]


def gs_tiff(src, out, *extra):
    """The page as a CMYK TIFF on the device grid, by Ghostscript alone (no wideprint code)."""
    subprocess.run(["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=tiff32nc", RES, *colour_flags(),
                    *extra, f"-sOutputFile={out}", str(src)], check=True, capture_output=True)
    return out


def gs_raw(src, device, *extra) -> np.ndarray:
    """A page rendered by Ghostscript to a PAM/PPM on stdout, as an array."""
    data = subprocess.run(["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", f"-sDEVICE={device}", "-sOutputFile=-",
                           *extra, str(src)], check=True, capture_output=True).stdout
    if data.startswith(b"P7"):
        end = data.index(b"ENDHDR\n") + 7
        head = dict(ln.split() for ln in data[:end].decode().splitlines()[1:-1] if not ln.startswith("#"))
        w, h, c = int(head["WIDTH"]), int(head["HEIGHT"]), int(head["DEPTH"])
        return np.frombuffer(data[end:end + w * h * c], np.uint8).reshape(h, w, c)
    parts = data.split(b"\n", 4)         # P6 / comment / w h / 255 / data
    w, h = map(int, parts[2].split())
    return np.frombuffer(parts[4][: w * h * 3], np.uint8).reshape(h, w, 3)


def rip_source(path, profile, **placement) -> DocumentSource:
    job = RipJob(str(path), RipSettings(placement=Placement(**placement)), profile)
    return job.source


def all_bands(src, rows=37) -> np.ndarray:
    return np.concatenate(list(src.bands(rows)), axis=0)


@pytest.fixture(scope="module")
def docs(tmp_path_factory):
    d = tmp_path_factory.mktemp("docs")
    ps = write_ps(d / "page.ps")
    eps = write_ps(d / "page.eps", eps=True)
    pdf = make_pdf(ps, d / "page.pdf")
    return {"ps": ps, "eps": eps, "pdf": pdf, "dir": d}


# -- detection ------------------------------------------------------------------------------------
def test_formats_are_sniffed_by_content_not_name(docs, tmp_path):
    assert sniff_input(docs["pdf"]) == "pdf" and sniff_input(docs["ps"]) == "ps"
    assert sniff_input(docs["eps"]) == "eps"
    disguised = tmp_path / "poster.jpg"
    disguised.write_bytes(docs["pdf"].read_bytes())
    assert sniff_input(disguised) == "pdf"
    dos = tmp_path / "dos.eps"                       # DOS EPS binary header
    dos.write_bytes(b"\xc5\xd0\xd3\xc6" + bytes(28) + docs["eps"].read_bytes())
    assert sniff_input(dos) == "eps"
    rtl = tmp_path / "a.prn"
    rtl.write_bytes(b"\x1bE\x1b*r100S")
    assert sniff_input(rtl) == "rtl"
    tif = tmp_path / "a.pdf"                         # a TIFF named .pdf stays a TIFF
    tifffile.imwrite(tif, np.zeros((4, 4, 3), np.uint8))
    assert sniff_input(tif) == "image"


# -- the same page, printed as a document and as a TIFF ------------------------------------------
@pytest.mark.parametrize("kind", ["pdf", "eps", "ps"])
def test_document_prints_bit_exact_like_its_page_rendered_to_tiff(docs, tmp_path, kind):
    src = docs[kind]
    ref = gs_tiff(src, tmp_path / "ref.tif", *(["-dEPSCrop"] if kind == "eps" else []))
    opts = ["--ink-limit", "400", "--dither", "fs"]      # CMYK files print as they are
    a, b = tmp_path / "doc-media.tif", tmp_path / "tif-media.tif"
    r = subprocess.run(EXE + ["print", str(src), "--media-out", str(a), "--json"] + opts,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    r2 = subprocess.run(EXE + ["print", str(ref), "--size", "pixels", "--media-out", str(b)] + opts,
                        capture_output=True, text=True)
    assert r2.returncode == 0, r2.stderr
    doc, tif = read_planes(a), read_planes(b)
    assert doc.shape == (556, 600, 4)                   # 2 x 1.5 in at 300 x 370.53 dpi
    assert np.array_equal(doc, tif)
    assert doc[..., 3].sum() > 500 and doc[..., 0].sum() > 500     # text and fills landed
    rep = json.loads(r.stdout)[0]
    assert rep["state"] == "done" and rep["stray_drops"] == 0


def test_pdf_eps_ps_render_the_same_page(docs, profile):
    """Vector content and the font come out the same from all three (the PDF's font is the
    embedded subset pdfwrite made)."""
    pdf = docs["pdf"].read_bytes()
    assert b"/FontFile" in pdf and b"/Type3" in pdf         # Times-Roman and the document's own font
    pages = {k: all_bands(rip_source(docs[k], profile)) for k in ("pdf", "eps", "ps")}
    assert np.array_equal(pages["pdf"], pages["ps"])
    assert np.array_equal(pages["eps"], pages["ps"])


def test_vector_edges_are_sharp_at_device_resolution(tmp_path, profile):
    """A rectangle from 1 in to 2 in across and 0.5 in to 1 in up lands on those columns
    and rows of the anisotropic grid (300 per inch across, 370.53 along), with no
    anti-aliasing: every dot full or empty."""
    ps = write_ps(tmp_path / "r.ps", b"0 0 0 1 setcmykcolor 72 36 72 36 rectfill\n", size=(216, 108))
    page = all_bands(rip_source(ps, profile))
    k = page[..., 3]
    assert set(np.unique(k)) == {0, 255}
    cols = np.nonzero(k.any(axis=0))[0]
    rows = np.nonzero(k.any(axis=1))[0]
    # Ghostscript's fill rule may take the pixel a boundary touches: within one dot
    assert abs(cols[0] - 300) <= 1 and abs(cols[-1] - 599) <= 1
    h = page.shape[0]                                     # 1.5 in: 556 rows; y up from the bottom
    assert abs(rows[0] - (h - round(YPI))) <= 1 and abs(rows[-1] - (h - round(YPI / 2) - 1)) <= 1
    assert len(cols) == 300 + (cols[0] == 299) + (cols[-1] == 600)


def test_colour_cmyk_kept_grey_to_k_rgb_through_the_rips_icc_path(tmp_path, profile):
    from wideprint.rip.color import Separator
    body = (b"0.2 0.4 0.6 0.2 setcmykcolor 0 0 36 36 rectfill 0.8 setgray 36 0 36 36 rectfill\n"
            b"0 1 99 { /i exch def i 99 div 0.3 1 i 99 div sub setrgbcolor i 36 1 36 rectfill } for\n")
    ps = write_ps(tmp_path / "c.ps", body, size=(100, 72))
    page = all_bands(rip_source(ps, profile))
    h = page.shape[0]
    assert tuple(page[h - 20, 20]) == (51, 102, 153, 51)           # DeviceCMYK: unchanged
    assert tuple(page[h - 20, 200]) == (0, 0, 0, 51)               # DeviceGray: K only, 1 - grey
    # RGB: Ghostscript's lcms with the RIP's profiles and intent = the RIP's own separation
    rgb = gs_raw(ps, "ppmraw", RES, f"-sDefaultRGBProfile={G.builtin_profile('srgb')}",
                 f"-sOutputICCProfile={G.builtin_profile('srgb')}")
    top = slice(0, h - round(36 * YPI / 72) - 2)
    ours = Separator("rgb", 8).convert(np.ascontiguousarray(rgb[top]))
    d = np.abs(ours.astype(int) - page[top].astype(int))
    assert d.max() <= 6 and d.mean() < 1.0


def test_rgb_content_gets_the_profiles_ink_limit_unless_overridden(tmp_path, profile):
    ps = write_ps(tmp_path / "k.ps", b"0 0 0 setrgbcolor 0 0 72 72 rectfill\n", size=(72, 72))
    job = RipJob(str(ps), RipSettings(), profile)
    assert job.ink_limit == profile.color.ink_limit_percent
    ink = job._separator().convert(next(iter(job.source.bands(8))))
    assert int(ink[0, 0].astype(int).sum()) <= int(profile.color.ink_limit_percent * 2.55) + 1
    assert RipJob(str(ps), RipSettings(ink_limit=400), profile).ink_limit == 400


# -- page boxes, pages, placement ----------------------------------------------------------------
@pytest.fixture(scope="module")
def boxed(tmp_path_factory):
    d = tmp_path_factory.mktemp("boxes")
    ps = d / "boxes.ps"
    ps.write_bytes(b"%!PS\n<< /PageSize [300 200] >> setpagedevice\n"
                   b"[ /CropBox [10 10 290 190] /TrimBox [20 20 280 180] /PAGE pdfmark\n"
                   b"0 0 1 0 setcmykcolor 0 0 300 200 rectfill\n"
                   b"0 0 0 1 setcmykcolor 20 20 10 10 rectfill showpage\n"
                   b"<< /PageSize [400 100] >> setpagedevice 1 0 0 0 setcmykcolor 0 0 400 100 rectfill showpage\n")
    return make_pdf(ps, d / "boxes.pdf")


def _k_corner(page):
    k = np.argwhere(page[..., 3] > 0)
    return tuple(k.min(axis=0)), tuple(k.max(axis=0))


@pytest.mark.parametrize("box, size_pt, corner_pt", [
    ("crop", (280, 180), (10, 10)), ("trim", (260, 160), (0, 0)), ("media", (300, 200), (20, 20)),
    ("art", (280, 180), (10, 10)),          # no ArtBox: the CropBox
])
def test_page_box(boxed, profile, box, size_pt, corner_pt):
    src = rip_source(boxed, profile, page_box=box, pages="1")
    w, h = round(size_pt[0] / 72 * 300), round(size_pt[1] / 72 * YPI)
    assert (src.width, src.height) == (w, h)
    page = all_bands(src)
    (r0, c0), (r1, c1) = _k_corner(page)
    assert abs(c0 - corner_pt[0] / 72 * 300) <= 1                       # Ghostscript's fill rule: 1 dot
    assert abs(r1 - (h - 1 - corner_pt[1] / 72 * YPI)) <= 1
    assert src.pages[0][0].box == ("crop" if box == "art" else box)


def test_pages_print_one_after_another_along_the_roll(boxed, profile):
    src = rip_source(boxed, profile, page_gap_mm=5)
    w1, h1 = round(280 / 72 * 300), round(180 / 72 * YPI)
    w2, h2 = round(400 / 72 * 300), round(100 / 72 * YPI)
    gap = round(5000 / 68.55)
    assert (src.width, src.height) == (max(w1, w2), h1 + gap + h2)
    page = all_bands(src, rows=50)
    assert page[:h1, :w1, 2].mean() > 250 and not page[:h1, w1:].any()   # page 1 yellow, left
    assert not page[h1:h1 + gap].any()                                   # the gap: blank paper
    assert page[h1 + gap:, :w2, 0].all()                                  # page 2 cyan
    only2 = rip_source(boxed, profile, pages="2")
    assert (only2.width, only2.height) == (w2, h2)
    with pytest.raises(ImageError, match="pages 3: the document has 2 pages"):
        rip_source(boxed, profile, pages="3")
    with pytest.raises(ValueError, match="pages must be like"):
        rip_source(boxed, profile, pages="two")


def test_size_options_render_at_the_final_resolution(docs, profile):
    src = rip_source(docs["pdf"], profile, width_mm=254)                  # 10 in wide
    assert (src.width, src.height) == (3000, round(7.5 * YPI))
    p0 = src.pages[0][1]
    assert abs(p0.xres - 1500) < 1e-6 and abs(p0.yres - 5 * YPI) < 1e-6   # rendered, not resampled
    big = all_bands(src, rows=256)
    assert set(np.unique(big[..., 3])) <= {0, 51, 102, 255}                  # no anti-aliased edges


def test_rotation_turns_each_page(tmp_path, profile):
    ps = write_ps(tmp_path / "t.ps", b"0 0 0 1 setcmykcolor 0 72 36 36 rectfill\n", size=(144, 108))
    src = rip_source(ps, profile, rotate=90)
    assert (src.width, src.height) == (round(1.5 * 300), round(2 * YPI))
    page = all_bands(src)
    (r0, c0), (r1, c1) = _k_corner(page)
    # the page's top-left corner goes to the top-right at 90 degrees clockwise
    assert r0 == 0 and c1 == src.width - 1
    assert abs((r1 + 1) - YPI / 2) <= 1 and abs((src.width - c0) - 150) <= 1
    mirrored = all_bands(rip_source(ps, profile, rotate=90, mirror=True))
    assert np.array_equal(mirrored, page[:, ::-1])


def test_pdf_rotate_and_userunit(tmp_path, profile):
    def mkpdf(path, extra):
        objs = [b"<< /Type /Catalog /Pages 2 0 R >>", b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
                b"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 200 100] " + extra + b" /Contents 4 0 R >>",
                b"<< /Length 28 >>\nstream\n0 0 0 1 k 0 0 20 20 re f\n\nendstream"]
        out, offs = bytearray(b"%PDF-1.6\n"), []
        for i, o in enumerate(objs):
            offs.append(len(out))
            out += b"%d 0 obj\n" % (i + 1) + o + b"\nendobj\n"
        x = len(out)
        out += b"xref\n0 5\n0000000000 65535 f \n" + b"".join(b"%010d 00000 n \n" % o for o in offs)
        out += b"trailer\n<< /Size 5 /Root 1 0 R >>\nstartxref\n%d\n%%%%EOF\n" % x
        path.write_bytes(bytes(out))
        return path
    src = rip_source(mkpdf(tmp_path / "r.pdf", b"/Rotate 90 /UserUnit 2"), profile)
    assert (src.width, src.height) == (round(200 / 72 * 300), round(400 / 72 * YPI))
    assert all_bands(src)[..., 3].any()


# -- containment -----------------------------------------------------------------------------------
def _fails(path, profile, match, **kw):
    t0 = time.monotonic()
    with pytest.raises(ImageError, match=match) as e:
        job = RipJob(str(path), RipSettings(**kw), profile)
        for _ in job.source.bands(64):
            pass
    assert e.value.path == str(path)
    return time.monotonic() - t0, str(e.value)


def test_endless_loop_is_killed(tmp_path, profile, monkeypatch):
    monkeypatch.setattr(G, "PROBE_CPU_S", 2.0)
    p = tmp_path / "loop.ps"
    p.write_bytes(b"%!PS\n<< /PageSize [100 100] >> setpagedevice showpage\n{} loop\n")
    took, msg = _fails(p, profile, "stopped after 2 s of processor time while reading the document")
    assert took < 20 and "endless loop" in msg


def test_loop_only_when_rendering_is_killed_too(tmp_path, profile, monkeypatch):
    """A program that behaves on the probe and loops on the real device: the render's own
    processor-time limit stops it."""
    monkeypatch.setenv("WIDEPRINT_GS_CPU_S", "2")
    p = tmp_path / "sly.ps"
    p.write_bytes(b"%!PS\n<< /PageSize [100 100] >> setpagedevice\n"
                  b"currentpagedevice /OutputDevice get /nullpage ne { {} loop } if showpage\n")
    took, msg = _fails(p, profile, "stopped after 2 s of processor time while rendering page 1")
    assert took < 20


def test_file_operators_are_refused(tmp_path, profile):
    secret = tmp_path / "secret.txt"
    secret.write_text("x")
    p = tmp_path / "read.ps"
    p.write_bytes(b"%%!PS\n(%s) (r) file showpage\n" % str(secret).encode())
    _fails(p, profile, r"PostScript error /invalidfileaccess in --file--: .*refused \(Ghostscript runs with -dSAFER\)")
    import tempfile
    target = os.path.join(tempfile.gettempdir(), f"wideprint-owned-{os.getpid()}.txt")
    for name in (target, str(tmp_path / "owned.txt")):
        p = tmp_path / "write.ps"
        p.write_bytes(b"%%!PS\n(%s) (w) file (x) writestring showpage\n" % name.encode())
        _fails(p, profile, "invalidfileaccess")
        assert not os.path.exists(name)
    p = tmp_path / "pipe.ps"
    p.write_bytes(b"%!PS\n(%pipe%touch owned) (r) file showpage\n")
    _fails(p, profile, "invalidfileaccess")


@pytest.mark.parametrize("size, match", [
    (b"1e7 1e7", r"page size 1e\+07 x 1e\+07 pt \(3527.78 x 3527.78 m\) is refused"),
    (b"90000 500", r"page 1 would be 31750 mm wide on the media, more than the printer's 3400 mm"),
    (b"500 300000", r"more than the limit of 1,000,000 per side"),
])
def test_huge_pages_are_refused_before_rendering(tmp_path, profile, size, match, monkeypatch):
    rendered = []
    monkeypatch.setattr(G, "render_page", lambda *a, **k: rendered.append(a))
    p = tmp_path / "huge.ps"
    p.write_bytes(b"%!PS\n<< /PageSize [" + size + b"] >> setpagedevice showpage\n")
    with pytest.raises(ImageError, match=match):
        RipJob(str(p), RipSettings(dpi=600), profile)
    assert not rendered


def test_postscript_and_pdf_errors_in_plain_words(tmp_path, profile):
    p = tmp_path / "undef.ps"
    p.write_bytes(b"%!PS\n/Helvetica findfont 12 scalefont setfont nosuchcommand\nshowpage\n")
    _fails(p, profile, "PostScript error /undefined in nosuchcommand: the document uses the name "
                       "nosuchcommand, which is not defined")
    p = tmp_path / "empty.ps"
    p.write_bytes(b"%!PS\n% draws nothing and never calls showpage\n")
    _fails(p, profile, r"nothing to print: the PostScript program produced no page \(no showpage\)")
    p = tmp_path / "broken.pdf"
    p.write_bytes(b"%PDF-1.4\n1 0 obj << /Type /Catalog >> endobj\ntrailer << >>\n%%EOF\n")
    _fails(p, profile, "PDF")
    assert "Unrecoverable" not in G.explain("Error: /syntaxerror in --token--\nGPL Ghostscript 10: "
                                            "Unrecoverable error, exit code 1", 1)


def test_a_bad_document_fails_only_its_job(docs, tmp_path):
    bad = tmp_path / "bad.ps"
    bad.write_bytes(b"%!PS\nfoo\n")
    r = subprocess.run(EXE + ["print", str(bad), str(docs["eps"]), "--media-out", str(tmp_path / "m.tif"),
                              "--json"], capture_output=True, text=True)
    assert r.returncode == 1
    assert "bad.ps: FAILED" in r.stderr and "PostScript error /undefined in foo" in r.stderr
    assert [x["state"] for x in json.loads(r.stdout)] == ["failed", "done"]
    assert read_planes(tmp_path / "m-2.tif").shape == (556, 600, 4)


def test_ghostscript_is_killed_when_the_consumer_stops(docs, profile):
    import gc
    src = rip_source(docs["pdf"], profile)
    it = src.bands(8)
    next(it)
    it.close()                               # the job was cancelled
    gc.collect()
    left = [d for d in os.listdir("/proc") if d.isdigit() and _is_our_gs(d)]
    assert not left


def _is_our_gs(pid: str) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        with open(f"/proc/{pid}/comm") as f:
            return ppid == os.getpid() and f.read().strip() == "gs"
    except (OSError, ValueError, IndexError):
        return False


def test_memory_is_bounded_by_the_band_not_the_page(tmp_path):
    """A 3.2 m x 1 m page at 150 dpi is 18,898 x 14,590 dots (1.1 GB as CMYK): streaming it
    costs the process a few bands."""
    ps = tmp_path / "banner.ps"
    ps.write_bytes(b"%!PS\n<< /PageSize [9071 2835] >> setpagedevice\n"
                   b"0 100 9000 { /x exch def x 9071 div 0 0.5 0 setcmykcolor x 0 50 2835 rectfill } for\n"
                   b"showpage\n")
    code = f"""
import resource, sys
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.profile import load_profile
job = RipJob({str(ps)!r}, RipSettings(dpi=150), load_profile())
assert (job.width, job.height) == (18898, 14590), (job.width, job.height)
next(iter(job.source.bands(64)))
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
n = 0
for band in job.source.bands(64):
    n += band.shape[0]
assert n == 14590
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) // 1024,
      resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss // 1024)
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    grew, gs_peak = map(int, r.stdout.split())
    print(f"peak RSS growth {grew} MB, Ghostscript peak {gs_peak} MB")
    assert grew < 60, f"peak RSS grew {grew} MB"
    assert gs_peak < 300, f"Ghostscript peaked at {gs_peak} MB"
