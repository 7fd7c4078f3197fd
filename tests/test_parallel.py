"""The RIP's threads (rip/parallel.py, docs/rip.md "Threads"): sized from the machine, capped
by $WIDEPRINT_THREADS or `--threads N`, and the same planes byte for byte whatever the count."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import tifffile

PY = sys.executable


def _run(code: str, env: dict | None = None, timeout=600) -> subprocess.CompletedProcess:
    e = dict(os.environ)
    e.pop("WIDEPRINT_THREADS", None)
    e.update(env or {})
    return subprocess.run([PY, "-c", code], capture_output=True, text=True, timeout=timeout, env=e)


def test_workers_are_the_cores_this_process_may_use():
    """Not `min(2, cpu_count)`: the affinity mask's cores (a container's share), all of them."""
    r = _run("import os; from wideprint.rip import parallel as p; "
             "print(p.WORKERS, len(os.sched_getaffinity(0)))")
    workers, cores = map(int, r.stdout.split())
    assert workers == cores, r.stderr


def test_an_affinity_mask_of_one_core_gives_one_worker():
    r = _run("import os; os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]}); "
             "from wideprint.rip import parallel as p; print(p.WORKERS)")
    assert r.stdout.split() == ["1"], r.stderr


@pytest.mark.parametrize("value", ["1", "3", "16"])
def test_the_environment_sets_the_count(value):
    """$WIDEPRINT_THREADS caps the pools (or raises them: 16 on 2 cores, to test), and the
    pool really has that many threads."""
    code = ("import threading; from wideprint.rip import parallel as p; "
            "import time; p.run_parallel([lambda: time.sleep(0.2)] * p.WORKERS); "
            "print(p.WORKERS, sum(t.name.startswith('wideprint-rip') for t in threading.enumerate()))")
    r = _run(code, {"WIDEPRINT_THREADS": value})
    assert r.stdout.split() == [value, "0" if value == "1" else value], r.stderr   # one: inline


@pytest.mark.parametrize("value", ["0", "-2", "many", "1000"])
def test_a_bad_environment_value_is_warned_of_and_the_machine_used(value):
    r = _run("import os; from wideprint.rip import parallel as p; "
             "print(p.WORKERS == len(os.sched_getaffinity(0)))", {"WIDEPRINT_THREADS": value})
    assert r.stdout.split() == ["True"] and "WIDEPRINT_THREADS" in r.stderr, r.stderr


def test_a_bad_threads_option_is_a_usage_error(tmp_path):
    r = subprocess.run([PY, "-m", "wideprint.app.cli", "rip", "--threads", "0", "x.tif",
                        "-o", str(tmp_path / "p.tif")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--threads" in r.stderr, r.stderr


# one script, run with 1, 2 and 4 workers: the planes of every halftone method, as hashes
_RIP_ALL = """
import hashlib, json, sys
from wideprint.app.cli import main
from wideprint.rip import parallel
out = {"workers": parallel.WORKERS}
for dither in sys.argv[2].split(","):
    planes = sys.argv[3] + "/" + dither + ".tif"
    assert main(["rip", sys.argv[1], "-o", planes, "--dither", dither, "--size", "pixels"] +
                sys.argv[4:]) == 0
    import tifffile
    out[dither] = hashlib.sha256(tifffile.imread(planes).tobytes()).hexdigest()
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    """2,000 x 700 RGB with gradients and noise: wide enough that every stage splits its
    bands (colour, screening, diffusion, packing) and long enough for many bands."""
    d = tmp_path_factory.mktemp("threads")
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:700, 0:2000]
    img = np.stack([x * 255 // 2000, y * 255 // 700, (x + 2 * y) % 256], -1).astype(np.int16)
    img = np.clip(img + rng.integers(-20, 21, img.shape), 0, 255).astype(np.uint8)
    tifffile.imwrite(d / "photo.tif", img, photometric="rgb", resolution=(300, 300))
    return d / "photo.tif"


def test_the_planes_are_the_same_with_1_2_and_4_workers(photo, tmp_path):
    """Every halftone method, byte for byte, whatever the pools' size (4 on this 2-core
    machine: more threads than cores, the order of their work the least like 1's)."""
    dithers = "vced,vector,fs,jarvis,bayer,bluenoise"
    seen = {}
    for n in ("1", "2", "4"):
        d = tmp_path / n
        d.mkdir()
        r = subprocess.run([PY, "-c", _RIP_ALL, str(photo), dithers, str(d)],
                           capture_output=True, text=True, timeout=900,
                           env=dict(os.environ, WIDEPRINT_THREADS=n))
        assert r.returncode == 0, r.stderr
        seen[n] = json.loads(r.stdout.strip().splitlines()[-1])
        assert seen[n].pop("workers") == int(n)
    assert seen["1"] == seen["2"] == seen["4"]


def test_the_threads_option_gives_the_same_planes_as_the_default(photo, tmp_path):
    from wideprint.app.cli import main
    from wideprint.rip import parallel
    before = parallel.WORKERS
    try:
        assert main(["rip", str(photo), "-o", str(tmp_path / "a.tif"), "--dither", "fs"]) == 0
        assert main(["rip", "--threads", "3", str(photo), "-o", str(tmp_path / "b.tif"),
                     "--dither", "fs"]) == 0
        assert parallel.WORKERS == 3
    finally:
        os.environ.pop("WIDEPRINT_THREADS", None)
        parallel.set_workers(before)
    assert tifffile.imread(tmp_path / "a.tif").tobytes() == tifffile.imread(tmp_path / "b.tif").tobytes()
