"""`wideprint print FILE...`: rip and print files on a printer or the emulator, one job a
file (or a nest of files), with the report, the media, preview, scan and cut files asked for."""

from __future__ import annotations

import contextlib
import json
import signal
import sys
import time
from pathlib import Path

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


def cmd_print(args) -> int:
    import os
    import tempfile
    from ...device_sim.faults import Faults
    from ..api import run_job
    from ..devices import is_emulator_spec, open_device
    from ...driver.link import LinkError
    from ...driver.printer import Printer
    from ...rip.load import ImageError
    from ...rip.pipeline import RipJob
    _collector_on()

    files, unlisted = _expand(args.files)
    reports: list[dict] = []

    def finish(code: int) -> int:
        """Every exit writes --report and --json (files not reached: failed, with why)."""
        if args.report:
            try:
                Path(args.report).write_text(json.dumps(reports, indent=2) + "\n")
            except OSError as exc:
                print(f"wideprint print: cannot write the report {shown(args.report)}: "
                      f"{exc.strerror or exc}", file=sys.stderr)
                code = code or EXIT_JOB_FAILED
        if args.json:
            print(json.dumps(reports, indent=2))
        return code

    def refuse(code: int, message: str) -> int:
        print(f"wideprint print: {shown(message)}", file=sys.stderr)
        reports.extend(dict(file=f, state="failed", message=f"not printed: {message}")
                       for f in files)
        return finish(code)

    if files and all(unlisted.get(f, "").endswith(NO_FILES) for f in files):
        return refuse(EXIT_USAGE, "; ".join(unlisted[f] for f in files))
    emulator = is_emulator_spec(args.device)
    try:
        from .media import job_settings
        profile, settings = job_settings(args, _profile(args))
        if args.cut_out:                        # print and cut (docs/cut.md)
            from ...rip.cut import wants_cut_marks
            from ...rip.cutfile import cut_format
            cut_format(args.cut_out)
            settings = wants_cut_marks(settings)
        faults = Faults.parse(args.inject)
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
        return refuse(EXIT_USAGE, str(exc))
    if args.inject and not emulator:
        return refuse(EXIT_USAGE, f"--inject needs an emulated device (--device emulator, "
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
        return refuse(EXIT_USAGE, f"{', '.join(only_emulator)} "
                      f"{'needs' if len(only_emulator) == 1 else 'need'} the in-process emulator "
                      f"(--device emulator); with --device {args.device} the media is written "
                      f"by the device: `wideprint emulator --media-out MEDIA_{{job}}.tif`")
    media: dict[int, str | None] = {}
    scans: dict[int, str | None] = {}
    spectros: dict[int, str | None] = {}
    scratch = tempfile.TemporaryDirectory(prefix="wideprint-") \
        if args.preview and not args.media_out and not args.proof else None
    try:
        scan = dict(scan_path=lambda job: scans.get(job), scan_dpi=args.scan_dpi) \
            if args.scan_out else {}
        if args.spectro_out:
            scan.update(spectro_path=lambda job: spectros.get(job), spectro_dpi=args.spectro_dpi)
        dev = open_device(args.device, profile, faults, media_path=lambda job: media.get(job),
                          event_log=args.event_log, **_emulator_options(args), **scan)
    except (LinkError, ValueError, OSError) as exc:
        if scratch:
            scratch.cleanup()
        return refuse(EXIT_DEVICE, str(exc))
    try:                          # reachable at all? (a port that is open but silent: exit 3)
        Printer(dev).connect()
    except LinkError as exc:
        _close_device(dev, args)
        if scratch:
            scratch.cleanup()
        return refuse(EXIT_DEVICE, str(exc))
    failed = 0
    say = sys.stderr if args.json else sys.stdout     # --json keeps stdout machine-readable
    log_json = open(args.log_json, "a") if args.log_json else None
    current: dict = {}
    base = cli_job_base()

    def interrupt(signum, frame):
        """First Ctrl-C: cancel (the line stops, the carriage parks); second: emergency stop."""
        job = current.get("job")
        if job is None:
            raise KeyboardInterrupt
        if job.control.cancelled.is_set():
            print("\nemergency stop", file=sys.stderr)
            job.control.estop()
        else:
            print("\ncancelling (Ctrl-C again for an emergency stop)", file=sys.stderr)
            job.control.cancel()
    signal.signal(signal.SIGINT, interrupt)

    def job_failed(f: str, message: str, rep: dict | None = None, what: str = "FAILED") -> dict:
        rep = dict(rep or {}, file=f, state="cancelled" if what == "CANCELLED" else "failed",
                   message=message)
        said = shown(message)
        if message.startswith(f + ": "):           # the loader's "NAME: problem"
            said = f"{shown(f, NAME_LIMIT)}: {shown(message[len(f) + 2:])}"
        print(f"{shown(f, NAME_LIMIT)}: {what}: {said}", file=sys.stderr)
        return rep

    extras: list[tuple] = [()] * len(files)
    if settings.placement.nest:           # one job per nest of files (docs/layout.md)
        files, extras = _nest_files(files, unlisted, settings, profile)
    try:
        for i, f in enumerate(files):
            job_id = base + i
            media_file = _media_path(args.media_out, i, len(files))
            if media_file is None and scratch is not None:    # --preview alone: drawn from this
                media_file = os.path.join(scratch.name, f"media-{i + 1}.tif")
            media[job_id] = media_file
            scans[job_id] = _media_path(args.scan_out, i, len(files))
            spectros[job_id] = _media_path(args.spectro_out, i, len(files))
            if f in unlisted:
                failed += 1
                reports.append(job_failed(f, unlisted[f], dict(job_id=job_id)))
                continue
            try:
                rip = RipJob(f, settings, profile, more=extras[i])
            except (ImageError, ValueError, OSError) as exc:
                failed += 1
                reports.append(job_failed(f, str(exc), dict(job_id=job_id)))
                continue
            cut_report = None
            if args.cut_out:                    # before printing: a file without cut paths is said
                from ...rip.cutfile import write_job_cut
                try:
                    cut_report = write_job_cut(str(_media_path(args.cut_out, i, len(files))), rip,
                                               settings, profile)
                except (ValueError, OSError) as exc:
                    rip.close()
                    failed += 1
                    reports.append(job_failed(f, f"cut file: {exc}", dict(job_id=job_id)))
                    continue
            label = f"{i + 1}/{len(files)} {shown(Path(f).name, 60)}" \
                + (f" +{len(extras[i])} nested" if extras[i] else "")

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
            run = run_job(dev, rip, job_id, on_event=on_event, internal_errors=True,
                          on_job=lambda job: current.__setitem__("job", job))
            rep = dict(run.report, job_id=job_id)
            if cut_report is not None:
                rep["cut"] = cut_report
                print(f"{shown(f, NAME_LIMIT)}: cut file {shown(cut_report['file'])}: "
                      f"{cut_report['paths']} path{'s' if cut_report['paths'] != 1 else ''}, "
                      f"{cut_report['length_mm'] / 1000:.3f} m, {cut_report['marks']} marks",
                      file=say)
            if run.state == "cancelled":
                progress(0, 1, "", final=True)
                failed += 1
                reports.append(job_failed(f, run.message, rep, "CANCELLED"))
                break
            if run.state != "done":
                progress(0, 1, f"{label} failed", final=True)
                failed += 1
                rep = job_failed(f, run.message, rep)
            else:
                progress(1, 1, f"{label} done", final=True)
                rep["media"] = media_file if args.media_out else None
                media_error = (dev.emulator.jobs_done.get(job_id, {}).get("media_error")
                               if dev.emulator is not None else None)
                if media_error:             # printed, but the media file asked for is missing
                    failed += 1
                    rep["media"], rep["media_error"] = None, media_error
                    print(f"{shown(f, NAME_LIMIT)}: media not written: {shown(media_error)}",
                          file=sys.stderr)
                if args.scan_out:
                    rep["scan"] = scans[job_id]
                if args.spectro_out:
                    rep["spectro"] = spectros[job_id]
                if dev.emulator is not None:
                    rep["stray_drops"] = dev.emulator.jobs_done.get(job_id, {}).get("stray")
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
                    rep["files"] = [f, *extras[i]]
                    print(f"{shown(f, NAME_LIMIT)}: {layout_line(rep['layout'])}", file=say)
                if args.preview and args.proof:
                    if not _proof(f, _media_path(args.preview, i, len(files)) or args.preview,
                                  settings, profile, rep, say):
                        failed += 1
                elif args.preview:
                    from ...rip.planes import write_preview
                    preview = _media_path(args.preview, i, len(files))
                    try:
                        write_preview(media_file, preview)
                        rep["preview"] = preview
                    except (OSError, ValueError) as exc:
                        failed += 1             # printed, but an output asked for is missing
                        why = f"{exc.strerror} ({preview})" if getattr(exc, "strerror", None) \
                            else str(exc)
                        rep["preview_error"] = why
                        print(f"{shown(f, NAME_LIMIT)}: preview not written: {shown(why)}",
                              file=sys.stderr)
                    finally:
                        if not args.media_out:
                            with contextlib.suppress(OSError):
                                os.unlink(media_file)
            reports.append(rep)
    finally:
        try:
            _close_device(dev, args)
        finally:
            if log_json is not None:
                log_json.close()
            if scratch is not None:
                scratch.cleanup()
    code = finish(EXIT_JOB_FAILED if failed else EXIT_OK)
    done = sum(1 for r in reports if r.get("state") == "done")
    print(f"summary: {done} of {len(files)} printed, {failed} failed", file=say)
    return code



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
