"""`wideprint emulator`: the printer emulator on a pty and TCP, for another process's driver."""

from __future__ import annotations

import signal
import sys

from .common import EXIT_OK, EXIT_USAGE, _emulator_job_options, _emulator_options, _profile


def cmd_emulator(args) -> int:
    from ...device_sim.faults import Faults
    from ...device_sim.printer import Printer
    from ...device_sim.server import EmulatorServer
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


def add_parser(sub) -> None:
    p = sub.add_parser("emulator", help="run the printer emulator on a pty and TCP")
    p.add_argument("--data-port", type=int, default=0, help="TCP port of the data channel (0 = any)")
    p.add_argument("--serial-port", type=int, default=None,
                   help="serve the command channel on this TCP port instead of a pty")
    p.add_argument("--data-pty", action="store_true",
                   help="serve the data channel on a pty (stands in for the PCI card's device node)")
    p.add_argument("--media-out", metavar="MEDIA.tif", help="media file ({job} = job id)")
    _emulator_job_options(p)
    p.set_defaults(func=cmd_emulator)
