import os
import sys
from pathlib import Path

# Qt must never look for a display in the test run (PySide6 aborts without one).
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# the run's own cache (rip/color/lutcache.py's LUTs): nothing read from or left in the user's ~/.cache
if "WIDEPRINT_CACHE_DIR" not in os.environ:
    import atexit
    import shutil
    import tempfile
    os.environ["WIDEPRINT_CACHE_DIR"] = tempfile.mkdtemp(prefix="wideprint-test-cache-")
    atexit.register(shutil.rmtree, os.environ["WIDEPRINT_CACHE_DIR"], True)

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

# the shared helpers live in tests/support, and test files import them from there
# (tests/test_support.py); this file turns them into fixtures
from support.background import Background, declared  # noqa: E402
from support.server import ServerProcess, inprocess_server  # noqa: E402


def _import_the_package_now() -> None:
    """pytest rewrites the asserts of every module of wideprint (its pytest11 plugin makes
    the distribution a plugin), compiling each module's source when it is first imported.
    CPython 3.11's compiler is not safe to run on two threads at once ("AST constructor
    recursion depth mismatch"): a module first imported by a server's worker thread while
    the test imports another fails at random.  So every module is imported here, once,
    before any test starts a thread (the GUI's only when PySide6 is there)."""
    import importlib
    import pkgutil
    import wideprint
    for m in pkgutil.walk_packages(wideprint.__path__, "wideprint."):
        if ".gui" in m.name or m.name.endswith("__main__"):
            continue
        try:
            importlib.import_module(m.name)
        except Exception:  # noqa: BLE001 - an optional dependency: that module's tests say so
            pass


_import_the_package_now()

@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """The markers `slow`, `system` and `gui` (`make test-fast` runs the suite without them),
    from the tables in tests/support/marks.py: the test files carry none themselves.  First,
    so that `-m` sees them."""
    from support.marks import markers_for
    for item in items:
        function = getattr(item, "originalname", None) or item.name.split("[")[0]
        for name in markers_for(item.path.name, function, getattr(item, "fixturenames", ())):
            item.add_marker(getattr(pytest.mark, name))


def pytest_collection_finish(session):
    """The long single-threaded computations that the run's tests declare (BACKGROUND in
    their module, tests/support/background.py) start now, at the lowest priority."""
    entries = [] if session.config.option.collectonly else declared(session.items)
    if entries:
        session.config._wideprint_background = bg = Background()
        for key, argv, env in entries:
            bg.submit(key, argv, env)


def pytest_sessionfinish(session):
    bg = getattr(session.config, "_wideprint_background", None)
    if bg is not None:
        bg.close()


@pytest.fixture(scope="session")
def background(pytestconfig):
    """The run's background computations (support.background.Background)."""
    bg = getattr(pytestconfig, "_wideprint_background", None)
    assert bg is not None, "no background computations were started"
    return bg


@pytest.fixture(scope="session")
def profile():
    from wideprint.rip.profile import load_profile
    return load_profile()


@pytest.fixture
def print_server(tmp_path):
    """Start in-process print servers (support.server.inprocess_server): call it with the
    ServerConfig fields that differ (`root` defaults to a fresh folder under tmp_path);
    every server it started is stopped after the test."""
    started = []

    def start(root=None, **config):
        root = root or tmp_path / f"server{len(started)}"
        started.append(inprocess_server(root, **config))
        return started[-1]
    yield start
    for s in reversed(started):
        s.stop(timeout=5)


@pytest.fixture
def server_process():
    """Start `wideprint serve` processes (support.server.ServerProcess(state, *args, ...));
    every one still running is stopped (SIGTERM) after the test."""
    started = []

    def start(state, *args, **kw):
        started.append(ServerProcess(state, *args, **kw))
        return started[-1]
    yield start
    for s in reversed(started):
        if s.proc.poll() is None:
            s.stop()
