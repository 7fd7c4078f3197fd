"""Build the compiled kernels (`make kernels`, run by `make`; docs/rip.md "Compiled kernels").

    python tools/build_kernels.py

Build tooling, not part of the installed package: a wheel ships no compiled kernels (they
run on numba's JIT there); a checkout's `make` builds them.

1. With numba's JIT (WIDEPRINT_KERNELS=jit), rip and print small generated jobs through
   every path that has a kernel (`warm`: every halftone method, pass count and pass mask,
   8/16 bits, RGB/CMYK; then also grey, the preview, the scanner model, dead-nozzle
   compensation, RTL rows and RLE BMPs): numba's on-disk cache is filled, and each kernel
   called from Python has the signatures it is called with.
2. Compile those signatures with numba's pycc into one extension module per package
   (rip/_aot*.so, device_sim/_aot*.so; a sub-package's kernels go into its top-level
   package's), for this machine's CPU, with the GIL released, and write the manifest beside
   it: the digest of the package's sources it was built from and, per kernel, which
   exported function takes which argument types (rip/compiled.py reads both and falls back
   to the JIT on anything else).

pycc is the ahead-of-time compiler numba ships (pending deprecation in favour of a
successor not released yet); it needs a C compiler and setuptools, both present wherever
`make` builds the IPP printer application.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path


def warm(verbose: bool = True) -> float:
    """Rip and print a small generated image on the in-process emulator with every halftone
    method, pass count and pass mask, 8 and 16 bits, RGB and CMYK: every kernel runs once on
    numba's JIT, whose on-disk cache (`cache=True`) it fills, so a kernel the compiled
    modules do not cover loads at its first call after set-up instead of compiling."""
    import numpy as np
    import tifffile

    from wideprint.app.devices import close_device, open_device
    from wideprint.driver.job import PrintJob
    from wideprint.rip.pipeline import RipJob
    from wideprint.rip.profile import load_profile
    from wideprint.rip.settings import METHODS, PASS_MASKS, Placement, RipSettings

    t0 = time.monotonic()
    profile = load_profile()
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory(prefix="wideprint-warmup-") as d:
        rgb = Path(d) / "rgb.tif"
        tifffile.imwrite(rgb, rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
        cmyk16 = Path(d) / "cmyk16.tif"
        tifffile.imwrite(cmyk16, rng.integers(0, 65536, (48, 64, 4), dtype=np.uint16),
                         photometric="separated")
        runs = [(rgb, m, 1, "checker") for m in METHODS]
        # hiding (per stroke too) calls random's kernels with the same argument types
        # (tests/test_nozzle_cal.py checks) and needs a profile with the nozzles measured
        runs += [(rgb, "fs", n, mask) for n in (2, 4) for mask in PASS_MASKS if not mask.startswith("hiding")]
        runs += [(cmyk16, "bayer", 2, "checker")]
        for path, method, passes, mask in runs:
            settings = RipSettings(dither=method, passes=passes, pass_mask=mask, bidir=passes > 1,
                                   placement=Placement(size="pixels"))
            dev = open_device("emulator", profile, media_path=str(Path(d) / "m.tif"))
            try:
                PrintJob(dev, RipJob(str(path), settings, profile)).run()
            finally:
                close_device(dev)
    took = time.monotonic() - t0
    if verbose:
        print(f"wideprint: numba kernels compiled and cached in {took:.1f} s")
    return took


# a small EPS with a CMYK box (the document path: Ghostscript renders CMYK bands)
_EPS = (b"%!PS-Adobe-3.0 EPSF-3.0\n%%BoundingBox: 0 0 36 24\n"
        b"0.2 0.4 0.1 0.3 setcmykcolor 4 4 20 12 rectfill showpage\n%%EOF\n")


def exercise() -> None:
    """Call every kernel the way the product calls it."""
    import numpy as np
    import tifffile

    from wideprint.app import api
    from wideprint.rip import deadrows, planes, rtl
    from wideprint.rip.load import bmp
    warm(verbose=False)
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory(prefix="wideprint-aot-") as d:
        images = []
        for depth in (np.uint8, np.uint16):             # grey, RGB and CMYK in 8 and 16 bits
            top = np.iinfo(depth).max + 1
            for name, shape, extra in (("grey", (40, 48), {}), ("rgb", (40, 48, 3), {}),
                                       ("cmyk", (40, 48, 4), {"photometric": "separated"})):
                path = Path(d) / f"{name}{np.dtype(depth).itemsize * 8}.tif"
                tifffile.imwrite(path, rng.integers(0, top, shape, dtype=depth), **extra)
                images.append(path)
        eps = Path(d) / "box.eps"
        eps.write_bytes(_EPS)
        media = Path(d) / "m.tif"
        for path in images:
            for dither in ("fs", "bayer", "vced"):
                api.print_file(path, dither=dither, size="pixels", media_out=media)
        for dither in ("fs", "bayer"):
            r = api.print_file(eps, dither=dither, media_out=media)
            if not r.ok:                # no Ghostscript here: that path stays with the JIT
                print(f"aot: the EPS path not exercised ({r.message})", file=sys.stderr)
        planes.write_preview(media, Path(d) / "m.png")
        from wideprint.rip.pipeline import RipJob
        from wideprint.rip.settings import Placement, RipSettings
        for fmt in planes.FORMATS:                  # `rip -o`: the RIP's bits to the planes file
            RipJob(str(images[1]), RipSettings(dither="bayer", placement=Placement(size="pixels"))
                   ).write_planes(Path(d) / f"p-{fmt}.tif", fmt)
        grey = images[0]
        api.predict_scan(grey, Path(d) / "scan.tif", size="pixels")
        api.predict_scan(grey, Path(d) / "scan-grey.tif", size="pixels", grey=True)
        # the spectrophotometer's kernels (device_sim/spectro.py): a print measured
        from wideprint.app.devices import close_device, open_device
        from wideprint.driver.job import PrintJob
        from wideprint.rip.profile import load_profile
        prof = load_profile()
        dev = open_device("emulator", prof, media_path=str(media),
                          spectro_path=str(Path(d) / "lab.tif"), spectro_dpi=50)
        try:
            PrintJob(dev, RipJob(str(images[1]), RipSettings(placement=Placement(size="pixels")),
                                 prof)).run()
        finally:
            close_device(dev)
    # paths no small generated file reaches cheaply: called as their callers call them
    for mode in (0, 1, 2, 3):
        rtl._decode_row(mode, np.frombuffer(b"\x00\x00", np.uint8), np.zeros(8, np.uint8))
    bmp._rle_decode(np.frombuffer(b"\x00\x01", np.uint8), 4, 4, 1, False, 2,
                     np.zeros((1, 4), np.uint8), np.zeros(4, np.int64))
    bmp._rle_decode(np.frombuffer(b"\x00\x01", np.uint8), 4, 8, 1, True, 2,
                     np.zeros((1, 4), np.uint8), np.zeros(4, np.int64))
    rows = np.zeros((16, 8, 4), np.uint8)
    deadrows._give_away(rows, np.array([1], np.int64), 0, 4, 0)


def arg_key(t) -> str | None:
    """The rip/compiled.py key of the Python values numba types as `t` (None: a type the
    compiled modules do not take; that signature stays with the JIT)."""
    from numba.core import types
    from numba.np.numpy_support import as_dtype
    if isinstance(t, types.Array):
        return (f"{as_dtype(t.dtype).str}{t.ndim}{t.layout}{'w' if t.mutable else 'r'}"
                f"{'' if t.aligned else 'u'}")
    if isinstance(t, types.Boolean):
        return "bool"
    if isinstance(t, (types.Integer, types.Float)):
        return t.name
    return None


def build(verbose: bool = True) -> dict[str, int]:
    import numba.pycc.compiler as pycc_compiler
    from numba.pycc import CC

    from wideprint.rip.compiled import KERNELS, MANIFEST, MODULE, sources_digest

    class _ReleaseGil(pycc_compiler.Flags):
        """numba's `nogil=True` for the exported functions' wrappers (pycc has no option)."""
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.release_gil = True

    pycc_compiler.Flags = _ReleaseGil

    os.environ["WIDEPRINT_KERNELS"] = "jit"        # the exercise runs, and types, on the JIT
    t0 = time.monotonic()
    exercise()
    t1 = time.monotonic()
    by_package: dict[str, list] = {}
    for k in KERNELS.values():
        if k.called and k._dispatcher is not None:
            by_package.setdefault(k.package, []).append(k)
    counts = {}
    for package, kernels in sorted(by_package.items()):
        pkg_dir = Path(sys.modules[package].__file__).parent
        cc = CC(MODULE)
        cc.output_dir = str(pkg_dir)
        cc.target_cpu = "host"
        manifest = {"sources": sources_digest(pkg_dir), "kernels": {}}
        n = 0
        for k in kernels:
            exports = manifest["kernels"].setdefault(k.name, [])
            for sig in k._dispatcher.signatures:
                keys = [arg_key(t) for t in sig]
                if any(x is None for x in keys):
                    print(f"aot: {k.name}{sig}: left to the JIT", file=sys.stderr)
                    continue
                export = f"k{n}"
                cc.export(export, k._dispatcher.overloads[sig].signature)(k.py_func)
                exports.append([export, keys])
                n += 1
        for old in pkg_dir.glob(f"{MODULE}.*.so"):
            old.unlink()
        (pkg_dir / MANIFEST).unlink(missing_ok=True)
        cc.compile()
        (pkg_dir / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
        counts[package] = n
    if verbose:
        print(f"wideprint: kernels run with numba's JIT in {t1 - t0:.0f} s, then "
              + ", ".join(f"{n} signatures of {p}" for p, n in counts.items())
              + f" compiled ahead of time in {time.monotonic() - t1:.0f} s")
    return counts



if __name__ == "__main__":
    build()
    sys.exit(0)
