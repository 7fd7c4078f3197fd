"""What several commands share: the exit codes, the option blocks (the RIP's settings, the
emulator's outputs, the scan, the measuring instrument), the checks of outputs before
anything prints, file names made safe for a terminal, the progress bar."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

# docs/cli.md "Exit codes": print, rip and the machine commands; the server's clients say
# EXIT_SERVER (3) when the server cannot be reached
EXIT_OK, EXIT_JOB_FAILED, EXIT_USAGE, EXIT_DEVICE = 0, 1, 2, 3
EXIT_FAILED, EXIT_SERVER = EXIT_JOB_FAILED, EXIT_DEVICE


def _rip_options(p: argparse.ArgumentParser) -> None:
    """The RIP and placement options: from the one settings schema (rip/settings.py)."""
    from ...rip.settings import add_arguments
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


def _emulator_job_options(p: argparse.ArgumentParser) -> None:
    """What an emulated printer of `test-print` and `emulator` is given: faults, its event
    log, the printer profile, and the outputs above."""
    p.add_argument("--inject", action="append", metavar="KIND=VALUE")
    p.add_argument("--event-log", metavar="JSONL")
    p.add_argument("--profile", metavar="TOML")
    _emulator_outputs(p)


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
    opts: dict = {}
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
    from ..devices import close_device
    close_device(dev)
    if dev.emulator is not None and getattr(args, "latched_out", None):
        _save_latched(dev.emulator, args.latched_out)


def _profile(args):
    from ...rip.profile import load_profile
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


# -- the measuring instrument of `media create|verify|recalibrate` and `spot swatch` ----------
def measure_options(q: argparse.ArgumentParser, inject_help: str = "emulator fault") -> None:
    """Where the charts print and who measures them, with the printer profile, faults and
    --json: one block for every command that prints a chart and reads it back."""
    q.add_argument("--profile", metavar="TOML")
    q.add_argument("--inject", action="append", metavar="KIND=VALUE", help=inject_help)
    q.add_argument("--json", action="store_true")
    q.add_argument("--device", default="emulator", help="where the charts print (default: "
                   "the in-process emulator, measured by its spectrophotometer)")
    q.add_argument("--measure-dir", metavar="DIR", help="measure outside wideprint: each "
                   "chart's picture and patches go to DIR/NAME.tif and NAME.ti1, and its "
                   "measurement DIR/NAME.ti3 (chartread's CGATS) is waited for")
    q.add_argument("--wait", type=float, default=86400.0, metavar="S",
                   help="how long to wait for a measurement file (default a day)")
    q.add_argument("--scanner-icc", metavar="ICC", help="measure the charts with the "
                   "emulated scanner through this input profile (media create --scan makes one)")


def _say(args):
    stream = sys.stderr if getattr(args, "json", False) else sys.stdout

    def progress(msg: str) -> None:
        print(msg, file=stream, flush=True)
    return progress


def _where(args) -> dict:
    """Where charts print and who measures them: the emulator's spectrophotometer, or
    (--measure-dir) an outside instrument whose .ti3 files are waited for."""
    where = {"device": args.device, "progress": _say(args)}
    if args.measure_dir:
        where.update(measure_dir=Path(args.measure_dir), wait_s=args.wait)
    if getattr(args, "scanner_icc", None):
        where["scanner_icc"] = Path(args.scanner_icc)
    return where


def family(sub, name: str, help: str, dest: str, dispatch, key: str, options=None):
    """A command with subcommands (`media list`, `spot swatch`, ...): its parser, and a
    function that adds one subcommand whose function goes in args.`key`, run by `dispatch`
    (which says the errors of them all alike).  `options(p)`: the command's own options,
    before its subcommands."""
    p = sub.add_parser(name, help=help)
    if options is not None:
        options(p)
    subs = p.add_subparsers(dest=dest, required=True)

    def cmd(name, func, help_):
        q = subs.add_parser(name, help=help_)
        q.set_defaults(func=dispatch, **{key: func})
        return q
    return p, cmd


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
    from ...rip.color import Separator
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


def _is_stdout(path: str) -> bool:
    import os
    try:
        return os.path.samestat(os.stat(path), os.fstat(sys.stdout.fileno()))
    except (OSError, ValueError, AttributeError):
        return False


# -- progress bar -------------------------------------------------------------------------------
def progress(done: float, total: float, label: str = "", width: int = 30, stream=None,
             final: bool = False) -> str:
    """Draw `[#####-----]  3/10  label` on one line of `stream` (default stderr; nothing
    is drawn when it is not a terminal); returns the line.  Call with final=True (or
    done == total) to end the line."""
    stream = sys.stderr if stream is None else stream
    frac = 0.0 if total <= 0 else max(0.0, min(1.0, done / total))
    filled = int(round(frac * width))
    num = f"{done:g}/{total:g}" if total else f"{done:g}"
    line = f"[{'#' * filled}{'-' * (width - filled)}] {frac * 100:5.1f}%  {num}" + \
        (f"  {label}" if label else "")
    if getattr(stream, "isatty", lambda: False)():
        cols = 100
        try:
            cols = os.get_terminal_size(stream.fileno()).columns
        except (OSError, ValueError, AttributeError):
            pass
        stream.write("\r" + line[:cols - 1].ljust(cols - 1))
        if final or (total and done >= total):
            stream.write("\n")
        stream.flush()
    return line
