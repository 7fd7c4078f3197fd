"""The `hiding` pass mask's shares (issue 36; docs/quality.md "Nozzle-error hiding as a
setting", docs/rip.md "Pass masks"): from the nozzles' errors the profile keeps ([layout]
nozzle_dy_um, nozzle_volume_pct, written by `wideprint calibrate nozzles`), each block of A
rows gets its shares per colour, row phase and pass from the error each of its strokes'
whole-step feeds leaves (`stroke_masks`, rip/stroke_hiding.py), so the feed's rounding and
the nozzles' errors cancel row by row.  `hiding_shares` (per row phase, held towards equal
shares by the strokes' RMS error, `rip.masks.stroke_error_um`) is what the setting used
before; bench/banding_hiding.py still measures it ("hiding per row phase").
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from .profile import DEFAULT_PROFILE, Profile, ProfileError


def weave_slots(profile: Profile, passes: int) -> np.ndarray:
    """(4, A, N, 2): the (head, nozzle) that prints colour c's row phase r in pass j
    (docs/geometry.md: slot r + (N - 1 - j) A + s0); (-1, -1) where no live nozzle is."""
    s0, s1 = profile.usable_slots()
    a = (s1 - s0) // passes
    r = np.arange(a)[:, None]
    j = np.arange(passes)[None, :]
    return profile.slot_table()[:, r + (passes - 1 - j) * a + s0]


def measured_errors(profile: Profile) -> tuple[np.ndarray, np.ndarray]:
    """(landing error µm, drop volume relative to the colour's median) per (head index,
    nozzle), as stored; a clear error naming what to run when nothing is."""
    lay = profile.layout
    if not lay.nozzle_dy_um:
        target = ("PRINTER.toml (a copy of the built-in profile)"
                  if Path(profile.path) == DEFAULT_PROFILE else profile.path)
        raise ProfileError(
            f"{profile.path}: pass mask \"hiding\" needs the nozzles measured, and this "
            "profile has no [layout] nozzle_dy_um: print `wideprint test-print nozzle-check "
            "--scan-dpi 1200 --scan-out nc.tif`, then run `wideprint calibrate nozzles --scan "
            f"nc.tif --write --profile {target}` (docs/calibration.md)")
    dy = np.array([lay.nozzle_dy_um[h.name] for h in profile.heads], np.float64)
    pct = np.array([lay.nozzle_volume_pct[h.name] for h in profile.heads], np.float64)
    return dy, 1.0 + pct / 100.0


def live_slots(profile: Profile, passes: int, volume: np.ndarray) -> np.ndarray:
    """`weave_slots` with the nozzles a measurement found without drops (volume 0: dead)
    out, as the profile's dead nozzles (which the slot table leaves out)."""
    slots = weave_slots(profile, passes).copy()
    h, z = slots[..., 0], slots[..., 1]
    dry = (h >= 0) & (volume[np.maximum(h, 0), z] <= 0)
    slots[dry] = -1
    return slots


def _measured_slots(profile: Profile, passes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dy, volume, live slots) from the profile's stored measurement."""
    dy, volume = measured_errors(profile)
    return dy, volume, live_slots(profile, passes, volume)


def _key(*arrays) -> str:
    return hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)).hexdigest()


def _cached(cache: dict, key: str, make):
    if key not in cache:
        if len(cache) >= 16:
            cache.pop(next(iter(cache)))
        cache[key] = make()
    return cache[key]


def stroke_masks(profile: Profile, passes: int, remap: np.ndarray, top_rows: int = 0):
    """The planner's selection per stroke (rip/stroke_hiding.py `StrokeMasks`) for
    `--pass-mask hiding`: shares per class of blocks from the measured nozzles and the
    strokes' known feed errors, the classes placed by the job's top margin `top_rows` (the
    driver feeds stroke i to `feed_steps_for_rows(i A + top_rows)`, driver/job.py).  The
    shares do not depend on the margin (only which class a block is), so one plan (1.3 s at
    4 passes) serves every job with the same measurement, weave, feed and dead nozzles."""
    from .stroke_hiding import StrokeClasses, StrokeMasks, stroke_hiding_weights
    dy, volume, slots = _measured_slots(profile, passes)
    classes = StrokeClasses.of(profile, passes)
    errors = classes.class_errors_um()
    key = _key(dy, volume, slots, errors)

    def plan():
        weights = stroke_hiding_weights(dy, volume, slots, errors)
        weights.setflags(write=False)
        return weights
    weights = _cached(_STROKE_SHARES, key, plan)
    masks = _cached(_STROKE_MASKS, _key(dy, volume, slots, errors, remap),
                    lambda: StrokeMasks(passes, remap, weights, classes, profile.usable_slots()[0]))
    return masks.at_top(top_rows)


def hiding_shares(profile: Profile, passes: int) -> np.ndarray:
    """(4, A, N) each pass's share of each colour's row phase.  A nozzle the measurement
    found without drops (volume 0: dead) takes no share, as the profile's dead nozzles
    (which the slot table leaves out) take none."""
    from .masks import hiding_weights, stroke_error_um
    dy, volume, slots = _measured_slots(profile, passes)
    stroke = stroke_error_um(profile, passes)

    # a row's programme tries every subset of its passes: 4.7 s a plan at 8 passes, so the
    # shares are kept for the next job with the same measurement, weave and feed
    def plan():
        shares = hiding_weights(dy, volume, slots, stroke_error_um=stroke)
        shares.setflags(write=False)
        return shares
    return _cached(_SHARES, _key(dy, volume, slots, np.array([stroke])), plan)


_SHARES: dict[str, np.ndarray] = {}
_STROKE_SHARES: dict[str, np.ndarray] = {}
_STROKE_MASKS: dict = {}
