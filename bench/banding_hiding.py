"""Pass masks designed against the measured machine (issue 36): "nozzle-error hiding".

    .venv/bin/python bench/banding_hiding.py [--machines typical,tired] [--seeds 1,2]
        [--passes 4] [--masks checker,...,stroke-hiding] [--out bench/results/banding_hiding.json]
    .venv/bin/python bench/banding_hiding.py --setting 2,3,4,6,8 [--machines ...] [--seeds ...]
        [--out bench/results/banding_hiding_setting.json]     # `--pass-mask hiding` as a user runs it

Per machine (docs/physical.md "The machine", drawn from the seed):
1. the nozzle check is printed on it and scanned at 1200 dpi; every nozzle's dash is
   measured by `calibrate nozzles`' own code (app/nozzles.py `measure_nozzle_errors`: its
   centroid through the frame bars' registration, its ink; in a window 4 rows high each side): the nozzle's
   landing error along the feed (µm, the dash's y less its cell's) and its drop volume (the
   dash's ink over its colour's median, to the power 3/2: a dot's ink is its area);
2. `rip.masks.hiding_weights` turns them into each row phase's shares per pass, so that
   every row's mean error is the colour's mean (the nozzles' errors cancel row by row), held
   towards equal shares by the error the feed's whole steps leave at each stroke
   (`rip.masks.stroke_error_um`), which shares per row phase cannot follow;
   "oracle" does the same from the machine's true errors (the bound of what the measurement
   could give); "stroke-hiding" (`rip.stroke_hiding`) gives each block of A rows its own
   shares from the known error of each of its strokes, so that the rounding cancels with the
   nozzles' errors row by row ("stroke-oracle": from the true errors): what
   `--pass-mask hiding` plans (rip/hiding.py `stroke_masks`);
3. the banding chart is printed at --passes with the checkerboard (today's default), the
   random mask (the same blue-noise split with equal shares) and the hiding shares, scanned
   at 600 dpi, and measured by `wideprint quality` (app/quality.py): the mean over the ten
   tints of the eye-weighted banding, RMS ΔL* at 500 mm.

The shares reach the stroke planner through its pass-mask hook (the planner's selection per
colour and row phase, rip/swath.py `_pass_mask`), the per-stroke shares through its
`_stroke_mask` hook (stroke i's selection): this bench swaps them in for the run.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from wideprint.app.calibrate import Scan, read_scan_white
from wideprint.app.cli import main as wideprint
from wideprint.app.nozzles import measure_nozzle_errors
from wideprint.app.quality import measure_scan
from wideprint.device_sim.faults import Faults
from wideprint.device_sim.physical import PhysicalModel
from wideprint.rip import swath
from wideprint.rip.hiding import live_slots
from wideprint.rip.masks import HIDE_FEED_NOISE_UM, hiding_weights, load_bluenoise_mask, stroke_error_um
from wideprint.rip.profile import load_profile
from wideprint.rip.stroke_hiding import StrokeClasses, StrokeMasks, stroke_hiding_weights
from wideprint.rip.testprints import scan_layout

NOZZLE_DPI, NOZZLE_WIDTH_MM, NOZZLE_SCAN_DPI = 150, 200, 1200
CHART_DPI, CHART_WIDTH_MM, CHART_SCAN_DPI = 300, 100, 600
_HIDING: dict = {}          # passes -> (4, A, N) shares, while a run prints with them
_STROKE: dict = {}          # passes -> ((K, 4, A, N) shares, StrokeClasses): per stroke


def _pass_mask(self, mask):
    """The planner's selection with the hiding shares per colour (the blue-noise split of
    the random mask, unequal shares)."""
    stroke = _STROKE.get(self.n)
    if stroke is not None and mask == "random":
        weights, classes = stroke
        self._stroke_masks = StrokeMasks(self.n, self._remap, weights, classes, self.s0)
        return self._stroke_masks.qmask, self._stroke_masks.sel[0]
    weights = _HIDING.get(self.n)
    if weights is None or mask != "random":
        return _ORIGINAL(self, mask)
    ranks = load_bluenoise_mask()
    qmask = (ranks.astype(np.int64) * swath.MASK_LEVELS // ranks.size).astype(np.int16)
    u = (np.arange(swath.MASK_LEVELS) + 0.5) / swath.MASK_LEVELS
    sel = np.empty((4, self.advance, swath.MASK_LEVELS), np.int16)
    for c in range(4):
        cum = np.cumsum(weights[c] / weights[c].sum(axis=1, keepdims=True), axis=1)
        jsel = np.minimum((u[None, :, None] > cum[:, None, :]).sum(axis=2), self.n - 1)
        sel[c] = np.take_along_axis(self._remap[c], jsel.astype(np.int64), axis=1)
    return np.ascontiguousarray(qmask), sel


def _stroke_mask(self, i):
    """Stroke i's selection: the per-stroke shares' where `_pass_mask` set them."""
    masks = getattr(self, "_stroke_masks", None)
    return _ORIGINAL_STROKE(self, i) if masks is None else masks(i)


_ORIGINAL = swath.StrokePlanner._pass_mask
_ORIGINAL_STROKE = swath.StrokePlanner._stroke_mask


def _cli(argv: list[str]) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        rc = wideprint(argv)
    if rc != 0:
        raise SystemExit(f"wideprint failed ({rc}): {' '.join(argv)}")


def whole_step_profile(workdir: str, passes: int) -> str:
    """The default profile with its feed roller sized so that the weave's advance is a whole
    number of steps (30.047 mm instead of 30 at 4 passes): no whole-step rounding."""
    profile = load_profile()
    s0, s1 = profile.usable_slots()
    feed = (s1 - s0) // passes * profile.row_um / profile.feed_um_per_step
    radius = profile.feed.roller_radius_mm * feed / round(feed)
    text, n = re.subn(r"(?m)^roller_radius_mm\s*=.*$", f"roller_radius_mm = {radius:.6f}",
                      Path(profile.path).read_text())
    if n != 1:
        raise SystemExit(f"{profile.path}: no roller_radius_mm line to change")
    path = os.path.join(workdir, "whole-step.toml")
    Path(path).write_text(text)
    return path


def _profile_args() -> list[str]:
    """The options every test print takes: the profile, the machine's overrides."""
    return (["--profile", PROFILE[0]] if PROFILE else []) + [a for kv in INJECT for a in ("--inject", kv)]


PROFILE: list[str] = []     # the profile test prints use (--whole-step-feed)
INJECT: list[str] = []      # the machine's errors overridden (--inject, e.g. feed-noise=0um)
FEED_NOISE_UM = [HIDE_FEED_NOISE_UM]    # the feed noise the per-stroke shares are robust to


def measured_nozzles(machine: str, seed: int, workdir: str, profile) -> tuple[np.ndarray, np.ndarray]:
    """(dy µm, volume) per (head, nozzle), from a 1200 dpi scan of the nozzle check, as
    `calibrate nozzles` measures them (app/nozzles.py; volume 0: no dash, dead)."""
    scan = os.path.join(workdir, f"nc-{machine}-{seed}.tif")
    _cli(["test-print", "nozzle-check", "--dpi", str(NOZZLE_DPI), "--width-mm", str(NOZZLE_WIDTH_MM),
          "--scan-out", scan, "--scan-dpi", str(NOZZLE_SCAN_DPI),
          "--inject", f"machine={machine}", "--inject", f"seed={seed}"] + _profile_args())
    k = profile.k(NOZZLE_DPI)
    width = int(round(NOZZLE_WIDTH_MM / 25.4 * profile.counts_per_inch / k))
    layout = scan_layout("nozzle-check", profile, width, NOZZLE_DPI)
    dark, white, sdpi = read_scan_white(scan)
    os.unlink(scan)
    # a head's mean y error is its offset (what `calibrate heads` trims); kept: it is the
    # rows' error too
    return measure_nozzle_errors(Scan(dark, sdpi, layout, profile, NOZZLE_DPI, white))


def true_nozzles(machine: str, seed: int, profile) -> tuple[np.ndarray, np.ndarray]:
    model = PhysicalModel(profile, Faults.parse([f"machine={machine}", f"seed={seed}"] + INJECT))
    return model.spread_dy_um.copy(), model.volume.copy()


def chart(machine: str, seed: int, passes: int, mask: str, workdir: str) -> dict:
    scan = os.path.join(workdir, f"chart-{machine}-{seed}-{passes}-{mask}.tif")
    _cli(["test-print", "banding-scan", "--dpi", str(CHART_DPI), "--passes", str(passes),
          "--pass-mask", mask, "--width-mm", str(CHART_WIDTH_MM), "--scan-out", scan,
          "--scan-dpi", str(CHART_SCAN_DPI), "--inject", f"machine={machine}",
          "--inject", f"seed={seed}"] + _profile_args())
    rep = measure_scan(scan, passes=passes)
    os.unlink(scan)
    return dict(**rep.summary(), tints={q.name: q.banding for q in rep.tints},
                advance=float(np.mean([q.components[0].amplitude for q in rep.tints])))


MASK_NAMES = ("checker", "random", "hiding", "oracle", "stroke-hiding")
STROKE_MASKS = ("stroke-hiding", "stroke-oracle")     # shares per stroke (rip/stroke_hiding.py)


def run(machine: str, seed: int, passes: int, workdir: str, profile,
        masks: tuple[str, ...] = MASK_NAMES) -> list[dict]:
    t0 = time.perf_counter()
    out = []
    dy_m, vol_m = measured_nozzles(machine, seed, workdir, profile)
    sl = live_slots(profile, passes, vol_m)
    dy_t, vol_t = true_nozzles(machine, seed, profile)
    live = sl[..., 0] >= 0
    used = (sl[..., 0][live], sl[..., 1][live])
    err = dict(dy_um=round(float(np.std(dy_m[used] - dy_m[used].mean() - (dy_t[used] - dy_t[used].mean()))), 3),
               volume_pct=round(float(np.std(vol_m[used] - vol_t[used])) * 100, 3),
               true_dy_um=round(float(np.std(dy_t[used])), 3),
               true_volume_pct=round(float(np.std(vol_t[used])) * 100, 3))
    print(f"{machine} seed {seed}: the nozzle check measures dy within {err['dy_um']} µm "
          f"(spread {err['true_dy_um']}), volume within {err['volume_pct']} % "
          f"(spread {err['true_volume_pct']})", flush=True)
    stroke = stroke_error_um(load_profile(PROFILE[0]) if PROFILE else profile, passes)
    err["stroke_error_um"] = round(stroke, 3)
    print(f"  the feed's whole steps leave {stroke:.2f} µm at a stroke", flush=True)
    shares = dict(hiding=lambda: hiding_weights(dy_m, vol_m, sl, stroke_error_um=stroke),
                  oracle=lambda: hiding_weights(dy_t, vol_t, sl, stroke_error_um=stroke))
    classes = StrokeClasses.of(load_profile(PROFILE[0]) if PROFILE else profile, passes)
    shares["stroke-hiding"] = lambda: stroke_hiding_weights(dy_m, vol_m, sl, classes.class_errors_um(),
                                                            feed_noise_um=FEED_NOISE_UM[0])
    shares["stroke-oracle"] = lambda: stroke_hiding_weights(dy_t, vol_t, sl, classes.class_errors_um(),
                                                            feed_noise_um=FEED_NOISE_UM[0])
    for name in masks:
        weights = shares[name]() if name in shares else None
        _HIDING.clear()
        _STROKE.clear()
        if name in STROKE_MASKS:
            _STROKE[passes] = (weights, classes)
        elif weights is not None:
            _HIDING[passes] = weights
        try:
            r = chart(machine, seed, passes, "checker" if name == "checker" else "random", workdir)
        finally:
            _HIDING.clear()
            _STROKE.clear()
        r.update(machine=machine, seed=seed, passes=passes, mask=name, nozzle_check=err,
                 whole_step_feed=bool(PROFILE), inject=list(INJECT), feed_noise_um=FEED_NOISE_UM[0],
                 sum_w2=None if weights is None else round(float((weights ** 2).sum(axis=2).mean()), 4))
        out.append(r)
        print(f"  {name:8s} banding {r['banding']:.3f} (worst {r['banding_max']:.3f}) advance "
              f"{r['advance']:.3f} grain {r['graininess']:.3f}  {time.perf_counter() - t0:.0f} s",
              flush=True)
    return out


SETTING_MASKS = ("checker", "hiding", "hiding-rows")


def run_setting(machine: str, seed: int, passes_list: list[int], workdir: str) -> list[dict]:
    """`--pass-mask hiding` as a user runs it: the nozzle check scanned at 1200 dpi,
    `wideprint calibrate nozzles --write` into a copy of the profile, then the banding chart
    printed with checker, hiding (shares per stroke) and hiding-rows (per row phase, what
    `hiding` planned before) on that profile and measured by `wideprint quality`."""
    from wideprint.rip.profile import DEFAULT_PROFILE
    t0 = time.perf_counter()
    prof_path = os.path.join(workdir, f"printer-{machine}-{seed}.toml")
    Path(prof_path).write_text(Path(DEFAULT_PROFILE).read_text())
    scan = os.path.join(workdir, f"nc-{machine}-{seed}.tif")
    machine_args = ["--inject", f"machine={machine}", "--inject", f"seed={seed}"]
    _cli(["test-print", "nozzle-check", "--dpi", str(NOZZLE_DPI), "--width-mm", str(NOZZLE_WIDTH_MM),
          "--scan-out", scan, "--scan-dpi", str(NOZZLE_SCAN_DPI)] + machine_args)
    _cli(["calibrate", "nozzles", "--scan", scan, "--width-mm", str(NOZZLE_WIDTH_MM), "--write",
          "--profile", prof_path])
    os.unlink(scan)
    out = []
    for passes in passes_list:
        for name in SETTING_MASKS:
            chart_scan = os.path.join(workdir, f"chart-{machine}-{seed}-{passes}-{name}.tif")
            _cli(["test-print", "banding-scan", "--dpi", str(CHART_DPI), "--passes", str(passes),
                  "--pass-mask", name, "--width-mm", str(CHART_WIDTH_MM), "--scan-out", chart_scan,
                  "--scan-dpi", str(CHART_SCAN_DPI), "--profile", prof_path] + machine_args)
            with contextlib.redirect_stdout(io.StringIO()) as buf:
                rc = wideprint(["quality", chart_scan, "--passes", str(passes), "--json"])
            os.unlink(chart_scan)
            if rc != 0:
                raise SystemExit(f"wideprint quality failed ({rc}) on {chart_scan}")
            summary = json.loads(buf.getvalue())["summary"]
            out.append(dict(machine=machine, seed=seed, passes=passes, mask=name,
                            banding=summary["banding"], banding_max=summary.get("banding_max"),
                            graininess=summary.get("graininess")))
            print(f"  {machine} seed {seed} {passes} passes {name:22s} banding {summary['banding']:.3f}"
                  f"  {time.perf_counter() - t0:.0f} s", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--machines", default="typical,tired")
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--whole-step-feed", action="store_true",
                    help="the feed roller sized so that every feed is whole steps (30.047 mm)")
    ap.add_argument("--masks", default=",".join(MASK_NAMES),
                    help="of " + ", ".join(MASK_NAMES + STROKE_MASKS[1:]))
    ap.add_argument("--inject", action="append", default=[],
                    help="override one of the machine's errors (docs/physical.md), e.g. feed-noise=0um")
    ap.add_argument("--feed-noise-um", type=float, default=HIDE_FEED_NOISE_UM,
                    help="the feed's random error (µm a feed) the per-stroke shares are robust to")
    ap.add_argument("--setting", default=None, metavar="PASSES",
                    help="measure --pass-mask hiding as a user runs it (calibrate nozzles, then "
                         "the chart with checker and hiding) at these pass counts, e.g. 2,3,4,6,8")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    profile = load_profile()
    INJECT[:] = args.inject
    FEED_NOISE_UM[:] = [args.feed_noise_um]
    swath.StrokePlanner._pass_mask = _pass_mask
    swath.StrokePlanner._stroke_mask = _stroke_mask
    runs: list[dict] = []
    try:
        with tempfile.TemporaryDirectory(prefix="wideprint-hiding-") as d:
            if args.setting:
                for machine in args.machines.split(","):
                    for seed in (int(s) for s in args.seeds.split(",")):
                        runs += run_setting(machine, seed, [int(p) for p in args.setting.split(",")], d)
                        if args.out:
                            Path(args.out).write_text(json.dumps(dict(runs=runs), indent=1) + "\n")
            elif args.whole_step_feed:
                PROFILE[:] = [whole_step_profile(d, args.passes)]
            for machine in args.machines.split(",") if not args.setting else ():
                for seed in (int(s) for s in args.seeds.split(",")):
                    runs += run(machine, seed, args.passes, d, profile,
                                masks=tuple(args.masks.split(",")))
                    if args.out:
                        Path(args.out).write_text(json.dumps(dict(runs=runs), indent=1) + "\n")
    finally:
        swath.StrokePlanner._pass_mask = _ORIGINAL
        swath.StrokePlanner._stroke_mask = _ORIGINAL_STROKE
    table: dict = {}
    for r in runs:
        table.setdefault(f"{r['machine']} {r['passes']} pass", {}).setdefault(r["mask"], []).append(r["banding"])
    summary = {mode: {m: round(float(np.mean(v)), 4) for m, v in masks.items()} for mode, masks in table.items()}
    for mode, masks in summary.items():
        ref = masks.get("checker", np.nan)
        print(mode + ": " + ", ".join(f"{m} {v:.3f} ({v / ref:.2f}x)" for m, v in masks.items()))
    if args.out:
        Path(args.out).write_text(json.dumps(dict(
            what="banding chart, 300 dpi, 600 dpi scan, eye at 500 mm; shares from a 1200 dpi "
                 "nozzle-check scan (bench/banding_hiding.py)", machine=platform.machine(),
            python=sys.version.split()[0], whole_step_feed=args.whole_step_feed, inject=args.inject, modes=summary,
            runs=runs),
            indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
