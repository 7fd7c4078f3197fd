"""Plain-language explanations of faults and failures for the operator."""

from __future__ import annotations

import re

# (pattern in the driver's / loader's message, what it means and what to do)
_RULES = [
    (r"dead nozzles .* unprintable with", "Nozzles marked dead in the printer profile leave rows that "
     "no other nozzle can print in this many passes. Choose 2 or more passes (the other passes print "
     "those rows), or, if the head was cleaned or replaced, clear the dead nozzles in Test prints & "
     "calibration (nozzle check)."),
    (r"FIFO underrun", "Print data reached the heads too late, so the stroke stopped. The computer "
     "or the data link could not keep up: close other programs, check the data cable, then print "
     "the job again."),
    (r"FIFO overflow", "The printer received more print data than announced (driver and firmware "
     "disagree). Restart the printer and this program."),
    (r"over-temperature", "A print head got too hot and was switched off. Let the heads cool down "
     "and check the head heater and ink supply; then Clear fault and print again."),
    (r"paper out|feed error", "The paper ran out or slipped during the feed. Load paper, Clear fault "
     "and print the job again."),
    (r"limit switch", "The carriage hit the end of its rail. Check that nothing blocks the "
     "carriage; Clear fault (the printer homes again)."),
    (r"nozzle 0 or 127", "The print data addressed a nozzle that must never fire. This is a "
     "software fault: save the log and report it."),
    (r"fire rate above|above their .* Hz", "The carriage would move too fast for the heads at this "
     "resolution. Use the profile's speed or a lower dpi."),
    (r"over-current", "The carriage motor drew too much current: something may be blocking the "
     "carriage. Check the rail and the belt, then Clear fault."),
    (r"following error", "The carriage could not follow its planned move (blocked or a slipping "
     "belt). Check the carriage, then Clear fault."),
    (r"CRC error", "Print data was damaged on its way to the printer. Check the data cable; the job "
     "can be printed again."),
    (r"out of sequence", "Print data arrived out of order (a link problem). Check the connection "
     "and print again."),
    (r"emergency stop", "The emergency stop was used. Make the machine safe, then press Clear fault "
     "before printing again."),
    (r"head configuration", "The heads are not configured (the printer was probably switched off "
     "and on). Connect again."),
    (r"data link lost|data link dropped|data link down", "The data connection to the printer dropped. "
     "Check the cable or network and print again."),
    (r"encoder glitch", "The carriage position sensor (encoder strip) gave an impossible reading. "
     "Clean the encoder strip, Clear fault and print again."),
    (r"mm wide at .* but the paper is", "The image is wider than the loaded paper. Load wider "
     "paper, or make the image smaller or rotate it."),
    (r"no paper loaded", "No paper is loaded. Load paper and print again."),
    (r"no printer answered|cannot reach the printer|cannot open|cannot connect|no valid answer",
     "The printer does not answer. Check that it is switched on, and the port and address in the "
     "Device field."),
    (r"did not finish", "The printer did not finish a movement in time. Check the carriage and "
     "the paper feed."),
    (r"cancel", "Cancelled by the operator."),
    (r"file not found", "The file is no longer there (moved or deleted)."),
    (r"not enough memory|not enough disk", "The computer ran out of memory or disk space for this "
     "image. Free some space or print a smaller image."),
    (r"ICC profile", "A colour profile could not be used. Choose another ICC profile or clear the "
     "field to use the default."),
    (r"truncated|corrupt|not a .*(image|TIFF|JPEG|BMP)|unknown format|cannot decode|cannot read|"
     r"unsupported|empty file|not an image|is a directory",
     "The file cannot be printed: it is damaged or not a supported image. Export it again as "
     "TIFF, BMP or JPEG."),
]


_PATH = re.compile(r"(?:[A-Za-z]:)?[/\\](?:[^\s:'\"/\\]+[/\\])+([^\s:'\"/\\]+)")


def short_paths(text: str) -> str:
    """File paths in a message reduced to their names (the full text goes in tooltips)."""
    return _PATH.sub(r"\1", text or "")


def plain_message(text: str) -> str:
    """What a failure message means for the operator ("" when we have nothing to add)."""
    if not text:
        return ""
    for pattern, advice in _RULES:
        if re.search(pattern, text, re.IGNORECASE):
            return advice
    return ""
