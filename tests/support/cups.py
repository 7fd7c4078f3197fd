"""What this machine's CUPS converts, read from its .convs files as cupsd reads them, for
the tests whose right outcome depends on Debian's cups-filters (tests/test_cups.py,
tests/test_ipp_cups.py).  A bare Debian with cups-daemon alone has no filter for TIFF or
plain text, so CUPS refuses them where the queue's PPD does not take them; a desktop Debian
(the `cups` package pulls cups-filters in) converts both to PDF.  The private cupsd of
tests/private_cups.py uses the system's DataDir and filters, so it converts what this says.
No test depends on a package being absent: each asserts what CUPS must do either way."""

from __future__ import annotations

from pathlib import Path

CUPS_MIME = Path("/usr/share/cups/mime")       # DataDir/mime: mime.convs, cupsfilters.convs ...
CUPS_FILTERS = Path("/usr/lib/cups/filter")    # ServerBin/filter


def conversions_from(mime_type: str, mime_dirs=(CUPS_MIME,), filter_dir=CUPS_FILTERS) -> list[str]:
    """The conversions from `mime_type` (a rule for it or for `super/*`) whose filter
    program is installed, as 'FILE: source destination cost program'."""
    wild = mime_type.split("/")[0] + "/*"
    found = []
    for convs in sorted(p for d in mime_dirs for p in Path(d).glob("*.convs")):
        for line in convs.read_text(errors="replace").splitlines():
            fields = line.split("#", 1)[0].split()
            if len(fields) == 4 and fields[0] in (mime_type, wild) and \
                    (fields[3] == "-" or (Path(filter_dir) / fields[3]).exists()):
                found.append(f"{convs.name}: {' '.join(fields)}")
    return found
