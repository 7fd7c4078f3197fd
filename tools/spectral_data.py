"""Regenerate the emulator's spectral data (docs/physical.md, "The colour of the print"):

    python -m wideprint.tools.spectral_data cie      # resources/spectra/cie1931-2deg-d50.json
    python -m wideprint.tools.spectral_data fit      # resources/spectra/solvent-vinyl.json

`cie` needs colour-science (pip install colour-science; used here only, never at run
time): the CIE 1931 2° observer and CIE D50, as ASTM E308 tristimulus weights for
reflectances sampled 380-730 nm every 10 nm (the bands of the emulator and of an i1Pro).

`fit` needs only numpy: the paper and the four inks, as spectra, fitted so that the
model's paper, solids and overprints match the published CIELAB targets (TARGETS below):
a Levenberg-Marquardt fit of a few smooth absorption bands per ink.  It prints the
residuals docs/physical.md quotes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

SPECTRA = Path(__file__).resolve().parent.parent / "resources" / "spectra"
CIE_FILE = SPECTRA / "cie1931-2deg-d50.json"
MEDIA_FILE = SPECTRA / "solvent-vinyl.json"
WL = np.arange(380, 740, 10, dtype=np.float64)

# ISO 12647-2:2004/Amd 1:2007, Table 2 (paper type 1, gloss coated, white backing): the
# characterisation data FOGRA39L.  D50, 2°, M0 (no UV cut), 0°/45° geometry.
TARGETS = {
    "": (95.0, 0.0, -2.0),        # paper
    "C": (55.0, -37.0, -50.0),
    "M": (48.0, 74.0, -3.0),
    "Y": (89.0, -5.0, 93.0),
    "K": (16.0, 0.0, 0.0),
    "MY": (47.0, 68.0, 48.0),     # red
    "CY": (50.0, -65.0, 27.0),    # green
    "CM": (24.0, 22.0, -46.0),    # blue
    "CMY": (23.0, 0.0, 0.0),
}
SURFACE = 0.006        # first-surface reflectance under every ink film (decision, docs)
INKS = "CMYK"
# start values of each ink's absorption bands: (height, centre nm, width nm); + a flat floor
START = {
    "C": [(1.6, 640.0, 55.0), (0.25, 400.0, 35.0), (0.3, 580.0, 30.0)],
    "M": [(1.3, 545.0, 40.0), (0.3, 430.0, 40.0), (0.3, 500.0, 30.0)],
    "Y": [(1.6, 430.0, 40.0), (0.2, 380.0, 30.0), (0.2, 480.0, 25.0)],
    "K": [(0.6, 450.0, 150.0), (0.6, 650.0, 150.0), (0.2, 550.0, 80.0)],
}
SMOOTH = 2.0         # weight of the curvature penalty (Lab units per unit of 2nd difference)
FLOOR = {"C": 0.02, "M": 0.02, "Y": 0.01, "K": 1.0}


def cie() -> None:
    import colour          # noqa: PLC0415 - only this sub-command needs it
    shape = colour.SpectralShape(380, 730, 10)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    d50 = colour.SDS_ILLUMINANTS["D50"]
    weights = []
    for k in range(WL.size):          # the XYZ of a unit in one band: the weights (linear)
        unit = np.zeros(WL.size)
        unit[k] = 1.0
        sd = colour.SpectralDistribution(dict(zip(WL, unit)))
        weights.append(colour.sd_to_XYZ(sd, cmfs, d50, method="ASTM E308") / 100.0)
    w = np.array(weights).T
    doc = {
        "about": "CIE 1931 2° standard observer under CIE illuminant D50: tristimulus "
                 "weights for reflectances sampled 380-730 nm at 10 nm (ASTM E308-18 "
                 "method, the weights of the bands beyond the range folded into the end "
                 "bands), normalised so that a perfect diffuser has Y = 1.",
        "source": "CIE 015:2018 Colorimetry, 4th ed. (observer, D50); ASTM E308-18; "
                  f"computed with colour-science {colour.__version__} "
                  "(colour.sd_to_XYZ, method 'ASTM E308') by tools/spectral_data.py cie",
        "wavelengths_nm": [int(v) for v in WL],
        "xyz_weights": [[round(float(v), 8) for v in row] for row in w],
        "white_xyz": [round(float(v), 8) for v in w.sum(axis=1)],
        "d50_relative_spd": [round(float(v), 4) for v in d50.copy().align(shape).values],
    }
    CIE_FILE.write_text(json.dumps(doc, indent=1, ensure_ascii=False) + "\n")
    print(f"wrote {CIE_FILE}: white XYZ {doc['white_xyz']}")


# -- the fit ---------------------------------------------------------------------------------
def _lab(refl: np.ndarray, w: np.ndarray) -> np.ndarray:
    xyz = refl @ w.T / w.sum(axis=1)
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]),
                     200 * (f[..., 1] - f[..., 2])], axis=-1)


def _unpack(p: np.ndarray):
    """Parameters -> paper reflectance, ink densities (4, bands)."""
    level, tilt, dip, dip_w, green = p[0], p[1], p[2], p[3], p[4]
    x = (WL - 550.0) / 100.0
    paper = (1 / (1 + np.exp(-level))) * (1 + 0.1 * np.tanh(tilt) * x
                                         + 0.05 * np.tanh(green) * np.exp(-0.5 * x * x)) \
        * (1 - (1 / (1 + np.exp(-dip))) * np.exp(-(WL - 380.0) / (10 + abs(dip_w))))
    dens = np.zeros((4, WL.size))
    i = 6
    for n, ink in enumerate(INKS):
        for _ in START[ink]:
            a, mu, s = np.exp(p[i]), p[i + 1], 20.0 + np.exp(p[i + 2])
            dens[n] += a * np.exp(-0.5 * ((WL - mu) / s) ** 2)
            i += 3
        dens[n] += np.exp(p[i])
        i += 1
    return paper, dens, 1 / (1 + np.exp(-p[5]))


def _start() -> np.ndarray:
    p = [2.3, -0.2, 0.0, 15.0, 0.0, 3.0]
    for ink in INKS:
        for a, mu, s in START[ink]:
            p += [np.log(a), mu, np.log(s - 20.0)]
        p.append(np.log(FLOOR[ink]))
    return np.array(p)


def primaries(paper: np.ndarray, dens: np.ndarray, trap: float,
              surface: float = SURFACE) -> np.ndarray:
    """The 16 Neugebauer primaries (index bit i: ink i of CMYK present): the paper seen
    through each combination of ink films (Beer-Lambert: densities add, each film on
    another ink counted `trap` of its own density)."""
    from ..device_sim.spectral import neugebauer_primaries
    return neugebauer_primaries(paper, dens, trap, surface)


def _index(name: str) -> int:
    return sum(1 << INKS.index(c) for c in name)


def _residuals(p: np.ndarray, w: np.ndarray) -> np.ndarray:
    paper, dens, trap = _unpack(p)
    prim = primaries(paper, dens, trap)
    names = list(TARGETS)
    lab = _lab(prim[[_index(n) for n in names]], w)
    r = (lab - np.array([TARGETS[n] for n in names]))
    r[0] *= 5.0                   # the paper white first: everything is relative to it
    r = r.ravel()
    # smooth spectra: a penalty on each density's curvature (20 nm scale), and the bands
    # kept near where they started (weak priors)
    i, prior = 6, [SMOOTH * np.diff(dens, 2, axis=1).ravel()]
    for ink in INKS:
        for a, mu, s in START[ink]:
            prior.append(np.array([0.02 * (p[i + 1] - mu)]))
            i += 3
        i += 1
    return np.concatenate([r] + prior)


def fit(w: np.ndarray) -> np.ndarray:
    p, lam = _start(), 1e-2
    r = _residuals(p, w)
    for _ in range(400):
        jac = np.empty((r.size, p.size))
        for k in range(p.size):
            h = 1e-6 * max(1.0, abs(p[k]))
            q = p.copy()
            q[k] += h
            jac[:, k] = (_residuals(q, w) - r) / h
        g, a = jac.T @ r, jac.T @ jac
        while True:
            step = np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-9), -g)
            q = p + step
            rq = _residuals(q, w)
            if rq @ rq < r @ r:
                p, r, lam = q, rq, max(lam / 3, 1e-9)
                break
            lam *= 4
            if lam > 1e9:
                return p
        if np.abs(step).max() < 1e-8:
            break
    return p


def de2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    from ..device_sim.spectral import delta_e2000
    return delta_e2000(lab1, lab2)


def fit_media() -> None:
    cie_doc = json.loads(CIE_FILE.read_text())
    w = np.array(cie_doc["xyz_weights"])
    p = fit(w)
    paper, dens, trap = _unpack(p)
    prim = primaries(paper, dens, trap)
    names = list(TARGETS)
    lab = _lab(prim[[_index(n) for n in names]], w)
    tgt = np.array([TARGETS[n] for n in names])
    de = de2000(lab, tgt)
    rows = []
    for n, l, t, e in zip(names, lab, tgt, de):
        rows.append({"patch": n or "paper", "target": list(t),
                     "model": [round(float(v), 2) for v in l], "de2000": round(float(e), 2)})
        print(f"{n or 'paper':6s} target {t} model {np.round(l, 2)} dE00 {e:.2f}")
    print(f"dE2000 mean {de.mean():.2f} max {de.max():.2f}")
    black = _lab(prim[15][None], w)[0]
    print(f"CMYK (not a target) {np.round(black, 2)}")
    doc = {
        "about": "White solvent vinyl and four solvent inks for the emulator's spectral "
                 "model (docs/physical.md): the paper's reflectance and each ink film's "
                 "optical density (log10, both passes), 380-730 nm at 10 nm.  The 16 "
                 "Neugebauer primaries are the paper seen through the films of each ink "
                 "combination: R = surface + (paper - surface) 10^-D, D the densities' "
                 "sum with every film after the first counted overprint_trap of its own.",
        "source": "Fitted by tools/spectral_data.py fit (Levenberg-Marquardt, a few "
                  "Gaussian absorption bands per ink) to the CIELAB targets of ISO "
                  "12647-2:2004/Amd 1:2007 Table 2, paper type 1, white backing "
                  "(characterisation data FOGRA39L): D50, 2°, M0.  No measured solvent-ink "
                  "spectra are available offline; solvent inks on white vinyl reach about "
                  "the gamut of this offset printing condition.",
        "surface_reflectance": SURFACE,
        "overprint_trap": round(float(trap), 5),
        "wavelengths_nm": [int(v) for v in WL],
        "paper": [round(float(v), 5) for v in paper],
        "density": {ink: [round(float(v), 5) for v in dens[i]] for i, ink in enumerate(INKS)},
        "fit": {"targets_de2000_mean": round(float(de.mean()), 3),
                "targets_de2000_max": round(float(de.max()), 3), "patches": rows,
                "cmyk_solid_lab": [round(float(v), 2) for v in black]},
    }
    MEDIA_FILE.write_text(json.dumps(doc, indent=1, ensure_ascii=False) + "\n")
    print(f"wrote {MEDIA_FILE}")


def main(argv: list[str]) -> int:
    if argv[:1] == ["cie"]:
        cie()
    elif argv[:1] == ["fit"]:
        fit_media()
    else:
        print(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
