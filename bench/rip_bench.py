"""RIP throughput and peak memory: wideprint against Ghostscript, ImageMagick and netpbm,
side by side in one run, on the same generated RGB image (issue targets printed beside).

    .venv/bin/python bench/rip_bench.py [--width 12000] [--height 4000] [--big]
                                        [--only wideprint|peers] [--no-netpbm] [--repeat 3] [--keep DIR]
    .venv/bin/python bench/rip_bench.py --profile bluenoise   # where wideprint's time goes

What is measured (1 image pixel = 1 device pixel, 1-bit CMYK out, each run in a fresh process
whose peak RSS is read from os.wait4's rusage):
- wideprint: file -> swath words (RipJob(...).strokes(), every StrokeData.words made), 300 dpi,
  1 pass, dither fs and vced (error diffusion; the RGB input goes through the ICC separation), bayer
  and bluenoise (ordered).  A tiny job runs first in a separate process (numba's cache, for a
  kernel the compiled modules lack), and each timed process runs a tiny job of its own before
  the clock starts, so the time is the RIP's, not the interpreter's start-up (shown apart).
- Ghostscript: tiffscaled4 (error diffusion) and bitcmyk (ordered screen) on a PostScript
  wrapper of the raw RGB (gs reads no TIFF), ICC colour through lcms2.
- ImageMagick 6: -ordered-dither o8x8 and Floyd-Steinberg (-separate -remap pattern:gray50),
  from the TIFF, with a relaxed policy.xml (Debian's caps width at 16K px and memory at 256 MiB).
- netpbm: pamditherbw -fs per plane (C, M, Y as inverted R, G, B; K from the luminance: no
  colour management), 4 pipelines one after the other.
Peers run whole processes (their wall time includes their own start-up; Ghostscript's and
ImageMagick's are well under 0.1 s); they use the threads they use by default, so CPU
seconds are printed beside wall seconds.
Then the whole commands users run, in the same run: `wideprint rip IMG -o PLANES.tif` per method
and planes encoding (a fresh process each: start-up, reading, RIP, deflating, writing),
`wideprint --help` and a 100 x 100 rip, with their ratios against Ghostscript's whole commands
(issue 17); then the targeted ones paired with Ghostscript run by run (gs, wideprint, gs, ...:
the median of per-pair ratios, immune to the machine's minute-to-minute drift); --wide adds
peak RSS of `rip` and `print` on 40,000 / 37,600 px wide images.
--big also rips 40,000 x 20,000 and 40,000 x 60,000 RGB TIFFs (deflate strips, written by a
generator that never holds the image) with bluenoise, to show that peak RSS does not grow
with the image length.  No assertions: a measurement only.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
try:
    import wideprint  # noqa: F401
except ImportError:  # run from a checkout without the package installed
    sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

# the targets
TARGET_FS_MPX = 100.0       # error diffusion with ICC, Mpx/s, 2 cores (issue 17 part 2; was 40)
TARGET_FS_VS_GS = 3.0       # ... and >= 3x Ghostscript tiffscaled4
TARGET_ORDERED_MPX = 100.0  # ordered / blue noise, Mpx/s
TARGET_RSS_MB = 400.0       # peak RSS for a 40,000 px wide image, whatever its length

TARGET_CLI_FS_VS_GS = 4.0         # issue 17: `wideprint rip -o` (fs) >= 4x gs tiffscaled4, whole commands
TARGET_CLI_ORDERED_VS_GS = 10.0   # ... and an ordered method >= 10x gs bitcmyk
TARGET_CLI_RSS_MB = 250.0         # peak RSS of `rip` and `print` at 40,000 px wide
TARGET_HELP_S = 0.15              # `wideprint --help`

WIDEPRINT_METHODS = ("fs", "bayer", "bluenoise", "vced")
# `wideprint rip IMG -o PLANES.tif` as a whole command: (dither, planes format)
CLI_RUNS = (("fs", "8bit"), ("fs", "packed"), ("vced", "packed"), ("bayer", "8bit"),
            ("bayer", "packed"), ("bluenoise", "8bit"), ("bluenoise", "packed"))
TARGET_VCED_VS_FS = 0.70    # issue 18: the default error diffusion at >= 70 % of fs's throughput
PAGE_ROWS = 4000            # the test image repeats vertically every PAGE_ROWS rows (a banner
                            # of step-and-repeat pages) so that big images are cheap to write


# ------------------------------------------------------------------------------------------
# the test image: one 'page' of a print job, made band by band


class TestImage:
    """A deterministic RGB 8-bit image of width x height made in bands: smooth colour
    gradients with photo-like soft blobs and grain, flat areas (white margins, a row of solid
    colour patches, a pale flat panel) and a block of text-like glyph rows with sharp edges.
    Row y shows page row y % PAGE_ROWS, so any height costs the same per band."""

    def __init__(self, width: int, height: int, seed: int = 0):
        self.w, self.h = width, height
        self.ph = min(height, PAGE_ROWS)
        w, ph = width, self.ph
        rng = np.random.default_rng(seed)
        x = np.arange(w, dtype=np.float32) / w
        y = np.arange(ph, dtype=np.float32) / ph
        # separable smooth gradients (per channel: a ramp across and one along the page)
        self.gx = np.stack([150 * x, 90 * (1 - x) + 40 * np.sin(2 * np.pi * 1.5 * x),
                            120 * np.abs(2 * x - 1)], axis=-1).astype(np.int16)       # (w, 3)
        self.gy = np.stack([80 * y, 100 * np.cos(np.pi * y), 90 * (1 - y) + 30],
                           axis=-1).astype(np.int16)                                   # (ph, 3)
        # photo-like soft blobs: a sum of products of low-frequency sines, shaded per channel
        self.bx = [np.sin(2 * np.pi * (f * x + p)).astype(np.float32)
                   for f, p in ((3.7, 0.1), (7.3, 0.4))]
        self.by = [np.sin(2 * np.pi * (f * y + p)).astype(np.float32)
                   for f, p in ((2.9 * max(1.0, ph / w * 3), 0.2), (5.1, 0.7))]
        self.shade = np.array([[40, -25, 30], [-20, 35, 25]], np.float32)
        # grain: a 256-row tile of mild noise, read with a vertical phase per row
        self.noise = rng.normal(0, 3.0, (256, w, 3)).round().clip(-12, 12).astype(np.int16)
        # flat areas and text, in page coordinates
        self.margin = max(8, w // 40)
        self.patch_y = (int(0.04 * ph), int(0.12 * ph))
        self.panel = (int(0.55 * ph), int(0.72 * ph), int(0.70 * w), int(0.95 * w))
        self.text = (int(0.78 * ph), int(0.95 * ph), int(0.06 * w), int(0.66 * w))
        self.patches = np.array([[255, 255, 255], [0, 0, 0], [220, 30, 40], [30, 160, 70],
                                 [30, 60, 200], [0, 170, 230], [230, 0, 140], [250, 220, 0],
                                 [128, 128, 128], [60, 40, 30]], np.uint8)

    def band(self, y0: int, rows: int) -> np.ndarray:
        """Rows y0 .. y0+rows-1 as uint8 (rows, width, 3)."""
        w = self.w
        yy = (y0 + np.arange(rows)) % self.ph
        v = self.gx[None, :, :] + self.gy[yy][:, None, :] + 20             # int16 (rows, w, 3)
        for k, (bx, by) in enumerate(zip(self.bx, self.by)):
            blob = np.multiply.outer(by[yy], bx)                           # float32 (rows, w)
            for c in range(3):
                v[..., c] += (blob * self.shade[k, c]).astype(np.int16)
        v += self.noise[(y0 + np.arange(rows)) % 256]
        out = v.clip(0, 255).astype(np.uint8)
        # flat: white margins left and right
        out[:, :self.margin] = 255
        out[:, w - self.margin:] = 255
        # flat: a row of solid patches
        a, b = self.patch_y
        sel = (yy >= a) & (yy < b)
        if sel.any():
            n = len(self.patches)
            span = w - 2 * self.margin
            idx = (np.arange(span) * n) // span
            out[sel, self.margin:w - self.margin] = self.patches[idx]
        # flat: a pale panel
        a, b, x0, x1 = self.panel
        sel = (yy >= a) & (yy < b)
        if sel.any():
            out[sel, x0:x1] = (235, 228, 210)
        # text: glyph cells 30 px wide (5 dots of 6 px, 6 px letter gap), lines 48 px high
        # (7 dots of 6 px, 6 px gap), dot pattern from a hash: sharp black-on-white edges
        a, b, x0, x1 = self.text
        sel = np.flatnonzero((yy >= a) & (yy < b))
        if sel.size:
            ty = yy[sel] - a
            tx = np.arange(x1 - x0)
            col_on = (tx % 36) < 30
            row_on = (ty % 48) < 42
            word_gap = ((tx // 36) % 7) == 6
            cx = (tx // 6).astype(np.uint32)
            ry = (ty // 6).astype(np.uint32)
            h = (cx[None, :] * np.uint32(2654435761)) ^ (ry[:, None] * np.uint32(40503))
            h ^= h >> np.uint32(13)
            ink = (((h >> np.uint32(7)) & np.uint32(7)) < 3) & col_on[None, :] & ~word_gap[None, :] \
                & row_on[:, None]
            block = np.where(ink[..., None], np.uint8(20), np.uint8(250))
            out[sel, x0:x1] = block
        return out

    def bands(self, rows: int = 256):
        for y in range(0, self.h, rows):
            yield self.band(y, min(rows, self.h - y))


def write_tiff(path: str, img: TestImage, compression: str | None = None, rowsperstrip: int = 64) -> None:
    """RGB 8-bit striped TIFF at 300 ppi written from bands, never holding the image: uncompressed
    row by row, or with compression='deflate' (level 1, horizontal predictor) as strips
    compressed here, on two threads, a few strips at a time.  (Not zstd: the libtiff inside
    pyvips-binary cannot decode it.)"""
    import tifffile
    kw = dict(shape=(img.h, img.w, 3), dtype=np.uint8, photometric="rgb", rowsperstrip=rowsperstrip,
              resolution=(300, 300), resolutionunit="INCH", metadata=None,
              software="wideprint bench/rip_bench.py")
    if not compression:
        def rows():
            for band in img.bands(256):
                yield from band
        tifffile.imwrite(path, rows(), **kw)
        return
    if compression != "deflate":
        raise ValueError("compression: deflate or None")
    from concurrent.futures import ThreadPoolExecutor

    import imagecodecs

    def encode(strip):
        return imagecodecs.deflate_encode(imagecodecs.delta_encode(strip, axis=1), level=1)

    def strips(pool):
        step = rowsperstrip * 8
        for y in range(0, img.h, step):
            band = img.band(y, min(step, img.h - y))
            yield from pool.map(encode, [band[r:r + rowsperstrip] for r in range(0, band.shape[0], rowsperstrip)])

    with ThreadPoolExecutor(2) as pool:
        tifffile.imwrite(path, strips(pool), compression="adobe_deflate", predictor=True, **kw)


def write_raw(path: str, img: TestImage, header: bytes = b"") -> None:
    with open(path, "wb") as f:
        f.write(header)
        for band in img.bands(256):
            f.write(band.tobytes())


# ------------------------------------------------------------------------------------------
# running a process and reading its peak RSS


@dataclass
class Run:
    wall: float = 0.0
    cpu: float = 0.0
    rss_mb: float = 0.0
    ok: bool = True
    out: str = ""
    err: str = ""


# A process's peak RSS (ru_maxrss) also counts the memory of the process it was forked from
# (Linux keeps the high-water mark across fork and exec), so a command started straight from
# this script would be charged with this script's own ~200 MB.  Every measured command is
# therefore started by this tiny launcher (python -I -S, ~10 MB), which forks, execs the
# command, and reports the command's rusage from wait4.
LAUNCHER = r"""
import json, os, sys, time
out, argv = sys.argv[1], sys.argv[2:]
t = time.perf_counter()
pid = os.fork()
if pid == 0:
    try:
        os.execvp(argv[0], argv)
    finally:
        os._exit(127)
_, status, ru = os.wait4(pid, 0)
wall = time.perf_counter() - t
with open(out, "w") as f:
    json.dump(dict(wall=wall, cpu=ru.ru_utime + ru.ru_stime, maxrss_kb=ru.ru_maxrss,
                   rc=os.waitstatus_to_exitcode(status)), f)
"""


def run_measured(cmd, *, shell: bool = False, env: dict | None = None) -> Run:
    """Run a command (or, with shell=True, a bash pipeline) in a fresh process: wall and CPU
    seconds and peak RSS (the largest resident set of the process and of every descendant it
    waited for, so for a pipeline the largest of its processes)."""
    if shell:
        cmd = ["/bin/bash", "-c", cmd]
    with tempfile.TemporaryDirectory() as td:
        res = os.path.join(td, "rusage.json")
        fo, fe = os.path.join(td, "out"), os.path.join(td, "err")
        with open(fo, "wb") as o, open(fe, "wb") as e:
            p = subprocess.run([sys.executable, "-I", "-S", "-c", LAUNCHER, res, *cmd], env=env,
                               stdout=o, stderr=e)
        with open(fo, "rb") as o, open(fe, "rb") as e:
            out, err = o.read().decode(errors="replace"), e.read().decode(errors="replace")
        if p.returncode != 0 or not os.path.exists(res):
            return Run(ok=False, out=out, err=err or f"launcher exit {p.returncode}")
        with open(res) as f:
            r = json.load(f)
        return Run(r["wall"], r["cpu"], r["maxrss_kb"] / 1024.0, r["rc"] == 0, out, err)


def rss_floor() -> float:
    """Peak RSS charged to a command that does nothing (the launcher's share), MB."""
    r = run_measured([sys.executable, "-I", "-S", "-c", "pass"] if not shutil.which("true") else ["true"])
    return r.rss_mb if r.ok else float("nan")


# ------------------------------------------------------------------------------------------
# wideprint (child side)


def _job(path: str, method: str):
    """The RIP job the bench times: 300 dpi, 1 pass, 1 image pixel = 1 device dot."""
    from wideprint.rip.pipeline import RipJob, RipSettings
    from wideprint.rip.profile import load_profile
    kw = {}
    try:  # placement on the device grid: "pixels" = no resampling
        from wideprint.rip.place import Placement
        kw["placement"] = Placement(size="pixels")
    except ImportError:
        pass
    return RipJob(path, RipSettings(dpi=300, passes=1, dither=method, **kw), load_profile())


def _consume(job) -> dict:
    n_strokes = 0
    words = 0
    dots = np.zeros(4, np.int64)
    for s in job.strokes():
        n_strokes += 1
        words += s.words.size
        dots += s.dots
    job.close()
    return dict(strokes=n_strokes, words=words, dots=int(dots.sum()), width=job.width, height=job.height)


def _rip(path: str, method: str) -> dict:
    return _consume(_job(path, method))


def child(method: str, path: str, warm: str | None) -> None:
    t0 = time.perf_counter()
    import wideprint.rip.pipeline  # noqa: F401  (imports numba, pyvips, the kernels)
    t_import = time.perf_counter() - t0
    t1 = time.perf_counter()
    if warm:
        _rip(warm, method)
    t_warm = time.perf_counter() - t1
    import resource
    rss_ready = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t2, c2 = time.perf_counter(), time.process_time()
    res = _rip(path, method)
    res.update(t=time.perf_counter() - t2, cpu=time.process_time() - c2, t_import=t_import, t_warm=t_warm,
               rss_ready=rss_ready)
    print(json.dumps(res))


def run_wideprint(method: str, path: str, warm: str) -> tuple[Run, dict]:
    r = run_measured([sys.executable, os.path.abspath(__file__), "--child", method, path, "--warm-file", warm])
    info = {}
    if r.ok:
        info = json.loads(r.out.strip().splitlines()[-1])
    return r, info


def wideprint_cmd(*args: str) -> list[str]:
    """The `wideprint` command line (as the console script runs it: a fresh interpreter)."""
    return [sys.executable, "-m", "wideprint.app.cli", *args]


def cli_env() -> dict:
    """The environment for `wideprint` commands: this checkout's package importable, and
    byte-code written (a user's installed package has its .pyc files; a checkout run with
    PYTHONDONTWRITEBYTECODE would compile every module on every start)."""
    import wideprint
    parent = os.path.dirname(os.path.dirname(os.path.abspath(wideprint.__file__)))
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = os.pathsep.join([parent] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def best_run(cmd, repeat: int, **kw) -> tuple[Run, list[float]]:
    runs = [run_measured(cmd, **kw) for _ in range(repeat)]
    good = [r for r in runs if r.ok]
    return (min(good, key=lambda r: r.wall) if good else runs[0]), [r.wall for r in good]


def whole_commands(d: str, tif: str, w: int, h: int, repeat: int) -> dict:
    """`wideprint rip IMG -o PLANES.tif` for CLI_RUNS, start-up figures: {key: (Mpx/s, Run)}."""
    env = cli_env()
    mpx = w * h / 1e6
    out = os.path.join(d, "planes.tif")
    small = os.path.join(d, "small.tif")
    write_tiff(small, TestImage(100, 100))
    for m in sorted({m for m, _ in CLI_RUNS}):        # numba's cache filled before any clock
        run_measured(wideprint_cmd("rip", small, "-o", out, "--dither", m), env=env)
    res = {}
    print("whole commands, as users run them: `wideprint rip IMG -o PLANES.tif --size pixels "
          "--dither M --planes-format F` (start-up, reading, RIP, writing; a fresh process each)")
    print(f"{'tool':12s} {'method':22s} {'wall s':>8s} {'cpu s':>8s} {'Mpx/s':>9s} {'RSS MB':>9s}  note")
    for method, fmt in CLI_RUNS:
        cmd = wideprint_cmd("rip", tif, "-o", out, "--size", "pixels", "--dither", method,
                            "--planes-format", fmt)
        r, walls = best_run(cmd, repeat, env=env)
        size = os.path.getsize(out) / 1e6 if r.ok and os.path.exists(out) else 0
        note = f"best of {len(walls)} ({', '.join(f'{t:.2f}' for t in walls)} s); file {size:.1f} MB"
        print(fmt_row("wideprint", f"rip -o {method} {fmt}", mpx, r, note), flush=True)
        if r.ok:
            res[("cli", method, fmt)] = (mpx / r.wall, r)
    with contextlib.suppress(OSError):
        os.unlink(out)
    r, walls = best_run(wideprint_cmd("--help"), max(5, repeat), env=env)
    print(fmt_row("wideprint", "--help", 0, r, f"best of {len(walls)}"))
    res[("cli", "--help")] = (0, r)
    r, walls = best_run(wideprint_cmd("rip", small, "-o", out, "--dither", "fs"), repeat, env=env)
    print(fmt_row("wideprint", "rip -o 100 x 100 (fs)", 0, r,
                  "start-up: imports, a tiny job"))
    res[("cli", "small")] = (0, r)
    with contextlib.suppress(OSError):
        os.unlink(out)
    return res


#: the whole commands paired with Ghostscript run by run (the issue's targets)
PAIRED_RUNS = (("fs", "8bit"), ("fs", "packed"), ("bayer", "packed"), ("bluenoise", "packed"))


def paired_commands(d: str, tif: str, peers: list, repeat: int) -> dict:
    """Each targeted `wideprint rip -o` and its Ghostscript peer run alternately, `repeat`
    pairs: this machine's speed drifts by tens of per cent from minute to minute, and a
    ratio of two figures measured minutes apart carries that drift; the median of ratios
    of runs made seconds apart does not.  {("paired", method, fmt): (median ratio, ratios)}"""
    env = cli_env()
    gs = {kind: cmd for tool, _, kind, cmd, _ in peers if tool == "ghostscript" and cmd}
    out = os.path.join(d, "planes.tif")
    res = {}
    print(f"paired with Ghostscript: gs, then wideprint, {repeat} times each; ratio = gs wall / "
          f"wideprint wall per pair, the median reported")
    for method, fmt in PAIRED_RUNS:
        kind = "ed" if method in ("fs", "vced") else "ordered"
        if kind not in gs:
            continue
        wp = wideprint_cmd("rip", tif, "-o", out, "--size", "pixels", "--dither", method,
                           "--planes-format", fmt)
        pairs = []
        for _ in range(repeat):
            g, r = run_measured(gs[kind]), run_measured(wp, env=env)
            if g.ok and r.ok:
                pairs.append((g.wall, r.wall))
        for f in os.listdir(d):
            if f.startswith("gs_out"):
                os.unlink(os.path.join(d, f))
        if not pairs:
            print(f"  rip -o {method} {fmt}: FAILED")
            continue
        ratios = sorted(g / r for g, r in pairs)
        med = statistics.median(ratios)
        peer = "tiffscaled4" if kind == "ed" else "bitcmyk"
        print(f"  rip -o {method:9s} {fmt:6s} vs gs {peer:11s} median {med:5.2f}x  (pairs, gs/wideprint s: "
              + ", ".join(f"{g:.2f}/{r:.2f}" for g, r in pairs) + ")", flush=True)
        res[("paired", method, fmt)] = (med, ratios)
    with contextlib.suppress(OSError):
        os.unlink(out)
    return res


def wide_memory(d: str, repeat: int = 1) -> dict:
    """Peak RSS of `wideprint rip` on a 40,000 px wide RGB image and `wideprint print`
    (in-process emulator) on the widest image the default paper takes (37,600 px at 300 dpi:
    3,200 mm less the 5 mm margins), every kind of method."""
    env = cli_env()
    h = 1500
    res = {}
    print(f"peak RSS of whole commands on wide images ({h} rows, RGB, uncompressed TIFF, --size pixels)")
    print(f"{'command':44s} {'wall s':>8s} {'cpu s':>8s} {'RSS MB':>8s}")
    for w, cmds in ((40000, "rip"), (37600, "print")):
        tif = os.path.join(d, f"wide{w}.tif")
        write_tiff(tif, TestImage(w, h))
        out = os.path.join(d, "wide_out.tif")
        if cmds == "rip":
            runs = [(f"rip -o {m} {f}, {w} px", ["rip", tif, "-o", out, "--dither", m, "--planes-format", f])
                    for m, f in (("fs", "8bit"), ("fs", "packed"), ("vced", "8bit"), ("bluenoise", "8bit"))]
        else:
            runs = [(f"print --device emulator {m}, {w} px", ["print", tif, "--device", "emulator",
                                                             "--dither", m, "--passes", "1"])
                    for m in ("fs", "vced", "bluenoise")]
        for name, args in runs:
            r, _ = best_run(wideprint_cmd(*args, "--size", "pixels"), repeat, env=env)
            if not r.ok:
                print(f"{name:44s} FAILED: {(r.err or r.out).strip()[-300:]}")
                continue
            print(f"{name:44s} {r.wall:8.2f} {r.cpu:8.2f} {r.rss_mb:8.0f}", flush=True)
            res[name] = r.rss_mb
        for f in (tif, out):
            with contextlib.suppress(OSError):
                os.unlink(f)
    if res:
        worst = max(res.values())
        print(f"largest peak RSS {worst:.0f} MB: target <= {TARGET_CLI_RSS_MB:.0f} MB: "
              f"{verdict(worst <= TARGET_CLI_RSS_MB)}")
    return res


# ------------------------------------------------------------------------------------------
# peers


RELAXED_POLICY = """<?xml version="1.0" encoding="UTF-8"?>
<!DOCTYPE policymap [
<!ELEMENT policymap (policy)*>
<!ATTLIST policymap xmlns CDATA #FIXED ''>
<!ELEMENT policy EMPTY>
<!ATTLIST policy xmlns CDATA #FIXED '' domain NMTOKEN #REQUIRED name NMTOKEN #IMPLIED
  pattern CDATA #IMPLIED rights NMTOKENS #IMPLIED stealth NMTOKEN #IMPLIED value CDATA #IMPLIED>
]>
<policymap>
  <policy domain="resource" name="memory" value="16GiB"/>
  <policy domain="resource" name="map" value="16GiB"/>
  <policy domain="resource" name="width" value="1MP"/>
  <policy domain="resource" name="height" value="1MP"/>
  <policy domain="resource" name="area" value="16GP"/>
  <policy domain="resource" name="disk" value="64GiB"/>
</policymap>
"""


def gs_wrapper(path_ps: str, raw: str, w: int, h: int, dpi: int = 300) -> None:
    """A PostScript page of w x h device pixels at dpi showing the raw RGB file 1:1."""
    with open(path_ps, "w") as f:
        f.write(f"""%!PS
/DeviceRGB setcolorspace
{w * 72 / dpi:.6f} {h * 72 / dpi:.6f} scale
<< /ImageType 1 /Width {w} /Height {h} /BitsPerComponent 8 /Decode [0 1 0 1 0 1]
   /ImageMatrix [{w} 0 0 -{h} 0 {h}] /Interpolate false
   /DataSource ({raw}) (r) file >> image
showpage
""")


def peer_commands(d: str, w: int, h: int, netpbm: bool) -> list[tuple[str, str, str, object, dict]]:
    """(tool, method, kind, command, options) for every installed peer; kind 'ed' or 'ordered'.
    A command None means the tool is not installed (the method names what is missing)."""
    tif, ps = os.path.join(d, "in.tif"), os.path.join(d, "in.ps")
    out = []
    gs = shutil.which("gs")
    for method, dev, kind in (("tiffscaled4 (ED)", "tiffscaled4", "ed"), ("bitcmyk (ordered)", "bitcmyk", "ordered")):
        if gs:
            ext = "tif" if dev.startswith("tiff") else "cmyk"
            cmd = [gs, "-q", "-dSAFER", f"--permit-file-read={d}/", "-dBATCH", "-dNOPAUSE", "-r300",
                   f"-g{w}x{h}", "-dFIXEDMEDIA", f"-sDEVICE={dev}", "-dDownScaleFactor=1",
                   f"-sOutputFile={d}/gs_out.{ext}", ps]
        else:
            cmd = None
        out.append(("ghostscript", method, kind, cmd, {}))
    convert = shutil.which("convert")
    is_im = False
    if convert:
        try:
            is_im = "ImageMagick" in subprocess.run([convert, "-version"], capture_output=True,
                                                    text=True, timeout=30).stdout
        except (OSError, subprocess.SubprocessError):
            pass
    env = dict(os.environ, MAGICK_CONFIGURE_PATH=d)
    for method, args, kind in (
            ("ordered o8x8", ["-colorspace", "CMYK", "-ordered-dither", "o8x8", "-depth", "1",
                              f"{d}/im_o.tif"], "ordered"),
            ("Floyd-Steinberg", ["-colorspace", "CMYK", "-separate", "-dither", "FloydSteinberg",
                                 "-remap", "pattern:gray50", "-depth", "1", f"{d}/im_fs_%d.tif"], "ed")):
        out.append(("imagemagick", method, kind, [convert, tif] + args if is_im else None, dict(env=env)))
    if netpbm:
        tools = [shutil.which(t) for t in ("pamchannel", "pamditherbw", "ppmtopgm")]
        if all(tools):
            ppm = os.path.join(d, "in.ppm")
            pipe = " && ".join(
                [f"pamchannel -infile {ppm} -tupletype GRAYSCALE {c} | pamditherbw -fs > {d}/pbm_{c}.pbm"
                 for c in range(3)] + [f"ppmtopgm {ppm} | pamditherbw -fs > {d}/pbm_k.pbm"])
            out.append(("netpbm", "pamditherbw -fs x4", "ed", pipe, dict(shell=True)))
        else:
            out.append(("netpbm", "pamditherbw -fs x4", "ed", None, {}))
    return out


# ------------------------------------------------------------------------------------------
# report helpers


def sh(cmd: list[str]) -> str:
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
        return (r.stdout or r.stderr).strip().splitlines()[0]
    except (OSError, subprocess.SubprocessError, IndexError):
        return "not installed"


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "?"


def print_header() -> None:
    import numba
    import pyvips
    print(f"rip_bench {time.strftime('%Y-%m-%d %H:%M')}  machine: {os.cpu_count()} CPUs "
          f"(nproc {sh(['nproc'])}), {cpu_model()}, "
          f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GiB, {platform.platform()}")
    print(f"  load average at start {' '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"(other work on the machine skews the figures)")
    print(f"  python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
          f"libvips {pyvips.version(0)}.{pyvips.version(1)}.{pyvips.version(2)}")
    im = sh(["convert", "-version"])
    im = im.replace("Version: ", "") if "ImageMagick" in im else "ImageMagick not installed"
    print(f"  ghostscript {sh(['gs', '--version'])}; {im}; "
          f"netpbm: {sh(['pamditherbw', '-version']).replace('pamditherbw: ', '')}")


def fmt_row(tool: str, method: str, mpx: float, r: Run | None, note: str = "") -> str:
    if r is None:
        return f"{tool:12s} {method:22s} {note}"
    if not r.ok:
        return f"{tool:12s} {method:22s} FAILED: {(r.err or r.out).strip()[-200:]}"
    rate = f"{mpx / r.wall:9.1f}" if mpx else f"{'-':>9s}"      # no pixels: start-up figures
    return f"{tool:12s} {method:22s} {r.wall:8.2f} {r.cpu:8.2f} {rate} {r.rss_mb:9.0f}  {note}"


def verdict(ok: bool) -> str:
    return "met" if ok else "MISSED"


# ------------------------------------------------------------------------------------------
# main


def bench(args) -> None:
    w, h = args.width, args.height
    mpx = w * h / 1e6
    print_header()
    tmp_root = "/tmp"
    d = args.keep or tempfile.mkdtemp(prefix="rip_bench_", dir=tmp_root)
    os.makedirs(d, exist_ok=True)
    try:
        img = TestImage(w, h)
        t = time.perf_counter()
        tif = os.path.join(d, "in.tif")
        write_tiff(tif, img)
        if args.only != "wideprint":
            write_raw(os.path.join(d, "in.rgb"), img)
            gs_wrapper(os.path.join(d, "in.ps"), os.path.join(d, "in.rgb"), w, h)
            if not args.no_netpbm:
                write_raw(os.path.join(d, "in.ppm"), img, f"P6\n{w} {h}\n255\n".encode())
            with open(os.path.join(d, "policy.xml"), "w") as f:
                f.write(RELAXED_POLICY)
        print(f"input: {w} x {h} RGB 8-bit uncompressed striped TIFF, 300 ppi ({mpx:.1f} Mpx, "
              f"{os.path.getsize(tif) / 1e6:.0f} MB; gradients, soft blobs, grain, flat patches, "
              f"text), made in {time.perf_counter() - t:.1f} s in {d}")
        print("Mpx/s = input pixels / wall seconds; RSS = peak resident set of the process "
              f"(the largest of its processes), MB; a no-op command measures {rss_floor():.0f} MB")
        print()
        print(f"{'tool':12s} {'method':22s} {'wall s':>8s} {'cpu s':>8s} {'Mpx/s':>9s} {'RSS MB':>9s}  note")
        res: dict[tuple[str, str], tuple[float, Run]] = {}

        if args.only != "peers":
            warm = os.path.join(d, "warm.tif")
            write_tiff(warm, TestImage(512, 64))
            for m in WIDEPRINT_METHODS:  # fill numba's on-disk cache in a throw-away process
                run_wideprint(m, warm, warm)
            for m in WIDEPRINT_METHODS:
                runs = [run_wideprint(m, tif, warm) for _ in range(args.repeat)]
                good = [ri for ri in runs if ri[0].ok]
                r, info = min(good, key=lambda ri: ri[1]["t"]) if good else runs[0]
                if r.ok:
                    # the RIP's own time (after imports and a warm-up job): what Mpx/s is made of
                    rip = Run(info["t"], info["cpu"], r.rss_mb, True)
                    times = ", ".join(f"{ri[1]['t']:.2f}" for ri in good)
                    note = (f"best of {len(good)} ({times} s); "
                            f"RSS {info['rss_ready']:.0f} MB before the job (imports + warm-up)")
                    label = {"fs": "fs (ICC + FS)", "bayer": "bayer (ICC + ordered)",
                             "vced": "vced (ICC + var. ED)",
                             "bluenoise": "bluenoise (ICC + ord.)"}[m]
                    print(fmt_row("wideprint", label, mpx, rip, note), flush=True)
                    res[("wideprint", m)] = (mpx / info["t"], rip)
                else:
                    print(fmt_row("wideprint", m, mpx, r), flush=True)

        if args.only != "wideprint":
            for tool, method, kind, cmd, opt in peer_commands(d, w, h, not args.no_netpbm):
                if cmd is None:
                    print(fmt_row(tool, method, mpx, None, "not installed"), flush=True)
                    continue
                r = min((run_measured(cmd, **opt) for _ in range(args.peer_repeat)),
                        key=lambda x: (not x.ok, x.wall))
                note = {"ghostscript": "ICC via lcms2",
                        "imagemagick": "no ICC (-colorspace CMYK); OpenMP threads",
                        "netpbm": "no colour management; 4 pipelines, 2 processes each"}[tool]
                print(fmt_row(tool, method, mpx, r, note), flush=True)
                if r.ok:
                    res[(tool, method)] = (mpx / r.wall, r)
                for f in os.listdir(d):  # outputs can be big: drop them as we go
                    if f.startswith(("gs_out", "im_", "pbm_")):
                        os.unlink(os.path.join(d, f))

        if args.only != "peers" and not args.no_cli:
            print()
            res.update(whole_commands(d, tif, w, h, args.repeat))
            if args.only is None:
                print()
                res.update(paired_commands(d, tif, peer_commands(d, w, h, False), args.repeat))
        print()
        print_ratios(res, w)
        if args.wide and args.only != "peers":
            print()
            wide_memory(d)
        if args.big and args.only != "peers":
            print()
            big(d, warm if args.only != "peers" else None)
    finally:
        if not args.keep:
            shutil.rmtree(d, ignore_errors=True)


def print_ratios(res, w: int) -> None:
    def rate(k):
        return res[k][0] if k in res else None

    fs, bay, bn, vced = (rate(("wideprint", m)) for m in WIDEPRINT_METHODS)
    gs_ed = rate(("ghostscript", "tiffscaled4 (ED)"))
    gs_or = rate(("ghostscript", "bitcmyk (ordered)"))
    im_or = rate(("imagemagick", "ordered o8x8"))
    im_fs = rate(("imagemagick", "Floyd-Steinberg"))
    print("ratios and targets")

    def line(name, val, target, ok):
        v = "n/a" if val is None else val
        print(f"  {name:44s} {v:>12s}   target {target:18s} {'' if ok is None else verdict(ok)}")

    line("wideprint fs, Mpx/s", None if fs is None else f"{fs:.1f}", f">= {TARGET_FS_MPX:.0f} Mpx/s",
         None if fs is None else fs >= TARGET_FS_MPX)
    r = fs / gs_ed if fs and gs_ed else None
    line("wideprint fs / gs tiffscaled4", None if r is None else f"{r:.2f}x", f">= {TARGET_FS_VS_GS:.0f}x",
         None if r is None else r >= TARGET_FS_VS_GS)
    if fs and im_fs:
        line("wideprint fs / ImageMagick Floyd-Steinberg", f"{fs / im_fs:.2f}x", "-", None)
    line("wideprint vced (the default), Mpx/s", None if vced is None else f"{vced:.1f}", "-", None)
    r = vced / fs if vced and fs else None
    line("wideprint vced / fs", None if r is None else f"{r:.2f}x", f">= {TARGET_VCED_VS_FS:.2f}x",
         None if r is None else r >= TARGET_VCED_VS_FS)
    for name, v in (("bayer", bay), ("bluenoise", bn)):
        line(f"wideprint {name}, Mpx/s", None if v is None else f"{v:.1f}", f">= {TARGET_ORDERED_MPX:.0f} Mpx/s",
             None if v is None else v >= TARGET_ORDERED_MPX)
        if v and gs_or:
            line(f"wideprint {name} / gs bitcmyk", f"{v / gs_or:.2f}x", "-", None)
        if v and im_or:
            line(f"wideprint {name} / ImageMagick o8x8", f"{v / im_or:.2f}x", "-", None)
    for (method, fmt) in CLI_RUNS:
        v = rate(("cli", method, fmt))
        peer, target = (gs_ed, TARGET_CLI_FS_VS_GS) if method in ("fs", "vced") else (gs_or, TARGET_CLI_ORDERED_VS_GS)
        if v and peer:
            line(f"rip -o {method} {fmt} / gs {'tiffscaled4' if peer is gs_ed else 'bitcmyk'} (whole)",
                 f"{v / peer:.2f}x", f">= {target:.0f}x" if method != "vced" else "-",
                 v / peer >= target if method != "vced" else None)
    for (method, fmt) in PAIRED_RUNS:
        if ("paired", method, fmt) in res:
            med = res[("paired", method, fmt)][0]
            target = TARGET_CLI_FS_VS_GS if method == "fs" else TARGET_CLI_ORDERED_VS_GS
            peer = "tiffscaled4" if method == "fs" else "bitcmyk"
            line(f"rip -o {method} {fmt} / gs {peer} (paired)", f"{med:.2f}x",
                 f">= {target:.0f}x", med >= target)
    if ("cli", "--help") in res:
        t = res[("cli", "--help")][1].wall
        line("wideprint --help, s", f"{t:.3f}", f"<= {TARGET_HELP_S:.2f} s", t <= TARGET_HELP_S)
    rss = [res[("wideprint", m)][1].rss_mb for m in WIDEPRINT_METHODS if ("wideprint", m) in res]
    if rss:
        line(f"wideprint peak RSS at {w} px wide, MB", f"{max(rss):.0f}",
             f"<= {TARGET_RSS_MB:.0f} MB at 40000 px",
             max(rss) <= TARGET_RSS_MB if w >= 40000 or max(rss) > TARGET_RSS_MB else None)


def big(d: str, warm: str | None) -> None:
    sizes = ((40000, 20000), (40000, 60000))
    print("memory vs image length: wideprint bluenoise, 300 dpi, 1 pass, 40,000 px wide "
          "(deflate-compressed striped TIFFs, written from a generator)")
    print(f"{'image':16s} {'Mpx':>7s} {'file GB':>8s} {'write s':>8s} {'rip s':>8s} {'Mpx/s':>7s} "
          f"{'RSS MB':>8s}")
    if warm is None:
        warm = os.path.join(d, "warm.tif")
        write_tiff(warm, TestImage(512, 64))
        run_wideprint("bluenoise", warm, warm)
    rss = []
    for w, h in sizes:
        path = os.path.join(d, f"big_{w}x{h}.tif")
        t = time.perf_counter()
        write_tiff(path, TestImage(w, h), compression="deflate")
        tw = time.perf_counter() - t
        size = os.path.getsize(path) / 1e9
        r, info = run_wideprint("bluenoise", path, warm)
        os.unlink(path)
        if not r.ok:
            print(f"{w}x{h}: FAILED: {(r.err or r.out).strip()[-300:]}")
            continue
        mpx = w * h / 1e6
        rss.append(r.rss_mb)
        print(f"{f'{w} x {h}':16s} {mpx:7.0f} {size:8.2f} {tw:8.1f} {info['t']:8.1f} "
              f"{mpx / info['t']:7.1f} {r.rss_mb:8.0f}", flush=True)
    if rss:
        print(f"peak RSS {' vs '.join(f'{v:.0f} MB' for v in rss)}: target <= {TARGET_RSS_MB:.0f} MB "
              f"whatever the length: {verdict(max(rss) <= TARGET_RSS_MB)}")


# ------------------------------------------------------------------------------------------
# --profile: where wideprint's time goes


def profile(method: str, w: int, h: int) -> None:
    """Stage times of one RIP (load, separation, halftone, the fused ordered screen, swath
    packing) measured by timing each stage's calls, then cProfile's top functions.  The
    stages run in several threads at once (docs/rip.md "Threads"), so their times overlap and
    can add up to more than the total."""
    import cProfile
    import pstats

    from wideprint.rip import color, halftone, screen, swath

    d = tempfile.mkdtemp(prefix="rip_bench_prof_", dir="/tmp")
    try:
        tif = os.path.join(d, "in.tif")
        write_tiff(tif, TestImage(w, h))
        _rip(tif, method)  # warm up (numba cache, page cache)
        stage = {"open": 0.0, "load": 0.0, "separation": 0.0, "halftone": 0.0, "screen": 0.0,
                 "swath": 0.0}

        def timed(name, fn):
            def wrap(*a, **k):
                t = time.perf_counter()
                try:
                    return fn(*a, **k)
                finally:
                    stage[name] += time.perf_counter() - t
            return wrap

        def timed_bands(orig):
            def bands(rows=256):
                it = orig(rows)

                def gen():
                    while True:
                        t = time.perf_counter()
                        try:
                            b = next(it)
                        except StopIteration:
                            stage["load"] += time.perf_counter() - t
                            return
                        stage["load"] += time.perf_counter() - t
                        yield b
                return gen()
            return bands

        patches = [(color.Separator, "convert", timed("separation", color.Separator.convert)),
                   (halftone.Halftoner, "process", timed("halftone", halftone.Halftoner.process)),
                   (screen.OrderedScreen, "process", timed("screen", screen.OrderedScreen.process)),
                   (swath.StrokePlanner, "feed_packed", timed("swath", swath.StrokePlanner.feed_packed)),
                   (swath.StrokePlanner, "finish", timed("swath", swath.StrokePlanner.finish))]
        saved = [(cls, name, cls.__dict__[name]) for cls, name, _ in patches]
        for cls, name, fn in patches:
            setattr(cls, name, fn)
        try:
            t = time.perf_counter()
            job = _job(tif, method)
            stage["open"] = time.perf_counter() - t
            job.source.bands = timed_bands(job.source.bands)  # the file (placed) as bands
            _consume(job)
            total = time.perf_counter() - t
        finally:
            for cls, name, fn in saved:
                setattr(cls, name, fn)
        mpx = w * h / 1e6
        print(f"wideprint {method}, {w} x {h} RGB ({mpx:.1f} Mpx): {total:.2f} s = {mpx / total:.1f} Mpx/s")
        for k, v in stage.items():
            print(f"  {k:11s} {v:7.2f} s  {100 * v / total:5.1f} %   ({mpx / v if v else float('inf'):8.1f} Mpx/s alone)")
        print("  (the stages overlap: load, separation or screening, diffusion and packing run in "
              "threads of their own)")
        print()
        pr = cProfile.Profile()
        pr.enable()
        _rip(tif, method)
        pr.disable()
        st = pstats.Stats(pr)
        st.sort_stats("tottime").print_stats(14)
    finally:
        shutil.rmtree(d, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=12000)
    ap.add_argument("--height", type=int, default=4000)
    ap.add_argument("--big", action="store_true",
                    help="also rip 40000x20000 and 40000x60000 images (bluenoise) for peak RSS; minutes")
    ap.add_argument("--only", choices=("wideprint", "peers"))
    ap.add_argument("--no-cli", action="store_true",
                    help="skip the whole `wideprint rip -o` commands and the start-up figures")
    ap.add_argument("--wide", action="store_true",
                    help="also measure peak RSS of `rip` and `print` at 40,000 px wide (~2 min)")
    ap.add_argument("--wide-only", action="store_true", help="only that")
    ap.add_argument("--no-netpbm", action="store_true", help="skip the (slow) netpbm pipelines")
    ap.add_argument("--repeat", type=int, default=3, help="wideprint runs per method, best taken")
    ap.add_argument("--peer-repeat", type=int, default=1, help="runs per peer, best taken")
    ap.add_argument("--keep", metavar="DIR", help="make the inputs in DIR and keep them")
    ap.add_argument("--profile", metavar="METHOD", choices=WIDEPRINT_METHODS,
                    help="print wideprint's time per stage and cProfile's top functions instead")
    ap.add_argument("--child", nargs=2, metavar=("METHOD", "PATH"), help=argparse.SUPPRESS)
    ap.add_argument("--warm-file", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child[0], args.child[1], args.warm_file)
    elif args.wide_only:
        d = tempfile.mkdtemp(prefix="rip_bench_", dir="/tmp")
        try:
            wide_memory(d)
        finally:
            shutil.rmtree(d, ignore_errors=True)
    elif args.profile:
        profile(args.profile, args.width, args.height)
    else:
        bench(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
