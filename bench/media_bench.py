"""The closed colour loop on the emulator (docs/media.md, issue 33): `media create` wall
time and its parts, profcheck, the default media's verify figures, drift (dot-gain) and
one recalibrate, and (--modes) the same chart at 150/300/600 dpi.  Writes
bench/results/media.json.

    .venv/bin/python bench/media_bench.py [--patches 1000] [--drift 8] [--skip-create]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
TARGETS = {"create_s": 600, "profcheck_mean": 1.0, "verify_mean": 1.5, "verify_p95": 3.0,
           "recalibrated_mean": 1.5}


MODES = (150, 600)           # linearised beside the media's own 300 dpi


def compare_modes(media, profile) -> dict:
    """The control chart through the media at 150, 300 and 600 dpi: each mode's verify,
    the ΔE2000 between the modes' prints and their ink per m² (the emulator's drops)."""
    import itertools
    from wideprint.app import mediacal
    from wideprint.device_sim.spectral import delta_e2000
    kept, out = {}, {}
    for dpi in (150, 300, 600):
        kept[dpi] = {}
        r = mediacal.verify(media, profile, dpi=dpi, keep=kept[dpi])
        out[f"verify_{dpi}"] = {k: r[k] for k in ("mean", "p95", "max", "pass")}
        out[f"ink_ml_m2_{dpi}"] = [round(v, 4) for v in kept[dpi]["ink_ml_m2"]]
    for a, b in itertools.combinations((150, 300, 600), 2):
        de = delta_e2000(kept[a]["lab"], kept[b]["lab"])
        ink = sum(kept[b]["ink_ml_m2"]) / sum(kept[a]["ink_ml_m2"])
        out[f"{a}_vs_{b}"] = {"de2000_mean": round(float(de.mean()), 3),
                              "de2000_max": round(float(de.max()), 3),
                              "ink_ratio": round(float(ink), 4)}
        print(f"{a} vs {b} dpi: ΔE2000 mean {de.mean():.2f} max {de.max():.2f}, "
              f"ink per m² x{ink:.3f}")
    return out


def scan_only(args) -> int:
    """`media create --scan` timed, then verified by the spectrophotometer (target: mean
    <= 2.5 for a profile built from scans)."""
    import subprocess
    with tempfile.TemporaryDirectory(prefix="media-bench-") as tmp:
        env = {**os.environ, "WIDEPRINT_MEDIA_DIR": tmp}
        cli = [sys.executable, "-m", "wideprint.app.cli", "media"]
        t0 = time.monotonic()
        subprocess.run(cli + ["create", "scanned", "--scan", "--patches", str(args.patches)],
                       env=env, check=True)
        wall = round(time.monotonic() - t0, 1)
        entry = json.loads(subprocess.run(cli + ["show", "scanned", "--json"], env=env,
                                          check=True, capture_output=True, text=True).stdout)
        r = subprocess.run(cli + ["verify", "scanned", "--json"], env=env,
                           capture_output=True, text=True)
        verify = json.loads(r.stdout)
    out = {"create_wall_s": wall, "build": entry["build"], "verify_by_spectro": verify,
           "target_mean": 2.5}
    print(f"scanned media: create {wall:.0f} s; verified by the spectrophotometer: ΔE2000 "
          f"mean {verify['mean']:.2f} p95 {verify['p95']:.2f} max {verify['max']:.2f}")
    path = Path(args.out).with_name("media_scan.json")
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"written {path}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patches", type=int, default=1000)
    ap.add_argument("--drift", type=float, default=8.0, help="dot gain, percent")
    ap.add_argument("--skip-create", action="store_true")
    ap.add_argument("--budget", type=float, default=0.5,
                    help="the created media's drop budget at 300 dpi (0.5: 150 dpi's ink)")
    ap.add_argument("--out", default=str(HERE / "results" / "media.json"))
    ap.add_argument("--scan", action="store_true", help="only: a media made from scans "
                    "(the scanner characterised first), verified by the spectrophotometer; "
                    "writes results/media_scan.json")
    args = ap.parse_args(argv)
    if args.scan:
        return scan_only(args)
    from wideprint.app import mediacal, medialib
    from wideprint.rip.profile import load_profile
    profile = load_profile()
    out: dict = {"machine_cores": os.cpu_count(), "targets": TARGETS}
    with tempfile.TemporaryDirectory(prefix="media-bench-") as tmp:
        if not args.skip_create:
            values = medialib.check_values({"name": "bench", "created": medialib.now()})
            t0 = time.monotonic()
            values = mediacal.create(Path(tmp) / "bench", values, profile,
                                     patches=args.patches, progress=print,
                                     budget=args.budget, modes=MODES)
            created = medialib.save(medialib.Media(Path(tmp) / "bench",
                                                   medialib.check_values(values)))
            out["create"] = {"wall_s": round(time.monotonic() - t0, 1), **values["build"],
                             "ink_limit_percent": values["ink_limit_percent"]}
            out["create"]["verify"] = mediacal.verify(created, profile)
            out["modes"] = compare_modes(created, profile)
        shipped = medialib.load(medialib.SHIPPED / medialib.DEFAULT_MEDIA, shipped=True)
        out["default_media"] = {"name": shipped.name, "build": shipped.build,
                                "ink_limit_percent": shipped.ink_limit_percent}
        out["verify"] = mediacal.verify(shipped, profile)
        drift = (f"dot-gain=+{args.drift:g}%",)
        out["drift"] = mediacal.verify(shipped, profile, inject=drift)
        folder = Path(tmp) / "copy"
        shutil.copytree(shipped.folder, folder)
        t0 = time.monotonic()
        values = mediacal.recalibrate(medialib.load(folder), profile, inject=drift)
        recal_s = round(time.monotonic() - t0, 1)
        m2 = medialib.save(medialib.Media(folder, medialib.check_values(values)))
        out["recalibrated"] = {**mediacal.verify(m2, profile, inject=drift), "seconds": recal_s}
    for key in ("verify", "drift", "recalibrated"):
        r = out[key]
        print(f"{key:13s} ΔE2000 mean {r['mean']:.2f}  p95 {r['p95']:.2f}  max {r['max']:.2f}  "
              f"{'pass' if r['pass'] else 'FAIL'}")
    if "create" in out:
        c = out["create"]
        print(f"create        {c['wall_s']:.0f} s ({c['patches']} patches), profcheck mean "
              f"{c['profcheck']['mean']:.2f} max {c['profcheck']['max']:.2f}; its verify mean "
              f"{c['verify']['mean']:.2f} p95 {c['verify']['p95']:.2f}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
