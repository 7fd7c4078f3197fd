"""Flow control: the fastest carriage speed that prints with zero FIFO underruns under the
emulator's host-jitter model (docs/emulator.md), with the seed's 256-word FIFOs, and the
same job at 660 mm/s with an on-card pass buffer (issue 5).

Each run prints full-width 300 dpi strokes (a 1-pass job); a "starve" is a trigger that
found a FIFO empty (with the starve guard on the line pauses and resumes, so we can count
them all; with the guard off each one would be an underrun fault).
Run: .venv/bin/python bench/flow_bench.py [--strokes 3] [--jitter typical]"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
from pathlib import Path

import numpy as np

from wideprint.device_sim.faults import Faults
from wideprint.app.devices import open_device
from wideprint.driver.job import PrintJob
from wideprint.rip.profile import DEFAULT_PROFILE, load_profile

import sys
sys.path.insert(0, str(Path(__file__).resolve().parent))
from emulator_bench import Ripped  # noqa: E402
from wideprint.rip.pipeline import RipSettings  # noqa: E402


def profile_with(tmp: Path, **fpga) -> object:
    text = DEFAULT_PROFILE.read_text()
    for key, value in fpga.items():
        text = re.sub(rf"(?m)^{key}\s*=\s*\S+", f"{key} = {value}", text)
    path = tmp / f"p-{'-'.join(f'{k}{v}' for k, v in fpga.items())}.toml"
    path.write_text(text)
    return load_profile(path)


def run(profile, job_planes, speed, jitter, seed):
    job = Ripped("flow", job_planes, RipSettings(dpi=300, passes=1), profile)
    dev = open_device("emulator", profile, Faults(host_jitter=jitter, seed=seed))
    t = time.perf_counter()
    PrintJob(dev, job, speed_mm_s=speed).run()
    wall = time.perf_counter() - t
    emu = dev.emulator
    lines = [e for e in emu.events if e["event"] == "line"]
    starves = sum(e["pauses"] for e in lines)
    levels = [e["min_fifo_words"] for e in lines if e["min_fifo_words"] is not None]
    min_fifo = min(levels) if levels else None      # None: the whole stroke was preloaded
    emu.close()
    return starves, min_fifo, wall


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--strokes", type=int, default=3)
    ap.add_argument("--jitter", default="typical", choices=("ideal", "typical", "loaded"))
    ap.add_argument("--seeds", type=int, default=2)
    args = ap.parse_args()
    base = load_profile()
    width = int(3180 / 25.4 * 300)
    rows = 252 * args.strokes
    rng = np.random.default_rng(0)
    planes = (rng.random((rows, width, 4)) < 0.25).astype(np.uint8)
    speeds = [100, 200, 300, 400, 500, 600, 660]
    print(f"job: {args.strokes} full-width strokes of {width} columns at 300 dpi; host jitter "
          f"'{args.jitter}', {args.seeds} seeds per point")
    print(f"FIFO {base.fifo_words} words/head, DMA ring {base.ring_blocks} blocks of "
          f"{base.block_fires} fires")
    best = 0
    print(f"{'speed mm/s':>10} {'fire Hz':>8} {'starves':>8} {'min FIFO words':>15}")
    for v in speeds:
        total, low = 0, 10 ** 9
        for seed in range(1, args.seeds + 1):
            s, m, _ = run(base, planes, v, args.jitter, seed)
            total, low = total + s, min(low, m if m is not None else low)
        print(f"{v:>10} {v / 25.4 * 300:>8.0f} {total:>8} {low:>15}")
        if total == 0:
            best = v
    print(f"fastest speed with zero underruns (256-word FIFOs): {best} mm/s")
    with tempfile.TemporaryDirectory() as tmp:
        words = (width + 4200) * 8
        prof = profile_with(Path(tmp), pass_buffer_words=words)
        total = 0
        for seed in range(1, args.seeds + 1):
            s, m, _ = run(prof, planes, 660, args.jitter, seed)
            total += s
        print(f"with a {words * 2 * len(base.heads) / 1e6:.1f} MB pass buffer "
              f"({words} words/head): 660 mm/s -> {total} underruns (target 0)")


if __name__ == "__main__":
    main()
