"""systemd's readiness protocol (sd_notify(3)): one datagram to $NOTIFY_SOCKET.

Written here rather than taken from a package: the protocol is a single datagram of
KEY=VALUE lines on a Unix socket (abstract when the path starts with '@'), the
standard library does it in a few lines, and the Python packages for it are either
unmaintained (sdnotify, last release 2017) or need libsystemd (systemd-python).
Outside systemd ($NOTIFY_SOCKET unset) every call does nothing.
"""

from __future__ import annotations

import os
import socket


def notify(**state: str | int) -> bool:
    """notify(READY=1, STATUS="...") -> True if systemd was told."""
    path = os.environ.get("NOTIFY_SOCKET")
    if not path or not state:
        return False
    if path.startswith("@"):                   # an abstract socket
        path = "\0" + path[1:]
    message = "\n".join(f"{k}={v}" for k, v in state.items()).encode()
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as s:
            s.connect(path)
            s.sendall(message)
        return True
    except OSError:
        return False
