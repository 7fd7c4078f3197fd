"""`wideprint` command line (README "Command line"; contract in docs/cli.md)."""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import time
from pathlib import Path

EXIT_OK, EXIT_JOB_FAILED, EXIT_USAGE, EXIT_DEVICE = 0, 1, 2, 3


def _rip_options(p: argparse.ArgumentParser) -> None:
    """The RIP and placement options: from the one settings schema (rip/settings.py)."""
    from ..rip.settings import add_arguments
    p.add_argument("--profile", metavar="TOML",
                   help="printer profile (default: resources/printers/default.toml)")
    p.add_argument("--threads", type=int, metavar="N",
                   help="the RIP's worker threads (default: $WIDEPRINT_THREADS, else one a core "
                   "this process may use); the result is the same whatever the count")
    add_arguments(p)


def _emulator_outputs(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vcd", metavar="FILE.vcd", help="emulator: waveform of the head interface "
                   "and encoder for --vcd-window (GTKWave)")
    p.add_argument("--vcd-window", default="0:0:0:8", metavar="STROKE:HEAD:FIRST:COUNT",
                   help="which fires go into the VCD (head index 0-7; default 0:0:0:8)")
    p.add_argument("--latched-out", metavar="FILE.npz",
                   help="emulator: the 128-bit words every head latched, per stroke")


def _scan_options(p: argparse.ArgumentParser, several: bool) -> None:
    p.add_argument("--scan-out", metavar="SCAN.tif",
                   help="emulator only: a scan of the print from the physical drop model "
                   "(docs/physical.md)" + ("; with several files: -N suffix or {job}" if several else ""))
    p.add_argument("--scan-dpi", type=int, default=1200, metavar="N",
                   help="resolution of --scan-out (default 1200; 600 or 1200 as a flatbed scans)")


SCAN_DPI = (50, 9600)
SPECTRO_DPI = (10, 300)      # device_sim/spectro.py SPECTRO_DPI (not imported: --help stays light)


def _check_scan(args) -> None:
    if args.scan_out and not SCAN_DPI[0] <= args.scan_dpi <= SCAN_DPI[1]:
        raise ValueError(f"--scan-dpi {args.scan_dpi}: must be {SCAN_DPI[0]}..{SCAN_DPI[1]}")


def _emulator_options(args) -> dict:
    opts = {}
    if getattr(args, "vcd", None):
        try:
            window = tuple(int(v) for v in args.vcd_window.split(":"))
            assert len(window) == 4
        except (ValueError, AssertionError):
            raise ValueError(f"--vcd-window {args.vcd_window!r}: expected STROKE:HEAD:FIRST:COUNT") from None
        opts.update(vcd_path=args.vcd, vcd_window=window)
    if getattr(args, "latched_out", None):
        opts["record_latched"] = True
    return opts


def _save_latched(printer, path: str) -> None:
    np_arrays = {f"stroke{i}": printer.latched_words(i) for i in sorted(printer.latched)}
    import numpy as np
    np.savez_compressed(path, **np_arrays)


def _close_device(dev, args) -> None:
    """Emulator outputs are complete once it is closed (app/devices.close_device); then
    the latched words asked for are saved."""
    from .devices import close_device
    close_device(dev)
    if dev.emulator is not None and getattr(args, "latched_out", None):
        _save_latched(dev.emulator, args.latched_out)


def _settings(args, profile):
    """RipSettings from the options given, the schema's defaults for the rest, checked
    against the printer profile (ValueError naming the setting)."""
    from ..rip.settings import from_mapping, mapping_from_args
    return from_mapping(mapping_from_args(args), profile)


def _profile(args):
    from ..rip.profile import load_profile
    return load_profile(args.profile)


def _media_path(pattern: str | None, index: int, count: int) -> str | None:
    if not pattern:
        return None
    if "{job}" in pattern:
        return pattern.replace("{job}", str(index + 1))
    if count == 1:
        return pattern
    p = Path(pattern)
    return str(p.with_name(f"{p.stem}-{index + 1}{p.suffix}"))


NAME_LIMIT = 400      # characters of a file name shown on the terminal
_BIDI_CONTROLS = set(range(0x202A, 0x202F)) | set(range(0x2066, 0x206A)) | {0x200E, 0x200F, 0x061C}


def shown(text, limit: int | None = None) -> str:
    """A file name (or a message holding one) safe to print on a terminal: control and
    bidirectional-override characters and the undecodable bytes of a non-UTF-8 name
    (surrogate escapes) are written as \\xNN / \\uNNNN, never sent raw.  `limit`: a longer
    text keeps its start and end (a path can be longer than a screen)."""
    import unicodedata
    text = str(text)
    if limit is not None and len(text) > limit:
        cut = len(text) - limit
        text = f"{text[:limit // 2]}...({cut} characters)...{text[-(limit // 2):]}"
    out = []
    for ch in text:
        o = ord(ch)
        if 0xDC80 <= o <= 0xDCFF:                    # a byte of a non-UTF-8 file name
            out.append(f"\\x{o - 0xDC00:02x}")
        elif o < 0x20 or 0x7F <= o < 0xA0:
            out.append(f"\\x{o:02x}")
        elif o in _BIDI_CONTROLS or unicodedata.category(ch) in ("Cs", "Zl", "Zp"):
            out.append(f"\\u{o:04x}")
        else:
            out.append(ch)
    return "".join(out)


def cli_job_base() -> int:
    """The printer job id of this run's first job (the next files count on from it).  Ids
    differ between runs - hundredths of a second, wrapping after about 347 days - so a
    standalone emulator's `{job}` media names are not reused by the next run; they are
    at least 1e9, above the print server's queue ids (docs/formats.md)."""
    return 1_000_000_000 + int(time.time() * 100) % 3_000_000_000


def _check_icc(settings) -> None:
    """A missing or unusable --input-icc / --output-icc is a bad option (ValueError),
    refused before any job; whether a profile fits an image's colour space is the job's."""
    from ..rip.color import Separator
    if settings.input_icc is not None:      # CMYK pass-through still reads and checks it
        Separator("cmyk", 8, input_icc=settings.input_icc)
    if settings.output_icc is not None:
        Separator("cmyk", 8, output_icc=settings.output_icc)


def _check_output_folders(**paths) -> None:
    """Output files must have a folder to go to: said before anything prints."""
    import os
    for option, path in paths.items():
        if not path:
            continue
        folder = os.path.dirname(path) or "."
        if os.path.isdir(path):
            raise ValueError(f"--{option.replace('_', '-')} {shown(path)} is a folder, not a file")
        if not os.path.isdir(folder):
            raise ValueError(f"--{option.replace('_', '-')} {shown(path)}: no folder {shown(folder)}")
        if not os.access(folder, os.W_OK):
            raise ValueError(f"--{option.replace('_', '-')} {shown(path)}: folder {shown(folder)} "
                             f"is not writable")


def cmd_rip(args) -> int:
    from ..rip.load import ImageError
    from ..rip.pipeline import RipJob
    from ..rip.planes import output_file
    _collector_on()
    try:
        from .media_cli import job_settings
        profile, settings = job_settings(args, _profile(args))
        _check_icc(settings)
        _check_output_folders(output=args.output, preview=args.preview)
        if args.proof and not args.preview:
            raise ValueError("--proof: the proof is written as --preview PNG; give both")
    except (ValueError, OSError) as exc:
        print(f"wideprint rip: {shown(exc)}", file=sys.stderr)
        return EXIT_USAGE
    job = None
    try:
        job = RipJob(args.file, settings, profile)
        # a temporary name, renamed when complete: a failed rip leaves no partial file
        with output_file(args.output) as tmp:
            dots = job.write_planes(tmp, args.planes_format)
    except (ImageError, ValueError, OSError) as exc:
        print(f"wideprint rip: {shown(exc)}", file=sys.stderr)
        return EXIT_JOB_FAILED
    except Exception as exc:  # noqa: BLE001 - a message, not a traceback
        print(f"wideprint rip: {shown(args.file, NAME_LIMIT)}: internal error: "
              f"{type(exc).__name__}: {shown(exc)}", file=sys.stderr)
        return EXIT_JOB_FAILED
    finally:
        if job is not None:
            job.close()
    say = sys.stderr if _is_stdout(args.output) else sys.stdout      # -o /dev/stdout
    print(f"{shown(args.output)}: {job.width} x {job.height} dots at {job.settings.dpi} x "
          f"{job.dpi_y:.1f} dpi, drops C {dots[0]} M {dots[1]} Y {dots[2]} K {dots[3]}",
          file=say)
    if args.preview and args.proof:
        return EXIT_OK if _proof(args.file, args.preview, settings, profile, {}, say) \
            else EXIT_JOB_FAILED
    if args.preview:
        from ..rip.planes import write_preview
        try:
            write_preview(args.output, args.preview)
        except (OSError, ValueError) as exc:
            print(f"wideprint rip: preview not written: {shown(exc)}", file=sys.stderr)
            return EXIT_JOB_FAILED
    return EXIT_OK


def _proof(f: str, png: str, settings, profile, rep: dict, say) -> bool:
    """`--preview PNG --proof`: the soft proof of file `f` through its media profile with
    the gamut warning (app/softproof.py), and its out-of-gamut share in the report."""
    from ..rip.load import ImageError
    from .jobpreview import proof_job
    from .softproof import GAMUT_DE2000, write_proof
    try:
        proof = proof_job(f, settings, profile)
        write_proof(proof, png)
    except (ImageError, ValueError, OSError) as exc:
        why = f"{exc.strerror} ({png})" if isinstance(exc, OSError) and exc.strerror \
            else str(exc)
        rep["preview_error"] = why
        print(f"{shown(f, NAME_LIMIT)}: proof not written: {shown(why)}", file=sys.stderr)
        return False
    rep.update(preview=png, proof_icc=proof.media_icc, out_of_gamut=proof.share)
    gamut = "not checked (device colours)" if proof.share is None else \
        f"{100 * proof.share:.1f} % of the image out of gamut (ΔE2000 > {GAMUT_DE2000:g})"
    print(f"{shown(f, NAME_LIMIT)}: proof {shown(png)} through {shown(proof.media_icc)}: {gamut}",
          file=say)
    return True


def _is_stdout(path: str) -> bool:
    import os
    try:
        return os.path.samestat(os.stat(path), os.fstat(sys.stdout.fileno()))
    except (OSError, ValueError, AttributeError):
        return False


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
    from ..rip.layout import nest_sheets
    sheets, waiting, bad = nest_sheets([f for f in files if f not in unlisted], settings, profile)
    unlisted.update(bad)
    sheets += [waiting] if waiting else []
    alone = [f for f in files if f in unlisted]
    return alone + [s[0] for s in sheets], [()] * len(alone) + [tuple(s[1:]) for s in sheets]


def cmd_print(args) -> int:
    import os
    import tempfile
    from ..device_sim.faults import Faults
    from .api import run_job
    from .devices import is_emulator_spec, open_device
    from ..driver.link import LinkError
    from ..driver.printer import Printer
    from ..rip.load import ImageError
    from ..rip.pipeline import RipJob
    from .server_cli import progress
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
        from .media_cli import job_settings
        profile, settings = job_settings(args, _profile(args))
        if args.cut_out:                        # print and cut (docs/cut.md)
            from ..rip.cut import wants_cut_marks
            from ..rip.cutfile import cut_format
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
                from ..rip.cutfile import write_job_cut
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
                    from .spot_cli import summary
                    print(f"{shown(f, NAME_LIMIT)}: spots: {shown(summary(rep['spots']), 400)}", file=say)
                if rip.layout is not None:
                    from ..rip.layout import layout_line
                    rep["files"] = [f, *extras[i]]
                    print(f"{shown(f, NAME_LIMIT)}: {layout_line(rep['layout'])}", file=say)
                if args.preview and args.proof:
                    if not _proof(f, _media_path(args.preview, i, len(files)) or args.preview,
                                  settings, profile, rep, say):
                        failed += 1
                elif args.preview:
                    from ..rip.planes import write_preview
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


def cmd_test_print(args) -> int:
    from ..device_sim.faults import Faults
    from .devices import is_emulator_spec, open_device
    from ..driver.job import JobError, PrintJob
    from ..driver.link import LinkError
    from ..rip.testprints import PatternJob
    if args.scan_out and not is_emulator_spec(args.device):
        print(f"wideprint test-print: --scan-out needs the in-process emulator (--device emulator): "
              f"a scan of a real print comes from a scanner", file=sys.stderr)
        return EXIT_USAGE
    try:
        _check_scan(args)
        profile = _profile(args)
        if args.thesis:
            profile = _thesis_line(args, profile)
        faults = Faults.parse(args.inject)
        k = profile.k(args.dpi)
        width = int(round(args.width_mm / 25.4 * profile.counts_per_inch / k))
        weave = dict(passes=args.passes, pass_mask=args.pass_mask, bidir=args.bidir)
        job = PatternJob.for_pattern(args.pattern, profile, width, args.dpi, head=args.head,
                                     nozzle=args.nozzle, **weave)
    except ValueError as exc:
        print(f"wideprint test-print: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.planes_out:
        job.write_planes(args.planes_out)
    try:
        scan = dict(scan_path=args.scan_out, scan_dpi=args.scan_dpi) if args.scan_out else {}
        dev = open_device(args.device, profile, faults, media_path=args.media_out,
                          event_log=args.event_log, **_emulator_options(args), **scan)
    except (LinkError, ValueError, OSError) as exc:
        print(f"wideprint test-print: {exc}", file=sys.stderr)
        return EXIT_DEVICE
    try:
        rep = PrintJob(dev, job, speed_mm_s=args.speed).run()
        if args.preview and args.media_out:
            from ..rip.planes import write_preview
            write_preview(args.media_out, args.preview)
        print(f"{args.pattern}: printed {rep.strokes_printed} strokes, {job.width} x {job.height} dots"
              + (f" -> {args.media_out}" if args.media_out else "")
              + (f", scan {args.scan_out}" if args.scan_out else ""))
        if args.thesis and dev.emulator is not None:
            for e in (e for e in dev.emulator.events if e.get("event") == "line"):
                print(f"thesis line, stroke {e['stroke']}: servo every {e['servo_period_s'] * 1e3:g} ms; "
                      f"max following error {e['max_following_error']:.2f} counts, final "
                      f"position error {e['final_error']:+.2f} counts, peak current "
                      f"{e['peak_current_a']:.3f} A; {e['fired']} of {e['fires']} columns fired")
        return EXIT_OK
    except JobError as exc:
        print(f"{args.pattern}: FAILED: {exc}", file=sys.stderr)
        return EXIT_JOB_FAILED
    finally:
        _close_device(dev, args)


THESIS_COUNTS, THESIS_RAMP_COUNTS, THESIS_SPEED_MM_S, THESIS_PERIOD_S = 20_000, 2_000, 100.0, 0.05


def _thesis_line(args, profile):
    """The thesis' test line (seed 000 3.3.1, docs/motion.md "Reproduced: the thesis' test
    line"): 150 dpi, 20,000 counts firing at 100 mm/s between 2,000-count ramps (so the
    acceleration is v² / (2 x 2,000 counts) = 59.1 mm/s²), the DSP loop at 50 ms."""
    from dataclasses import replace
    if args.pattern not in ("line", "sawtooth"):
        raise ValueError("--thesis goes with the line or sawtooth pattern (the thesis' tests 1 and 2)")
    cpi = profile.counts_per_inch
    ramp_mm = THESIS_RAMP_COUNTS / cpi * 25.4
    args.dpi = 150
    args.speed = THESIS_SPEED_MM_S
    args.width_mm = THESIS_COUNTS / cpi * 25.4
    carriage = replace(profile.carriage, accel_mm_s2=THESIS_SPEED_MM_S ** 2 / (2 * ramp_mm),
                       servo_period_s=THESIS_PERIOD_S)
    return replace(profile, carriage=carriage)


def cmd_emulator(args) -> int:
    from ..device_sim.faults import Faults
    from ..device_sim.printer import Printer
    from ..device_sim.server import EmulatorServer
    try:
        faults = Faults.parse(args.inject)
        profile = _profile(args)
    except ValueError as exc:
        print(f"wideprint emulator: {exc}", file=sys.stderr)
        return EXIT_USAGE
    media = args.media_out
    try:
        options = _emulator_options(args)
    except ValueError as exc:
        print(f"wideprint emulator: {exc}", file=sys.stderr)
        return EXIT_USAGE
    printer = Printer(profile, faults,
                      media_path=(lambda job: media.format(job=job) if "{job}" in media else media)
                      if media else None, event_log=args.event_log, **options)
    server = EmulatorServer(printer, host="127.0.0.1", data_port=args.data_port,
                            serial_tcp_port=args.serial_port, data_pty=args.data_pty)
    print(f"device: {server.device_spec}", flush=True)
    if not args.data_pty:
        host = server.data_listener.getsockname()[0]
        print(f"device (USB): serial={server.serial_spec},data=usb-emu://{host}:{server.data_port}",
              flush=True)
    signal.signal(signal.SIGTERM, lambda *a: server.stop())
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return EXIT_OK


def cmd_gui(args) -> int:
    from .gui import run as gui_run        # it says so if PySide6 is missing
    return gui_run(args)


def cmd_devices(args) -> int:
    """What printers this machine can reach: serial ports, USB printers, device nodes."""
    import glob
    from ..driver.transport import USB_PID, USB_VID
    try:
        from serial.tools import list_ports
        ports = list(list_ports.comports())
    except Exception as exc:  # noqa: BLE001 - listing must never crash
        ports, err = [], exc
        print(f"serial ports: cannot list ({err})")
    print("serial ports (command channel):")
    for p in ports:
        print(f"  {p.device:20s} {p.description}" + (f" [{p.hwid}]" if p.hwid != "n/a" else ""))
    if not ports:
        print("  none")
    print(f"USB printers {USB_VID:04x}:{USB_PID:04x} (data channel):")
    try:
        import usb.core
        import usb.util
        found = list(usb.core.find(find_all=True, idVendor=USB_VID, idProduct=USB_PID) or [])
        for d in found:
            try:
                serial = usb.util.get_string(d, d.iSerialNumber)
            except Exception:  # noqa: BLE001 - no permission: say so
                serial = "? (no permission: install resources/udev/60-wideprint.rules)"
            print(f"  usb://{USB_VID:04x}:{USB_PID:04x}/{serial}  bus {d.bus} address {d.address}")
        if not found:
            print("  none")
    except usb.core.NoBackendError:
        print("  cannot look: libusb-1.0 is not installed (Debian: apt-get install libusb-1.0-0)")
    from ..driver.vfio import list_plx9054
    print("PCI cards (PLX 9054, data channel through vfio-pci; docs/pci.md):")
    cards = list_plx9054()
    for c in cards:
        if not c["wideprint"]:
            print(f"  {c['address']}  a PLX 9054 that is not a wideprint card (subsystem "
                  f"{c['subsystem']}); usable only as vfio://{c['address']} if it is one")
            continue
        state = "ready" if not c["problems"] else "not ready: " + "; ".join(c["problems"])
        print(f"  vfio://{c['address']}  {state}")
    if not cards:
        print("  none")
    nodes = sorted(glob.glob("/dev/wideprint*"))
    print("device nodes (data channel):")
    for n in nodes:
        print(f"  {n}")
    if not nodes:
        print("  none")
    print("emulator: --device emulator (in-process), or run `wideprint emulator` for a spec")
    return EXIT_OK


def cmd_acceptance(args) -> int:
    """pytest on the sample suite (resources/acceptance/); the plugin comes with the
    package (entry point pytest11)."""
    try:
        import pytest
    except ImportError:
        print("wideprint acceptance: needs pytest (pip install 'wideprint[test]')", file=sys.stderr)
        return EXIT_USAGE
    suite = args.suite or str(Path(__file__).resolve().parent.parent / "resources" / "acceptance")
    argv = [suite, "-q", "-p", "no:cacheprovider", f"--wideprint-device={args.device}"]
    if args.junit_xml:
        argv.append(f"--junit-xml={args.junit_xml}")
    return int(pytest.main(argv + list(args.pytest_args)))


def cmd_completion(args) -> int:
    """The completion script, generated from this very parser by shtab."""
    import shtab
    try:
        print(shtab.complete(build_parser(), shell=args.shell))
    except BrokenPipeError:        # `| head`: the reader has what it wanted
        pass
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    from . import devices
    from .. import __version__
    from .media_cli import add_parser as add_media_parser
    ap = argparse.ArgumentParser(prog="wideprint", description="RIP and driver for the "
                                 "3.4 m CMYK solvent printer (8 x Xaar XJ128), with its emulator.")
    ap.add_argument("--version", action="version", version=f"wideprint {__version__}")
    ap.add_argument("-v", "--verbose", action="store_true")
    sub = ap.add_subparsers(dest="command", required=True)

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

    p = sub.add_parser("rip", help="write the halftone planes the RIP intends")
    p.add_argument("file", metavar="FILE")
    p.add_argument("-o", "--output", required=True, metavar="PLANES.tif")
    p.add_argument("--planes-format", choices=("8bit", "packed"), default="8bit",
                   help="8bit: one byte per dot and ink, read by any TIFF reader (default); "
                   "packed: one bit per dot and ink, 8x less to compress, read by tifffile, "
                   "libtiff and wideprint but not PIL or libvips (docs/formats.md)")
    p.add_argument("--preview", metavar="PNG", help="a PNG picture of the planes")
    p.add_argument("--proof", action="store_true",
                   help="--preview is the soft proof instead: the job as its media prints it, "
                   "out-of-gamut areas striped grey (docs/color.md)")
    _rip_options(p)
    p.set_defaults(func=cmd_rip)

    p = sub.add_parser("gui", help="the operator GUI (PySide6), a client of this machine's print "
                                   "server (started in the background when none runs)")
    from .gui import add_arguments as add_gui_arguments   # argparse only: --help stays light
    add_gui_arguments(p)
    p.set_defaults(func=cmd_gui)

    add_media_parser(sub)         # media list|show|create|verify|recalibrate|remove|export|import
    from .spot_cli import add_parser as add_spot_parser
    add_spot_parser(sub)          # spot list|show|import|export|remove|forget|swatch|pick (docs/spot.md)
    from .server_cli import add_parser as add_server_parsers
    add_server_parsers(sub)       # serve, submit, queue, cancel, hold, release, requeue, status,
    #                               presets, report
    from .cups_cli import add_parser as add_cups_parser
    add_cups_parser(sub)          # cups install|uninstall|status (docs/ipp.md "CUPS queues")

    p = sub.add_parser("completion", help="print a shell completion script (bash, zsh, tcsh)",
                       description="Shell completion for wideprint, e.g. "
                       "`wideprint completion bash > /etc/bash_completion.d/wideprint` or "
                       "`source <(wideprint completion bash)`.")
    p.add_argument("shell", choices=("bash", "zsh", "tcsh"))
    p.set_defaults(func=cmd_completion)

    p = sub.add_parser("acceptance", help="run the sample acceptance suite (docs/acceptance.md)",
                       description="Runs wideprint's sample acceptance suite (the thesis' test "
                       "prints, a colour chart, a fault drill) with pytest and the wideprint "
                       "plugin; extra arguments after -- go to pytest.")
    p.add_argument("--device", default="emulator", help=devices.DEVICE_HELP)
    p.add_argument("--junit-xml", metavar="FILE", help="write a JUnit XML report (for CI systems)")
    p.add_argument("--suite", metavar="DIR", help="another suite folder (default: the sample suite)")
    p.add_argument("pytest_args", nargs="*", metavar="PYTEST-ARG")
    p.set_defaults(func=cmd_acceptance)

    from .printer_cli import add_parser as add_printer_parser
    add_printer_parser(sub)       # printer status|home|park|feed|measure|clear-fault

    from .calibrate_cli import add_parser as add_calibrate_parser
    add_calibrate_parser(sub)     # calibrate nozzles|bidir|heads|feed (docs/calibration.md)

    from .quality_cli import add_parser as add_quality_parser
    add_quality_parser(sub)       # quality SCAN.tif: banding, grain, mottle (docs/quality.md)

    p = sub.add_parser("devices", help="list the serial ports, USB printers and device nodes")
    p.set_defaults(func=cmd_devices)

    from ..rip.settings import TEST_PATTERNS as PATTERNS, setting
    p = sub.add_parser("test-print", help="print a test pattern (nozzle check, line, sawtooth, "
                       "bidirectional and head alignment)")
    p.add_argument("pattern", choices=PATTERNS)
    p.add_argument("--device", default="emulator")
    p.add_argument("--media-out", metavar="MEDIA.tif")
    p.add_argument("--planes-out", metavar="PLANES.tif", help="write the pattern's planes")
    p.add_argument("--preview", metavar="PNG", help="a PNG picture of the media")
    p.add_argument("--head", default="K1", help="head for line and sawtooth (default K1)")
    p.add_argument("--nozzle", type=int, default=64, help="nozzle for line (1..126)")
    p.add_argument("--width-mm", type=float, default=100.0, help="pattern length along the sweep")
    p.add_argument("--dpi", type=int, choices=setting("dpi").choices, default=150,
                   help="resolution of the pattern (default 150, the thesis' test mode)")
    p.add_argument("--speed", type=float, metavar="MM_S", help="carriage speed (default: profile)")
    p.add_argument("--passes", type=int, choices=setting("passes").choices, default=1,
                   help="banding-scan: the weave's passes to print the chart with (default 1)")
    p.add_argument("--pass-mask", choices=setting("pass_mask").choices,
                   help="banding-scan: the pass mask (default: the RIP's)")
    p.add_argument("--bidir", action="store_true", help="banding-scan: print on both strokes")
    p.add_argument("--thesis", action="store_true",
                   help="the thesis' test line (seed 000, docs/motion.md): 150 dpi, 24,000 "
                        "encoder counts (2,000 accelerating, 20,000 at 100 mm/s, 2,000 braking), "
                        "the DSP's loop at 50 ms; prints the servo's measurements")
    p.add_argument("--inject", action="append", metavar="KIND=VALUE")
    p.add_argument("--event-log", metavar="JSONL")
    p.add_argument("--profile", metavar="TOML")
    _emulator_outputs(p)
    _scan_options(p, several=False)
    p.set_defaults(func=cmd_test_print)

    p = sub.add_parser("emulator", help="run the printer emulator on a pty and TCP")
    p.add_argument("--data-port", type=int, default=0, help="TCP port of the data channel (0 = any)")
    p.add_argument("--serial-port", type=int, default=None,
                   help="serve the command channel on this TCP port instead of a pty")
    p.add_argument("--data-pty", action="store_true",
                   help="serve the data channel on a pty (stands in for the PCI card's device node)")
    p.add_argument("--media-out", metavar="MEDIA.tif", help="media file ({job} = job id)")
    p.add_argument("--inject", action="append", metavar="KIND=VALUE")
    p.add_argument("--event-log", metavar="JSONL")
    p.add_argument("--profile", metavar="TOML")
    _emulator_outputs(p)
    p.set_defaults(func=cmd_emulator)
    return ap


def _give_back_big_buffers() -> None:
    """glibc raises its mmap threshold to the size of each large block freed (up to 32 MiB),
    so the RIP's band buffers soon come from the heap arenas, and freed they stay in the
    process's memory, fragmented among threads (an arena each, up to 8 per core).  A fixed
    threshold of 4 MiB keeps the big buffers (media window, whole strokes, image rows) an
    mmap of their own, returned when freed, and two arenas hold the rest.  Not lower: a
    band's buffers (1-3 MB at full width) would each be a fresh mmap, page-faulted and
    zeroed at every band - 256 KiB cost `print` 0.55 s and `rip` 0.6 s of 3 at full width
    for 16 MB less (bench/README.md, "Memory").  The smaller blocks freed at the top of an
    arena stay there up to 32 MiB (M_TRIM_THRESHOLD; glibc's default gives back all beyond
    128 KiB, and the next band faults the same pages in again): a full-width print's page
    faults 110,000 -> 35,000 and its system time -0.1 s for ~6 MB more peak.  Before any
    thread starts."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt(-3, 4 << 20)           # M_MMAP_THRESHOLD (glibc)
        libc.mallopt(-8, 2)                 # M_ARENA_MAX: the RIP's few threads share two
        libc.mallopt(-1, 32 << 20)          # M_TRIM_THRESHOLD
    except (OSError, AttributeError):       # not glibc: its own policy stays
        pass


def _one_blas_thread() -> None:
    """numpy's OpenBLAS starts a thread per core at its first matrix product (the emulator's
    servo model multiplies 4 x 4 matrices) and those threads spin on after it: ~0.1 CPU-s a
    job taken from the RIP for nothing.  Before numpy is loaded; OPENBLAS_NUM_THREADS set by
    the user wins."""
    import os
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


_collector_was_off = False


def _collector_off() -> None:
    """Start-up makes ~30,000 container objects that live as long as the process (modules,
    classes, functions, the parser), and Python's cyclic garbage collector walks the young
    ones every 700 allocations and all of them at each full collection during the imports:
    25-30 ms of a tiny `rip`'s 0.23 s (median of 15).  Off until the command's modules are
    imported (`_collector_on`).  Only when `wideprint` is the process (main() without
    argv): a caller's own process keeps its collector as it is."""
    global _collector_was_off
    import gc
    if gc.isenabled():
        gc.disable()
        _collector_was_off = True


def _collector_on() -> None:
    """The objects made so far frozen (never walked again, since they are never garbage)
    and the collector back on for the job's own."""
    global _collector_was_off
    if _collector_was_off:
        import gc
        gc.freeze()
        gc.enable()
        _collector_was_off = False


# the commands that turn the collector back on themselves, once their modules are imported
_QUICK_START = ("print", "rip")


def main(argv: list[str] | None = None) -> int:
    _one_blas_thread()
    if argv is None:                # the `wideprint` command itself
        _collector_off()
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.command not in _QUICK_START:
        _collector_on()
    if getattr(args, "threads", None) is not None:      # before the RIP makes its pools
        import os
        os.environ["WIDEPRINT_THREADS"] = str(args.threads)    # and for child processes
        from ..rip.parallel import set_workers
        try:
            set_workers(args.threads)
        except ValueError as exc:
            ap.error(str(exc))
    _give_back_big_buffers()
    import logging                  # here: `--help` and usage errors never need it
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    # libvips reports decoding trouble as warnings too; our ImageError says it better
    logging.getLogger("pyvips").setLevel(logging.DEBUG if args.verbose else logging.ERROR)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
