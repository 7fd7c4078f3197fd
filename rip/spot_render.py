"""A document's spot colours resolved for its job, and the file Ghostscript renders
(docs/spot.md "Rendering").

`prepare(path, fmt, settings, spot_names)` resolves every spot name the document uses on
the job's media (rip/spot.py) and, when one is a library colour or a cut colour, writes
the rewritten copy (rip/spot_pdf.py) into a private temporary folder; PostScript and EPS
are first distilled to PDF by Ghostscript's pdfwrite, which keeps Separation and DeviceN.
A document with neither is rendered from the original file, exactly as before.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field

from .color import DEFAULT_OUTPUT_ICC
from .load import ImageError
from .spot import DEFAULT_MEDIA, SpotBook
from .spot_pdf import PROCESS

__all__ = ["SpotPlan", "prepare", "resolve_names", "file_spots", "job_spots"]


@dataclass
class SpotPlan:
    """What the render uses: the file and format to give Ghostscript, and the report."""
    path: str
    fmt: str
    spots: list[dict] = field(default_factory=list)
    folder: str | None = None          # the private copy's folder, removed by close()
    warnings: list[str] = field(default_factory=list)

    def close(self) -> None:
        if self.folder:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None


def job_media(settings) -> tuple[str | None, str | None]:
    """(media name for saved recipes, ICC the Lab goes through) of a job: its media and
    output profile; with neither, the shipped default media's."""
    media = getattr(settings, "media", None)
    icc = settings.output_icc
    if media:
        return media, icc or DEFAULT_OUTPUT_ICC
    if icc:
        return None, icc
    return DEFAULT_MEDIA, DEFAULT_OUTPUT_ICC if os.path.isfile(DEFAULT_OUTPUT_ICC) else None


#: tints at which a colorant in no library is sampled alone (a DeviceN that mixes, docs/spot.md)
ALONE_SAMPLES = 17
_PATCH_PT = 4


def sampler(settings, folder: str):
    """`sample_alone(pdf, space, indices)` for rip/spot_pdf.rewrite: each listed colorant of a
    DeviceN space painted alone (the others at tint 0) at ALONE_SAMPLES even tints, rendered
    by Ghostscript exactly as the job renders the document (its colour conversions: the
    alternate space through the job's output profile), read back as ink fractions, less
    what tint 0 prints: {index: (S, 4) array}."""
    def sample_alone(pdf, space, indices: list[int]) -> dict:
        import numpy as np
        import pikepdf

        from .ghostscript import GsPage, colour_args, render_page
        n, S, P = len(space[1]), ALONE_SAMPLES, _PATCH_PT
        out = pikepdf.new()
        src = space if space.is_indirect else pdf.make_indirect(space)
        page = out.add_blank_page(page_size=(S * P, len(indices) * P))
        page.Resources = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(D0=out.copy_foreign(src)))
        body = ["/D0 cs"]
        for r, i in enumerate(indices):
            y = (len(indices) - 1 - r) * P
            for k in range(S):
                tints = ["0"] * n
                tints[i] = f"{k / (S - 1):.6f}"
                body.append(f"{' '.join(tints)} scn {k * P} {y} {P} {P} re f")
        page.Contents = out.make_stream("\n".join(body).encode())
        path = os.path.join(folder, f"alone-{len(os.listdir(folder))}.pdf")
        out.save(path)
        colour = colour_args(settings.input_icc, settings.output_icc, settings.intent)
        w, h = S * P, len(indices) * P
        img = np.concatenate(list(render_page(path, "pdf", GsPage(1, w, h), w, h, 72.0, 72.0,
                                              colour, h)))
        res = {}
        for r, i in enumerate(indices):
            inks = img[r * P + P // 2, P // 2::P][:S].astype(np.float64) / 255.0
            res[i] = np.clip(inks - inks[0], 0.0, 1.0)
        return res
    return sample_alone


def _distil(path: str, fmt: str, folder: str) -> str:
    """PostScript/EPS -> PDF (Ghostscript pdfwrite: Separation and DeviceN kept)."""
    from .ghostscript import _env, gs_path
    out = os.path.join(folder, "distilled.pdf")
    args = [gs_path(), "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pdfwrite",
            "-dAutoRotatePages=/None", "-dCompatibilityLevel=1.7",
            "-sColorConversionStrategy=LeaveColorUnchanged", "-dDownsampleColorImages=false",
            "-dDownsampleGrayImages=false", "-dDownsampleMonoImages=false",
            "-dAutoFilterColorImages=false", "-dColorImageFilter=/FlateEncode",
            "-dAutoFilterGrayImages=false", "-dGrayImageFilter=/FlateEncode",
            f"-sOutputFile={out}"]
    if fmt == "eps":
        args.append("-dEPSCrop")
    done = subprocess.run([*args, "-f", os.path.abspath(path)], env=_env(folder), cwd=folder,
                          capture_output=True, timeout=600)
    if done.returncode != 0 or not os.path.isfile(out):
        raise ImageError(path, "Ghostscript could not distil the document to PDF for its spot "
                               f"colours: {done.stderr.decode('latin-1', 'replace').strip()[-200:]}")
    return out


def resolve_names(names: dict[str, str] | None, settings, book: SpotBook | None = None):
    """(name -> Resolved, the report's entries) of the spot names a document uses (name ->
    kind) on the job's media, by the job's spot library (a server's: settings.spot_dir)."""
    names = {n: k for n, k in (names or {}).items()       # a DeviceN's process inks are no spots
             if not (k == "devicen" and n.casefold() in PROCESS)}
    if not names:
        return {}, []
    book = book or SpotBook(getattr(settings, "spot_dir", None))   # a server's (STATE/spots)
    media, icc = job_media(settings)
    resolved = {n: book.resolve(n, media or "", icc) for n in names}
    spots = [dict(res.as_dict(), kind="cut" if res.resolved == "cut" else names[n])
             for n, res in resolved.items()]
    return resolved, spots


def file_spots(path: str, settings, book: SpotBook | None = None) -> list[dict]:
    """The report's spot entries of one file as `prepare` makes them, without rewriting or
    rendering it: a PDF's resources are read (milliseconds), a PostScript or EPS program
    is probed by Ghostscript; [] for an image or RTL, or a PDF that QPDF cannot read."""
    from .ghostscript import sniff_document        # not rip/inputs.py: it imports the document
    try:
        with open(path, "rb") as f:
            fmt = sniff_document(f.read(1024))
    except OSError:
        return []
    if fmt not in ("pdf", "ps", "eps"):
        return []
    names: dict[str, str] = {}
    if fmt == "pdf":
        from .spot_pdf import spot_names
        try:
            names = spot_names(path).names
        except Exception:       # noqa: BLE001 - prints through the alternates (prepare's warning)
            return []
    else:
        from .ghostscript import probe
        probe(path, fmt, settings.placement.page_box, spots=names)
    return resolve_names(names, settings, book)[1]


def job_spots(rip) -> list[dict]:
    """The spots a RipJob prints (docs/server.md, the job's `spots`): its document's as
    rendered; a layout's items are ripped while it prints, so each of their files is read
    here (every name once, in the order of the files)."""
    source = getattr(rip, "source", None)
    if source is not None and getattr(rip, "layout", None) is None:
        return list(getattr(source, "spots", None) or [])
    out: dict[str, dict] = {}
    layout = getattr(rip, "layout", None)
    for path in dict.fromkeys(getattr(layout, "paths", ()) or ()):
        for entry in file_spots(path, rip.settings):
            out.setdefault(entry["name"], entry)
    return list(out.values())


def prepare(path: str, fmt: str, settings, names: dict[str, str] | None = None,
            book: SpotBook | None = None) -> SpotPlan:
    """The spot plan of a job.  `names`: the spot names a PostScript/EPS probe saw
    (name -> kind); PDF files are read here."""
    from .spot_pdf import rewrite, spot_names     # pikepdf is loaded only for documents
    if fmt == "pdf":
        try:
            names = spot_names(path).names
        except Exception as e:      # noqa: BLE001 - QPDF refused a file Ghostscript may still read
            return SpotPlan(path, fmt, warnings=[f"spot colours not read (QPDF: {str(e)[:160]}): "
                                                 f"they print through their alternate space"])
    resolved, spots = resolve_names(names, settings, book)
    if not spots:
        return SpotPlan(path, fmt)
    if not any(r.resolved in ("library", "recipe", "cut") for r in resolved.values()):
        return SpotPlan(path, fmt, spots)
    folder = tempfile.mkdtemp(prefix="wideprint-spot-")
    try:
        src = path if fmt == "pdf" else _distil(path, fmt, folder)
        dst = os.path.join(folder, "spots.pdf")
        recipes = {n: r.cmyk for n, r in resolved.items() if r.cmyk is not None}
        icc_data = None
        if settings.output_icc:
            with open(settings.output_icc, "rb") as f:
                icc_data = f.read()
        rewrite(src, dst, lambda n: recipes.get(n), icc_data, sampler(settings, folder))
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return SpotPlan(dst, "pdf", spots, folder)
