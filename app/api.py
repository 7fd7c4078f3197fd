"""wideprint's stable Python API (docs/acceptance.md): rip, print, compare.

Everything named in `__all__` keeps its meaning within a major `API_VERSION`: a name is
removed or changed only in the next major version, after at least one minor version in
which using it raises a DeprecationWarning saying what replaces it.  What is not in
`__all__` (every other module of the package) may change at any release.

    from wideprint.app import api
    planes = api.rip("poster.tif", settings={"dpi": 300, "passes": 2})
    result = api.print_file("poster.tif", settings={"dpi": 300, "passes": 2})
    assert api.compare(result.media, planes).equal

The pytest plugin (app/pytest_plugin.py) is built on it; so is `wideprint print`.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable

import numpy as np

if TYPE_CHECKING:       # types only: each is imported where it is used, on first use
    from ..rip.profile import Profile
    from ..rip.settings import RipSettings
    from .scancheck import ScanComparison, ScanTolerances

API_VERSION = "1.1"      # 1.1: scans (predict_scan, compare_scan, scan_dpi / scan_out)
COLORS = "CMYK"

__all__ = ["API_VERSION", "Comparison", "EmulatedPrinter", "PrintResult", "compare",
           "compare_scan", "diff_image", "load_profile", "predict_scan", "print_file",
           "read_planes", "rip", "rip_settings"]


# -- settings and profiles -----------------------------------------------------------------
def load_profile(path: str | Path | None = None) -> Profile:
    """The printer profile (default: the built-in one), validated (ProfileError names the
    file, section and key)."""
    from ..rip.profile import load_profile as _load
    return _load(path)


def rip_settings(settings: Any = None, profile: Profile | None = None, **kw: Any) -> RipSettings:
    """RipSettings from a RipSettings, a settings mapping (docs/settings.md: placement in a
    nested "placement" object) and/or keyword settings (placement ones allowed flat, e.g.
    size="pixels"), checked against the printer profile; ValueError names the setting."""
    from ..rip.settings import PLACEMENT_KEYS, RipSettings, from_mapping, merge
    if isinstance(settings, RipSettings):
        if kw:
            raise TypeError("give either a RipSettings or settings to build one, not both")
        if profile is not None:
            settings.check(profile)
        return settings
    flat = {"placement": {k: v for k, v in kw.items() if k in PLACEMENT_KEYS}}
    flat.update({k: v for k, v in kw.items() if k not in PLACEMENT_KEYS})
    if not flat["placement"]:
        del flat["placement"]
    return from_mapping(merge(dict(settings or {}), flat), profile)


def _media_job(settings: Any, profile: Profile, kw: dict[str, Any]) -> tuple[RipSettings, Profile]:
    """(RipSettings, profile) of a job whose settings may name a `media` (docs/media.md "A
    job's media"): the media's print mode under the settings given, its ICC and its ink
    limit, curves and drop budget, as `wideprint print --media` applies them."""
    from ..rip.settings import RipSettings as _Rs
    if isinstance(settings, _Rs) or not ((settings or {}).get("media") or kw.get("media")):
        return rip_settings(settings, profile, **kw), profile
    from ..rip.settings import PLACEMENT_KEYS, merge
    from .medialib import resolve
    flat: dict[str, Any] = {"placement": {k: v for k, v in kw.items() if k in PLACEMENT_KEYS}}
    flat.update({k: v for k, v in kw.items() if k not in PLACEMENT_KEYS})
    profile, mapping = resolve(merge(dict(settings or {}), flat), profile)
    return rip_settings(mapping, profile), profile


def read_planes(path: str | Path) -> np.ndarray:
    """A planes or media TIFF (docs/formats.md) as uint8 (rows, columns, 4): C, M, Y, K
    drops per dot."""
    from ..rip.planes import read_planes as _read
    return _read(path)


def rip(file: str | Path, settings: Any = None, *, profile: Profile | None = None,
        out: str | Path | None = None, **kw: Any) -> np.ndarray:
    """The halftone the RIP means for `file` (what `wideprint rip` writes), as a planes array;
    also written to `out` when given.  Raises rip.load.ImageError for a file it cannot read."""
    from ..rip.pipeline import RipJob
    profile = profile if profile is not None else load_profile()
    rs, profile = _media_job(settings, profile, kw)
    with tempfile.TemporaryDirectory(prefix="wideprint-rip-") as d:
        target = Path(out) if out else Path(d) / "planes.tif"
        job = RipJob(str(file), rs, profile)
        try:      # read back here: the compact encoding unless the caller keeps the file
            job.write_planes(target, "8bit" if out else "packed")
        finally:
            job.close()
        return read_planes(target)


# -- printing -------------------------------------------------------------------------------
@dataclass
class PrintResult:
    """One printed job."""
    file: str
    state: str                          # done | failed | cancelled
    message: str = ""
    report: dict[str, Any] = field(default_factory=dict)  # the job report (`print --report` keys)
    media: np.ndarray | None = None     # what landed (emulator only), planes layout
    media_path: Path | None = None
    events: list[dict[str, Any]] = field(default_factory=list)  # the emulator's event log records
    settings: Any = None                # the RipSettings it was printed with
    profile: Any = None
    planes: np.ndarray | None = None    # test prints: the pattern's planes
    scan_path: Path | None = None       # the emulator's scan of the job (scan_out=)

    @property
    def ok(self) -> bool:
        return self.state == "done"

    @property
    def ink_ml(self) -> list[float]:
        return list(self.report.get("ink_ml", [0.0] * 4))

    @property
    def faults(self) -> list[str]:
        """The faults the printer latched during the job (emulator event log), by name."""
        return [e.get("fault", "") for e in self.events if e.get("event") == "fault"]


class EmulatedPrinter:
    """The in-process emulator as one printer that keeps its state between jobs (paper
    position, faults, head configuration), like a real one; or, with `device=`, a real
    printer (no media read-back).  Use as a context manager.

        with EmulatedPrinter(faults=["dead-nozzle=M1:57"]) as printer:
            result = printer.print("chart.tif", passes=2)
    """

    def __init__(self, profile: Profile | str | Path | None = None, *,
                 faults: Iterable[str] | None = None, device: str = "emulator",
                 machine_profile: Profile | None = None,
                 workdir: str | Path | None = None, scan_dpi: float | None = None) -> None:
        from ..device_sim.faults import Faults
        from .devices import is_emulator_spec, open_device
        self.profile: Profile = (load_profile(profile) if isinstance(profile, (str, Path)) else
                                 profile if profile is not None else load_profile())
        self.device_spec = device
        self.emulated = is_emulator_spec(device)
        self.faults = Faults.parse(list(faults or []))
        if faults and not self.emulated:
            raise ValueError("faults can only be injected into the emulator")
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        if workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="wideprint-printer-")
            workdir = self._tmp.name
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self._media: dict[int, Path] = {}
        self._scans: dict[int, Path] = {}
        self.jobs = 0
        scan: dict[str, Any] = {}
        if scan_dpi is not None:            # the emulator scans each job (docs/physical.md)
            if not self.emulated:
                raise ValueError("only the emulator scans its prints")
            scan = dict(scan_path=lambda job: str(self._scans[job]) if job in self._scans else None,
                        scan_dpi=scan_dpi)
        self.device = open_device(device, self.profile, self.faults if self.emulated else None,
                                  media_path=lambda job: str(self._media[job]) if job in self._media else None,
                                  machine_profile=machine_profile, **scan)

    @property
    def emulator(self) -> Any:
        return self.device.emulator

    def print(self, file: str | Path, settings: Any = None, *, media_out: str | Path | None = None,
              scan_out: str | Path | None = None, **kw: Any) -> PrintResult:
        """Rip and print one file; never raises for a job that fails (the result says why),
        only for settings that are refused (ValueError)."""
        from ..rip.load import ImageError
        from ..rip.pipeline import RipJob
        rs, profile = _media_job(settings, self.profile, kw)
        result = PrintResult(file=str(file), state="failed", settings=rs, profile=profile)
        try:
            job = RipJob(str(file), rs, profile)
        except (ImageError, ValueError, OSError) as exc:
            self.jobs += 1
            result.message = str(exc)
            return result
        return self._run(job, result, media_out, scan_out)

    def print_pattern(self, pattern: str, *, width_mm: float = 100.0, dpi: int = 150,
                      head: str = "K1", nozzle: int = 64,
                      media_out: str | Path | None = None) -> PrintResult:
        """A test print (`wideprint test-print`: nozzle-check, line, sawtooth, bidir-align,
        head-align); `result.planes` holds the pattern's planes."""
        from ..rip.testprints import PatternJob
        width = int(round(width_mm / 25.4 * self.profile.counts_per_inch / self.profile.k(dpi)))
        job = PatternJob.for_pattern(pattern, self.profile, width, dpi, head=head, nozzle=nozzle)
        result = PrintResult(file=f"test-print:{pattern}", state="failed", settings=job.settings,
                             profile=self.profile, planes=job.planes)
        return self._run(job, result, media_out)

    def _run(self, rip_job: Any, result: PrintResult, media_out: str | Path | None,
             scan_out: str | Path | None = None) -> PrintResult:
        self.jobs += 1
        job_id = self.jobs
        media = Path(media_out) if media_out else self.workdir / f"media-{job_id}.tif"
        if self.emulated:
            self._media[job_id] = media
            if scan_out is not None:
                self._scans[job_id] = Path(scan_out)
        events0 = len(self.emulator.events) if self.emulated else 0
        run = run_job(self.device, rip_job, job_id)
        result.state, result.message, result.report = run.state, run.message, run.report
        if self.emulated:
            if result.state != "done":
                self.emulator.abandon_job()      # complete its media file for inspection
            result.events = list(self.emulator.events)[events0:]
            if media.exists():
                result.media_path, result.media = media, read_planes(media)
            if job_id in self._scans and self._scans[job_id].exists():
                result.scan_path = self._scans[job_id]
        return result

    def close(self) -> None:
        from .devices import close_device
        close_device(self.device)
        if self._tmp is not None:
            self._tmp.cleanup()

    def __enter__(self) -> "EmulatedPrinter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class JobRun:
    """What run_job did: the driver's PrintJob, how it ended and its report."""
    job: Any
    state: str                          # done | failed | cancelled
    message: str
    report: dict[str, Any]


def run_job(device: Any, rip_job: Any, job_id: int, *, on_event: Callable[..., Any] | None = None,
            on_job: Callable[[Any], Any] | None = None, internal_errors: bool = False) -> JobRun:
    """The job engine of `EmulatedPrinter.print` and `wideprint print` alike: one ripped job
    printed on an open device, the RIP job closed after it.  A job that fails or is
    cancelled does not raise: the JobRun says why (`internal_errors`: any other exception,
    a bug, too, as "internal error: ..." - a batch goes on; otherwise it propagates).
    `on_job(print_job)` is called before the job starts (a Ctrl-C handler cancels through
    it).  The report holds the `print --report` keys, the layout's when there is one, and
    on the emulator `printer_s`, the job's time on the printer's own clock."""
    from ..driver.job import JobCancelled, JobError, PrintJob
    from ..rip.load import ImageError
    pj = PrintJob(device, rip_job, job_id=job_id, on_event=on_event)
    if on_job is not None:
        on_job(pj)
    state, message = "failed", ""
    try:
        pj.run()
        state = "done"
    except JobCancelled as exc:
        state, message = "cancelled", str(exc)
    except (JobError, ImageError, ValueError, OSError) as exc:
        # ValueError / OSError: the RIP refused this file midway (e.g. an ICC profile for
        # another colour space)
        message = str(exc)
    except Exception as exc:
        if not internal_errors:
            raise
        message = f"internal error: {type(exc).__name__}: {exc}"
    finally:
        rip_job.close()
    report = dict(pj.report.as_dict(), state=state, message=message or pj.report.message)
    if getattr(rip_job, "layout", None) is not None:      # docs/layout.md: media saved
        report["layout"] = rip_job.layout.report
    from ..rip.spot_render import job_spots
    spots = job_spots(rip_job)               # a layout's (print and cut, nesting) too
    if spots:                                # docs/spot.md: the spots and how each printed
        report["spots"] = spots
    if device.emulator is not None:
        from .devices import emulated_seconds
        report["printer_s"] = emulated_seconds(device.emulator, job_id)
    return JobRun(pj, state, message, report)


def print_file(file: str | Path, settings: Any = None, *, device: str = "emulator",
               profile: Profile | str | Path | None = None, faults: Iterable[str] | None = None,
               media_out: str | Path | None = None, **kw: Any) -> PrintResult:
    """Print one file on a fresh printer (the in-process emulator by default) and return
    what happened: the report, and on the emulator the media that landed (also written to
    `media_out` when given)."""
    with tempfile.TemporaryDirectory(prefix="wideprint-print-") as d:
        with EmulatedPrinter(profile, faults=faults, device=device, workdir=d) as printer:
            result = printer.print(file, settings, media_out=media_out, **kw)
        if result.media_path is not None and media_out is None:
            result.media_path = None                    # it was in the temporary folder
        return result


def predict_scan(file: str | Path, out: str | Path, settings: Any = None, *, scan_dpi: float = 600,
                 grey: bool = False, profile: Profile | str | Path | None = None, **kw: Any) -> Path:
    """The physical model's prediction of a scan of this job (docs/acceptance.md): the job
    printed on a perfect emulated machine and scanned at `scan_dpi` without sensor noise,
    written to `out` (an RGB TIFF, or grey, with its resolution)."""
    faults = ["scan-noise=0"] + (["scan-mode=grey"] if grey else [])
    with tempfile.TemporaryDirectory(prefix="wideprint-predict-") as d:
        with EmulatedPrinter(profile, faults=faults, workdir=d, scan_dpi=scan_dpi) as printer:
            result = printer.print(file, settings, scan_out=out, **kw)
    if not result.ok:
        raise ValueError(f"{file}: the prediction's print failed: {result.message}")
    return Path(out)


def compare_scan(scan: str | Path, predicted: str | Path,
                 tolerances: ScanTolerances | None = None) -> ScanComparison:
    """A scan of a print against the predicted scan (predict_scan): registered, then ink
    density, rows and dot positions within `tolerances` (a ScanTolerances; the defaults are
    docs/acceptance.md's).  Returns a ScanComparison: `ok`, `problems`, `explain()`."""
    from .scancheck import compare_scan as _compare
    return _compare(scan, predicted, tolerances)


# -- comparing ------------------------------------------------------------------------------
@dataclass
class Comparison:
    """Media against planes, dot for dot."""
    equal: bool
    shape_a: tuple[int, ...]
    shape_b: tuple[int, ...]
    differing: int = 0
    missing: list[int] = field(default_factory=lambda: [0] * 4)   # per channel: in b, not in a
    stray: list[int] = field(default_factory=lambda: [0] * 4)     # per channel: in a, not in b
    drops_a: list[int] = field(default_factory=lambda: [0] * 4)
    drops_b: list[int] = field(default_factory=lambda: [0] * 4)
    first: list[tuple[int, int, str, int, int]] = field(default_factory=list)  # (row, column, "C", a, b)

    def explain(self, a_name: str = "media", b_name: str = "planes") -> str:
        if self.shape_a != self.shape_b:
            return (f"{a_name} is {self.shape_a[1]} x {self.shape_a[0]} dots but {b_name} is "
                    f"{self.shape_b[1]} x {self.shape_b[0]}")
        if self.equal:
            return f"{a_name} equals {b_name}: {self.shape_a[1]} x {self.shape_a[0]} dots"
        lines = [f"{self.differing} dots differ between {a_name} and {b_name} "
                 f"({self.shape_a[1]} x {self.shape_a[0]} dots)"]
        for i, c in enumerate(COLORS):
            if self.missing[i] or self.stray[i]:
                lines.append(f"  {c}: {a_name} {self.drops_a[i]} drops, {b_name} {self.drops_b[i]}; "
                             f"{self.missing[i]} missing, {self.stray[i]} stray")
        lines.append("  first differences (row, column, ink: "
                     f"{a_name} / {b_name}): "
                     + ", ".join(f"({r}, {col}, {c}: {va} / {vb})" for r, col, c, va, vb in self.first))
        return "\n".join(lines)


def _as_planes(x: Any) -> np.ndarray:
    if isinstance(x, (str, Path)):
        return read_planes(x)
    if isinstance(x, PrintResult):
        if x.media is None:
            raise ValueError(f"{x.file}: no media (a real printer, or the job printed nothing)")
        return x.media
    return np.asarray(x)


def compare(a: Any, b: Any, first: int = 10) -> Comparison:
    """Compare two planes arrays, planes/media TIFFs or a PrintResult's media."""
    a, b = _as_planes(a), _as_planes(b)
    cmp = Comparison(equal=False, shape_a=a.shape, shape_b=b.shape)
    if a.shape != b.shape:
        return cmp
    diff = a != b
    cmp.differing = int(diff.any(axis=-1).sum())
    cmp.drops_a = [int(v) for v in a.reshape(-1, 4).sum(axis=0, dtype=np.int64)]
    cmp.drops_b = [int(v) for v in b.reshape(-1, 4).sum(axis=0, dtype=np.int64)]
    cmp.missing = [int(((b[..., i] > 0) & (a[..., i] == 0)).sum()) for i in range(4)]
    cmp.stray = [int(((a[..., i] > 0) & (b[..., i] == 0)).sum()) for i in range(4)]
    cmp.equal = cmp.differing == 0
    if not cmp.equal:
        r, c, ch = np.nonzero(diff)
        cmp.first = [(int(r[i]), int(c[i]), COLORS[ch[i]], int(a[r[i], c[i], ch[i]]),
                      int(b[r[i], c[i], ch[i]])) for i in range(min(first, len(r)))]
    return cmp


def diff_image(a: Any, b: Any, path: str | Path, max_side: int = 2000) -> Path:
    """A PNG of where two planes differ: grey where they agree on a drop, red where b has a
    drop a lacks (missing), blue where a has one b lacks (stray), white elsewhere; area
    reduced (a differing dot in a block colours the block) to at most `max_side` pixels."""
    import cv2
    a, b = _as_planes(a), _as_planes(b)
    h, w = max(a.shape[0], b.shape[0]), max(a.shape[1], b.shape[1])
    pa = np.zeros((h, w, 4), np.uint8)
    pb = np.zeros((h, w, 4), np.uint8)
    pa[:a.shape[0], :a.shape[1]] = a
    pb[:b.shape[0], :b.shape[1]] = b
    missing = ((pb > 0) & (pa == 0)).any(axis=-1)
    stray = ((pa > 0) & (pb == 0)).any(axis=-1)
    agree = ((pa > 0) & (pb > 0)).any(axis=-1)
    step = max(1, -(-max(h, w) // max_side))
    if step > 1:                                   # block-reduce: any differing dot shows
        hh, ww = -(-h // step) * step, -(-w // step) * step
        def red(m: Any) -> Any:         # numpy types .any(axis=) as an array or a scalar
            m2 = np.zeros((hh, ww), bool)
            m2[:h, :w] = m
            return m2.reshape(hh // step, step, ww // step, step).any(axis=(1, 3))
        missing, stray, agree = red(missing), red(stray), red(agree)
    img = np.full(missing.shape + (3,), 255, np.uint8)          # BGR for OpenCV
    img[agree] = (160, 160, 160)
    img[stray] = (255, 0, 0)
    img[missing] = (0, 0, 255)
    path = Path(path)
    cv2.imwrite(str(path), img)
    return path
