"""`wideprint printer status|home|park|feed MM|measure|clear-fault|spit|purge|cap|uncap`:
the machine commands
of the printer API (driver/printer.py) from the command line, on a real link or the
emulator (docs/driver.md, "The printer API").

`wideprint printer roll [show|load|set|unload]`: the roll loaded on a printer of the print
server, through its API (docs/server.md "Rolls") - the server owns the printers' paper count.

A motion command brings the printer as far as it needs first (enable, home), as the
front panel of a plotter does, and says so.  Exit codes as `print`: 0 done, 1 the printer
refused or faulted, 2 bad options, 3 the printer cannot be reached.
"""

from __future__ import annotations

import argparse
import json
import sys

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_DEVICE = 0, 1, 2, 3
ACTIONS = ("status", "home", "park", "feed", "measure", "clear-fault",
           "spit", "purge", "cap", "uncap",          # the last four: head care (protocol 2.9)
           "roll")                                   # the print server's roll (its API)
ROLL_ACTIONS = ("show", "load", "set", "unload")


def add_parser(sub) -> None:
    from .. import devices
    p = sub.add_parser("printer", help="printer status and machine commands (home, park, "
                       "feed, measure the paper, clear a fault, spit, purge, cap)",
                       description="Status and machine commands of one printer, through the "
                       "driver's printer API.")
    p.add_argument("action", choices=ACTIONS)
    p.add_argument("mm", nargs="?", help="feed: millimetres of paper (negative: back); roll: "
                   f"{', '.join(ROLL_ACTIONS)} (default show)")
    p.add_argument("--device", default="emulator",
                   help=devices.DEVICE_HELP + " (default: emulator)")
    p.add_argument("--profile", metavar="TOML", help="printer profile")
    p.add_argument("--inject", action="append", metavar="KIND=VALUE",
                   help="emulator fault (docs/emulator.md)")
    p.add_argument("--heads", metavar="C1,M2,...",
                   help="spit, purge: only these heads (default: all)")
    p.add_argument("--drops", type=int, metavar="N",
                   help="spit: drops per nozzle (default: the profile's spit_drops)")
    p.add_argument("--ms", type=int, metavar="MS",
                   help="purge: pump time in ms (default: the profile's purge_ms)")
    p.add_argument("--json", action="store_true", help="status as JSON")
    r = p.add_argument_group("roll (through the print server: docs/server.md \"Rolls\")")
    r.add_argument("--printer", metavar="NAME", help="the server's printer (default: its first)")
    r.add_argument("--media", metavar="NAME", help="roll load: the media (library name: "
                   "wideprint media list)")
    r.add_argument("--length", metavar="M", help="roll load: its length (50, 50m, 50000mm)")
    r.add_argument("--label", metavar="TEXT", help="roll load: the roll's label as read, e.g. "
                   "'media=vinyl-300 length=50m'")
    r.add_argument("--remaining", metavar="M", help="roll set: what is left on it, measured")
    r.add_argument("--spare", metavar="M", help="roll load, set: warn when the roll left is less "
                   "than the jobs waiting need plus this (default 1 m)")
    r.add_argument("--state-dir", metavar="DIR", help="the server's state directory")
    p.set_defaults(func=cmd_printer)


def _show_roll(r: dict) -> None:
    roll = r["roll"]
    if roll is None:
        print(f"printer {r['printer']}: no roll loaded (wideprint printer roll load --media "
              f"NAME --length M)")
        return
    width = roll["width_mm"] if roll["width_mm"] is not None else r.get("paper_mm")
    left = "unknown length" if roll["remaining_m"] is None else \
        f"{roll['remaining_m']:,.2f} m left of {roll['length_m']:,.2f} m"
    print(f"printer {r['printer']}: {roll['media']}, "
          + (f"{width:,.0f} mm wide" if width else "width not measured yet") + f", {left}")


def cmd_roll(args) -> int:
    """`wideprint printer roll ...`: the print server's roll on one printer."""
    from ..client import ApiError, Client
    what = args.mm or "show"
    if what not in ROLL_ACTIONS:
        print(f"wideprint printer roll: {what!r}: one of {', '.join(ROLL_ACTIONS)}", file=sys.stderr)
        return EXIT_USAGE
    body: dict | None = None
    if what == "load":
        body = {k: v for k, v in (("media", args.media), ("length_m", args.length),
                                  ("label", args.label), ("spare_m", args.spare)) if v is not None}
    elif what == "set":
        if args.remaining is None and args.spare is None:
            print("wideprint printer roll set: --remaining M and/or --spare M", file=sys.stderr)
            return EXIT_USAGE
        body = {k: v for k, v in (("remaining_m", args.remaining), ("spare_m", args.spare))
                if v is not None}
    elif what == "unload":
        body = {"unload": True}
    try:
        client = Client(args.state_dir)
        name = args.printer or client.printers()[0]["name"]
        r = client.roll(name, body)
    except ApiError as exc:
        print(f"wideprint printer roll: {exc}", file=sys.stderr)
        return EXIT_DEVICE if exc.status == 0 else EXIT_FAILED
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        _show_roll(r)
        # the printer's warning before a job runs off the roll (docs/server.md "Rolls: the warning")
        for p in client.printers():
            for w in p.get("warnings") or [] if p["name"] == name else []:
                print(f"WARNING: {w['message']}")
    return EXIT_OK


def status_dict(printer) -> dict:
    """Everything the status command shows, as JSON-able values."""
    from ...driver import protocol as P
    st = printer.status()
    info = printer.identity or {}
    flags = {name: bool(st.flags & bit) for name, bit in (
        ("enabled", P.FLAG_ENABLED), ("homed", P.FLAG_HOMED),
        ("heads_configured", P.FLAG_HEADS_CONFIGURED), ("paper_measured", P.FLAG_PAPER_MEASURED),
        ("job_open", P.FLAG_JOB_OPEN))}
    cpi = printer.profile.counts_per_inch
    out = dict(
        firmware=f"{info.get('firmware', 0) >> 8}.{info.get('firmware', 0) & 0xFF}",
        serial=info.get("serial", ""), protocol=f"{info.get('proto_major')}.{info.get('proto_minor')}",
        **flags, motion=P.Motion(st.motion).name.lower() if st.motion in P.Motion._value2member_map_
        else str(st.motion),
        carriage_mm=round(st.carriage / cpi * 25.4, 2), paper_steps=st.paper_steps,
        fifo_words=dict(zip((h.name for h in printer.profile.heads), printer.fifo_levels(st))),
        heads={h.name: dict(temperature_c=h.temperature_c, piezo_v=h.piezo_v,
                            configured=h.configured, overtemp=h.overtemp, dead=h.dead)
               for h in printer.heads()},
        fault=printer.fault_text(st) or None)
    if (info.get("proto_major"), info.get("proto_minor", 0)) >= (1, 1):
        svc = printer.call(P.Op.SERVICE_STATUS)
        out["capped"] = bool(svc.capped)
        out["since_spit_s"] = {h.name: (None if a == 0xFFFFFFFF else round(a / 1000, 1))
                               for h, a in zip(printer.profile.heads, svc.spit_age_ms)}
    if flags["paper_measured"]:
        paper = printer.paper()
        out["paper"] = dict(present=paper.present, width_mm=round(paper.width_mm, 1),
                            left_mm=round(paper.left_mm, 1))
    return out


def _print_status(d: dict) -> None:
    print(f"printer: firmware {d['firmware']}, serial {d['serial']}, protocol {d['protocol']}")
    state = [k.replace("_", " ") for k in ("enabled", "homed", "heads_configured",
                                           "paper_measured", "job_open") if d[k]]
    print(f"state: {', '.join(state) or 'not enabled'}; motion {d['motion']}")
    print(f"carriage: {d['carriage_mm']} mm; paper feed: step {d['paper_steps']}")
    if "paper" in d:
        p = d["paper"]
        print(f"paper: {p['width_mm']} mm wide from {p['left_mm']} mm" if p["present"] else "paper: none")
    print("heads: " + ", ".join(f"{n} {h['temperature_c']:.1f} °C" + (" OVER-TEMPERATURE" if h["overtemp"] else "")
                                + ("" if h["configured"] else " (not configured)")
                                for n, h in d["heads"].items()))
    print("FIFO words: " + ", ".join(f"{n} {w}" for n, w in d["fifo_words"].items()))
    if "capped" in d:
        print(f"heads {'capped' if d['capped'] else 'uncapped'}; since the last spit: "
              + ", ".join(f"{n} {'never' if s is None else f'{s} s'}"
                          for n, s in d["since_spit_s"].items()))
    print(f"fault: {d['fault'] or 'none'}")


def head_mask(profile, names: str | None) -> int:
    """`C1,M2` -> the heads' bit mask (docs/protocol.md 2.9); None: every head."""
    heads = {h.name: h.index for h in profile.heads}
    if not names:
        return (1 << len(heads)) - 1
    mask = 0
    for name in (n.strip() for n in names.split(",")):
        if name not in heads:
            raise ValueError(f"--heads: no head {name!r} (heads: {', '.join(heads)})")
        mask |= 1 << heads[name]
    return mask


def _names(profile, mask: int) -> str:
    return ", ".join(h.name for h in profile.heads if mask >> h.index & 1)


def _again(printer, step, tries: int = 3):
    """Run a machine command; when the link fails (3 tries of a frame, e.g. a slow or noisy
    line) reconnect and run it again.  Every command here is safe to repeat: home, park,
    measure and enable are idempotent, a feed goes to an absolute position."""
    from ...driver.link import LineTooNoisy, LinkError
    for attempt in range(tries):
        try:
            return step()
        except LineTooNoisy:
            raise
        except LinkError:
            if attempt == tries - 1:
                raise
            try:
                printer.connect()
            except LinkError:
                pass                        # the next try says it again, or the last one raises


def cmd_printer(args) -> int:
    from ...driver import protocol as P
    from ...driver.link import DeviceError, LinkError
    from ...driver.printer import Printer, PrinterFault
    from ...rip.profile import load_profile
    from ...driver.headcare import HeadCare
    from ..devices import close_device, is_emulator_spec, open_device
    if args.action == "roll":
        return cmd_roll(args)
    if (args.action == "feed") != (args.mm is not None):
        print("wideprint printer: feed takes a length in mm (and only feed does)", file=sys.stderr)
        return EXIT_USAGE
    if args.action == "feed":
        try:
            args.mm = float(args.mm)
        except ValueError:
            print(f"wideprint printer: feed {args.mm!r}: a length in mm", file=sys.stderr)
            return EXIT_USAGE
    try:
        profile = load_profile(args.profile)
        mask = head_mask(profile, args.heads)
        faults = None
        if args.inject:
            if not is_emulator_spec(args.device):
                raise ValueError(f"--inject needs an emulated device (--device emulator, "
                                 f"emulator-usb or emulator-pci), not {args.device}")
            from ...device_sim.faults import Faults
            faults = Faults.parse(args.inject)
    except ValueError as exc:
        print(f"wideprint printer: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        dev = open_device(args.device, profile, faults)
    except (LinkError, ValueError, OSError) as exc:
        print(f"wideprint printer: {exc}", file=sys.stderr)
        return EXIT_DEVICE
    printer = Printer(dev)
    try:
        _again(printer, printer.connect)
        if args.action == "status":
            d = status_dict(printer)
            print(json.dumps(d, indent=2)) if args.json else _print_status(d)
            return EXIT_OK
        if args.action == "clear-fault":
            cleared = printer.clear_fault()
            print(f"cleared: {P.FAULT_TEXT.get(P.Fault(cleared), hex(cleared))}" if cleared
                  in P.Fault._value2member_map_ and cleared else "no fault was latched")
            return EXIT_OK
        st = printer.status()
        if st.fault != P.Fault.NONE:
            print(f"wideprint printer: {args.action}: the printer reports a fault: "
                  f"{printer.fault_text(st)} (clear it first: wideprint printer clear-fault)",
                  file=sys.stderr)
            return EXIT_FAILED
        if not st.flags & P.FLAG_ENABLED:
            _again(printer, printer.enable)
        if args.action == "uncap" or (st.flags & P.FLAG_CAPPED and args.action != "cap"):
            print("uncapping")               # before anything moves: protocol 2.9
            _again(printer, lambda: HeadCare(printer).cap(False))
            if args.action == "uncap":
                return EXIT_OK
            print("uncapping")
            _again(printer, lambda: HeadCare(printer).cap(False))
        if args.action == "home" or not st.flags & P.FLAG_HOMED:
            print("homing")
            _again(printer, printer.home)
        if args.action == "park":
            _again(printer, printer.park)
            print(f"parked at {printer.status().carriage / profile.counts_per_inch * 25.4:.1f} mm")
        elif args.action == "measure":
            paper = _again(printer, printer.measure_paper)
            print(f"paper: {paper.width_mm:.1f} mm wide from {paper.left_mm:.1f} mm" if paper.present
                  else "paper: none loaded")
        elif args.action == "feed":
            steps = int(round(args.mm * 1000 / profile.feed_um_per_step))
            target = printer.status().paper_steps + steps       # absolute: safe to repeat
            _again(printer, lambda: printer.feed_to(target))
            print(f"fed {steps * profile.feed_um_per_step / 1000:.3f} mm ({steps} steps)")
        elif args.action == "cap":
            _again(printer, lambda: HeadCare(printer).cap(True))
            print("parked and capped")
        elif args.action == "spit":
            care = HeadCare(printer)
            drops = args.drops or profile.maintenance.spit_drops
            _again(printer, lambda: care.spit(mask, drops))
            print(f"spat {drops} drops per nozzle: heads {_names(profile, mask)}")
        elif args.action == "purge":
            care = HeadCare(printer)
            ms = args.ms or profile.maintenance.purge_ms
            _again(printer, lambda: care.purge(mask, ms))
            print(f"purged {ms} ms and wiped: heads {_names(profile, mask)}")
        return EXIT_OK
    except LinkError as exc:
        print(f"wideprint printer: {exc}", file=sys.stderr)
        return EXIT_DEVICE
    except (PrinterFault, DeviceError) as exc:
        print(f"wideprint printer: {args.action}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        close_device(dev)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="wideprint")
    add_parser(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    return args.func(args)
