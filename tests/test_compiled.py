"""The kernels compiled ahead of time (rip/compiled.py, tools/build_kernels.py; docs/rip.md "Compiled
kernels"): `make` builds them, the product's commands run on them without numba, they print
exactly the dots numba's JIT prints, and anything they were not built for goes to the JIT."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import tifffile

from wideprint.rip import compiled
from wideprint.rip.compiled import MANIFEST, _key

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "resources" / "samples" / "sample.tif"


def _run(code: str, *args: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("WIDEPRINT_KERNELS", None)
    env.update(env_extra or {})
    r = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                       env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return r


def test_the_build_is_there_and_matches_its_sources():
    """`make` built both modules from the sources of this checkout (a stale or missing build
    would silently cost every command numba's start-up: fail here instead)."""
    for package in ("rip", "device_sim"):
        pkg = ROOT / package
        manifest = json.loads((pkg / MANIFEST).read_text())
        assert manifest["sources"] == compiled.sources_digest(pkg), f"{package}: run make"
        assert list(pkg.glob("_aot.*.so")), f"{package}: no compiled module"


def test_print_rip_and_preview_run_without_numba(tmp_path):
    """The print path (every halftone method, 1 and 2 passes, the emulator, the media file
    and its preview) and `rip -o` call only compiled kernels: numba is never imported."""
    code = f"""
import sys
from wideprint.app.cli import main
for d in ("vced", "vector", "dbs", "fs", "jarvis", "stucki", "bayer", "bluenoise"):
    for p in ("1", "2"):
        assert not main(["print", {str(SAMPLE)!r}, "--device", "emulator", "--dither", d,
                         "--passes", p, "--media-out", {str(tmp_path / "m.tif")!r},
                         "--preview", {str(tmp_path / "m.png")!r}])
assert not main(["rip", {str(SAMPLE)!r}, "-o", {str(tmp_path / "p.tif")!r}])
print(sorted(m for m in sys.modules if m.split(".")[0] in ("numba", "llvmlite")))
"""
    r = _run(code)
    assert r.stdout.strip().splitlines()[-1] == "[]"
    assert "older than their sources" not in r.stderr


def test_compiled_and_jit_kernels_land_the_same_dots(tmp_path):
    """Bit for bit the same media with the compiled kernels and with numba's JIT, for a
    16-bit RGB image, every method, one pass and four."""
    img = tmp_path / "rgb16.tif"
    rng = np.random.default_rng(7)
    ramp = np.linspace(0, 65535, 160, dtype=np.float64)[None, :, None]
    px = np.clip(ramp + rng.normal(0, 9000, (96, 160, 3)), 0, 65535).astype(np.uint16)
    tifffile.imwrite(img, px)
    code = """
import sys
from wideprint.app import api
out = sys.argv[1]
for d in ("vced", "vector", "dbs", "fs", "jarvis", "stucki", "bayer", "bluenoise"):
    for p in (1, 4):
        r = api.print_file(IMG, dither=d, passes=p, size="pixels", media_out=f"{out}-{d}-{p}.tif")
        assert r.ok, r.message
""".replace("IMG", repr(str(img)))
    _run(code, str(tmp_path / "aot"))
    _run(code, str(tmp_path / "jit"), env_extra={"WIDEPRINT_KERNELS": "jit"})
    for a in sorted(tmp_path.glob("aot-*.tif")):
        j = tmp_path / a.name.replace("aot-", "jit-")
        da, dj = tifffile.imread(a), tifffile.imread(j)
        assert da.shape == dj.shape and np.array_equal(da, dj), a.name
        assert da.any()


def test_a_call_the_build_did_not_see_goes_to_the_jit():
    """A strided view where a C-contiguous array was compiled for (pycc would read it as if
    contiguous), another dtype: both reach numba's dispatcher and give the right answer."""
    from wideprint.rip.planes import _LUT, _box_sums
    rng = np.random.default_rng(3)
    band = (rng.random((8, 40, 4)) < 0.4).astype(np.uint8)
    table = compiled._compiled_table(_box_sums)
    assert table, "no compiled _box_sums (run make)"
    assert (_key(band), "int64", "int64", "int64", _key(_LUT),
            _key(np.zeros((2, 2, 3), np.uint32))) in table

    def sums(b):
        out = np.zeros((2, 10, 3), np.uint32)
        _box_sums(b, 0, 4, 4, _LUT, out)
        return out

    want = sums(band)                                     # compiled
    wide = np.zeros((8, 80, 4), np.uint8)
    wide[:, ::2] = band
    view = wide[:, ::2]
    assert not view.flags.c_contiguous and _key(view) not in {k[0] for k in table}
    assert _key(np.uint8(3)) == "uint8" and _key(3) == _key(np.int64(3)) == "int64"
    assert np.array_equal(sums(view), want)               # the JIT, reading the strides
    assert _box_sums.called and _box_sums._dispatcher is not None


def test_compiled_kernels_release_the_gil():
    """The RIP's worker threads run the compiled kernels in parallel: while one runs for a
    while in a thread, this thread keeps running Python."""
    from wideprint.rip.halftone import _fs_four
    assert compiled._compiled_table(_fs_four), "no compiled _fs_four (run make)"
    src = np.random.default_rng(1).integers(0, 256, (2000, 8000, 4), dtype=np.uint8)
    dst = np.empty_like(src)
    err = np.zeros((4, 2, 8004), np.int32)
    started, done = threading.Event(), threading.Event()

    def work():
        started.set()
        _fs_four(src, dst, err, 0)
        done.set()

    t = threading.Thread(target=work)
    t0 = time.perf_counter()
    t.start()
    started.wait()
    time.sleep(0.02)                      # the worker enters the kernel
    woke = time.perf_counter()
    running = not done.is_set()           # held GIL: this line would run only after the kernel
    t.join()
    took = time.perf_counter() - t0
    assert took > 0.1, "the kernel ran too briefly to tell"
    assert running, f"this thread was blocked {woke - t0:.2f} s of the kernel's {took:.2f} s"


def test_a_stale_build_is_not_used(monkeypatch, capsys):
    """Sources edited since `make`: the compiled module is not trusted, the JIT runs."""
    monkeypatch.setattr(compiled, "sources_digest", lambda d: "edited")
    assert compiled._load_package("wideprint.rip") == {}
    assert "older than their sources" in capsys.readouterr().err
