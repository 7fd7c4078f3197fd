"""Text from clients made safe to show to people (docs/server.md "Safety rules"): a job's
name may hold characters that are invisible or that reorder what follows them (U+202E
RIGHT-TO-LEFT OVERRIDE makes `invoice\u202efdp.exe` look like `invoiceexe.pdf`).  Such
characters are shown escaped (`\\u202e`) wherever a name reaches a person: the API's
`display_name`, the command line's tables, the GUI and the log.  The stored name stays
exactly as it was sent.

Escaped: Unicode categories Cc (control, except tab and newline where a caller keeps
them), Cf (format: the bidirectional embeddings, overrides and isolates, LRM/RLM/ALM,
zero-width space/joiners, word joiner, BOM, soft hyphen, ...), Co, Cs, Cn (private, lone
surrogates, unassigned), Zl and Zp (line and paragraph separators), and the fillers that
draw nothing (Hangul fillers, braille blank, ...).  Letters of every script stay as they
are.

`LogFilter` applies the same to every log line of the loggers it is put on, and takes out
secrets (API tokens) that a line might carry: a token in a URL query or one of the tokens
registered with `add_secret`.
"""

from __future__ import annotations

import logging
import re
import threading
import unicodedata

# drawn as nothing, yet letters (category Lo/So) or spaces
INVISIBLE = frozenset("\u115f\u1160\u3164\uffa0\u2800\u180e\u034f\u17b4\u17b5")
UNSAFE_CATEGORIES = frozenset(("Cc", "Cf", "Co", "Cs", "Cn", "Zl", "Zp"))


def _escape(ch: str) -> str:
    n = ord(ch)
    if n < 0x100:
        return f"\\x{n:02x}"
    if n < 0x10000:
        return f"\\u{n:04x}"
    return f"\\U{n:08x}"


def unsafe(ch: str, keep: str = "") -> bool:
    """Whether a character must be escaped when shown (`keep`: characters let through,
    e.g. "\\n\\t" for multi-line text)."""
    if ch in keep:
        return False
    if ch.isascii():
        return not ch.isprintable()
    return ch in INVISIBLE or unicodedata.category(ch) in UNSAFE_CATEGORIES


def safe(text, keep: str = "") -> str:
    """`text` with every invisible, control or reordering character escaped (`\\u202e`);
    a backslash stays a backslash (this is for showing, not for parsing back)."""
    text = str(text)
    if text.isascii() and text.isprintable():
        return text                                    # the usual case, at once
    return "".join(_escape(ch) if unsafe(ch, keep) else ch for ch in text)


# -- the log -------------------------------------------------------------------------------------
_secrets: set[str] = set()
_secrets_lock = threading.Lock()
QUERY_SECRET = re.compile(r"(?i)((?:^|[?&;\s'\"])(?:access_token|token|auth|authorization|"
                          r"password|passwd|secret|api_key|apikey)=)([^&;\s'\"]*)")
REDACTED = "[redacted]"


def add_secret(value: str) -> None:
    """A secret (an API token) never to be written to the log."""
    if value and len(value) >= 8:
        with _secrets_lock:
            _secrets.add(value)


def forget_secret(value: str) -> None:
    with _secrets_lock:
        _secrets.discard(value)


def redact(text: str) -> str:
    """`text` without the registered secrets and without the value of a token-like query
    parameter (`token=...`)."""
    text = QUERY_SECRET.sub(lambda m: m.group(1) + (REDACTED if m.group(2) else ""), text)
    with _secrets_lock:
        secrets = tuple(_secrets)
    for s in secrets:
        if s in text:
            text = text.replace(s, REDACTED)
    return text


class LogFilter(logging.Filter):
    """Every record's message made safe to show and free of secrets (the record is
    rewritten once, before any handler formats it)."""

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            msg = record.getMessage()
        except Exception:  # noqa: BLE001 - a broken record: logging reports it itself
            return True
        clean = redact(safe(msg, keep="\n\t"))
        if clean != msg:
            record.msg, record.args = clean, ()
        return True


_installed: set[str] = set()


def install_log_filter(*names: str) -> None:
    """Put one LogFilter on each named logger (a logger's filters see the records logged
    to it by name, so every logger that may log a client's text gets one)."""
    for name in names:
        if name not in _installed:
            logging.getLogger(name).addFilter(LogFilter())
            _installed.add(name)
