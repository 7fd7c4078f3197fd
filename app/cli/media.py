"""`wideprint media list|show|create|verify|recalibrate|remove|export|import` and the
job settings of `print` and `rip` with `--media NAME` (docs/media.md)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE, _say, _where, family, measure_options


def job_settings(args, profile):
    """(profile, RipSettings) of a job from the command line: with --media (a setting of
    the schema, rip/settings.py), the media applied by `medialib.resolve`."""
    from ...rip.settings import from_mapping, mapping_from_args
    from ..medialib import resolve
    profile, mapping = resolve(mapping_from_args(args), profile)
    return profile, from_mapping(mapping, profile)


def _profile(args):
    from ...rip.profile import load_profile
    return load_profile(getattr(args, "profile", None))


def cmd_list(args) -> int:
    from ..medialib import DEFAULT_MEDIA, list_media
    rows = list_media()
    if args.json:
        print(json.dumps([{"name": m.name, "version": m.version, "shipped": m.shipped,
                           "dpi": m.dpi, "ink_limit_percent": m.ink_limit_percent,
                           "folder": str(m.folder)} for m in rows], indent=2))
        return EXIT_OK
    for m in rows:
        mark = " (default)" if m.name == DEFAULT_MEDIA else ""
        where = "shipped" if m.shipped else "user"
        print(f"{m.name:24s} v{m.version:<3d} {m.dpi} dpi {m.passes} pass "
              f"{m.dither:9s} ink {m.ink_limit_percent:g} %  {where}{mark}")
    if not rows:
        print("no media (`wideprint media create NAME`)")
    return EXIT_OK


def cmd_show(args) -> int:
    from ..medialib import find, to_toml
    m = find(args.name)
    if args.json:
        print(json.dumps({**m.values, "folder": str(m.folder), "shipped": m.shipped}, indent=2))
    else:
        print(f"# {m.folder}{' (shipped)' if m.shipped else ''}")
        print(to_toml(m.values), end="")
    return EXIT_OK


def cmd_create(args) -> int:
    from .. import mediacal
    from ..medialib import Media, check_name, check_values, now, save, user_dir
    name = check_name(args.name)
    dest = Path(args.dir) / name if args.dir else user_dir() / name
    if (dest / "media.toml").exists() and not args.replace:
        raise ValueError(f"media {name!r} exists ({dest}); --replace to make it again")
    profile = _profile(args)
    values = check_values({"name": name, "created": now(), "updated": now(),
                           "description": args.description or "",
                           "printer": Path(args.profile).stem if args.profile else "default",
                           "paper": profile.physical.media, "dpi": args.dpi,
                           "passes": args.passes, "bidir": args.bidir, "dither": args.dither})
    say = _say(args)
    instrument = "the scanner" if args.scan or args.scanner_icc else \
        "outside instrument" if args.measure_dir else "spectrophotometer"
    say(f"wideprint media create {name}: {args.dpi} dpi, {args.passes} pass, {args.dither}, "
        f"on {args.device} ({instrument})")
    scanner_s = None
    if args.scan and not args.scanner_icc:      # characterise the scanner first
        from ..argyll import tool
        tool("colprof")
        t0 = time.monotonic()
        args.scanner_icc = str(mediacal.scanner_profile(profile, dest, progress=say))
        scanner_s = round(time.monotonic() - t0, 1)
    values = mediacal.create(dest, values, profile, patches=args.patches,
                             ink_limit=args.ink_limit, linearise=args.linearise,
                             inject=tuple(args.inject or ()), quality=args.quality,
                             progress=say, budget=args.drop_budget,
                             modes=tuple(int(v) for v in args.modes.split(",") if v)
                             if args.modes else (), where=_where(args))
    if args.scanner_icc:
        values["build"] = {**values["build"], "scanner_icc": str(args.scanner_icc),
                           "scanner_profile_s": scanner_s}
    m = save(Media(dest, check_values(values)))
    if args.json:
        print(json.dumps({"name": name, "folder": str(dest), **m.values["build"]}, indent=2))
    else:
        say(f"media {name} v{m.version} written to {dest}")
    return EXIT_OK


def report_text(r: dict) -> str:
    tol = r["tolerances"]
    lines = [f"media {r['media']} v{r['version']}: {r['patches']} in-gamut control patches "
             f"(seed {r['seed']}), relative colorimetric, ΔE2000",
             f"  mean {r['mean']:.2f}   (tolerance {tol.get('mean', '-')})",
             f"  p95  {r['p95']:.2f}   (tolerance {tol.get('p95', '-')})",
             f"  max  {r['max']:.2f}   (tolerance {tol.get('max', '-')})",
             f"  {'PASS' if r['pass'] else 'FAIL: ' + ', '.join(r['failed']) + ' over tolerance'}"]
    if not r["pass"]:
        lines.append(f"  `wideprint media recalibrate {r['media']}` re-linearises from one "
                     f"wedge print")
    return "\n".join(lines)


def cmd_verify(args) -> int:
    from .. import mediacal
    from ..medialib import find
    m = find(args.name)
    kept: dict = {}
    r = mediacal.verify(m, _profile(args), count=args.patches, seed=args.seed,
                        inject=tuple(args.inject or ()), progress=_say(args), dpi=args.dpi,
                        keep=kept, where=_where(args))
    if args.picture:
        mediacal.verify_picture(kept, Path(args.picture))
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        print(report_text(r))
    return EXIT_OK if r["pass"] else EXIT_FAILED


def cmd_recalibrate(args) -> int:
    from .. import mediacal
    from ..medialib import Media, check_values, find, now, save, user_dir
    m = find(args.name)
    if m.shipped:              # a shipped entry is recalibrated into the user's library
        import shutil
        dest = user_dir() / m.name
        shutil.copytree(m.folder, dest, dirs_exist_ok=True)
        m = Media(dest, m.values)
    values = mediacal.recalibrate(m, _profile(args), inject=tuple(args.inject or ()),
                                  progress=_say(args), where=_where(args))
    values["updated"] = now()
    m = save(Media(m.folder, check_values(values)))
    shift = values["build"]["recalibrated"]["max_shift_de"]
    out = {"media": m.name, "version": m.version, "folder": str(m.folder),
           "max_shift_de": shift}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"media {m.name} v{m.version}: new linearisation curves (largest response "
              f"shift found, ΔE: " + ", ".join(f"{k} {v:.1f}" for k, v in shift.items()) + ")")
    return EXIT_OK


def cmd_remove(args) -> int:
    from ..medialib import remove
    print(f"removed {remove(args.name)}")
    return EXIT_OK


def cmd_export(args) -> int:
    from ..medialib import export
    print(export(args.name, Path(args.output)))
    return EXIT_OK


def cmd_import(args) -> int:
    from ..medialib import import_
    m = import_(Path(args.archive), args.name, args.replace)
    print(f"media {m.name} v{m.version} imported to {m.folder}")
    return EXIT_OK


def cmd_media(args) -> int:
    from ..argyll import ArgyllError
    t0 = time.monotonic()
    try:
        return args.media_func(args)
    except (ValueError, OSError) as exc:      # (TimeoutError is an OSError)
        print(f"wideprint media {args.media_command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ArgyllError as exc:
        print(f"wideprint media {args.media_command}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        if args.verbose_time:
            print(f"{time.monotonic() - t0:.1f} s", file=sys.stderr)


def add_parser(sub) -> None:
    def timing(p) -> None:
        p.add_argument("--time", dest="verbose_time", action="store_true", help=argparse.SUPPRESS)
    _, cmd = family(sub, "media", "media entries: ICC profile, ink limits, linearisation "
                    "(docs/media.md)", "media_command", cmd_media, "media_func", timing)

    q = cmd("list", cmd_list, "the media in the library")
    q.add_argument("--json", action="store_true")
    q = cmd("show", cmd_show, "one entry's fields")
    q.add_argument("name")
    q.add_argument("--json", action="store_true")

    q = cmd("create", cmd_create, "make a media on the emulator: wedge, ink limit, "
            "profiling chart, colprof (minutes)")
    q.add_argument("name")
    q.add_argument("--dpi", type=int, default=300, choices=(150, 300, 600))
    q.add_argument("--passes", type=int, default=1)
    q.add_argument("--bidir", action="store_true")
    q.add_argument("--dither", default="vced")
    q.add_argument("--patches", type=int, default=1000, help="profiling chart (default 1000)")
    q.add_argument("--ink-limit", type=float, metavar="PERCENT",
                   help="total ink limit (default: chosen from the ink-limit chart, at most 300)")
    q.add_argument("--no-linearise", dest="linearise", action="store_false",
                   help="keep the raw response (identity curves) as the reference")
    q.add_argument("--quality", default="m", choices=("l", "m", "h"), help="colprof -q")
    q.add_argument("--scan", action="store_true", help="measure the charts with the "
                   "emulated scanner (characterised first: scanner.icc in the entry)")
    q.add_argument("--drop-budget", type=float, default=1.0, metavar="F",
                   help="the fraction of each ink amount the media's mode prints (docs/color.md)")
    q.add_argument("--modes", metavar="DPI,...", help="other dpi modes to linearise to the "
                   "same colour at the same ink per m2, e.g. 150,600")
    q.add_argument("--description")
    q.add_argument("--dir", help="write the entry under this folder instead of the library")
    q.add_argument("--replace", action="store_true")
    measure_options(q)

    for name, func, help_ in (("verify", cmd_verify, "print and measure a control chart: "
                               "ΔE2000 against the entry's tolerances (exit 1: fail)"),
                              ("recalibrate", cmd_recalibrate, "re-linearise from one wedge "
                               "print; the profile is kept")):
        q = cmd(name, func, help_)
        q.add_argument("name")
        measure_options(q, "emulator fault, e.g. dot-gain=+8%%")
        if name == "verify":
            q.add_argument("--dpi", type=int, help="verify in this mode of the entry")
            q.add_argument("--picture", metavar="PNG", help="the report as a picture: each "
                           "patch aimed at (upper half) and measured (lower half)")
            q.add_argument("--patches", type=int, default=150)
            q.add_argument("--seed", type=int, default=7)

    q = cmd("remove", cmd_remove, "delete a user entry")
    q.add_argument("name")
    q = cmd("export", cmd_export, "an entry as a .tar.gz")
    q.add_argument("name")
    q.add_argument("-o", "--output", required=True, metavar="FILE.tar.gz")
    q = cmd("import", cmd_import, "an exported entry into the user's library")
    q.add_argument("archive")
    q.add_argument("--name")
    q.add_argument("--replace", action="store_true")
