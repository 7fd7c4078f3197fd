"""`wideprint rip FILE -o PLANES.tif`: the halftone planes the RIP intends, without a printer."""

from __future__ import annotations

import sys

from .common import (EXIT_JOB_FAILED, EXIT_OK, EXIT_USAGE, NAME_LIMIT, _check_icc,
                     _check_output_folders, _is_stdout, _profile, _rip_options, shown)
from .process import _collector_on
from .proof import _proof


def cmd_rip(args) -> int:
    from ...rip.load import ImageError
    from ...rip.pipeline import RipJob
    from ...rip.planes import output_file
    _collector_on()
    try:
        from .media import job_settings
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
        from ...rip.planes import write_preview
        try:
            write_preview(args.output, args.preview)
        except (OSError, ValueError) as exc:
            print(f"wideprint rip: preview not written: {shown(exc)}", file=sys.stderr)
            return EXIT_JOB_FAILED
    return EXIT_OK



def add_parser(sub) -> None:
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
