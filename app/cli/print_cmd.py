"""`wideprint print FILE...`: rip and print files on a printer or the emulator, one job a
file (or a nest of files), with the report, the media, preview, scan and cut files asked for."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, TextIO

from .. import devices
from .common import (EXIT_DEVICE, EXIT_JOB_FAILED, EXIT_OK, EXIT_USAGE, NAME_LIMIT, SPECTRO_DPI,
                     _check_icc, _check_output_folders, _check_scan, _close_device,
                     _emulator_options, _emulator_outputs, _media_path, _profile, _rip_options,
                     _scan_options, cli_job_base, progress, shown)
from .process import _collector_on
from .proof import _proof


def _expand(files: list[str]) -> tuple[list[str], dict[str, str]]:
    """The files to print, and why a folder among them could not be listed."""
    out, problems = [], {}
    for f in files:
        p = Path(f)
        try:
            is_dir = p.is_dir()
        except OSError:                  # e.g. a name longer than PATH_MAX: open_image says so
            is_dir = False
        if not is_dir:
            out.append(f)
            continue
        try:
            listed = sorted(str(c) for c in p.iterdir() if not c.name.startswith(".") and c.is_file())
        except OSError as exc:
            out.append(f)
            problems[f] = f"{f}: cannot list the folder: {exc.strerror or exc}"
            continue
        if not listed:                   # a job of its own, failed: never "0 of 0 printed"
            out.append(f)
            problems[f] = f"{f}: {NO_FILES}"
        out += listed
    return out, problems


NO_FILES = "no files to print in the folder"


def _nest_files(files: list[str], unlisted: dict, settings, profile) -> tuple[list, list]:
    """--nest: the files grouped into nests by the start rule (rip/layout.nest_sheets);
    the files still waiting make a last nest, since no more are coming.  A file that
    cannot be nested stays a job of its own, failed with why (in `unlisted`)."""
    from ...rip.layout import nest_sheets
    sheets, waiting, bad = nest_sheets([f for f in files if f not in unlisted], settings, profile)
    unlisted.update(bad)
    sheets += [waiting] if waiting else []
    alone = [f for f in files if f in unlisted]
    return alone + [s[0] for s in sheets], [()] * len(alone) + [tuple(s[1:]) for s in sheets]


def _import_job_modules() -> None:
    """The modules a print needs, imported while start-up has the garbage collector off,
    before it comes back on for the job's own objects (app/cli/process.py)."""
    from ...device_sim import faults  # noqa: F401
    from ...driver import link, printer  # noqa: F401
    from ...rip import load, pipeline  # noqa: F401
    from .. import api, devices  # noqa: F401


class PrintCommand:
    """`wideprint print`, in its parts: the inputs expanded and the options checked (any
    problem refuses every file, with why, before anything prints), the device opened, each
    file (or nest of files) ripped and printed as a job with the outputs asked for, and
    the summary with the exit code.  Every exit writes --report and --json."""

    def __init__(self, args):
        self.args = args
        self.files: list[str] = []
        self.unlisted: dict[str, str] = {}         # file -> why it cannot be printed
        self.extras: list[tuple] = []               # the files nested with each job's first
        self.reports: list[dict] = []
        self.failed = 0
        self.say = sys.stderr if args.json else sys.stdout  # --json keeps stdout machine-readable
        self.profile: Any = None                    # the printer profile, with the media's
        self.settings: Any = None                   # RipSettings
        self.faults: Any = None                     # the emulator's, from --inject
        self.dev: Any = None                        # app/devices.Device
        # each job's outputs by job id, asked for by the emulator as it prints
        self.media: dict[int, str | None] = {}
        self.scans: dict[int, str | None] = {}
        self.spectros: dict[int, str | None] = {}
        self.scratch: tempfile.TemporaryDirectory | None = None
        self.log_json: TextIO | None = None
        self.current: dict = {}                     # the job printing, for Ctrl-C

    def run(self) -> int:
        _import_job_modules()
        _collector_on()
        self.files, self.unlisted = _expand(self.args.files)
        refusal = self.check_inputs() or self.check_options()
        if refusal:
            return self.refuse(*refusal)
        refusal = self.open_device()
        if refusal:
            return self.refuse(*refusal)
        self.log_json = open(self.args.log_json, "a") if self.args.log_json else None
        base = cli_job_base()
        signal.signal(signal.SIGINT, self.interrupt)
        self.nest()
        try:
            for i, f in enumerate(self.files):
                if not self.print_file(i, f, base + i):
                    break
        finally:
            self.close()
        return self.summary()

    # -- before anything prints ---------------------------------------------------------------
    def check_inputs(self) -> tuple[int, str] | None:
        """Folders with nothing to print and nothing else: a usage error, never "0 of 0"."""
        files, unlisted = self.files, self.unlisted
        if files and all(unlisted.get(f, "").endswith(NO_FILES) for f in files):
            return EXIT_USAGE, "; ".join(unlisted[f] for f in files)
        return None

    def check_options(self) -> tuple[int, str] | None:
        """The settings against the profile and media, the outputs' folders, and the
        options only the in-process emulator can honour."""
        from ...device_sim.faults import Faults
        from .media import job_settings
        args = self.args
        try:
            self.profile, settings = job_settings(args, _profile(args))
            if args.cut_out:                        # print and cut (docs/cut.md)
                from ...rip.cut import wants_cut_marks
                from ...rip.cutfile import cut_format
                cut_format(args.cut_out)
                settings = wants_cut_marks(settings)
            self.settings = settings
            self.faults = Faults.parse(args.inject)
            _check_icc(settings)
            _check_scan(args)
            if args.proof and not args.preview:
                raise ValueError("--proof: the proof is written as --preview PNG; give both")
            if args.spectro_out and not SPECTRO_DPI[0] <= args.spectro_dpi <= SPECTRO_DPI[1]:
                raise ValueError(f"--spectro-dpi {args.spectro_dpi}: must be "
                                 f"{SPECTRO_DPI[0]}..{SPECTRO_DPI[1]}")
            _check_output_folders(report=args.report, media_out=args.media_out,
                                  preview=args.preview, log_json=args.log_json,
                                  event_log=args.event_log, scan_out=args.scan_out,
                                  spectro_out=args.spectro_out)
        except (ValueError, OSError) as exc:
            return EXIT_USAGE, str(exc)
        return self.check_emulator_options()

    def check_emulator_options(self) -> tuple[int, str] | None:
        from ..devices import is_emulator_spec
        args = self.args
        emulator = is_emulator_spec(args.device)
        if args.inject and not emulator:
            return EXIT_USAGE, (f"--inject needs an emulated device (--device emulator, "
                                f"emulator-usb or emulator-pci), not {args.device}")
        only_emulator = [o for o, v in (("--media-out", args.media_out),
                                        ("--preview", args.preview and not args.proof),
                                        ("--event-log", args.event_log), ("--vcd", args.vcd),
                                        ("--latched-out", args.latched_out),
                                        ("--scan-out", args.scan_out),
                                        ("--spectro-out", args.spectro_out)) if v]
        if only_emulator and not emulator:
            # a standalone emulator writes its media in its own process (`wideprint emulator
            # --media-out`); a real printer has none
            return EXIT_USAGE, (f"{', '.join(only_emulator)} "
                                f"{'needs' if len(only_emulator) == 1 else 'need'} the "
                                f"in-process emulator (--device emulator); with --device "
                                f"{args.device} the media is written by the device: "
                                f"`wideprint emulator --media-out MEDIA_{{job}}.tif`")
        return None

    def open_device(self) -> tuple[int, str] | None:
        """The device opened and reached (a port that is open but silent: exit 3); a
        scratch folder for the media when only its --preview is wanted."""
        from ...driver.link import LinkError
        from ...driver.printer import Printer
        from ..devices import open_device
        args = self.args
        if args.preview and not args.media_out and not args.proof:
            self.scratch = tempfile.TemporaryDirectory(prefix="wideprint-")
        try:
            scan: dict = dict(scan_path=self.scans.get, scan_dpi=args.scan_dpi) \
                if args.scan_out else {}
            if args.spectro_out:
                scan.update(spectro_path=self.spectros.get, spectro_dpi=args.spectro_dpi)
            self.dev = open_device(args.device, self.profile, self.faults,
                                   media_path=self.media.get, event_log=args.event_log,
                                   **_emulator_options(args), **scan)
        except (LinkError, ValueError, OSError) as exc:
            self.drop_scratch()
            return EXIT_DEVICE, str(exc)
        try:
            Printer(self.dev).connect()
        except LinkError as exc:
            _close_device(self.dev, args)
            self.drop_scratch()
            return EXIT_DEVICE, str(exc)
        return None

    def nest(self) -> None:
        """--nest: one job per nest of files (docs/layout.md); else one job a file."""
        self.extras = [()] * len(self.files)
        if self.settings.placement.nest:
            self.files, self.extras = _nest_files(self.files, self.unlisted, self.settings,
                                                  self.profile)

    def interrupt(self, signum, frame) -> None:
        """First Ctrl-C: cancel (the line stops, the carriage parks); second: emergency stop."""
        job = self.current.get("job")
        if job is None:
            raise KeyboardInterrupt
        if job.control.cancelled.is_set():
            print("\nemergency stop", file=sys.stderr)
            job.control.estop()
        else:
            print("\ncancelling (Ctrl-C again for an emergency stop)", file=sys.stderr)
            job.control.cancel()

    # -- one job ------------------------------------------------------------------------------
    def print_file(self, i: int, f: str, job_id: int) -> bool:
        """File `f` (and the files nested with it) ripped and printed as job `job_id`, its
        report added; False when the run stops here (the job was cancelled)."""
        media_file = self.job_outputs(i, job_id)
        prepared = self.prepare(i, f, job_id)
        if prepared is None:
            return True
        rip, cut_report = prepared
        label = f"{i + 1}/{len(self.files)} {shown(Path(f).name, 60)}" \
            + (f" +{len(self.extras[i])} nested" if self.extras[i] else "")
        run = self.run_job(rip, job_id, f, label)
        rep = dict(run.report, job_id=job_id)
        if cut_report is not None:
            rep["cut"] = cut_report
            print(f"{shown(f, NAME_LIMIT)}: cut file {shown(cut_report['file'])}: "
                  f"{cut_report['paths']} path{'s' if cut_report['paths'] != 1 else ''}, "
                  f"{cut_report['length_mm'] / 1000:.3f} m, {cut_report['marks']} marks",
                  file=self.say)
        if run.state == "cancelled":
            progress(0, 1, "", final=True)
            self.job_failed(f, run.message, rep, "CANCELLED")
            return False
        if run.state != "done":
            progress(0, 1, f"{label} failed", final=True)
            self.job_failed(f, run.message, rep)
            return True
        progress(1, 1, f"{label} done", final=True)
        self.printed(i, f, job_id, rip, rep, media_file)
        self.reports.append(rep)
        return True

    def prepare(self, i: int, f: str, job_id: int) -> tuple[Any, dict | None] | None:
        """Job i's RipJob and, for print and cut, its cut file written before printing (a
        file without cut paths is said then); None when it cannot print (failed, said)."""
        from ...rip.load import ImageError
        from ...rip.pipeline import RipJob
        if f in self.unlisted:
            self.job_failed(f, self.unlisted[f], dict(job_id=job_id))
            return None
        try:
            rip = RipJob(f, self.settings, self.profile, more=self.extras[i])
        except (ImageError, ValueError, OSError) as exc:
            self.job_failed(f, str(exc), dict(job_id=job_id))
            return None
        if not self.args.cut_out:
            return rip, None
        from ...rip.cutfile import write_job_cut
        try:
            return rip, write_job_cut(str(self.output(self.args.cut_out, i)), rip,
                                      self.settings, self.profile)
        except (ValueError, OSError) as exc:
            rip.close()
            self.job_failed(f, f"cut file: {exc}", dict(job_id=job_id))
            return None

    def output(self, pattern: str | None, i: int) -> str | None:
        """Job i's file of an output option (-N suffix or {job} with several files)."""
        return _media_path(pattern, i, len(self.files))

    def job_outputs(self, i: int, job_id: int) -> str | None:
        """Where job i's media, scan and spectro go; returns the media's file."""
        media_file = self.output(self.args.media_out, i)
        if media_file is None and self.scratch is not None:    # --preview alone: drawn from this
            media_file = os.path.join(self.scratch.name, f"media-{i + 1}.tif")
        self.media[job_id] = media_file
        self.scans[job_id] = self.output(self.args.scan_out, i)
        self.spectros[job_id] = self.output(self.args.spectro_out, i)
        return media_file

    def run_job(self, rip, job_id: int, f: str, label: str):
        """The job printed (app/api.run_job: its state, message and report), its progress
        on the terminal and in --log-json."""
        from ..api import run_job
        log_json = self.log_json

        def on_event(kind, label=label, job_id=job_id, file=f, **kw):
            if kind == "stroke":                    # a progress bar on a terminal
                # the count before the file name: a terminal cuts the line's end
                # (a 45-character name on 100 columns showed "stroke 4 of 1" for 14)
                progress(kw["index"], kw["total"],
                         f"stroke {kw['index'] + 1} of {kw['total']}  {label}")
            if log_json is not None:                # structured log: one JSON object a line
                import dataclasses
                data = {k: (dataclasses.asdict(v) if dataclasses.is_dataclass(v) else v)
                        for k, v in kw.items()}
                log_json.write(json.dumps({"time": round(time.time(), 3), "job": job_id,
                                           "file": file, "event": kind, **data},
                                          default=str) + "\n")
                log_json.flush()
        run = run_job(self.dev, rip, job_id, on_event=on_event, internal_errors=True,
                      on_job=lambda job: self.current.__setitem__("job", job))
        return run

    def job_failed(self, f: str, message: str, rep: dict | None = None,
                   what: str = "FAILED") -> None:
        """A job that did not print (or was cancelled): said, counted and reported."""
        rep = dict(rep or {}, file=f, state="cancelled" if what == "CANCELLED" else "failed",
                   message=message)
        said = shown(message)
        if message.startswith(f + ": "):           # the loader's "NAME: problem"
            said = f"{shown(f, NAME_LIMIT)}: {shown(message[len(f) + 2:])}"
        print(f"{shown(f, NAME_LIMIT)}: {what}: {said}", file=sys.stderr)
        self.failed += 1
        self.reports.append(rep)

    def printed(self, i: int, f: str, job_id: int, rip, rep: dict, media_file: str | None) -> None:
        """A job that printed: its outputs checked and said, the preview or proof drawn."""
        self.check_outputs(f, job_id, rep, media_file)
        self.say_printed(i, f, rip, rep)
        args = self.args
        if args.preview and args.proof:
            if not _proof(f, self.output(args.preview, i) or args.preview,
                          self.settings, self.profile, rep, self.say):
                self.failed += 1
        elif args.preview:
            preview = self.output(args.preview, i)
            # the media's file: --media-out's, else the scratch folder's (open_device)
            assert media_file is not None and preview is not None
            self.preview(f, media_file, preview, rep)

    def check_outputs(self, f: str, job_id: int, rep: dict, media_file: str | None) -> None:
        """The media, scan and spectro files in the report; a media file asked for and not
        written fails the job although it printed."""
        args = self.args
        emu = self.dev.emulator                     # the in-process emulator, or None
        rep["media"] = media_file if args.media_out else None
        media_error = (emu.jobs_done.get(job_id, {}).get("media_error")
                       if emu is not None else None)
        if media_error:             # printed, but the media file asked for is missing
            self.failed += 1
            rep["media"], rep["media_error"] = None, media_error
            print(f"{shown(f, NAME_LIMIT)}: media not written: {shown(media_error)}",
                  file=sys.stderr)
        if args.scan_out:
            rep["scan"] = self.scans[job_id]
        if args.spectro_out:
            rep["spectro"] = self.spectros[job_id]
        if emu is not None:
            rep["stray_drops"] = emu.jobs_done.get(job_id, {}).get("stray")

    def say_printed(self, i: int, f: str, rip, rep: dict) -> None:
        """What printed: strokes, dots, ink and files; the spots and the layout."""
        say = self.say
        print(f"{shown(f, NAME_LIMIT)}: printed {rep['strokes_printed']} strokes, "
              f"{rep['width_dots']} x {rep['height_rows']} dots, "
              f"ink C/M/Y/K {'/'.join(f'{v:.4f}' for v in rep['ink_ml'])} ml"
              + (f" -> {shown(rep['media'])}" if rep["media"] else "")
              + (f", scan {shown(rep['scan'])}" if rep.get("scan") else "")
              + (f", spectro {shown(rep['spectro'])}" if rep.get("spectro") else ""),
              file=say)
        if rep.get("spots"):                # docs/spot.md "The job's report"
            from .spot import summary
            print(f"{shown(f, NAME_LIMIT)}: spots: {shown(summary(rep['spots']), 400)}", file=say)
        if rip.layout is not None:
            from ...rip.layout import layout_line
            rep["files"] = [f, *self.extras[i]]
            print(f"{shown(f, NAME_LIMIT)}: {layout_line(rep['layout'])}", file=say)

    def preview(self, f: str, media_file: str, preview: str, rep: dict) -> None:
        """--preview: the media drawn as a PNG; the media file goes after unless asked for."""
        from ...rip.planes import write_preview
        try:
            write_preview(media_file, preview)
            rep["preview"] = preview
        except (OSError, ValueError) as exc:
            self.failed += 1             # printed, but an output asked for is missing
            strerror = getattr(exc, "strerror", None)
            why = f"{strerror} ({preview})" if strerror else str(exc)
            rep["preview_error"] = why
            print(f"{shown(f, NAME_LIMIT)}: preview not written: {shown(why)}",
                  file=sys.stderr)
        finally:
            if not self.args.media_out:
                with contextlib.suppress(OSError):
                    os.unlink(media_file)

    # -- the end ------------------------------------------------------------------------------
    def close(self) -> None:
        try:
            _close_device(self.dev, self.args)
        finally:
            if self.log_json is not None:
                self.log_json.close()
            self.drop_scratch()

    def drop_scratch(self) -> None:
        if self.scratch is not None:
            self.scratch.cleanup()

    def summary(self) -> int:
        code = self.finish(EXIT_JOB_FAILED if self.failed else EXIT_OK)
        done = sum(1 for r in self.reports if r.get("state") == "done")
        print(f"summary: {done} of {len(self.files)} printed, {self.failed} failed", file=self.say)
        return code

    def refuse(self, code: int, message: str) -> int:
        """Nothing printed: every file failed with why."""
        print(f"wideprint print: {shown(message)}", file=sys.stderr)
        self.reports.extend(dict(file=f, state="failed", message=f"not printed: {message}")
                            for f in self.files)
        return self.finish(code)

    def finish(self, code: int) -> int:
        """--report and --json (files not reached: failed, with why)."""
        args = self.args
        if args.report:
            try:
                Path(args.report).write_text(json.dumps(self.reports, indent=2) + "\n")
            except OSError as exc:
                print(f"wideprint print: cannot write the report {shown(args.report)}: "
                      f"{exc.strerror or exc}", file=sys.stderr)
                code = code or EXIT_JOB_FAILED
        if args.json:
            print(json.dumps(self.reports, indent=2))
        return code


def cmd_print(args) -> int:
    return PrintCommand(args).run()


def add_parser(sub) -> None:
    p = sub.add_parser("print", help="rip and print files")
    p.add_argument("files", nargs="+", metavar="FILE", help="images (TIFF/JPEG/PNG/BMP), PDF, PostScript, "
                   "EPS, HP RTL, or folders")
    p.add_argument("--device", default="emulator",
                   help=devices.DEVICE_HELP + " (default: emulator)")
    p.add_argument("--media-out", metavar="MEDIA.tif",
                   help="emulator only: write the printed media (with several files: -N suffix or {job})")
    p.add_argument("--inject", action="append", metavar="KIND=VALUE", help="emulator fault")
    p.add_argument("--preview", metavar="PNG", help="emulator only: a PNG picture of the media")
    p.add_argument("--proof", action="store_true",
                   help="--preview is the soft proof instead (any device): the job as its media "
                   "prints it, through the media's ICC profile, out-of-gamut areas striped "
                   "grey; the report gives the share out of gamut (docs/color.md)")
    p.add_argument("--report", metavar="JSON", help="write the job reports")
    p.add_argument("--json", action="store_true", help="print the job reports as JSON")
    p.add_argument("--event-log", metavar="JSONL", help="emulator event log")
    p.add_argument("--log-json", metavar="JSONL",
                   help="structured job log: states, strokes, status, recoveries (JSON lines)")
    _emulator_outputs(p)
    _scan_options(p, several=True)
    p.add_argument("--cut-out", metavar="CUT.plt",
                   help="print and cut: write the paths drawn in a cut spot colour (CutContour, "
                   "...) as a cut file, .plt/.hpgl (HP-GL/2) or .dxf, in the printed sheet's "
                   "millimetres; turns on --marks cut unless other marks are asked for "
                   "(docs/cut.md; with several files: -N suffix or {job})")
    p.add_argument("--spectro-out", metavar="LAB.tif",
                   help="emulator only: the print measured by a spectrophotometer, float32 "
                   "CIELAB (D50, 2°, M0) over the image area (docs/physical.md); with several "
                   "files: -N suffix or {job}")
    p.add_argument("--spectro-dpi", type=int, default=50, metavar="N",
                   help="resolution of --spectro-out (default 50: a 0.5 mm aperture; 10..300)")
    _rip_options(p)
    p.set_defaults(func=cmd_print)
