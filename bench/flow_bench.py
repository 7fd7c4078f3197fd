"""Flow control: the fastest carriage speed that prints with zero FIFO underruns under the
emulator's host-jitter model (docs/emulator.md), with the seed's 256-word FIFOs, and the
same job at 660 mm/s with an on-card pass buffer (issue 5); each speed through the
in-process data channel (`emulator`) and through the PCI card modelled at register level
(`emulator-pci`: the host's PciData driving the 9054's chained demand-mode DMA, issue 19).

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


def run(profile, job_planes, speed, jitter, seed, device="emulator"):
    job = Ripped("flow", job_planes, RipSettings(dpi=300, passes=1), profile)
    dev = open_device(device, profile, Faults(host_jitter=jitter, seed=seed))
    t = time.perf_counter()
    PrintJob(dev, job, speed_mm_s=speed).run()
    wall = time.perf_counter() - t
    emu = dev.emulator
    lines = [e for e in emu.events if e["event"] == "line"]
    starves = sum(e["pauses"] for e in lines)
    levels = [e["min_fifo_words"] for e in lines if e["min_fifo_words"] is not None]
    min_fifo = min(levels) if levels else None      # None: the whole stroke was preloaded
    emu.close()
    dev.data.close()
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
    devices = ("emulator", "emulator-pci")
    best = dict.fromkeys(devices, 0)
    print(f"{'speed mm/s':>10} {'fire Hz':>8}" + "".join(
        f" {d + ' starves':>20} {'min FIFO words':>15} {'wall s':>7}" for d in devices))
    for v in speeds:
        row = f"{v:>10} {v / 25.4 * 300:>8.0f}"
        for d in devices:
            total, low, wall = 0, 10 ** 9, 0.0
            for seed in range(1, args.seeds + 1):
                s, m, w = run(base, planes, v, args.jitter, seed, d)
                total, low, wall = total + s, min(low, m if m is not None else low), wall + w
            row += f" {total:>20} {low:>15} {wall:>7.1f}"
            if total == 0:
                best[d] = v
        print(row)
    for d in devices:
        print(f"fastest speed with zero underruns (256-word FIFOs), {d}: {best[d]} mm/s")
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
