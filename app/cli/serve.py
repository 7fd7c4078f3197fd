"""`wideprint serve`: the print server (docs/server.md), and `serve --check [--repair]`,
its state directory checked."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from .. import devices
from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE
from .remote import _state_dir_option


def _printer_configs(args) -> list:
    """--printer NAME=SPEC (repeated) and --printer-profile NAME=TOML; none: one printer,
    "main", with --device and --profile."""
    from ..server.config import PrinterConfig
    if not args.printer:
        if args.printer_profile:
            raise ValueError("--printer-profile goes with --printer")
        return []
    profiles = {}
    for item in args.printer_profile or []:
        name, eq, path = item.partition("=")
        if not eq or not name or not path:
            raise ValueError(f"--printer-profile {item!r}: expected NAME=TOML")
        profiles[name] = path
    out = []
    for item in args.printer:
        name, eq, spec = item.partition("=")
        if not eq or not name or not spec:
            raise ValueError(f"--printer {item!r}: expected NAME=SPEC (e.g. plotter1=emulator)")
        out.append(PrinterConfig(name, spec, profiles.pop(name, args.profile)))
    if profiles:
        raise ValueError(f"--printer-profile for no printer: {', '.join(profiles)}")
    return out


def cmd_check(args) -> int:
    """`serve --check [--repair]`: the state directory checked like a file system
    (docs/server.md "The state directory"); --repair rebuilds a lost queue from the spool."""
    import fcntl
    from ..server import default_state_dir, fsck
    state = Path(args.state_dir or default_state_dir())
    if not state.is_dir():
        print(f"wideprint serve --check: {state} is not a folder", file=sys.stderr)
        return EXIT_USAGE
    fd = os.open(state / "server.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"wideprint serve --check: a server is running on {state}: stop it first",
                  file=sys.stderr)
            return EXIT_FAILED
        res = fsck.repair(state) if args.repair else fsck.check(state)
    finally:
        os.close(fd)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(f"state directory {res['state_dir']}")
        print(f"  database: {res['database']}")
        print(f"  jobs: {res['jobs']} ({res['active']} queued, held or printing)")
        for what, words in (("missing", "spool copy missing"), ("damaged", "spool copy damaged")):
            for j in res[what]:
                print(f"  job {j['id']} {safe(j['name'])}: {words} ({j['path']})")
        for f in res["orphans"]:
            print(f"  {f['path']}: {safe(f['name'] or '?')}, no job owns it (can be rebuilt)")
        for f in res["undescribed"]:
            print(f"  {f['path']}: no job owns it and no description is beside it")
        if args.repair:
            if res["set_aside"]:
                print(f"  the lost database was moved to {res['set_aside']}")
            print(f"  rebuilt: {len(res['rebuilt'])} job(s), held: "
                  + (", ".join(map(str, res["rebuilt"])) or "-"))
            for f in res["skipped"]:
                print(f"  not queued: {f['path']}: {f['why']}")
        elif not res["ok"]:
            print("  run again with --repair to queue the spooled files again (held)")
    if args.repair:
        return EXIT_OK if not res["skipped"] else EXIT_FAILED
    return EXIT_OK if res["ok"] else EXIT_FAILED


def safe(text: str) -> str:
    return "".join(ch if ch.isprintable() else f"\\u{ord(ch):04x}" for ch in text)


def cmd_serve(args) -> int:
    import logging
    from ..server import ServerConfig, default_state_dir, serve
    if args.check or args.repair:
        return cmd_check(args)
    logging.getLogger("wideprint").setLevel(logging.DEBUG if args.verbose_server else logging.INFO)
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.WARNING,
                            format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if not (args.settle_time >= 0 and args.api_timeout > 0 and args.api_connections > 0):
        print("wideprint serve: --settle-time must be 0 or more, --api-timeout and "
              "--api-connections positive", file=sys.stderr)
        return EXIT_USAGE
    if args.max_file_size is not None and args.max_file_size <= 0:
        print("wideprint serve: --max-file-size must be positive", file=sys.stderr)
        return EXIT_USAGE
    cfg = ServerConfig(device=args.device, state_dir=Path(args.state_dir or default_state_dir()),
                       media_dir=Path(args.media_dir) if args.media_dir else None,
                       hot_folder_root=Path(args.hot_folder_root) if args.hot_folder_root else None,
                       host=args.host, port=args.port, on_crash=args.on_crash,
                       scan_interval=args.scan_interval, start_paused=args.paused,
                       profile_path=args.profile, settle_s=args.settle_time,
                       api_timeout_s=args.api_timeout, api_max_connections=args.api_connections)
    try:
        cfg.printers = _printer_configs(args)
        cfg.printer_configs()                    # names checked before anything starts
    except ValueError as exc:
        print(f"wideprint serve: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.inject:
        from ..devices import is_emulator_spec, parse_inject
        try:
            parse_inject(args.inject)                    # checked before anything starts
        except ValueError as exc:
            print(f"wideprint serve: {exc}", file=sys.stderr)
            return EXIT_USAGE
        if not any(is_emulator_spec(p.device) for p in cfg.printer_configs()):
            print("wideprint serve: --inject needs an emulated printer", file=sys.stderr)
            return EXIT_USAGE
        cfg.inject = list(args.inject)
    if args.max_file_size is not None:
        cfg.max_file_bytes = args.max_file_size
    if args.keep_failed is not None:
        if not args.keep_failed >= 0:            # negative or NaN
            print("wideprint serve: --keep-failed must be 0 or more days", file=sys.stderr)
            return EXIT_USAGE
        cfg.keep_failed_s = args.keep_failed * 86400
    from ..server import archive
    try:
        for key, value in archive.from_args(args).items():
            setattr(cfg, key, value)
    except ValueError as exc:
        print(f"wideprint serve: {exc}", file=sys.stderr)
        return EXIT_USAGE
    ipp = _IppStarter(args) if args.ipp or args.ipp_listen else None
    try:
        rc = serve(cfg, ready=ipp.start if ipp else None)
    except (ValueError, OSError) as exc:
        print(f"wideprint serve: {exc}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        if ipp:
            ipp.stop()
    return EXIT_FAILED if ipp and ipp.failed else rc


class _IppStarter:
    """`serve --ipp`: the IPP Everywhere Printer Application beside the server (docs/ipp.md);
    a Printer Application that cannot start stops the server, loudly."""

    def __init__(self, args):
        self.args, self.bridge, self.failed = args, None, False

    def start(self, server) -> None:
        from ..ipp import IppBridge
        a = self.args
        listen = a.ipp_listen or "localhost"
        if listen not in ("localhost", "127.0.0.1", "::1"):
            print(f"wideprint serve: the IPP printers listen on {listen}, beyond this machine"
                  + ("" if a.ipp_auth == "token" else ", and anyone who reaches them can print"),
                  file=sys.stderr, flush=True)
        try:
            self.bridge = IppBridge(server.state_dir, listen=listen, port=a.ipp_port,
                                    auth=a.ipp_auth, url=server.url, token=server.token)
            uris = self.bridge.start()
        except (RuntimeError, OSError, ValueError) as exc:
            print(f"wideprint serve: --ipp: {exc}", file=sys.stderr, flush=True)
            self.failed = True
            server.stop_requested.set()
            return
        server.publish(ipp=uris)
        for name, uri in uris.items():
            print(f"wideprint serve: IPP printer {name}: {uri}", flush=True)

    def stop(self) -> None:
        if self.bridge:
            self.bridge.stop()


def add_parser(sub) -> None:
    from ..server.config import (DEFAULT_API_CONNECTIONS, DEFAULT_API_TIMEOUT_S, DEFAULT_PORT,
                                DEFAULT_SETTLE_S)
    from ..ipp.bridge import DEFAULT_IPP_PORT

    p = sub.add_parser("serve", help="run the print server: queue, API, hot folders")
    p.add_argument("--device", default="emulator",
                   help=devices.DEVICE_HELP + " (default: emulator)")
    _state_dir_option(p)
    p.add_argument("--media-dir", metavar="DIR",
                   help="in-process emulator: write each job's media as DIR/job-ID.tif")
    p.add_argument("--hot-folder-root", metavar="DIR",
                   help="watch DIR/PRESET/ for every preset (files there become jobs)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address of the API (default 127.0.0.1; anything else exposes it)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"API port (default {DEFAULT_PORT}; 0 = any free port)")
    p.add_argument("--check", action="store_true",
                   help="check the state directory (database, spool) and report; the server "
                        "does not start (docs/server.md 'The state directory')")
    p.add_argument("--repair", action="store_true",
                   help="with --check: a lost or damaged database is moved aside and the "
                        "spooled files are queued again, held")
    p.add_argument("--json", action="store_true", help="with --check: the report as JSON")
    p.add_argument("--on-crash", choices=("resume", "hold", "reprint"), default="resume",
                   help="a job that was printing when the server died: resume it at its "
                        "first unfinished stroke once the printer confirms the sheet holds "
                        "the strokes before it, else hold it (resume, the default); always "
                        "hold it (hold); resume it when confirmed, else print it again from "
                        "its first stroke (reprint). docs/server.md 'Crash recovery'")
    p.add_argument("--max-file-size", type=int, metavar="BYTES",
                   help="largest file accepted (default 4 GiB)")
    p.add_argument("--scan-interval", type=float, default=1.0, metavar="S",
                   help="hot-folder scan interval (default 1 s)")
    p.add_argument("--settle-time", type=float, default=DEFAULT_SETTLE_S, metavar="S",
                   help="a hot-folder file unchanged this long, and open for writing by "
                        f"nobody, is complete (default {DEFAULT_SETTLE_S:g} s)")
    p.add_argument("--api-timeout", type=float, default=DEFAULT_API_TIMEOUT_S, metavar="S",
                   help="close API connections silent this long (default "
                        f"{DEFAULT_API_TIMEOUT_S:g} s)")
    p.add_argument("--api-connections", type=int, default=DEFAULT_API_CONNECTIONS, metavar="N",
                   help=f"API connections served at once; more get 503 (default "
                        f"{DEFAULT_API_CONNECTIONS})")
    p.add_argument("--keep-failed", type=float, metavar="DAYS",
                   help="keep the spooled files of failed and cancelled jobs this long, so "
                        "they can be requeued (default 7; 0 = delete them at once)")
    from ..server import archive
    archive.add_arguments(p)               # the archive's retention (docs/server.md)
    p.add_argument("--paused", action="store_true",
                   help="start with the queue paused (jobs are accepted, none printed)")
    p.add_argument("--profile", metavar="TOML", help="printer profile")
    p.add_argument("--printer", action="append", metavar="NAME=SPEC",
                   help="a printer of this server (repeat for several, e.g. --printer "
                        "left=serial=/dev/ttyS0,data=usb://1209:5750 --printer right=...); "
                        "default: one printer, 'main', on --device")
    p.add_argument("--printer-profile", action="append", metavar="NAME=TOML",
                   help="that printer's profile (default: --profile)")
    p.add_argument("--inject", action="append", metavar="KIND=VALUE",
                   help="an emulator fault for every emulated printer (tests, demos, training; "
                        "kinds as for `wideprint print --inject`)")
    p.add_argument("--ipp", action="store_true",
                   help="also run the IPP Everywhere Printer Application: every printer becomes "
                        "a driverless IPP printer (docs/ipp.md); its URIs go to server.json")
    p.add_argument("--ipp-listen", metavar="ADDR",
                   help="address of the IPP printers (default localhost; '*' = every address: "
                        "the network); implies --ipp")
    p.add_argument("--ipp-port", type=int, default=DEFAULT_IPP_PORT, metavar="N",
                   help=f"port of the IPP printers (default {DEFAULT_IPP_PORT})")
    p.add_argument("--ipp-auth", choices=("token", "none"), default="token",
                   help="token (default): IPP clients authenticate with the API token as "
                        "password (Basic); none: whoever reaches the port may print")
    p.add_argument("--verbose-server", action="store_true", help="debug logging")
    p.set_defaults(func=cmd_serve)
