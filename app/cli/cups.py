"""`wideprint cups install|uninstall|status`: wideprint's MIME conversions on a CUPS server
(docs/ipp.md "CUPS queues").

A driverless CUPS queue (`lpadmin -m everywhere`) in front of wideprint's IPP printers
passes JPEG and PNG unchanged, but has no rule to pass TIFF, PDF or PostScript as they are:
without cups-filters CUPS refuses them, with cups-filters (any desktop Debian: the `cups`
package pulls it in) it converts them — an A3 PDF fitted to the default page, a TIFF turned
into a rotated page of PDF — and the RIP never sees the client's file.
`resources/cups/wideprint.convs` gives CUPS a rule of cost 0 from each of them to
`application/vnd.cups-raw` (no filter): CUPS takes the cheapest chain, so these formats go
to the printer unchanged, with or without cups-filters.

`install` copies it into CUPS' ServerRoot (`--server-root`, else $CUPS_SERVERROOT, else
/etc/cups; 0644, written whole) and makes cupsd read it: SIGHUP to `--cupsd-pid PID`, else
`systemctl restart cups` where systemd runs CUPS, else it says to restart cupsd.  `make
install` runs it when a CUPS server is installed.  Exit codes: 0 done (or already so),
1 it could not (no CUPS server there, no permission), 2 bad options.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from importlib import resources
from pathlib import Path

CONVS = "wideprint.convs"
EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def convs_text() -> bytes:
    """The conversions as the package ships them (resources/cups/wideprint.convs)."""
    return (resources.files("wideprint.resources") / "cups" / CONVS).read_bytes()


def server_root(given: str | None) -> Path:
    return Path(given or os.environ.get("CUPS_SERVERROOT") or "/etc/cups")


def install(root: Path) -> bool:
    """The conversions in `root` (True: written; False: already there, unchanged).
    FileNotFoundError when `root` is not a CUPS ServerRoot; OSError otherwise."""
    if not root.is_dir():
        raise FileNotFoundError(f"{root} is not there: no CUPS server on this machine "
                                f"(apt-get install cups), or give --server-root")
    data = convs_text()
    dest = root / CONVS
    try:
        if dest.read_bytes() == data:
            return False
    except FileNotFoundError:
        pass
    tmp = root / f".{CONVS}.tmp"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.chmod(tmp, 0o644)
    os.replace(tmp, dest)
    return True


def uninstall(root: Path) -> bool:
    try:
        os.unlink(root / CONVS)
    except FileNotFoundError:
        return False
    return True


def reload_cupsd(pid: int | None) -> str:
    """Make cupsd read its MIME conversions again; what was done, in words.  OSError or
    CalledProcessError when it could not."""
    if pid is not None:
        os.kill(pid, signal.SIGHUP)              # cupsd reloads its whole configuration
        return f"cupsd (pid {pid}) told to reload (SIGHUP)"
    systemctl = shutil.which("systemctl")
    if systemctl and Path("/run/systemd/system").is_dir():
        active = subprocess.run([systemctl, "is-active", "--quiet", "cups.service"])
        if active.returncode == 0:
            # Debian's cups.service has no reload: a restart (queued jobs are kept)
            subprocess.run([systemctl, "restart", "cups.service"], check=True,
                           capture_output=True, timeout=60)
            return "cups.service restarted"
        return "cups.service is not running: it reads the rules when it starts"
    return "restart cupsd to load the rules (no systemd here to do it)"


def cmd_cups(args) -> int:
    root = server_root(args.server_root)
    if args.action == "status":
        dest = root / CONVS
        if not dest.exists():
            print(f"{dest}: not installed")
            return EXIT_FAILED
        same = dest.read_bytes() == convs_text()
        print(f"{dest}: installed{'' if same else ', but not this version (run: wideprint cups install)'}")
        return EXIT_OK if same else EXIT_FAILED
    try:
        if args.action == "install":
            changed = install(root)
            print(f"{root / CONVS}: {'installed' if changed else 'already installed'} - TIFF, "
                  f"PDF and PostScript go to driverless queues unchanged (docs/ipp.md)")
        else:
            changed = uninstall(root)
            print(f"{root / CONVS}: {'removed' if changed else 'was not installed'}")
    except OSError as exc:
        print(f"wideprint cups {args.action}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    if changed and not args.no_reload:
        try:
            print(reload_cupsd(args.cupsd_pid))
        except (OSError, subprocess.SubprocessError) as exc:
            print(f"wideprint cups {args.action}: the rules are in place, but cupsd could not be "
                  f"told ({exc}): restart it", file=sys.stderr)
            return EXIT_FAILED
    return EXIT_OK


def add_parser(sub) -> None:
    p = sub.add_parser("cups", help="put wideprint's MIME conversions on a CUPS server "
                       "(driverless queues pass TIFF and PDF unchanged)",
                       description="Installs resources/cups/wideprint.convs in CUPS' "
                       "ServerRoot, so that a driverless queue in front of wideprint's IPP "
                       "printers sends TIFF, PDF and PostScript unchanged, with or without "
                       "cups-filters (docs/ipp.md \"CUPS queues\"), and makes cupsd read it.")
    p.add_argument("action", choices=("install", "uninstall", "status"))
    p.add_argument("--server-root", metavar="DIR",
                   help="CUPS' ServerRoot (default: $CUPS_SERVERROOT, else /etc/cups)")
    p.add_argument("--cupsd-pid", type=int, metavar="PID",
                   help="tell this cupsd to reload (SIGHUP) instead of `systemctl restart cups`")
    p.add_argument("--no-reload", action="store_true", help="only write the file")
    p.set_defaults(func=cmd_cups)
