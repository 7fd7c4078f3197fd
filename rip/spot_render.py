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

__all__ = ["SpotPlan", "prepare"]


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
    names = {n: k for n, k in (names or {}).items()       # a DeviceN's process inks are no spots
             if not (k == "devicen" and n.casefold() in PROCESS)}
    if not names:
        return SpotPlan(path, fmt)
    book = book or SpotBook()
    media, icc = job_media(settings)
    resolved = {n: book.resolve(n, media or "", icc) for n in names}
    spots = [dict(res.as_dict(), kind="cut" if res.resolved == "cut" else names[n])
             for n, res in resolved.items()]
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
        rewrite(src, dst, lambda n: recipes.get(n), icc_data)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return SpotPlan(dst, "pdf", spots, folder)
