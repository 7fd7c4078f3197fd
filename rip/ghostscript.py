"""PostScript, EPS and PDF through Ghostscript, rendered straight onto the device grid
(docs/documents.md).

Ghostscript (``gs``) runs as a separate process, never in ours:

1. **Probe** (one small run per document, nothing rasterised): the page count and every
   page's size.  PDF: the page dictionaries (MediaBox, CropBox, TrimBox, BleedBox,
   ArtBox, Rotate, UserUnit) through Ghostscript's PDF interpreter with the null device.
   PostScript/EPS: the program runs once on the ``nullpage`` device with an EndPage
   procedure that reports each page's PageSize (EPS: ``-dEPSCrop``, the BoundingBox).
   Pages whose device-grid size exceeds the placement limit are refused here, before
   anything is rendered.
2. **Render** (one run per page, when the RIP pulls the bands): ``-sDEVICE=pamcmyk32
   -sOutputFile=-`` at ``-r{xres}x{yres}`` on a fixed medium of exactly the page's
   device-grid size (``-g{W}x{H} -dFIXEDMEDIA``), so 1 rendered pixel = 1 device dot and
   vector content is rasterised at the final resolution.  The CMYK rows are read from the
   pipe in bands: memory is one band, whatever the page size; nothing goes to disk.

Containment: ``-dSAFER`` (file operators refused), a processor-time limit per process
(RLIMIT_CPU: an endless ``{} loop`` is killed), an address-space limit (RLIMIT_AS), a
wall-clock limit on the probe, ``GS_OPTIONS`` removed from the environment, and the
render's PAM header checked against the probed size.  Every failure is an
:class:`~.load.ImageError` that gives Ghostscript's reason in plain words.
"""

from __future__ import annotations

import math
import os
import re
import resource
import secrets
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from .load import ImageError

__all__ = ["GsPage", "probe", "render_page", "gs_path", "DOC_FORMATS", "PAGE_BOXES"]

#: what sniff_document() returns
DOC_FORMATS = ("pdf", "ps", "eps")
#: PDF page boxes, in the order of the PDF spec's defaults (Trim/Bleed/Art default to Crop,
#: Crop to Media)
PAGE_BOXES = ("media", "crop", "trim", "bleed", "art")
_BOX_KEYS = {"media": "MediaBox", "crop": "CropBox", "trim": "TrimBox", "bleed": "BleedBox",
             "art": "ArtBox"}
_BOX_FLAGS = {"media": None, "crop": "-dUseCropBox", "trim": "-dUseTrimBox",
              "bleed": "-dUseBleedBox", "art": "-dUseArtBox"}

#: limits (seconds of processor time, bytes); tests and operators may change them, or set
#: WIDEPRINT_GS_CPU_S (a fixed render limit) and WIDEPRINT_GS_PROBE_S in the environment
PROBE_CPU_S = 60.0          # the probe interprets the whole program once, rasterises nothing
PROBE_WALL_S = 180.0
RENDER_CPU_BASE_S = 60.0    # per page: this much, plus one second per RENDER_PX_PER_S pixels
RENDER_PX_PER_S = 4e6       # (measured: ~600 Mpx/s for simple vector pages on this machine)
MEMORY_LIMIT = 3 << 30      # address space of one gs process
STDERR_KEEP = 64 << 10      # bytes of Ghostscript's messages kept for the error text


def gs_path() -> str:
    """The Ghostscript executable ($WIDEPRINT_GS, else `gs` on the PATH)."""
    exe = os.environ.get("WIDEPRINT_GS") or "gs"
    found = shutil.which(exe)
    if not found:
        raise FileNotFoundError(exe)
    return found


def _env(tmp: str | None = None) -> dict:
    env = dict(os.environ)
    env.pop("GS_OPTIONS", None)          # nobody slips options (e.g. -dNOSAFER) into our runs
    env["LC_ALL"] = "C"
    if tmp:
        # -dSAFER still lets a program write files in Ghostscript's temporary directory:
        # each run gets its own, removed when it ends
        env["TMPDIR"] = env["TEMP"] = env["TMP"] = tmp
    return env


def _limit_s(name: str, default: float) -> float:
    try:
        v = float(os.environ.get(name, ""))
        return v if v > 0 else default
    except ValueError:
        return default


# --------------------------------------------------------------------------------------
# running Ghostscript


class _Gs:
    """One Ghostscript process with limits; stderr (and, for the probe, stdout) collected
    by threads into bounded buffers."""

    def __init__(self, path: str, args: list[str], cpu_s: float, *, stream_stdout: bool):
        try:
            exe = gs_path()
        except FileNotFoundError:
            raise ImageError(path, "PostScript and PDF need Ghostscript (gs), which is not installed "
                                   "(Debian: apt-get install ghostscript)") from None
        self.path = path
        self.cpu_s = cpu_s
        self.tmp = tempfile.mkdtemp(prefix="wideprint-gs-")
        try:
            self.proc = subprocess.Popen([exe, *args], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                         stderr=subprocess.PIPE, env=_env(self.tmp), bufsize=0,
                                         start_new_session=True, cwd=self.tmp)
        except OSError as e:
            shutil.rmtree(self.tmp, ignore_errors=True)
            raise ImageError(path, f"cannot run Ghostscript: {e.strerror or e}") from None
        try:
            cpu = max(1, int(math.ceil(cpu_s)))
            resource.prlimit(self.proc.pid, resource.RLIMIT_CPU, (cpu, cpu + 5))
            resource.prlimit(self.proc.pid, resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
        except (OSError, ValueError, AttributeError):   # the process already ended, or no prlimit
            pass
        self.err = bytearray()
        self.out = bytearray()
        self._threads = [threading.Thread(target=self._drain, args=(self.proc.stderr, self.err),
                                          daemon=True, name="gs-stderr")]
        if not stream_stdout:
            self._threads.append(threading.Thread(target=self._drain, args=(self.proc.stdout, self.out),
                                                  daemon=True, name="gs-stdout"))
        for t in self._threads:
            t.start()
        self.killed_for: str | None = None

    @staticmethod
    def _drain(pipe, buf: bytearray) -> None:
        try:
            while True:
                chunk = pipe.read(65536)
                if not chunk:
                    return
                room = STDERR_KEEP - len(buf)
                if room > 0:
                    buf += chunk[:room]
        except (OSError, ValueError):
            return

    def kill(self, why: str | None = None) -> None:
        if self.proc.poll() is None:
            self.killed_for = self.killed_for or why
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except OSError:
                try:
                    self.proc.kill()
                except OSError:
                    pass

    def wait(self, timeout: float | None = None) -> int:
        try:
            rc = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill(f"took more than {timeout:.0f} s")
            rc = self.proc.wait()
        for t in self._threads:
            t.join(5)
        return rc

    def close(self) -> None:
        self.kill()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:  # pragma: no cover - SIGKILL does not fail
            pass
        for pipe in (self.proc.stdout, self.proc.stderr):
            try:
                pipe.close()
            except (OSError, ValueError):
                pass
        for t in self._threads:
            t.join(1)
        shutil.rmtree(self.tmp, ignore_errors=True)

    def messages(self) -> str:
        return (bytes(self.out) + b"\n" + bytes(self.err)).decode("latin-1", "replace")

    def failure(self, rc: int, what: str) -> ImageError:
        """The error for a run that ended with `rc` (or was killed)."""
        return ImageError(self.path, explain(self.messages(), rc, self.cpu_s, self.killed_for, what))


# --------------------------------------------------------------------------------------
# Ghostscript's messages in plain words

_PS_ERRORS = {
    "undefined": "the document uses a name that is not defined (a misspelt command, or a "
                 "procedure set or font that is missing)",
    "invalidfileaccess": "the document tried to open a file on this computer, which is refused "
                         "(Ghostscript runs with -dSAFER)",
    "invalidaccess": "the document tried an operation that is not allowed (Ghostscript runs with "
                     "-dSAFER)",
    "undefinedfilename": "the document refers to a file that does not exist",
    "VMerror": "the document needs more memory than a job is allowed",
    "limitcheck": "the document exceeds one of Ghostscript's limits",
    "typecheck": "a command was given an operand of the wrong type",
    "rangecheck": "a command was given a value out of range",
    "stackunderflow": "a command found too few operands (a truncated or damaged file?)",
    "stackoverflow": "the program put too much on the operand stack",
    "dictstackoverflow": "the program nests dictionaries too deeply",
    "execstackoverflow": "the program recurses too deeply",
    "dictstackunderflow": "the program ends more dictionaries than it began",
    "syntaxerror": "the PostScript syntax is broken (unbalanced brackets or braces; a truncated file?)",
    "ioerror": "a read error (a truncated or damaged file?)",
    "invalidfont": "a font in the document is damaged or of an unsupported kind",
    "configurationerror": "the page device refused a setting",
    "nocurrentpoint": "a drawing command came before a current point was set",
    "unmatchedmark": "a ] or >> without its [ or <<",
    "undefinedresult": "a calculation had no result (e.g. a division by zero)",
    "undefinedresource": "the document asks for a resource (font, colour space, ...) that does not exist",
    "unregistered": "an internal Ghostscript error",
    "interrupt": "Ghostscript was interrupted",
    "timeout": "a time limit was reached",
}

_ERR_RE = re.compile(r"Error: /(\w+) in (.*)")
_UNRECOVERABLE_RE = re.compile(r"Unrecoverable error: (\w+) in (.*)")
_ADDITIONAL_RE = re.compile(r"Additional information: (.*)")
_PAGESIZE_RE = re.compile(r"/PageSize \[\s*([-+\d.e]+)\s+([-+\d.e]+)\s*\]", re.I)


def _short(s: str, n: int = 160) -> str:
    s = " ".join(s.split())
    return s if len(s) <= n else s[: n - 3] + "..."


def explain(text: str, rc: int | None, cpu_s: float | None = None, killed_for: str | None = None,
            what: str = "rendering") -> str:
    """Ghostscript's output of a failed run -> the reason in plain words."""
    if killed_for:
        return (f"Ghostscript was stopped: {what} {killed_for} (a PostScript program that never "
                f"ends, such as an endless loop?)")
    if rc is not None and rc < 0:
        sig = -rc
        if sig == signal.SIGXCPU or (sig == signal.SIGKILL and cpu_s is not None):
            return (f"Ghostscript was stopped after {cpu_s:.0f} s of processor time while {what} "
                    f"(a PostScript program that never ends, such as an endless loop?)")
        name = signal.Signals(sig).name if sig in signal.Signals._value2member_map_ else str(sig)
        return f"Ghostscript crashed while {what} (signal {name})"
    lines = [ln.rstrip() for ln in text.splitlines()]
    for i, ln in enumerate(lines):
        m = _ERR_RE.search(ln) or _UNRECOVERABLE_RE.search(ln)
        if m:
            name, where = m.group(1), _short(m.group(2), 80)
            more = next((_ADDITIONAL_RE.search(x) for x in lines[i + 1: i + 4] if _ADDITIONAL_RE.search(x)), None)
            if name == "configurationerror" and more and _PAGESIZE_RE.search(more.group(1)):
                pm = _PAGESIZE_RE.search(more.group(1))
                w, h = float(pm.group(1)), float(pm.group(2))
                return (f"PostScript error /configurationerror in {where}: the page size {w:g} x {h:g} pt "
                        f"({w / 72 * 0.0254:.6g} x {h / 72 * 0.0254:.6g} m) is refused: too large or "
                        f"not a size")
            if name == "undefined" and where and not where.startswith("--"):
                why = f"the document uses the name {where}, which is not defined"
            else:
                why = _PS_ERRORS.get(name, "an error in the document")
            extra = f" ({_short(more.group(1), 80)})" if more and name not in ("undefined",) else ""
            return f"PostScript error /{name} in {where}{extra}: {why}"
    pdf = [_short(ln.split("****", 1)[1].strip(" :"), 120) for ln in lines if "**** Error" in ln]
    pdf = [p[len("Error"):].strip(" :") if p.startswith("Error") else p for p in pdf]
    if pdf:
        detail = next((_short(ln) for ln in lines if ln and "****" not in ln and not ln.startswith((" ", "WP"))
                       and "Output may be incorrect" not in ln), "")
        return f"PDF error: {'; '.join(dict.fromkeys(pdf))}" + (f" ({detail})" if detail else "")
    rest = [ln.strip() for ln in lines if ln.strip() and "GPL Ghostscript" not in ln and not ln.startswith("WP")
            and not ln.startswith(("Operand stack", "Execution stack", "Dictionary stack", "Current allocation",
                                   "Last OS error", "   "))]
    if rest:
        return f"Ghostscript failed while {what}: {_short(rest[0])}"
    return f"Ghostscript failed while {what} (exit code {rc})"


# --------------------------------------------------------------------------------------
# probing


@dataclass
class GsPage:
    """One page of a document as Ghostscript will render it."""
    number: int                    # 1-based
    width_pt: float                # as viewed: after /Rotate and /UserUnit, points (1/72 in)
    height_pt: float
    box: str = "media"             # the box actually used ("crop" asked, no CropBox: "media")
    flags: tuple = ()              # the Ghostscript switches that select that box
    boxes: dict = field(default_factory=dict)   # PDF: every box the page has (points)
    rotate: int = 0                # PDF /Rotate (Ghostscript applies it)
    user_unit: float = 1.0


def sniff_document(head: bytes) -> str | None:
    """'pdf', 'eps', 'ps' from a file's first bytes (at least 1 KiB), else None."""
    if head[:4] == b"\xc5\xd0\xd3\xc6":
        return "eps"                                  # DOS EPS binary header
    h = head.lstrip(b"\x04")                          # a leading Ctrl-D (some Windows drivers)
    if h.startswith(b"\xef\xbb\xbf"):
        h = h[3:]
    if h.startswith(b"%!PS") or h.startswith(b"%!"):
        first = h.split(b"\n", 1)[0].split(b"\r", 1)[0]
        return "eps" if b"EPSF" in first else "ps"
    if b"%PDF-" in head[:1024]:
        return "pdf"
    return None


def _probe_args(path: str, fmt: str, nonce: str) -> list[str]:
    path = os.path.abspath(path)         # absolute: never taken for an option; gs runs in its own cwd
    common = ["-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-dNOINTERPOLATE"]
    if fmt == "pdf":
        prog = (f"/WPn ({nonce}) def "
                "WPFile (r) file runpdfbegin "
                "WPn print ( count ) print pdfpagecount =only (\\n) print "
                "1 1 pdfpagecount { /WPi exch def WPi pdfgetpage /WPd exch def "
                "WPn print ( page ) print WPi =only "
                "WPd type /dicttype eq { "
                "[/MediaBox /CropBox /TrimBox /BleedBox /ArtBox /Rotate /UserUnit] { /WPk exch def "
                "WPd WPk known { ( ) print WPk =only ( ) print WPd WPk get ==only } if } forall } if "
                "(\\n) print flush } for quit")
        return [*common, "-dNODISPLAY", f"--permit-file-read={path}", f"-sWPFile={path}", "-c", prog]
    hook = (f"<< /EndPage {{ exch pop 2 ne {{ ({nonce} page ) print currentpagedevice /PageSize get "
            "{ =only ( ) print } forall (\\n) print flush false } { false } ifelse } bind >> setpagedevice "
            # the spot colours the program sets (docs/spot.md): each Separation and DeviceN
            # name once (a program that sets its colour space at every object must not
            # flood the output, whose first 64 KiB hold the page sizes)
            f"/WPspots 64 dict def /WPspot {{ 1 index WPspots exch known {{ pop pop }} {{ 1 index WPspots "
            f"exch true put ({nonce} spot ) print print ( ) print =only (\\n) print }} ifelse }} bind def "
            "/setcolorspace { dup type /arraytype eq { dup length 1 gt { dup 0 get dup /Separation eq "
            "{ pop dup 1 get (separation) WPspot } { /DeviceN eq { dup 1 get { (devicen) WPspot } forall } "
            "if } ifelse } if } if //setcolorspace } bind def")
    args = [*common, "-sDEVICE=nullpage", "-r72"]
    if fmt == "eps":
        args.append("-dEPSCrop")
    return [*args, "-c", hook, "-f", path]


_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_BOX_RE = re.compile(r"/?(MediaBox|CropBox|TrimBox|BleedBox|ArtBox)\s+\[\s*(" + _NUM + r")\s+(" + _NUM
                     + r")\s+(" + _NUM + r")\s+(" + _NUM + r")\s*\]")
_SCALAR_RE = re.compile(r"/?(Rotate|UserUnit)\s+(" + _NUM + r")")


def _box_size(b):
    return abs(b[2] - b[0]), abs(b[3] - b[1])


def _intersect(a, b):
    ax0, ax1 = sorted((a[0], a[2]))
    ay0, ay1 = sorted((a[1], a[3]))
    bx0, bx1 = sorted((b[0], b[2]))
    by0, by1 = sorted((b[1], b[3]))
    return (max(ax0, bx0), max(ay0, by0), min(ax1, bx1), min(ay1, by1))


def _pdf_page(number: int, fields: str, box: str) -> GsPage:
    boxes = {}
    for m in _BOX_RE.finditer(fields):
        boxes[m.group(1)] = tuple(float(m.group(i)) for i in range(2, 6))
    scal = {m.group(1): float(m.group(2)) for m in _SCALAR_RE.finditer(fields)}
    media = boxes.get("MediaBox", (0.0, 0.0, 612.0, 792.0))      # the PDF default: US Letter
    crop = _intersect(boxes["CropBox"], media) if "CropBox" in boxes else None
    # the box we ask for, else the spec's default chain (Trim/Bleed/Art -> Crop -> Media)
    chosen, used = None, "media"
    want = _BOX_KEYS[box]
    if box != "media" and want in boxes:
        chosen, used = _intersect(boxes[want], media), box
    elif box != "media" and crop is not None:
        chosen, used = crop, "crop"
    if chosen is None or min(_box_size(chosen)) <= 0:
        chosen, used = media, "media"
    uu = scal.get("UserUnit", 1.0)
    uu = uu if uu > 0 and math.isfinite(uu) else 1.0
    rot = int(round(scal.get("Rotate", 0))) % 360
    rot = rot - rot % 90
    w, h = _box_size(chosen)
    w, h = w * uu, h * uu
    if rot in (90, 270):
        w, h = h, w
    flag = _BOX_FLAGS[used]
    return GsPage(number, w, h, used, (flag,) if flag else (), dict(boxes), rot, uu)


def probe(path: str, fmt: str, box: str = "crop",
          spots: dict[str, str] | None = None) -> tuple[list[GsPage], list[str]]:
    """Every page's size, without rasterising anything.  Returns (pages, warnings).
    PostScript/EPS: the Separation and DeviceN names the program sets are added to `spots`
    (name -> "separation" | "devicen"; docs/spot.md); a PDF's are read by rip/spot_pdf.py."""
    nonce = "WP" + secrets.token_hex(8)
    cpu = _limit_s("WIDEPRINT_GS_PROBE_S", PROBE_CPU_S)
    gs = _Gs(path, _probe_args(path, fmt, nonce), cpu, stream_stdout=False)
    try:
        rc = gs.wait(max(PROBE_WALL_S, 2 * cpu))
        text = gs.messages()
        mine = [ln[len(nonce):].strip() for ln in text.splitlines() if ln.startswith(nonce)]
        failed = rc != 0 or gs.killed_for is not None
        if fmt != "pdf" and (failed or _ERR_RE.search(text)):
            raise gs.failure(rc, "reading the document")
        pages: list[GsPage] = []
        count = None
        for ln in mine:
            if ln.startswith("count "):
                try:
                    count = int(ln.split()[1])
                except (IndexError, ValueError):
                    count = None
            elif ln.startswith("spot ") and spots is not None:
                parts = ln.split(None, 2)
                if len(parts) == 3 and parts[2] not in ("None", "All"):
                    spots.setdefault(parts[2], parts[1])
            elif ln.startswith("page "):
                parts = ln.split(None, 2)
                if fmt == "pdf":
                    try:
                        n = int(parts[1])
                    except (IndexError, ValueError):
                        continue
                    pages.append(_pdf_page(n, parts[2] if len(parts) > 2 else "", box))
                else:
                    try:
                        w, h = float(parts[1]), float(ln.split()[2])
                    except (IndexError, ValueError):
                        continue
                    pages.append(GsPage(len(pages) + 1, w, h, "page", ()))
        if fmt == "pdf" and (failed or count is None or count == 0 or _ERR_RE.search(text)):
            if failed or _ERR_RE.search(text) or "**** Error" in text:
                raise gs.failure(rc, "reading the document")
            if count == 0:
                raise ImageError(path, "PDF has no pages")
            raise ImageError(path, f"PDF: Ghostscript could not read the page list "
                                   f"({_short(text) or 'no output'})")
        if not pages:
            raise ImageError(path, "nothing to print: the PostScript program produced no page (no showpage)"
                             if fmt != "pdf" else "PDF has no pages")
        warnings = [_short(ln.split("****", 1)[1].strip(" :"), 120) for ln in text.splitlines()
                    if "**** Warning" in ln or "**** Error" in ln]
        return pages, list(dict.fromkeys(warnings))
    finally:
        gs.close()


# --------------------------------------------------------------------------------------
# colour: the RIP's ICC path (docs/color.md), executed by Ghostscript's lcms

_ICC_DIR: str | None = None
_ICC_LOCK = threading.Lock()


def builtin_profile(name: str) -> str:
    """A file holding libvips' built-in profile `name` ('srgb', 'cmyk'): the RIP's defaults,
    written once per process into a private temporary directory."""
    global _ICC_DIR
    with _ICC_LOCK:
        if _ICC_DIR is None or not os.path.isdir(_ICC_DIR):
            _ICC_DIR = tempfile.mkdtemp(prefix="wideprint-icc-")
        p = os.path.join(_ICC_DIR, f"{name}.icc")
        if not os.path.exists(p):
            import pyvips
            data = pyvips.Operation.call("profile_load", name)
            tmp = p + ".tmp"
            with open(tmp, "wb") as f:
                f.write(bytes(data))
            os.replace(tmp, p)
        return p


_INTENTS = {"perceptual": 0, "relative": 1, "saturation": 2, "absolute": 3}


def _icc_space(path: str) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(20)[16:20]
    except OSError:
        return b""


def colour_args(input_icc: str | None, output_icc: str | None, intent: str) -> list[str]:
    """The same conversions as rip/color/'s Separator, done by Ghostscript:

    * RGB content: input_icc (an RGB profile) else built-in sRGB -> output_icc else the
      built-in CMYK profile, with the job's intent and no black point compensation;
    * CMYK content: unchanged unless output_icc is given (then input_icc if it is a CMYK
      profile, else the built-in CMYK profile -> output_icc);
    * grey content: K only (Ghostscript's DeviceGrayToK), ink = 1 - grey.
    Embedded ICC profiles of the document's images and colour spaces are honoured."""
    rgb = builtin_profile("srgb")
    cmyk_in = builtin_profile("cmyk")
    if input_icc:
        space = _icc_space(input_icc)
        if space == b"RGB ":
            rgb = os.path.abspath(input_icc)
        elif space == b"CMYK" and output_icc:
            cmyk_in = os.path.abspath(input_icc)
    out = os.path.abspath(output_icc) if output_icc else builtin_profile("cmyk")
    if not output_icc:
        cmyk_in = out                   # the same profile both sides: Ghostscript leaves CMYK alone
    return [f"-sDefaultRGBProfile={rgb}", f"-sDefaultCMYKProfile={cmyk_in}", f"-sOutputICCProfile={out}",
            f"-dRenderIntent={_INTENTS.get(intent, 1)}", "-dOverrideRI", "-dBlackPtComp=0",
            "-dDeviceGrayToK=true"]


# --------------------------------------------------------------------------------------
# rendering


def _fmt_res(r: float) -> str:
    return f"{r:.6f}".rstrip("0").rstrip(".")


def render_args(path: str, fmt: str, page: GsPage, width: int, height: int, xres: float, yres: float,
                colour: list[str]) -> list[str]:
    path = os.path.abspath(path)
    args = ["-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pamcmyk32", "-sstdout=%stderr",
            "-sOutputFile=-", f"-r{_fmt_res(xres)}x{_fmt_res(yres)}", f"-g{width}x{height}", "-dFIXEDMEDIA",
            f"-sPageList={page.number}", "-dTextAlphaBits=1", "-dGraphicsAlphaBits=1", *colour, *page.flags]
    if fmt == "eps":
        args.append("-dEPSCrop")
    return [*args, "-f", path]


def render_cpu_s(width: int, height: int) -> float:
    env = os.environ.get("WIDEPRINT_GS_CPU_S")
    if env:
        return _limit_s("WIDEPRINT_GS_CPU_S", RENDER_CPU_BASE_S)
    return RENDER_CPU_BASE_S + width * height / RENDER_PX_PER_S


def _read_header(stream, gs: _Gs) -> tuple[int, int]:
    hdr = bytearray()
    while not hdr.endswith(b"ENDHDR\n"):
        b = stream.read(1)
        if not b:
            return -1, -1
        hdr += b
        if len(hdr) > 4096:
            raise ImageError(gs.path, "Ghostscript's output is not a PAM image (bad header)")
    text = hdr.decode("latin-1")
    if not text.startswith("P7\n"):
        raise ImageError(gs.path, "Ghostscript's output is not a PAM image (bad header)")
    vals = dict(ln.split(None, 1) for ln in text.splitlines()[1:] if " " in ln and not ln.startswith("#"))
    try:
        w, h = int(vals["WIDTH"]), int(vals["HEIGHT"])
        depth, maxval = int(vals["DEPTH"]), int(vals["MAXVAL"])
    except (KeyError, ValueError):
        raise ImageError(gs.path, "Ghostscript's output is not a PAM image (bad header)") from None
    if depth != 4 or maxval != 255:
        raise ImageError(gs.path, f"Ghostscript's output has {depth} channels of 0..{maxval}, expected CMYK 8-bit")
    return w, h


def _readinto(stream, mv: memoryview) -> int:
    got = 0
    n = len(mv)
    while got < n:
        k = stream.readinto(mv[got:])
        if not k:
            break
        got += k
    return got


def render_page(path: str, fmt: str, page: GsPage, width: int, height: int, xres: float, yres: float,
                colour: list[str], rows: int) -> Iterator[np.ndarray]:
    """The page as (h, width, 4) uint8 CMYK bands (ink: 0 = none), streamed from Ghostscript.
    The process is killed when the consumer stops early."""
    gs = _Gs(path, render_args(path, fmt, page, width, height, xres, yres, colour),
             render_cpu_s(width, height), stream_stdout=True)
    what = f"rendering page {page.number}"
    try:
        stream = gs.proc.stdout
        w, h = _read_header(stream, gs)
        if w < 0:
            rc = gs.wait()
            raise gs.failure(rc, what) if rc != 0 or gs.killed_for else \
                ImageError(path, f"Ghostscript rendered nothing for page {page.number} "
                                 f"({explain(gs.messages(), rc, None, None, what)})")
        if (w, h) != (width, height):
            raise ImageError(path, f"page {page.number}: Ghostscript rendered {w} x {h} pixels where the "
                                   f"probe gave {width} x {height} (the page size changed between runs)")
        y = 0
        row_bytes = width * 4
        while y < height:
            n = min(rows, height - y)
            band = np.empty((n, width, 4), np.uint8)
            got = _readinto(stream, memoryview(band).cast("B"))
            if got != n * row_bytes:
                rc = gs.wait()
                if rc != 0 or gs.killed_for:
                    raise gs.failure(rc, what)
                raise ImageError(path, f"page {page.number}: Ghostscript's output ended at row "
                                       f"{y + got // row_bytes} of {height}")
            yield band
            y += n
        extra = stream.read(1)
        rc = gs.wait()
        if rc != 0 or gs.killed_for:
            raise gs.failure(rc, what)
        if extra:
            # a second page from one PageList entry: the document changed under us
            raise ImageError(path, f"page {page.number}: Ghostscript rendered more than one page")
    finally:
        gs.close()


def warm_up() -> float:
    """Seconds one trivial Ghostscript run takes (start-up cost; bench/pdf_bench.py)."""
    t0 = time.perf_counter()
    subprocess.run([gs_path(), "-q", "-dNODISPLAY", "-dBATCH", "-c", "quit"], env=_env(), check=False,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0
