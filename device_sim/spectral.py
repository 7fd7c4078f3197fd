"""The emulator's spectral colour model (docs/physical.md, "The colour of the print").

The paper and the four inks are spectral data (resources/spectra/*.json, 380-730 nm every
10 nm, with their sources); the 16 Neugebauer primaries are the paper seen through every
combination of ink films.  A spot of the print is a mixture of those primaries, weighted
by the area each combination covers (the Demichel weights of the local coverages), mixed
by the Yule-Nielsen modified spectral Neugebauer model:

    R(λ) = ( Σ_j w_j R_j(λ)^(1/n) )^n

with the media's n.  Colorimetry: CIE 1931 2° observer, D50, ASTM E308 weights (M0: the
emulated instrument's illuminant has no UV cut and the paper no fluorescence to excite).

Everything here is plain numpy on arrays of any leading shape; the instruments
(spectro.py, scanner.py) call it on rows of pixels.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

SPECTRA = Path(__file__).resolve().parent.parent / "resources" / "spectra"
CIE_FILE = SPECTRA / "cie1931-2deg-d50.json"
INKS = "CMYK"
# the primaries in Neugebauer order: index j has ink i when bit i of j is set (C = bit 0)
PRIMARY_NAMES = tuple("".join(INKS[i] for i in range(4) if j >> i & 1) or "W" for j in range(16))


# -- colorimetry -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Observer:
    wavelengths: np.ndarray       # (bands,) nm
    weights: np.ndarray           # (3, bands): XYZ of a reflectance, perfect white Y = 1
    white: np.ndarray             # (3,) XYZ of the perfect diffuser (D50)


@lru_cache(maxsize=1)
def observer() -> Observer:
    doc = json.loads(CIE_FILE.read_text())
    w = np.array(doc["xyz_weights"], np.float64)
    return Observer(np.array(doc["wavelengths_nm"], np.float64), w, w.sum(axis=1))


_EPS = (6.0 / 29.0) ** 3


def xyz_to_lab(xyz: np.ndarray, white: np.ndarray | None = None) -> np.ndarray:
    """CIE 1976 L*a*b* (CIE 015) of XYZ (... , 3), relative to `white` (default D50)."""
    white = observer().white if white is None else white
    t = np.asarray(xyz, np.float64) / white
    f = np.where(t > _EPS, np.cbrt(t), t / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]),
                     200 * (f[..., 1] - f[..., 2])], axis=-1)


def lab_to_xyz(lab: np.ndarray, white: np.ndarray | None = None) -> np.ndarray:
    white = observer().white if white is None else white
    lab = np.asarray(lab, np.float64)
    fy = (lab[..., 0] + 16) / 116
    f = np.stack([fy + lab[..., 1] / 500, fy, fy - lab[..., 2] / 200], axis=-1)
    t = np.where(f > 6 / 29, f ** 3, 3 * (6 / 29) ** 2 * (f - 4 / 29))
    return t * white


def reflectance_to_lab(refl: np.ndarray) -> np.ndarray:
    obs = observer()
    return xyz_to_lab(np.asarray(refl, np.float64) @ obs.weights.T)


def delta_e2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """CIEDE2000 (CIE 142-2001; Sharma, Wu, Dalal 2005), kL = kC = kH = 1."""
    lab1, lab2 = np.asarray(lab1, np.float64), np.asarray(lab2, np.float64)
    l1, a1, b1 = lab1[..., 0], lab1[..., 1], lab1[..., 2]
    l2, a2, b2 = lab2[..., 0], lab2[..., 1], lab2[..., 2]
    c_bar = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    g = 0.5 * (1 - np.sqrt(c_bar ** 7 / (c_bar ** 7 + 25.0 ** 7)))
    a1p, a2p = (1 + g) * a1, (1 + g) * a2
    c1p, c2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360
    dl, dc = l2 - l1, c2p - c1p
    dh = h2p - h1p
    dh = np.where(dh > 180, dh - 360, np.where(dh < -180, dh + 360, dh))
    dh = np.where(c1p * c2p == 0, 0.0, dh)
    dhh = 2 * np.sqrt(c1p * c2p) * np.sin(np.radians(dh / 2))
    lp, cp = (l1 + l2) / 2, (c1p + c2p) / 2
    hsum = h1p + h2p
    hp = np.where(np.abs(h1p - h2p) > 180, np.where(hsum < 360, hsum + 360, hsum - 360), hsum) / 2
    hp = np.where(c1p * c2p == 0, hsum, hp)
    t = (1 - 0.17 * np.cos(np.radians(hp - 30)) + 0.24 * np.cos(np.radians(2 * hp))
         + 0.32 * np.cos(np.radians(3 * hp + 6)) - 0.20 * np.cos(np.radians(4 * hp - 63)))
    sl = 1 + 0.015 * (lp - 50) ** 2 / np.sqrt(20 + (lp - 50) ** 2)
    sc, sh = 1 + 0.045 * cp, 1 + 0.015 * cp * t
    rt = (-2 * np.sqrt(cp ** 7 / (cp ** 7 + 25.0 ** 7))
          * np.sin(np.radians(60 * np.exp(-(((hp - 275) / 25) ** 2)))))
    return np.sqrt((dl / sl) ** 2 + (dc / sc) ** 2 + (dhh / sh) ** 2
                   + rt * (dc / sc) * (dhh / sh))


# -- halftone mixing ---------------------------------------------------------------------------
def demichel(cov: np.ndarray) -> np.ndarray:
    """The 16 Demichel weights (..., 16) of coverages (..., 4) in C, M, Y, K order: the
    share of the area each ink combination covers when the inks lie independently."""
    cov = np.asarray(cov, np.float64)
    w = np.ones(cov.shape[:-1] + (16,))
    for i in range(4):
        c = cov[..., i:i + 1]
        has = (np.arange(16) >> i & 1).astype(bool)
        w *= np.where(has, c, 1.0 - c)
    return w


# -- the media ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpectralMedia:
    """A media and its inks, ready to mix: the primaries and their n-th roots."""
    name: str
    wavelengths: np.ndarray
    paper: np.ndarray               # (bands,) reflectance
    density: np.ndarray             # (4, bands) optical density of each ink's film
    surface: float
    n: float                        # Yule-Nielsen
    ink_limit_ml_m2: float          # the wet ink the media takes (ml/m² = µm of film)
    bleed_um: float                 # the reach over which that volume is shared
    primaries: np.ndarray           # (16, bands)
    q: np.ndarray                   # (16, bands) primaries ** (1 / n)

    @classmethod
    def load(cls, name: str = "solvent-vinyl", n: float = 1.7, ink_limit_ml_m2: float = 20.0,
             bleed_um: float = 150.0) -> SpectralMedia:
        doc = _media_doc(name)
        paper = np.array(doc["paper"], np.float64)
        dens = np.array([doc["density"][i] for i in INKS], np.float64)
        surface = float(doc["surface_reflectance"])
        prim = neugebauer_primaries(paper, dens, float(doc["overprint_trap"]), surface)
        if not np.array_equal(np.array(doc["wavelengths_nm"], np.float64), observer().wavelengths):
            raise ValueError(f"{name}: its wavelengths are not the observer's")
        return cls(name, observer().wavelengths, paper, dens, surface, float(n),
                   float(ink_limit_ml_m2), float(bleed_um), prim, prim ** (1.0 / n))

    @classmethod
    def from_profile(cls, profile) -> SpectralMedia:
        ph = profile.physical
        return _cached(ph.media, ph.yule_nielsen_n, ph.ink_limit_ml_m2, ph.bleed_um)

    # -- mixing ---------------------------------------------------------------------------
    def reflectance(self, weights: np.ndarray) -> np.ndarray:
        """Spectral reflectance (..., bands) of Neugebauer weights (..., 16)."""
        q = np.asarray(weights, np.float64) @ self.q
        return np.maximum(q, 0.0) ** self.n

    def lab(self, weights: np.ndarray) -> np.ndarray:
        return reflectance_to_lab(self.reflectance(weights))

    def coverage_lab(self, coverage) -> np.ndarray:
        """Lab of a halftone with these fractional coverages (..., 4), C M Y K in 0..1, the
        inks lying independently (Demichel): the model's colour of a flat tint."""
        return self.lab(demichel(coverage))

    def primary_lab(self) -> dict[str, np.ndarray]:
        return dict(zip(PRIMARY_NAMES, reflectance_to_lab(self.primaries)))


def neugebauer_primaries(paper: np.ndarray, density: np.ndarray, trap: float,
                         surface: float) -> np.ndarray:
    """The 16 primaries (16, bands): the paper seen through each combination of ink films,
    Beer-Lambert (densities add), every film after the first (the ink does not wet another
    ink's film as it wets the vinyl: it spreads thinner) counted `trap` of its density, and
    the film's first surface reflecting `surface` of the light whatever lies under it."""
    prim = np.empty((16, paper.size))
    for j in range(16):
        films = [density[i] for i in range(4) if j >> i & 1]
        d = sum(films, np.zeros(paper.size))
        d = d * trap ** (len(films) - 1) if films else d
        prim[j] = surface + (paper - surface) * 10.0 ** (-d)
    return prim


def _media_doc(name: str) -> dict:
    path = SPECTRA / f"{name}.json"
    if not path.is_file():
        have = sorted(p.stem for p in SPECTRA.glob("*.json") if p != CIE_FILE)
        raise ValueError(f"no spectral data for media {name!r} (have: {', '.join(have)})")
    return json.loads(path.read_text())


@lru_cache(maxsize=8)
def _cached(name: str, n: float, limit: float, bleed: float) -> SpectralMedia:
    return SpectralMedia.load(name, n, limit, bleed)

