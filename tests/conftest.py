import os
import sys
from pathlib import Path

# Qt must never look for a display in the test run (PySide6 aborts without one).
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# the run's own cache (rip/color.py's LUTs): nothing read from or left in the user's ~/.cache
if "WIDEPRINT_CACHE_DIR" not in os.environ:
    import atexit
    import shutil
    import tempfile
    os.environ["WIDEPRINT_CACHE_DIR"] = tempfile.mkdtemp(prefix="wideprint-test-cache-")
    atexit.register(shutil.rmtree, os.environ["WIDEPRINT_CACHE_DIR"], True)

import numpy as np
import pytest
import tifffile

sys.path.insert(0, str(Path(__file__).resolve().parent))

ROOT = Path(__file__).resolve().parent.parent

from wideprint.rip.place import Placement  # noqa: E402


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


# 1 image pixel = 1 device dot: the placement for tests that compare the media with the
# planes they wrote (a physical-size placement resamples them)
PX = Placement(size="pixels")


@pytest.fixture(scope="session")
def profile():
    from wideprint.rip.profile import load_profile
    return load_profile()


# the default profile's device grid at 300 dpi: 300 columns and 25400 / 68.55 rows per inch
DEVICE_PPI = (300.0, 25400 / 68.55)


def write_cmyk_tiff(path, planes01: np.ndarray) -> Path:
    """A CMYK TIFF whose channels hold only 0 and 255, from 0/1 planes (h, w, 4), tagged
    with the 300 dpi device grid's resolution, so that even a physical-size placement
    prints it 1 pixel = 1 dot."""
    tifffile.imwrite(path, (planes01 * 255).astype(np.uint8), photometric="separated",
                     resolution=DEVICE_PPI, resolutionunit="INCH")
    return Path(path)


def random_planes(h: int, w: int, density: float = 0.3, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.random((h, w, 4)) < density).astype(np.uint8)


def read_bands(src, rows: int = 37) -> np.ndarray:
    """All of an image source's bands, checking their heights, shape and dtype."""
    parts = list(src.bands(rows))
    for p in parts[:-1]:
        assert p.shape[0] == rows
    arr = np.concatenate(parts, axis=0)
    assert arr.shape == (src.height, src.width, src.channels)
    assert arr.dtype == (np.uint16 if src.depth == 16 else np.uint8)
    return arr
