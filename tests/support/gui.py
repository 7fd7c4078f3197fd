"""The operator GUI's tests (tests/test_gui*.py): a `wideprint serve` process for the window to
attach to, the real main window on it, and reading the window's job tables.  Import after
PySide6 is known to be there (the test files import-or-skip it first)."""

from __future__ import annotations

from pathlib import Path

import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import ServerProcess
from wideprint.app.gui.main_window import MainWindow
from wideprint.app.gui.server_link import ServerLink, find_or_start

LONG = 90_000          # ms: whole jobs on a loaded 2-core machine


class Server(ServerProcess):
    """`wideprint serve` for the GUI: media and hot folders under `root`, a hot folder that
    settles in 0.3 s and is scanned every 0.2 s, the log in ROOT/server.out."""

    def __init__(self, root: Path, *extra: str):
        self.root = root
        self.media = root / "media"
        self.hot = root / "hot"
        super().__init__(root / "state", "--hot-folder-root", str(self.hot),
                         "--settle-time", "0.3", "--scan-interval", "0.2", *extra,
                         device=None, media_dir=self.media, log=root / "server.out")


def open_window(qtbot, srv: Server, cfg: Path) -> MainWindow:
    """The main window attached to `srv` (found through its state folder, as the GUI finds a
    running server), 1366 x 768, shown, once it lists the printers."""
    client, proc = find_or_start(srv.state)
    assert proc is None                            # the running server, not a new one
    w = MainWindow(ServerLink(srv.state, client), config_dir=cfg)
    w.ask_before_closing = False
    qtbot.addWidget(w)
    w.resize(1366, 768)
    w.show()
    qtbot.waitUntil(lambda: bool(w.printers), timeout=20_000)
    return w


@pytest.fixture
def paused_server(tmp_path):
    """A paused `wideprint serve` for the test (a test file names it: `server = paused_server`)."""
    s = Server(tmp_path, "--paused")
    yield s
    s.stop()


@pytest.fixture
def window(qtbot, server, tmp_path):
    """The main window on the test's `server` (`win = window`), stopped after the test."""
    w = open_window(qtbot, server, tmp_path / "cfg")
    yield w
    w.link.stop()


def image(tmp_path: Path, name: str, seed: int, rows: int = 300, cols: int = 400):
    planes = random_planes(rows, cols, seed=seed)
    return write_cmyk_tiff(tmp_path / name, planes), planes


def names_in(view) -> list[str]:
    return [j["name"] for j in view.model().jobs]


def job_named(win, name: str) -> dict:
    for j in win.queue_model.jobs + win.history_model.jobs:
        if j["name"] == name:
            return j
    raise KeyError(name)


def select(win, names) -> None:
    win.tabs.setCurrentIndex(0)
    win.queue_view.select_ids([job_named(win, n)["id"] for n in names])
    win._show_selection()
