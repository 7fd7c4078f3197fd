"""IPP Everywhere for wideprint (docs/ipp.md): the Printer Application (wideprint-ipp.c,
built on PAPPL) and its bridge to the print server (bridge.py)."""

from .bridge import DEFAULT_IPP_PORT, IppBridge, find_binary  # noqa: F401
