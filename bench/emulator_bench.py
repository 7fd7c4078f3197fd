"""Emulator speed: simulated printing seconds per wall second on a full-width 300 dpi job
in standard mode (issue 4 target: >= 20x real time).

The job is ripped first (not timed); then driver + emulator print it in-process.
Run: .venv/bin/python bench/emulator_bench.py [--rows 3000] [--width-mm 3180]"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from wideprint.app.devices import open_device
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipSettings
from wideprint.rip.profile import load_profile
from wideprint.rip.testprints import PatternJob


@dataclass
class Ripped(PatternJob):
    """A job whose strokes were computed before the clock starts."""

    def __post_init__(self):
        super().__post_init__()
        self._strokes = list(super().strokes())

    def strokes(self, planner=None):
        return iter(self._strokes)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=3000)
    ap.add_argument("--width-mm", type=float, default=3180)
    ap.add_argument("--density", type=float, default=0.3)
    ap.add_argument("--passes", type=int, default=2)
    args = ap.parse_args()
    prof = load_profile()
    dpi = 300
    width = int(args.width_mm / 25.4 * dpi)
    rng = np.random.default_rng(0)
    planes = (rng.random((args.rows, width, 4)) < args.density).astype(np.uint8)
    t = time.perf_counter()
    job = Ripped("bench", planes, RipSettings(dpi=dpi, passes=args.passes, bidir=True), prof)
    rip_s = time.perf_counter() - t
    dev = open_device("emulator", prof)
    emu = dev.emulator
    t = time.perf_counter()
    rep = PrintJob(dev, job).run()
    wall = time.perf_counter() - t
    begin = next(e["t"] for e in emu.events if e["event"] == "job_begin")
    sim = emu.time - begin
    emu.close()
    mpx = width * args.rows / 1e6
    print(f"job: {width} x {args.rows} dots ({args.width_mm:.0f} mm wide, {dpi} dpi, "
          f"{args.passes}-pass bidirectional), {rep.strokes_printed} strokes, {mpx:.0f} Mpx")
    print(f"rip (not timed): {rip_s:.1f} s")
    print(f"printing: simulated {sim:.1f} s, wall {wall:.1f} s -> {sim / wall:.1f}x real time "
          f"(target >= 20x)")


if __name__ == "__main__":
    main()
