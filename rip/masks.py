"""The shipped threshold masks (resources/masks/, README there): the pass masks' 128x128
blue-noise tile, the ``bluenoise`` screen's 256x256 mask and the modulation mask of ``vced``
/ ``vector``; each read once, checked to be a permutation of its ranks, read-only.

Used by rip/halftone.py (the screens, the diffusion's modulation) and by rip/diffusion.py's
offline tuning; rip/halftone.py re-exports every name here."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

MASKS = Path(__file__).resolve().parent.parent / "resources" / "masks"
BLUENOISE_PATH = MASKS / "bluenoise128.npy"       # the pass masks' tile (rip/swath.py)
SCREEN_PATH = MASKS / "screen256.npy"             # the bluenoise screen
MODULATION_PATH = MASKS / "bluenoise256.npy"      # vced's and vector's threshold modulation


@functools.lru_cache(maxsize=None)
def _bluenoise_cached(path: str) -> np.ndarray:
    mask = np.load(path, allow_pickle=False)
    if mask.ndim != 2 or mask.shape[0] != mask.shape[1]:
        raise ValueError(f"{path}: blue-noise mask must be square, got shape {mask.shape}")
    flat = mask.reshape(-1).astype(np.int64)
    if flat.min() < 0 or flat.max() >= flat.size or np.bincount(flat, minlength=flat.size).max() != 1:
        raise ValueError(f"{path}: blue-noise mask is not a permutation of 0..{flat.size - 1}")
    mask = mask.astype(np.uint16 if flat.size <= 1 << 16 else np.uint32)
    mask.setflags(write=False)
    return mask


def load_bluenoise_mask(path: str | os.PathLike | None = None) -> np.ndarray:
    """The shipped 128x128 blue-noise rank mask (read-only, cached): the pass masks' tile."""
    return _bluenoise_cached(str(BLUENOISE_PATH if path is None else path))


def load_screen_mask(path: str | os.PathLike | None = None) -> np.ndarray:
    """The shipped 256x256 screen rank mask (read-only, cached): the ``bluenoise`` screen
    (resources/masks/README.md)."""
    return _bluenoise_cached(str(SCREEN_PATH if path is None else path))


def load_modulation_mask() -> np.ndarray:
    """The shipped 256x256 rank mask of ``vced`` / ``vector``'s threshold modulation
    (read-only, cached; the screen mask before the coarse-scale one, kept because the
    modulation strength is tuned on it)."""
    return _bluenoise_cached(str(MODULATION_PATH))


@functools.lru_cache(maxsize=None)
def modulation_noise() -> np.ndarray:
    """The modulation mask as uint8 noise 0..255 (each value on n*n/256 pixels): the threshold
    modulation of the variable-coefficient error diffusion."""
    ranks = load_modulation_mask().astype(np.int64)
    noise = (ranks * 256 // ranks.size).astype(np.uint8)
    noise.setflags(write=False)
    return noise
