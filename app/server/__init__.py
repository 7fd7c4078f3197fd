"""The print server (docs/server.md): one process owns the printer and a persistent queue;
the CLI, the GUI, CUPS and hot folders are its clients.  One module per concern:

    config      state directory, token, constants, ServerConfig
    validate    what a request may contain (settings: the one schema, rip/settings.py)
    presets     settings presets, re-read without a restart
    spool       the persistent queue and the accounting rows (SQLite, WAL)
    worker      prints queued jobs on the printer, checkpoint after every stroke
    hotfolders  folders whose files become jobs
    api         the local HTTP/JSON API
    accounting  CSV of printed copies
    core        PrintServer (ties the above together) and serve()
"""

from .accounting import CSV_COLUMNS, prints_csv
from .config import (DEFAULT_MAX_FILE, DEFAULT_PORT, IGNORED_SUFFIXES, IMAGE_SUFFIXES,
                     MAX_COPIES, PRESET_FILES, PRIORITY_RANGE, SERVER_FILE, TOKEN_FILE,
                     ServerConfig, default_state_dir, ensure_token)
from .core import PrintServer, serve
from .hotfolders import HotFolders, open_for_writing
from .presets import DEFAULT_PRESETS, Presets, load_presets, preset_file, read_presets
from .spool import COLORS, Spool, SpoolError
from .validate import (Invalid, rip_settings, validate_job_request, validate_name,
                       validate_settings)
from .worker import Worker

__all__ = [
    "CSV_COLUMNS", "COLORS", "DEFAULT_MAX_FILE", "DEFAULT_PORT", "DEFAULT_PRESETS",
    "HotFolders", "IGNORED_SUFFIXES", "IMAGE_SUFFIXES", "Invalid", "MAX_COPIES",
    "PRESET_FILES", "PRIORITY_RANGE", "Presets", "PrintServer", "SERVER_FILE", "Spool",
    "SpoolError", "TOKEN_FILE", "ServerConfig", "Worker", "default_state_dir",
    "ensure_token", "load_presets", "open_for_writing", "preset_file", "prints_csv",
    "read_presets", "rip_settings", "serve", "validate_job_request", "validate_name",
    "validate_settings",
]
