"""`wideprint test-print PATTERN`: a test pattern (nozzle check, line, sawtooth, the
calibration scans), and the thesis' test line."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any, cast

from .common import (EXIT_DEVICE, EXIT_JOB_FAILED, EXIT_OK, EXIT_USAGE, _check_scan,
                     _close_device, _emulator_job_options, _emulator_options, _profile,
                     _scan_options)

if TYPE_CHECKING:
    from ...rip.pipeline import RipJob


def cmd_test_print(args) -> int:
    from ...device_sim.faults import Faults
    from ..devices import is_emulator_spec, open_device
    from ...driver.job import JobError, PrintJob
    from ...driver.link import LinkError
    from ...rip.testprints import PatternJob
    if args.scan_out and not is_emulator_spec(args.device):
        print("wideprint test-print: --scan-out needs the in-process emulator (--device emulator): "
              "a scan of a real print comes from a scanner", file=sys.stderr)
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
        # a PatternJob has the RipJob interface the driver uses (rip/testprints.py)
        rep = PrintJob(dev, cast("RipJob", job), speed_mm_s=args.speed).run()
        if args.preview and args.media_out:
            from ...rip.planes import write_preview
            write_preview(args.media_out, args.preview)
        print(f"{args.pattern}: printed {rep.strokes_printed} strokes, {job.width} x {job.height} dots"
              + (f" -> {args.media_out}" if args.media_out else "")
              + (f", scan {args.scan_out}" if args.scan_out else ""))
        emu: Any = dev.emulator                 # the in-process emulator, or None
        if args.thesis and emu is not None:
            for e in (e for e in emu.events if e.get("event") == "line"):
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


def add_parser(sub) -> None:
    from ...rip.settings import TEST_PATTERNS as PATTERNS, setting
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
    _emulator_job_options(p)
    _scan_options(p, several=False)
    p.set_defaults(func=cmd_test_print)
