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
    fsck        the state directory checked at start and by `serve --check`; a lost queue rebuilt
    crashpoints named points of a job's life where the crash tests kill the server
    core        PrintServer (ties the above together) and serve()
    ports       what api, worker and hotfolders see of PrintServer (they never import core)
"""

import importlib

# the names below load their module on first use (PEP 562), so that `wideprint --help`
# and the client commands import only the small config module, not the whole server
_WHERE = {
    "COLORS": "spool",
    "CSV_COLUMNS": "accounting",
    "DEFAULT_MAX_FILE": "config",
    "DEFAULT_PORT": "config",
    "DEFAULT_PRESETS": "presets",
    "HotFolders": "hotfolders",
    "IGNORED_SUFFIXES": "config",
    "IMAGE_SUFFIXES": "config",
    "Invalid": "validate",
    "MAX_COPIES": "config",
    "PRESET_FILES": "config",
    "PRIORITY_RANGE": "config",
    "Presets": "presets",
    "PrintServer": "core",
    "SERVER_FILE": "config",
    "ServerConfig": "config",
    "Spool": "spool",
    "SpoolError": "spool",
    "TOKEN_FILE": "config",
    "Worker": "worker",
    "default_state_dir": "config",
    "ensure_token": "config",
    "load_presets": "presets",
    "open_for_writing": "hotfolders",
    "preset_file": "presets",
    "prints_csv": "accounting",
    "read_presets": "presets",
    "rip_settings": "validate",
    "serve": "core",
    "validate_job_request": "validate",
    "validate_name": "validate",
    "validate_settings": "validate",
}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "CSV_COLUMNS", "COLORS", "DEFAULT_MAX_FILE", "DEFAULT_PORT", "DEFAULT_PRESETS",
    "HotFolders", "IGNORED_SUFFIXES", "IMAGE_SUFFIXES", "Invalid", "MAX_COPIES",
    "PRESET_FILES", "PRIORITY_RANGE", "Presets", "PrintServer", "SERVER_FILE", "Spool",
    "SpoolError", "TOKEN_FILE", "ServerConfig", "Worker", "default_state_dir",
    "ensure_token", "load_presets", "open_for_writing", "preset_file", "prints_csv",
    "read_presets", "rip_settings", "serve", "validate_job_request", "validate_name",
    "validate_settings",
]
