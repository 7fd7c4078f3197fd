"""150 dpi against 300 dpi through the whole colour loop (docs/media.md "Every dpi mode the
same colour", issue 33 item 5): a media made at 300 dpi, drop budget 0.5 (150 dpi's ink), with
a 150 dpi mode of its own (curves and profile), its 150 dpi mode halftoned by each method
given; the control chart printed in both modes: ΔE2000 between them and the ratio of their
ink per m² (target: mean <= 1.5, within 5 %).  Writes bench/results/ink150_media.json.

    .venv/bin/python bench/ink150_media.py [--patches 1000] [--methods vced,joint/k-alone,joint]

The 150 dpi mode's halftone is the method given (the entry's own stays vced): the bench sets
`mediacal.MODE_DITHER`, the halftone `media create` gives a 150 dpi mode (joint).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def run(method: str, patches: int, profile) -> dict:
    """One media made and compared; `method` a halftone, or `joint/k-alone`: joint with K
    left out of the cell's count (K stacking on C, M and Y at random), for the record."""
    from wideprint.app import mediacal, medialib
    from wideprint.device_sim.spectral import delta_e2000
    from wideprint.rip import joint
    plain, made = mediacal.MODE_DITHER, joint.JointDiffuser.__init__
    mediacal.MODE_DITHER = {150: {"dither": method.split("/")[0]}}
    if method == "joint/k-alone":
        def k_alone(self, width, channels, noise, k_in_count=False):
            made(self, width, channels, noise, k_in_count=k_in_count)
        joint.JointDiffuser.__init__ = k_alone  # type: ignore[method-assign]
    try:
        with tempfile.TemporaryDirectory(prefix="ink150-") as tmp:
            values = medialib.check_values({"name": "ink150", "created": medialib.now()})
            t0 = time.monotonic()
            values = mediacal.create(Path(tmp) / "m", values, profile, patches=patches,
                                     budget=0.5, modes=(150,))
            media = medialib.save(medialib.Media(Path(tmp) / "m", medialib.check_values(values)))
            wall = time.monotonic() - t0
            kept: dict = {150: {}, 300: {}}
            ver = {dpi: mediacal.verify(media, profile, dpi=dpi, keep=kept[dpi])
                   for dpi in (150, 300)}
    finally:
        mediacal.MODE_DITHER, joint.JointDiffuser.__init__ = plain, made
    de = delta_e2000(kept[150]["lab"], kept[300]["lab"])
    ink = sum(kept[150]["ink_ml_m2"]) / sum(kept[300]["ink_ml_m2"])
    out = {"method_150": method, "create_s": round(wall, 1),
           "ink_limit_percent": values["ink_limit_percent"],
           "profcheck_150": values["modes"]["150"]["profcheck"],
           "verify_150": {k: ver[150][k] for k in ("mean", "p95", "max")},
           "verify_300": {k: ver[300][k] for k in ("mean", "p95", "max")},
           "de2000_150_vs_300_mean": round(float(de.mean()), 3),
           "de2000_150_vs_300_max": round(float(de.max()), 3),
           "ink_ml_m2_150": round(float(sum(kept[150]["ink_ml_m2"])), 4),
           "ink_ml_m2_300": round(float(sum(kept[300]["ink_ml_m2"])), 4),
           "ink_ratio_150_over_300": round(float(ink), 4),
           "ink_ml_m2_per_ink_150": [round(float(v), 4) for v in kept[150]["ink_ml_m2"]],
           "ink_ml_m2_per_ink_300": [round(float(v), 4) for v in kept[300]["ink_ml_m2"]]}
    print(f"150 dpi {method}: ΔE2000 vs 300 mean {de.mean():.2f} max {de.max():.2f}, "
          f"ink x{ink:.3f}; verify 150 mean {ver[150]['mean']:.2f}, 300 {ver[300]['mean']:.2f}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patches", type=int, default=1000)
    ap.add_argument("--methods", default="vced,joint/k-alone,joint")
    ap.add_argument("--out", default=str(HERE / "results" / "ink150_media.json"))
    args = ap.parse_args(argv)
    from wideprint.rip.profile import load_profile
    profile = load_profile()
    cases = [run(m, args.patches, profile) for m in args.methods.split(",")]
    out = {"what": "media made at 300 dpi budget 0.5 with a 150 dpi mode; control chart "
                   "(150 in-gamut sRGB colours, seed 7) in both modes",
           "patches": args.patches, "cases": cases}
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
