"""The print server's command line (docs/server.md): `serve`, and the clients of its local
API — `submit`, `queue`, `cancel`, `hold`, `release`, `requeue`, `status`, `presets`,
`report` — plus `progress()`, a text progress bar for batch commands.

app/cli.py calls `add_parser(sub)`; `python -m wideprint.app.server_cli ...` runs these
commands on their own.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

# the API's client (app/client.py), its names re-exported here for the commands' users
from .client import (ApiError, Client, _os_user, _read_client_token,  # noqa: F401
                     find_token, read_server_file, user_token_file)

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_SERVER = 0, 1, 2, 3


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


# -- commands -------------------------------------------------------------------------------------
def _client(args) -> Client:
    return Client(args.state_dir, url=getattr(args, "url", None))


def _fail(cmd: str, exc: Exception) -> int:
    print(f"wideprint {cmd}: {exc}", file=sys.stderr)
    if isinstance(exc, ApiError) and exc.status == 0:
        return EXIT_SERVER
    return EXIT_FAILED


def _printer_configs(args) -> list:
    """--printer NAME=SPEC (repeated) and --printer-profile NAME=TOML; none: one printer,
    "main", with --device and --profile."""
    from .server.config import PrinterConfig
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


def cmd_clear_fault(args) -> int:
    try:
        client = _client(args)
        printer = args.printer or client.status()["printers"][0]["name"]
        r = client.printer_action(printer, "clear-fault", {"then": "fail" if args.fail else "resume"})
    except ApiError as exc:
        return _fail("clear-fault", exc)
    jobs = ", ".join(str(j) for j in r["jobs"]) or "no job was stopped"
    print(f"printer {r['printer']}: fault cleared; {jobs}"
          + (f" {'resumes' if r['then'] == 'resume' else 'failed'}" if r["jobs"] else ""))
    return EXIT_OK


def cmd_move(args) -> int:
    try:
        job = _client(args).move(args.id, args.printer)
    except ApiError as exc:
        return _fail("move", exc)
    print(f"job {job['id']}: printer {job['printer'] or 'any'}")
    return EXIT_OK


def cmd_estop(args) -> int:
    try:
        stopped = _client(args).estop()
    except ApiError as exc:
        return _fail("estop", exc)
    print("emergency stop: " + (", ".join(stopped) or "nothing was printing") +
          "; every printer paused")
    return EXIT_OK


def cmd_check(args) -> int:
    """`serve --check [--repair]`: the state directory checked like a file system
    (docs/server.md "The state directory"); --repair rebuilds a lost queue from the spool."""
    import fcntl
    from .server import default_state_dir, fsck
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
    from .server import ServerConfig, default_state_dir, serve
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
        from .devices import is_emulator_spec, parse_inject
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
    from .server import archive
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
        from .ipp import IppBridge
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


def _settings_from(args) -> dict:
    """The print options given on the command line (the settings schema's mapping); the
    server overlays them on the preset and validates them against its printer profile."""
    from ..rip.settings import mapping_from_args
    return mapping_from_args(args)


def _expand(files: list[str]) -> list[Path]:
    out = []
    for f in files:
        p = Path(f)
        if p.is_dir():
            out += sorted(c for c in p.iterdir() if c.is_file() and not c.name.startswith("."))
        else:
            out.append(p)
    return out


def cmd_submit(args) -> int:
    try:
        client = _client(args)
    except ApiError as exc:
        return _fail("submit", exc)
    files = _expand(args.files)
    results, failed = [], 0
    for i, f in enumerate(files):
        try:
            r = client.submit(f, preset=args.preset, copies=args.copies, priority=args.priority,
                              hold=args.hold or None, settings=_settings_from(args) or None,
                              client=args.client, printer=args.printer,
                              force=args.force or None, rip_hold=args.rip_hold or None)
            job = r["job"]
            results.append(job)
            if not args.json:
                print(f"{f}: job {job['id']} {job['state']}"
                      + (" (already submitted)" if r.get("duplicate") else ""))
        except ApiError as exc:
            failed += 1
            results.append({"file": str(f), "error": str(exc)})
            print(f"{f}: REFUSED: {exc}", file=sys.stderr)
            if exc.status == 0:
                return EXIT_SERVER
        except OSError as exc:
            failed += 1
            results.append({"file": str(f), "error": exc.strerror})
            print(f"{f}: {exc.strerror}", file=sys.stderr)
        if len(files) > 3 and not args.json:
            progress(i + 1, len(files), f.name)
    if args.json:
        print(json.dumps(results, indent=2))
    if args.wait and not failed:
        for job in results:
            done = client.wait(job["id"], timeout=args.wait)
            print(f"job {done['id']}: {done['state']}" + (f": {done['message']}" if done["message"] else ""),
                  file=sys.stderr if args.json else sys.stdout)
            if done["state"] != "done":
                failed += 1
    return EXIT_FAILED if failed else EXIT_OK


def _age(t: float | None) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) if t else ""


def cmd_queue(args) -> int:
    try:
        client = _client(args)
        states = None if args.all else "queued,held,printing"
        if args.state:
            states = args.state
        jobs = client.jobs(states)
    except ApiError as exc:
        return _fail("queue", exc)
    if args.json:
        print(json.dumps(jobs, indent=2))
        return EXIT_OK
    if not jobs:
        print("the queue is empty" + ("" if args.all else " (--all shows finished jobs)"))
        return EXIT_OK
    from .safe_text import safe
    print(f"{'ID':>6} {'STATE':9} {'POS':>4} {'PRI':>4} {'STROKES':>9} {'COPIES':>6} "
          f"{'PRESET':10} {'SOURCE':12} {'SUBMITTED':9} NAME / MESSAGE")
    for j in jobs:
        strokes = f"{j['strokes_done']}/{j['strokes_total']}" if j["strokes_total"] else ""
        print(f"{j['id']:>6} {j['state']:9} {j.get('position') or '':>4} {j['priority']:>4} "
              f"{strokes:>9} {j['copies_done']}/{j['copies']:<4} {(j['preset'] or '-'):10.10} "
              f"{safe(j['source']):12.12} {_age(j['submitted']):9} {safe(j['name'])}"
              + (f" (attempt {j['attempt']})" if j.get("attempt", 1) > 1 else "")
              + (f"  [{safe(j['message'])}]" if j["message"] else ""))
    return EXIT_OK


def _job_action(what: str):
    def cmd(args) -> int:
        from .safe_text import safe
        try:
            client = _client(args)
            rc = EXIT_OK
            for job_id in args.ids:
                try:
                    if what == "cancel":
                        # exit 0 only for a job that is cancelled (docs/server.md "The API")
                        job = client.cancel(job_id, timeout=args.timeout)
                        if job["state"] != "cancelled":
                            print(f"wideprint cancel: job {job['id']} is {job['state']}"
                                  + (f" {args.timeout:g} s after the cancel: the printer has "
                                     f"not stopped yet (still printing); run cancel again "
                                     f"or see `wideprint queue`" if job["state"] == "printing"
                                     else ""), file=sys.stderr)
                            rc = EXIT_FAILED
                            continue
                    elif what == "release" and args.force:
                        job = client.release(job_id, force=True)
                    elif what == "hold" and args.rip:
                        job = client.rip_hold(job_id)
                    else:
                        job = client.action(job_id, what)
                    print(f"job {job['id']}: {job['state']}"
                          + (f" ({safe(job['message'])})" if job["message"] else ""))
                except ApiError as exc:
                    if exc.status == 0:
                        raise
                    print(f"wideprint {what}: {exc}", file=sys.stderr)
                    rc = EXIT_FAILED
            return rc
        except ApiError as exc:
            return _fail(what, exc)
    return cmd


def cmd_users(args) -> int:
    """`wideprint users add|remove|list`: straight on the state directory (who can write
    there is the operator)."""
    from .server.auth import add_user, check_user_name, list_users, remove_user
    from .server.config import default_state_dir, write_token_file
    state = Path(args.state_dir or default_state_dir())
    what = args.users_command
    if what == "list":
        for name in list_users(state):
            print(name)
        return EXIT_OK
    try:
        check_user_name(args.name)
    except ValueError as exc:
        print(f"wideprint users: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if what == "remove":
        if not remove_user(state, args.name):
            print(f"wideprint users: user {args.name} has no token in {state}", file=sys.stderr)
            return EXIT_FAILED
        print(f"user {args.name}: token deleted (refused from the next request)", file=sys.stderr)
        return EXIT_OK
    if not state.is_dir():
        print(f"wideprint users: no state directory {state}", file=sys.stderr)
        return EXIT_USAGE
    try:
        path, token = add_user(state, args.name, replace=args.replace)
        if args.out:
            out = Path(args.out)
            write_token_file(out, token, replace=True)
    except FileExistsError:
        print(f"wideprint users: user {args.name} has a token already (--replace makes a new "
              f"one)", file=sys.stderr)
        return EXIT_FAILED
    except OSError as exc:
        print(f"wideprint users: {exc.filename or state}: {exc.strerror}", file=sys.stderr)
        return EXIT_FAILED
    if args.out:
        print(f"user {args.name}: token in {path} and {args.out} (0600); the user keeps it in "
              f"{user_token_file()} or names it in $WIDEPRINT_TOKEN_FILE", file=sys.stderr)
    else:
        print(f"user {args.name}: token made ({path}); the user keeps it in "
              f"{user_token_file()} (0600) or names it in $WIDEPRINT_TOKEN_FILE",
              file=sys.stderr)
        print(token)
    return EXIT_OK


def cmd_status(args) -> int:
    try:
        client = _client(args)
        if args.pause or args.resume:
            client.pause_queue(bool(args.pause))
        st = client.status()
    except ApiError as exc:
        return _fail("status", exc)
    if args.json:
        print(json.dumps(st, indent=2))
        return EXIT_OK
    s, q, p, cur = st["server"], st["queue"], st["printer"], st["current"]
    print(f"server   {s['url']}  pid {s['pid']}  up {time.time() - s['started']:.0f} s  "
          f"device {s['device']}  on crash: {s['on_crash']}")
    for pr in st.get("printers") or [dict(name="main", state=p["state"], error=p["error"],
                                           paused=q["paused"], reason=q["reason"], current=cur)]:
        pc = pr["current"]
        print(f"printer  {pr['name']}: {pr['state']}" + (f": {pr['error']}" if pr["error"] else "")
              + (f"  [paused: {pr['reason']}]" if pr["paused"] else "")
              + (f"  job {pc['id']} {pc['name']} stroke {pc['strokes_printed']}/{pc['strokes_total']}"
                 if pc else ""))
    counts = ", ".join(f"{k} {v}" for k, v in q["counts"].items())
    print(f"queue    {'PAUSED (' + q['reason'] + ')' if q['paused'] else 'running'}; {counts}")
    pr = st.get("presets")
    if pr:
        print(f"presets  {', '.join(pr['names'])} ({pr['file']})"
              + (f"; NOT RE-READ: {pr['error']}" if pr["error"] else ""))
    if cur:
        print(f"current  job {cur['id']} {cur['name']}: {cur['state']}"
              f"{' ' + cur['detail'] if cur['detail'] else ''}, stroke "
              f"{cur['strokes_printed']}/{cur['strokes_total']}, copy {cur['copy']}/{cur['copies']}"
              + (" (resumed)" if cur.get("resumed") else ""))
    return EXIT_OK


def cmd_presets(args) -> int:
    try:
        client = _client(args)
        if args.reload:
            r = client.reload_presets()
            changes = "; ".join(f"{k} {', '.join(r[k])}" for k in ("added", "removed", "changed")
                                if r[k])
            # the server also re-reads a changed file by itself: then this finds nothing new
            print(f"re-read {r['file']}: "
                  + (changes or f"no change (the presets in use date from {_age(r['loaded'])})"),
                  file=sys.stderr if args.json else sys.stdout)
        else:
            r = client.presets()
    except ApiError as exc:
        return _fail("presets", exc)
    if r.get("error"):                     # changed on disk but broken: these are the old ones
        print(f"wideprint presets: {r['error']}", file=sys.stderr)
    if args.json:
        print(json.dumps(r["presets"], indent=2))
        return EXIT_OK
    for name, settings in sorted(r["presets"].items()):
        print(f"{name:12} " + (", ".join(f"{k}={json.dumps(v)}" for k, v in settings.items())
                               or "(the RIP's defaults)"))
    return EXIT_OK


def _set_values(items: list[str] | None) -> dict:
    """--set KEY=VALUE (repeated) as a partial settings mapping: VALUE as JSON when it is
    JSON (numbers, true, null), else a string; placement.KEY for a placement setting."""
    out: dict = {}
    for item in items or []:
        key, eq, text = item.partition("=")
        if not eq or not key:
            raise ValueError(f"--set {item!r}: expected KEY=VALUE (e.g. dpi=600, "
                             f"placement.rotate=90)")
        try:
            value = json.loads(text)
        except ValueError:
            value = text
        if key.startswith("placement."):
            out.setdefault("placement", {})[key[len("placement."):]] = value
        else:
            out[key] = value
    return out


def cmd_reprint(args) -> int:
    """`wideprint reprint ID...`: finished jobs printed again from the archive
    (docs/server.md "Archive and reprint")."""
    from .safe_text import safe
    try:
        client = _client(args)
        change: dict = {}
        settings = dict(_settings_from(args) or {})
        more = _set_values(args.set)
        if "placement" in more and "placement" in settings:
            more["placement"] = dict(settings["placement"], **more["placement"])
        settings.update(more)
        if settings:
            change["settings"] = settings
        for key in ("copies", "priority", "printer"):
            if getattr(args, key) is not None:
                change[key] = getattr(args, key)
        if args.hold:
            change["hold"] = True
        if args.force:
            change["force"] = True
    except (ApiError, ValueError) as exc:
        return _fail("reprint", exc)
    rc = EXIT_OK
    for job_id in args.ids:
        try:
            job = client.reprint(job_id, **change)
        except ApiError as exc:
            print(f"wideprint reprint: job {job_id}: {exc}", file=sys.stderr)
            if exc.status == 0:
                return EXIT_SERVER
            rc = EXIT_FAILED
            continue
        print(f"job {job_id}: reprinted as job {job['id']} ({safe(job['name'])}) {job['state']}")
        if args.wait:
            done = client.wait(job["id"], timeout=args.wait)
            print(f"job {done['id']}: {done['state']}"
                  + (f": {safe(done['message'])}" if done["message"] else ""))
            rc = rc if done["state"] == "done" else EXIT_FAILED
    return rc


def cmd_prices(args) -> int:
    """`wideprint prices [--set FILE]`: the server's price list (docs/server.md "Prices and
    costs")."""
    try:
        client = _client(args)
        if args.set:
            text = Path(args.set).read_text()
            if args.set.endswith(".toml"):
                import tomllib
                new = tomllib.loads(text)
            else:
                new = json.loads(text)
            prices = client.prices(new)
        else:
            prices = client.prices()
    except (ApiError, OSError, ValueError) as exc:
        return _fail("prices", exc)
    if args.json:
        print(json.dumps(prices, indent=2))
        return EXIT_OK
    cur = prices["currency"]
    print("ink per ml:      " + ", ".join(f"{c.upper()} {v:g}" for c, v in
                                          prices["ink_per_ml"].items()) + f" {cur}")
    print("media per m²:    " + ", ".join(f"{m} {v:g}" for m, v in
                                          sorted(prices["media_per_m2"].items())) + f" {cur}")
    print(f"machine per hour: {prices['machine_per_hour']:g} {cur}")
    return EXIT_OK


def _report_costs(client, args) -> int:
    """`report --costs`: every printed copy with its cost at the server's price list, and
    the totals."""
    if args.csv:
        text = client.report_csv(args.job, costs=True)
        Path(args.csv).write_text(text)
        print(f"{args.csv}: {text.count(chr(10)) - 1} prints, with costs")
        return EXIT_OK
    r = client.report_costs(args.job)
    if args.json:
        print(json.dumps(r, indent=2))
        return EXIT_OK
    cur = r["prices"]["currency"]
    print(f"{'JOB':>5} {'COPY':>4} {'OUTCOME':9} {'M2':>8} {'INK ML':>9} {'SECONDS':>8} "
          f"{'INK':>9} {'MEDIA':>9} {'TIME':>9} {'COST':>10}  FILE")
    for p in r["prints"]:
        c = p["cost"]
        ink = sum(p[f"ink_{k}_ml"] for k in "cmyk")
        print(f"{p['job_id']:>5} {p['copy']:>4} {p['outcome']:9} {p['area_m2']:8.4f} "
              f"{ink:9.4f} {p['duration_s']:8.1f} {c['ink']:9.4f} {c['media']:9.4f} "
              f"{c['time']:9.4f} {c['total']:10.4f}  {p['file']}")
    t = r["totals"]
    print(f"total: {t['prints']} prints, {t['area_m2']:.4f} m², {t['ink_ml']:.4f} ml ink; "
          f"ink {t['ink']:.4f} + media {t['media']:.4f} + time {t['time']:.4f} = "
          f"{t['total']:.4f} {cur}")
    return EXIT_OK


def cmd_report(args) -> int:
    try:
        client = _client(args)
        if args.costs:
            return _report_costs(client, args)
        text = client.report_csv(args.job)
    except ApiError as exc:
        return _fail("report", exc)
    if args.csv:
        Path(args.csv).write_text(text)
        print(f"{args.csv}: {text.count(chr(10)) - 1} prints")
        return EXIT_OK
    if args.json:
        print(json.dumps(client.report(args.job), indent=2))
        return EXIT_OK
    import csv
    import io
    rows = list(csv.DictReader(io.StringIO(text)))
    print(f"{'JOB':>5} {'COPY':>4} {'OUTCOME':9} {'STROKES':>7} {'M2':>9} {'INK ML':>10} "
          f"{'SECONDS':>8}  FILE")
    for r in rows:
        print(f"{r['job_id']:>5} {r['copy']:>4} {r['outcome']:9} "
              f"{r['strokes_printed'] + '/' + r['strokes_total']:>7} {float(r['area_m2']):9.4f} "
              f"{float(r['ink_total_ml']):10.5f} {float(r['duration_s']):8.1f}  {r['file']}")
    return EXIT_OK


# -- parsers -------------------------------------------------------------------------------------
def _state_dir_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--state-dir", metavar="DIR",
                   help="the server's state directory (default $WIDEPRINT_STATE_DIR, "
                        "/var/lib/wideprint for root, else ~/.local/state/wideprint)")


def _client_parser(sub, name: str, help: str) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help)
    _state_dir_option(p)
    p.add_argument("--url", help=argparse.SUPPRESS)
    return p


def add_parser(sub) -> None:
    """Add serve, submit, queue, cancel, hold, release, requeue, status, presets and report
    to the `wideprint` command's subparsers."""
    from . import devices
    from .server.config import (DEFAULT_API_CONNECTIONS, DEFAULT_API_TIMEOUT_S, DEFAULT_PORT,
                                DEFAULT_SETTLE_S)
    from ..rip.settings import add_arguments as add_settings_arguments
    from .ipp.bridge import DEFAULT_IPP_PORT

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
    from .server import archive
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

    p = _client_parser(sub, "submit", "send files to the print server's queue")
    p.add_argument("files", nargs="+", metavar="FILE", help="images or folders")
    p.add_argument("--preset", help="settings preset (the server's presets file)")
    p.add_argument("--copies", type=int)
    p.add_argument("--priority", type=int, help="-100..100, higher prints first (default 0)")
    p.add_argument("--hold", action="store_true", help="queue the job held (default: the "
                   "preset's hold)")
    p.add_argument("--force", action="store_true", help="queue it even if it does not fit the "
                   "paper loaded (too wide, longer than the roll left)")
    p.add_argument("--rip-hold", action="store_true", help="queue it held and RIP it ahead: "
                   "its release prints the kept planes without ripping again")
    p.add_argument("--client", help="a tag for the accounting (default: none)")
    p.add_argument("--printer", metavar="NAME", help="the printer to print on (default: any, the "
                   "first free one)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--wait", type=float, nargs="?", const=3600.0, metavar="S",
                   help="wait until the jobs have printed (exit 1 if any did not)")
    # every print option of `wideprint print`, from the one settings schema; ICC profiles
    # are named from the server's icc/ folder
    add_settings_arguments(p)
    p.set_defaults(func=cmd_submit)

    p = _client_parser(sub, "queue", "list the print server's queue")
    p.add_argument("--all", action="store_true", help="finished jobs too")
    p.add_argument("--state", help="only these states, e.g. failed or queued,held")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_queue)

    for name, help in (("cancel", "cancel jobs (a printing job stops at once)"),
                       ("hold", "hold queued jobs"), ("release", "release held jobs"),
                       ("requeue", "put failed or cancelled jobs back in the queue "
                                   "(they print again from the start)")):
        p = _client_parser(sub, name, help)
        p.add_argument("ids", nargs="+", type=int, metavar="ID")
        if name == "release":
            p.add_argument("--force", action="store_true", help="past the fit checks (a job "
                           "held because the roll is too short: the operator knows better)")
        if name == "hold":
            p.add_argument("--rip", action="store_true", help="and RIP them ahead: their "
                           "release prints the kept planes without ripping again")
        if name == "cancel":
            p.add_argument("--timeout", type=float, default=60.0, metavar="S",
                           help="wait at most this long for a printing job to stop (default "
                                "60 s); exit 1 if it has not")
        p.set_defaults(func=_job_action(name))

    p = sub.add_parser("users", help="the operator's user tokens: a user acts on its own jobs "
                                     "only (docs/server.md \"Users and roles\")")
    usub = p.add_subparsers(dest="users_command", required=True)
    for name, help in (("add", "make a user's token (printed, or written to --out)"),
                       ("remove", "delete a user's token: refused from the next request"),
                       ("list", "the users with a token")):
        q = usub.add_parser(name, help=help)
        _state_dir_option(q)
        if name != "list":
            q.add_argument("name", metavar="NAME")
        if name == "add":
            q.add_argument("--out", metavar="FILE", help="write the token to FILE (0600) "
                           "instead of printing it; the user keeps it in "
                           "~/.config/wideprint/token")
            q.add_argument("--replace", action="store_true",
                           help="a user with a token gets a new one (the old one stops working)")
        q.set_defaults(func=cmd_users)

    p = _client_parser(sub, "status", "the print server, printer and current job")
    p.add_argument("--json", action="store_true")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--pause", action="store_true", help="pause the queue (no new job starts)")
    g.add_argument("--resume", action="store_true", help="resume the queue")
    p.set_defaults(func=cmd_status)

    p = _client_parser(sub, "presets", "the server's settings presets")
    p.add_argument("--reload", action="store_true",
                   help="re-read the presets file now (it is also re-read when it changes)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_presets)

    p = _client_parser(sub, "report", "accounting: one row per printed copy")
    p.add_argument("--csv", metavar="FILE", help="write the CSV here")
    p.add_argument("--json", action="store_true")
    p.add_argument("--job", type=int, metavar="ID")
    p.add_argument("--costs", action="store_true", help="each copy's cost (ink, media, "
                   "machine time) at the server's price list, and the totals")
    p.set_defaults(func=cmd_report)

    p = _client_parser(sub, "reprint", "print finished jobs again from the archive, with "
                       "their settings or changed ones")
    p.add_argument("ids", nargs="+", type=int, metavar="ID")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="change a setting (repeat; placement.KEY for placement, e.g. "
                        "placement.rotate=90; null: back to automatic)")
    p.add_argument("--copies", type=int)
    p.add_argument("--priority", type=int)
    p.add_argument("--printer", metavar="NAME", help="print it on this printer (or any)")
    p.add_argument("--hold", action="store_true", help="add it held (default: its preset's)")
    p.add_argument("--force", action="store_true", help="even if it does not fit the paper")
    p.add_argument("--wait", type=float, nargs="?", const=3600.0, metavar="S",
                   help="wait until it has printed (exit 1 if it did not)")
    add_settings_arguments(p)
    p.set_defaults(func=cmd_reprint)

    p = _client_parser(sub, "prices", "the price list that turns estimates into quotes and "
                       "prints into costs")
    p.add_argument("--set", metavar="FILE", help="a new price list (JSON or TOML: currency, "
                   "ink_per_ml, media_per_m2, machine_per_hour)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_prices)

    p = _client_parser(sub, "clear-fault", "a printer's fault cleared: its stopped job resumes "
                       "at its first unfinished stroke (or fails), its queue runs again")
    p.add_argument("printer", nargs="?", metavar="PRINTER", help="default: the first printer")
    p.add_argument("--fail", action="store_true", help="fail the stopped job instead of resuming it")
    p.set_defaults(func=cmd_clear_fault)

    p = _client_parser(sub, "move", "move a job not yet started to another printer")
    p.add_argument("id", type=int, metavar="ID")
    p.add_argument("printer", metavar="PRINTER", help="a printer's name, or any")
    p.set_defaults(func=cmd_move)

    p = _client_parser(sub, "estop", "emergency stop: every printing printer stops at once")
    p.set_defaults(func=cmd_estop)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="wideprint")
    sub = ap.add_subparsers(dest="command", required=True)
    add_parser(sub)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
