"""The `hiding` pass mask's shares (issue 36; docs/quality.md "Nozzle-error hiding as a
setting", docs/rip.md "Pass masks"): from the nozzles' errors the profile keeps ([layout]
nozzle_dy_um, nozzle_volume_pct, written by `wideprint calibrate nozzles`), each colour's
row phases get their shares per pass by `rip.masks.hiding_weights`, held towards equal
shares by the error the feed's whole steps leave at each stroke (`rip.masks.stroke_error_um`).
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


def hiding_shares(profile: Profile, passes: int) -> np.ndarray:
    """(4, A, N) each pass's share of each colour's row phase.  A nozzle the measurement
    found without drops (volume 0: dead) takes no share, as the profile's dead nozzles
    (which the slot table leaves out) take none."""
    from .masks import hiding_weights, stroke_error_um
    dy, volume = measured_errors(profile)
    slots = weave_slots(profile, passes).copy()
    h, z = slots[..., 0], slots[..., 1]
    dry = (h >= 0) & (volume[np.maximum(h, 0), z] <= 0)
    slots[dry] = -1
    stroke = stroke_error_um(profile, passes)
    # a row's programme tries every subset of its passes: 4.7 s a plan at 8 passes, so the
    # shares are kept for the next job with the same measurement, weave and feed
    key = hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in (
        dy, volume, slots, np.array([stroke])))).hexdigest()
    if key not in _SHARES:
        if len(_SHARES) >= 16:
            _SHARES.pop(next(iter(_SHARES)))
        shares = hiding_weights(dy, volume, slots, stroke_error_um=stroke)
        shares.setflags(write=False)
        _SHARES[key] = shares
    return _SHARES[key]


_SHARES: dict[str, np.ndarray] = {}
