"""Halftone quality (issue 18): wideprint's methods beside Ghostscript's and ImageMagick's on
the same CMYK planes, scored with the human-visual-system metric of bench/hvs.py.

    .venv/bin/python bench/quality_bench.py [--only wideprint] [--keep DIR] [--quick]

Inputs (every tool halftones the same 8-bit C, M, Y, K planes, 1 input pixel = 1 dot):
- photographs: scikit-image's sample photos ``astronaut`` (512 x 512) and ``coffee``
  (600 x 400), installed for the bench only (``pip install scikit-image``; not a dependency of
  wideprint: without it a generated photo-like image stands in, and the header says so),
  separated by wideprint's own ICC separation (built-in profiles, 300 % ink limit); once
  1:1 (a 300 ppi photo) and once enlarged 2x with lanczos3 (a 150 ppi photo placed on the
  300 dpi grid: smoother content, so the halftone's own noise counts for more);
- flat tints 1 % .. 99 % (26 of them) of one ink, 320 x 320 each, measured on the inner
  256 x 256 (after error diffusion's start-up);
- light mixed tints: C = M = 5, 10, 15, 20, 30, 40 %, and five mixed colours (C/M/Y/K);
- a 0 .. 100 % ramp (1024 x 256), a zone plate (512 x 512, rings up to 0.5 cycles/px) and
  text (6 to 14 pt at 300 dpi, K).

Scores (bench/hvs.py: Gaussian blur of 1.2 px "fine" and 2.5 px "coarse" at 300 dpi, the
same physical size along the feed, i.e. x 370.5/300 rows):
- photo fine / coarse: RMSE of the blurred halftone against the blurred contone, mean over
  the 4 planes and both photos; photo SSIM (fine); "x2": the enlarged photos;
- tints coarse: mean over the tints of the coarse RMSE (flat-tint grain); LF: the mean share
  of the pattern's power below 0.1 cycles/px; struct: the largest ``structure_peak`` over the
  tints (rip/diffusion.py: > 20 means a periodic structure - lines, grids, checkerboard
  domains); tone: the largest |dot density - ink| over the tints and over 64-row blocks, %;
- ramp / zone / text: fine RMSE (text: SSIM);
- C/M overlap: dots where both C and M print over the product of their densities, mean over
  C = M = 5 .. 20 % (independent placement: 1; identical patterns: 1 / density);
  mix grain: coarse RMS of the darkness image (C 0.51, M 0.59, Y 0.08, K 1.0, summed) of the
  mixed tints: the graininess a viewer sees in light colours.

Peers: Ghostscript 10 ``tiffscaled4`` (its error diffusion) and ``bitcmyk`` (its ordered
screen) on a PostScript wrapper of the raw CMYK planes (the planes pass unchanged: no
colour conversion between DeviceCMYK and the CMYK device); ImageMagick 6 (/usr/bin/convert)
``-dither FloydSteinberg -remap pattern:gray50`` and ``-ordered-dither o8x8`` per plane.
References inside wideprint: ``ostromoukhov`` (Ostromoukhov 2001, his published table, no
modulation: the issue's yardstick), ``bluenoise128`` (the screen before this work: the
128 px mask with its old channel offsets) and ``bluenoise256`` (the first 256 px screen of
this work, now vced's modulation mask, in today's channel layout); for issue 36 ``DBS``
(direct binary search on the whole image - the bound - started from vced's dots, toggles
and swaps with the 8 neighbours until a pass changes nothing, the eye model's fine
Gaussian as its filter: issue 36's yardstick) and ``DBS tone`` (the same with ``dbs``'s
objective - fine + 1.5 x coarse - and its tone guard: the bound of what ``dbs`` does row
by row).  Below the table: every
screen mask's noise over all 254 ink levels against the bound no threshold mask can beat
(``rip.bluenoise.nested_bound``).  No assertions: a measurement; the targets of the
issue are printed with met / MISSED.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
try:
    import wideprint  # noqa: F401
except ImportError:  # run from a checkout without the package installed
    sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

import hvs  # noqa: E402

TINTS = (1, 2, 3, 5, 8, 10, 15, 20, 25, 30, 33, 40, 45, 50, 55, 60, 67, 70, 75, 80, 85, 90, 95,
         97, 98, 99)
CELL, START = 320, 64          # tint patches, and the start-up rows/columns not measured
CM_TINTS = (5, 10, 15, 20, 30, 40)
MIXED = ((20, 10, 10, 0), (5, 25, 30, 0), (40, 10, 0, 0), (10, 10, 10, 5), (0, 30, 30, 0))
STRUCTURE_VISIBLE = 20.0
ISSUE36_FINE = 0.0135          # issue 36: photo fine-scale error, halfway from vced to DBS


# ------------------------------------------------------------------------------------------
# inputs


def _vips_to_array(img) -> np.ndarray:
    return np.ndarray(buffer=img.write_to_memory(), dtype=np.uint8,
                      shape=(img.height, img.width, img.bands))


def photos() -> tuple[list[tuple[str, np.ndarray]], str]:
    """RGB photographs: scikit-image's samples, or a generated stand-in."""
    try:
        import skimage.data as skd
        return [("astronaut", skd.astronaut()), ("coffee", skd.coffee())], "scikit-image samples"
    except Exception:  # noqa: BLE001 - any failure: fall back
        from rip_bench import TestImage
        return [("generated", TestImage(768, 512).band(1500, 512))], \
            "generated stand-in (scikit-image not installed)"


def enlarge(rgb: np.ndarray, f: int = 2) -> np.ndarray:
    import pyvips
    return _vips_to_array(pyvips.Image.new_from_array(np.ascontiguousarray(rgb)).resize(f, kernel="lanczos3"))


def separate(rgb: np.ndarray) -> np.ndarray:
    from wideprint.rip.color import Separator
    return np.ascontiguousarray(Separator("rgb", 8, ink_limit=300.0).convert(np.ascontiguousarray(rgb)))


def tint_sheet() -> tuple[np.ndarray, list]:
    """Every tint as a CELL x CELL patch of all four inks, in one image (5 patches a row)."""
    cols = 5
    rows = -(-len(TINTS) // cols)
    img = np.zeros((rows * CELL, cols * CELL, 4), np.uint8)
    where = []
    for i, t in enumerate(TINTS):
        y, x = divmod(i, cols)
        v = round(t * 255 / 100)
        img[y * CELL:(y + 1) * CELL, x * CELL:(x + 1) * CELL] = v
        where.append((t, v, y * CELL, x * CELL))
    return img, where


def mixed_sheet() -> tuple[np.ndarray, list]:
    patches = [(t, t, 0, 0) for t in CM_TINTS] + list(MIXED)
    img = np.zeros((CELL, len(patches) * CELL, 4), np.uint8)
    where = []
    for i, p in enumerate(patches):
        ink = np.round(np.array(p) * 255 / 100).astype(np.uint8)
        img[:, i * CELL:(i + 1) * CELL] = ink
        where.append((p, i * CELL))
    return img, where


def ramp() -> np.ndarray:
    r = np.round(np.linspace(0, 255, 1024)).astype(np.uint8)
    img = np.zeros((256, 1024, 4), np.uint8)
    img[:] = r[None, :, None]
    return img


def zone_plate(n: int = 512) -> np.ndarray:
    y, x = np.mgrid[0:n, 0:n] - n / 2
    k = np.pi / n          # the phase's second derivative: rings reach 0.5 cycles/px at the edge
    v = 0.5 + 0.5 * np.cos(k * (x * x + y * y))
    img = np.zeros((n, n, 4), np.uint8)
    img[:, :, 3] = np.round(255 * v)
    return img


def text() -> np.ndarray:
    import pyvips
    lines = []
    for pt in (6, 8, 10, 14):
        t = pyvips.Image.text(f"{pt} pt: Halftone quality at the state of the art 0123456789",
                              dpi=300, font=f"sans {pt}")
        lines.append(_vips_to_array(t)[:, :, 0])
    w = max(a.shape[1] for a in lines) + 32
    img = np.zeros((sum(a.shape[0] + 16 for a in lines) + 16, w, 4), np.uint8)
    y = 16
    for a in lines:
        img[y:y + a.shape[0], 16:16 + a.shape[1], 3] = a
        y += a.shape[0] + 16
    return img


# ------------------------------------------------------------------------------------------
# wideprint's methods (and the references)


def _screen(ranks: np.ndarray, offsets, inverted=None):
    """An ordered screen with the given rank mask and channel layout, as a callable."""
    from wideprint.rip.halftone import threshold_tile
    n = ranks.shape[0]
    t = threshold_tile(ranks)
    t_inv = threshold_tile(ranks.size - 1 - ranks.astype(np.int64))

    def run(cmyk):
        h, w = cmyk.shape[:2]
        out = np.empty_like(cmyk)
        for k, (ox, oy) in enumerate(offsets):
            tile = np.roll(t_inv if inverted is not None and inverted[k] else t,
                           (-int(oy), -int(ox)), axis=(0, 1))
            big = np.tile(tile, (-(-h // n), -(-w // n)))[:h, :w]
            out[:, :, k] = cmyk[:, :, k] > big
        return out
    return run


def wideprint_methods() -> dict:
    from wideprint.rip.diffusion import VCDiffuser
    from wideprint.rip.halftone import (Halftoner, load_bluenoise_mask, load_modulation_mask,
                                        mask_offsets, modulation_noise, screen_layout)

    def ht(method):
        def run(cmyk):
            h = Halftoner(method, cmyk.shape[1], 4)
            return np.concatenate([h.process(cmyk[y:y + 64]) for y in range(0, cmyk.shape[0], 64)])
        return run

    def ostromoukhov(cmyk):
        return VCDiffuser(cmyk.shape[1], 4, modulation_noise(), table="ostromoukhov",
                          strength="ostromoukhov", next_boost=1.0).process(cmyk)

    m = {name: ht(name) for name in ("vced", "vector", "dbs", "fs", "jarvis", "stucki", "bluenoise", "bayer")}
    m["ostromoukhov"] = ostromoukhov
    m["DBS"] = full_dbs(tone=False)            # issue 36: the bound, and dbs's own objective's
    m["DBS tone"] = full_dbs(tone=True)
    # the screen before issue 18 (the 128 px mask, its old channel offsets), and the first
    # 256 px screen of issue 18 (now the modulation mask; today's channel layout)
    m["bluenoise128"] = _screen(load_bluenoise_mask(), mask_offsets(128, 4))
    m["bluenoise256"] = _screen(load_modulation_mask(), *screen_layout(256, 4))
    return m


def _dbs_kernel():
    """Direct binary search on a whole plane (numba, the bench only): h (H, W) uint8 dots,
    improved in place; c (H, W) float64 ink 0..1; cpp the filter's autocorrelation (2 ry + 1,
    2 rx + 1); toggles only where ``guard < 255 c < 255 - guard`` (guard < 0: everywhere),
    swaps with the 8 neighbours where neither ink is 0 or 1.  Passes in scan order until
    one changes nothing (at most ``passes``)."""
    import numba

    @numba.njit(cache=True)
    def dbs_plane(h, c, cpp, passes, guard):
        H, W = h.shape
        ry, rx = cpp.shape[0] // 2, cpp.shape[1] // 2
        cpe = np.zeros((H, W))

        def stamp(y, x, a):
            for dy in range(-ry, ry + 1):
                yy = y + dy
                if 0 <= yy < H:
                    for dx in range(-rx, rx + 1):
                        xx = x + dx
                        if 0 <= xx < W:
                            cpe[yy, xx] += a * cpp[dy + ry, dx + rx]
        for y in range(H):
            for x in range(W):
                stamp(y, x, h[y, x] - c[y, x])
        c0 = cpp[ry, rx]
        for _ in range(passes):
            changes = 0
            for y in range(H):
                for x in range(W):
                    a0 = 1.0 - 2.0 * h[y, x]
                    lv = c[y, x] * 255.0
                    best = c0 + 2 * a0 * cpe[y, x] if guard < lv < 255 - guard else 0.0
                    by, bx = -1, -1
                    if 0 < lv < 255:
                        for dy in range(-1, 2):
                            for dx in range(-1, 2):
                                yy, xx = y + dy, x + dx
                                if (dy or dx) and 0 <= yy < H and 0 <= xx < W and h[yy, xx] != h[y, x] \
                                        and 0 < c[yy, xx] < 1:
                                    d = 2 * c0 - 2 * cpp[ry + dy, rx + dx] + 2 * a0 * (cpe[y, x] - cpe[yy, xx])
                                    if d < best:
                                        best, by, bx = d, yy, xx
                    if best < -1e-12:
                        changes += 1
                        h[y, x] = 1 - h[y, x]
                        stamp(y, x, a0)
                        if by >= 0:
                            h[by, bx] = 1 - h[by, bx]
                            stamp(by, bx, -a0)
            if changes == 0:
                break
    return dbs_plane


def _autocorrelation(sigma: float, weight: float = 1.0) -> np.ndarray:
    """The autocorrelation of the eye model's Gaussian (sigma px across, x ASPECT along; cut at
    4 sigma), times ``weight``."""
    from numpy.fft import fft2, ifft2
    sx, sy = sigma, sigma * hvs.ASPECT
    rx, ry = int(np.ceil(4 * sx)), int(np.ceil(4 * sy))
    g = np.outer(np.exp(-np.arange(-ry, ry + 1) ** 2 / (2 * sy * sy)),
                 np.exp(-np.arange(-rx, rx + 1) ** 2 / (2 * sx * sx)))
    g /= g.sum()
    p = np.zeros((4 * ry + 1, 4 * rx + 1))
    p[:2 * ry + 1, :2 * rx + 1] = g
    return weight * np.fft.fftshift(np.real(ifft2(np.abs(fft2(p)) ** 2)))


def full_dbs(tone: bool):
    """Whole-image DBS from vced's dots (see the module docstring): the fine filter alone
    (the bound issue 36 quotes), or ``dbs``'s objective and tone guard (``tone``)."""
    from wideprint.rip import dbs
    from wideprint.rip.halftone import Halftoner
    cpp = _autocorrelation(hvs.FINE)
    if tone:
        wide = _autocorrelation(hvs.COARSE, dbs.COARSE_WEIGHT)
        oy, ox = (wide.shape[0] - cpp.shape[0]) // 2, (wide.shape[1] - cpp.shape[1]) // 2
        wide[oy:oy + cpp.shape[0], ox:ox + cpp.shape[1]] += cpp
        cpp = wide
    guard = dbs.TONE_GUARD if tone else -1
    kernel = _dbs_kernel()

    def run(cmyk):
        dots = Halftoner("vced", cmyk.shape[1], 4).process(cmyk)
        for k in range(4):
            plane = np.ascontiguousarray(dots[:, :, k])
            kernel(plane, cmyk[:, :, k] / 255.0, np.ascontiguousarray(cpp), 30, guard)
            dots[:, :, k] = plane
        return dots
    return run


def mask_levels() -> list[tuple[str, float, float]]:
    """(name, coarse, fine): each screen mask's noise over all ink levels 1..254 (RMS of
    ``rip.bluenoise.level_noise``), first the bound no threshold mask can beat."""
    from wideprint.rip.bluenoise import level_noise, nested_bound
    from wideprint.rip.halftone import (bayer_matrix, load_bluenoise_mask, load_modulation_mask,
                                        load_screen_mask)
    rows = [("bound (any threshold mask)", nested_bound(hvs.COARSE), nested_bound(hvs.FINE))]
    for name, ranks in (("bluenoise", load_screen_mask()), ("bluenoise256", load_modulation_mask()),
                        ("bluenoise128", load_bluenoise_mask()), ("bayer", bayer_matrix(16))):
        rows.append((name, *(float(np.sqrt(np.mean(level_noise(ranks, s) ** 2)))
                             for s in (hvs.COARSE, hvs.FINE))))
    return rows


# ------------------------------------------------------------------------------------------
# peers


def _read_pbm(path: str) -> np.ndarray:
    with open(path, "rb") as f:
        data = f.read()
    parts = data.split(maxsplit=3)
    if parts[0] != b"P4":
        raise ValueError(f"{path}: not a raw PBM")
    w, h = int(parts[1]), int(parts[2])
    raw = np.frombuffer(parts[3][:h * ((w + 7) // 8)], np.uint8).reshape(h, -1)
    return np.unpackbits(raw, axis=1)[:, :w]


def peer_methods(work: str) -> dict:
    """name -> callable(cmyk) -> dots, or None (not installed)."""
    out = {}
    gs = shutil.which("gs")
    for name, dev in (("gs tiffscaled4", "tiffscaled4"), ("gs bitcmyk", "bitcmyk")):
        if not gs:
            out[name] = None
            continue

        def run(cmyk, dev=dev):
            h, w = cmyk.shape[:2]
            raw, ps = os.path.join(work, "gs_in.cmyk"), os.path.join(work, "gs_in.ps")
            cmyk.tofile(raw)
            with open(ps, "w") as f:
                f.write(f"%!PS\n/DeviceCMYK setcolorspace\n{w * 72 / 300:.6f} {h * 72 / 300:.6f} scale\n"
                        f"<< /ImageType 1 /Width {w} /Height {h} /BitsPerComponent 8 "
                        f"/Decode [0 1 0 1 0 1 0 1] /ImageMatrix [{w} 0 0 -{h} 0 {h}] "
                        f"/Interpolate false /DataSource ({raw}) (r) file >> image\nshowpage\n")
            res = os.path.join(work, "gs_out")
            subprocess.run([gs, "-q", "-dSAFER", f"--permit-file-read={work}/", "-dBATCH", "-dNOPAUSE",
                            "-r300", f"-g{w}x{h}", "-dFIXEDMEDIA", f"-sDEVICE={dev}",
                            "-dDownScaleFactor=1", f"-sOutputFile={res}", ps], check=True,
                           capture_output=True)
            if dev == "bitcmyk":
                bits = np.unpackbits(np.fromfile(res, np.uint8))[:h * w * 4]
                return bits.reshape(h, w, 4)
            import tifffile
            return tifffile.imread(res).astype(np.uint8).reshape(h, w, 4)
        out[name] = run
    convert = "/usr/bin/convert"
    is_im = False
    if os.path.exists(convert):
        try:
            is_im = "ImageMagick" in subprocess.run([convert, "-version"], capture_output=True,
                                                    text=True, timeout=30).stdout
        except (OSError, subprocess.SubprocessError):
            pass
    for name, args in (("imagemagick FS", ["-dither", "FloydSteinberg", "-remap", "pattern:gray50"]),
                       ("imagemagick o8x8", ["-ordered-dither", "o8x8"])):
        if not is_im:
            out[name] = None
            continue

        def run(cmyk, args=args):
            h, w = cmyk.shape[:2]
            dots = np.empty_like(cmyk)
            for k in range(4):
                pgm, pbm = os.path.join(work, "im.pgm"), os.path.join(work, "im.pbm")
                with open(pgm, "wb") as f:
                    f.write(f"P5 {w} {h} 255\n".encode() + (255 - cmyk[:, :, k]).tobytes())
                subprocess.run([convert, pgm, *args, pbm], check=True, capture_output=True)
                dots[:, :, k] = _read_pbm(pbm)       # PBM 1 = black = a drop
            return dots
        out[name] = run
    return out


# ------------------------------------------------------------------------------------------
# scoring


def score(run, inputs) -> dict:
    from wideprint.rip.diffusion import structure_peak
    r = {}
    t0 = time.perf_counter()
    for key, imgs in (("photo", inputs["photos"]), ("photo2", inputs["photos2"])):
        fine, coarse, ssim, lum = [], [], [], []
        for cmyk in imgs:
            dots = run(cmyk)
            for k in range(4):
                h, c = dots[:, :, k], cmyk[:, :, k] / 255.0
                fine.append(hvs.rmse(h, c, hvs.FINE))
                coarse.append(hvs.rmse(h, c, hvs.COARSE))
                if key == "photo":
                    ssim.append(hvs.ssim(h, c))
            dk = (dots * hvs.DARKNESS).sum(axis=2) - (cmyk / 255.0 * hvs.DARKNESS).sum(axis=2)
            lum.append(float(np.sqrt(np.mean(hvs.blur(dk, hvs.COARSE) ** 2))))
        r[f"{key}_fine"], r[f"{key}_coarse"] = np.mean(fine), np.mean(coarse)
        r[f"{key}_lum"] = np.mean(lum)
        if ssim:
            r["photo_ssim"] = np.mean(ssim)
    sheet, where = inputs["tints"]
    dots = run(sheet)
    co, lf, st, tone = [], [], [], []
    for _t, v, y, x in where:
        patch = dots[y + START:y + CELL, x + START:x + CELL, 0]
        co.append(hvs.rmse(patch, np.full(patch.shape, v / 255), hvs.COARSE, margin=16))
        lf.append(hvs.lf_share(patch))
        st.append(structure_peak(patch))
        whole = dots[y:y + CELL, x:x + CELL, 0].astype(np.float64)
        blocks = whole[:CELL - CELL % 64].reshape(-1, 64, CELL).mean(axis=(1, 2))
        tone.append(max(abs(whole.mean() - v / 255), np.abs(blocks - v / 255).max()))
    r["tint_coarse"], r["tint_lf"] = np.mean(co), np.mean(lf)
    r["tint_struct"], r["tone"] = np.max(st), 100 * np.max(tone)
    r["struct_at"] = TINTS[int(np.argmax(st))]
    mixed, mwhere = inputs["mixed"]
    dots = run(mixed)
    ov, grain = [], []
    for p, x in mwhere:
        patch = dots[START:, x + START:x + CELL]
        if p[0] == p[1] and p[2] == p[3] == 0 and p[0] <= 20:
            c, m = patch[:, :, 0].astype(np.float64), patch[:, :, 1].astype(np.float64)
            ov.append((c * m).mean() / max(c.mean() * m.mean(), 1e-9))
        grain.append(hvs.luminance_noise(patch))
    r["cm_overlap"], r["mix_grain"] = np.mean(ov), np.mean(grain)
    for key in ("ramp", "zone"):
        img = inputs[key]
        dots = run(img)
        ks = range(4) if key == "ramp" else (3,)
        r[f"{key}_fine"] = np.mean([hvs.rmse(dots[:, :, k], img[:, :, k] / 255.0, hvs.FINE) for k in ks])
    img = inputs["text"]
    dots = run(img)
    r["text_ssim"] = hvs.ssim(dots[:, :, 3], img[:, :, 3] / 255.0)
    r["seconds"] = time.perf_counter() - t0
    return r


COLUMNS = (("photo_fine", "photo fine", 5), ("photo_coarse", "coarse", 5), ("photo_ssim", "SSIM", 4),
           ("photo2_fine", "x2 fine", 5), ("photo2_coarse", "coarse", 5), ("photo_lum", "lum", 5),
           ("tint_coarse", "tints crs", 5), ("tint_lf", "LF", 4), ("tint_struct", "struct", 0),
           ("tone", "tone %", 2), ("ramp_fine", "ramp", 4), ("zone_fine", "zone", 4),
           ("text_ssim", "text", 3), ("cm_overlap", "C/M ovl", 2), ("mix_grain", "mix grain", 5))


def fmt(v, digits):
    return f"{v:.0f}" if digits == 0 else f"{v:.{digits}f}"


def print_table(results: dict) -> None:
    w0 = max(len(k) for k in results) + 1
    print(f"{'method':{w0}s}" + "".join(f"{h:>10s}" for _, h, _ in COLUMNS))
    for name, r in results.items():
        if r is None:
            print(f"{name:{w0}s} not installed")
            continue
        print(f"{name:{w0}s}" + "".join(f"{fmt(r[k], d):>10s}" for k, _, d in COLUMNS))


def verdict(ok: bool) -> str:
    return "met" if ok else "MISSED"


def print_targets(res: dict) -> None:
    def ratio(a, b, key):
        return res[a][key] / res[b][key] if res.get(a) and res.get(b) else float("nan")

    print()
    print("ratios (lower is better for RMSE, LF, grain and overlap)")
    rows = []
    for key, label in (("photo_fine", "photo fine"), ("photo_coarse", "photo coarse"),
                       ("photo2_fine", "photo x2 fine"), ("photo2_coarse", "photo x2 coarse"),
                       ("photo_lum", "photo luminance coarse"), ("tint_coarse", "tints coarse"),
                       ("mix_grain", "mixed-tint grain")):
        rows.append((f"vced / fs, {label}", ratio("vced", "fs", key)))
        rows.append((f"vced / ostromoukhov, {label}", ratio("vced", "ostromoukhov", key)))
    for peer in ("gs tiffscaled4", "imagemagick FS"):
        rows.append((f"vced / {peer}, photo fine", ratio("vced", peer, "photo_fine")))
        rows.append((f"vced / {peer}, photo coarse", ratio("vced", peer, "photo_coarse")))
    for ref in ("bluenoise128", "bluenoise256"):
        for key, label in (("tint_coarse", "tints coarse"), ("photo_coarse", "photo coarse"),
                           ("photo_fine", "photo fine"), ("photo2_coarse", "photo x2 coarse"),
                           ("tint_lf", "tints LF share"), ("mix_grain", "mixed-tint grain")):
            rows.append((f"bluenoise / {ref}, {label}", ratio("bluenoise", ref, key)))
    rows.append(("vector / vced, mixed-tint grain", ratio("vector", "vced", "mix_grain")))
    for label, v in rows:
        if v == v:              # not NaN: both methods were scored (--methods, --only)
            print(f"  {label:48s} {v:6.3f}")

    print()
    print("targets (issue 18)")
    v, o = res.get("vced"), res.get("ostromoukhov")
    if v and o:
        print(f"  vced photo fine <= Ostromoukhov's ({v['photo_fine']:.5f} vs {o['photo_fine']:.5f}): "
              f"{verdict(v['photo_fine'] <= o['photo_fine'])}")
        print(f"  vced photo coarse <= Ostromoukhov's ({v['photo_coarse']:.5f} vs {o['photo_coarse']:.5f}): "
              f"{verdict(v['photo_coarse'] <= o['photo_coarse'])}")
        print(f"  vced x2 photo fine and coarse <= Ostromoukhov's: "
              f"{verdict(v['photo2_fine'] <= o['photo2_fine'] and v['photo2_coarse'] <= o['photo2_coarse'])}")
        print(f"  vced: no periodic structure in the tints 1-99 % (largest peak {v['tint_struct']:.0f} "
              f"at {v['struct_at']} %, limit {STRUCTURE_VISIBLE:.0f}; Ostromoukhov {o['tint_struct']:.0f} "
              f"at {o['struct_at']} %): {verdict(v['tint_struct'] < STRUCTURE_VISIBLE)}")
    for name in ("vced", "vector", "bluenoise"):
        if res.get(name):
            print(f"  {name}: tone within 0.5 % on every tint and 64-row block ({res[name]['tone']:.2f} %): "
                  f"{verdict(res[name]['tone'] <= 0.5)}")
    b, b0 = res.get("bluenoise"), res.get("bluenoise128")
    if b and b0:
        print(f"  bluenoise coarse-scale noise halved against the 128 px mask: tints "
              f"{b['tint_coarse'] / b0['tint_coarse']:.2f}x, photo {b['photo_coarse'] / b0['photo_coarse']:.2f}x: "
              f"{verdict(b['tint_coarse'] <= 0.5 * b0['tint_coarse'])}")
        levels = {name: (c, f) for name, c, f in mask_levels()}
        bound = levels.pop("bound (any threshold mask)")
        print(f"    (no threshold mask can: over all ink levels the coarse noise is at least "
              f"{bound[0]:.5f}, {bound[0] / levels['bluenoise128'][0]:.2f}x the 128 px mask's; "
              f"bluenoise is at {levels['bluenoise'][0] / bound[0]:.2f}x the bound)")
    for name in ("vector", "bluenoise"):
        if res.get(name) and res.get("vced"):
            print(f"  {name}: C/M overlap in equal light tints {res[name]['cm_overlap']:.2f} x independent "
                  f"(vced {res['vced']['cm_overlap']:.2f}, fs {res['fs']['cm_overlap']:.2f}): "
                  f"{verdict(res[name]['cm_overlap'] <= 0.5)}")
    d, v, b = res.get("dbs"), res.get("vced"), res.get("DBS")
    if d and v:
        print()
        print("targets (issue 36, part 4)")
        print(f"  dbs photo fine <= 0.0135 (the issue's figure): {d['photo_fine']:.5f}: "
              f"{verdict(d['photo_fine'] <= ISSUE36_FINE)}")
        if b:
            half = (v["photo_fine"] + b["photo_fine"]) / 2
            print(f"  dbs photo fine at least halfway from vced ({v['photo_fine']:.5f}) to DBS "
                  f"({b['photo_fine']:.5f}) as measured here, <= {half:.5f}: "
                  f"{verdict(d['photo_fine'] <= half)} "
                  f"({(v['photo_fine'] - d['photo_fine']) / (v['photo_fine'] - b['photo_fine']):.0%} of the way)")
        print(f"  dbs photo coarse no worse than vced's ({d['photo_coarse']:.5f} vs {v['photo_coarse']:.5f}): "
              f"{verdict(d['photo_coarse'] <= v['photo_coarse'])}")
        print(f"  dbs: tone within 0.5 % on every tint and 64-row block ({d['tone']:.2f} %): "
              f"{verdict(d['tone'] <= 0.5)}")
        print(f"  dbs: no periodic structure in the tints 1-99 % (largest peak {d['tint_struct']:.0f} at "
              f"{d['struct_at']} %): {verdict(d['tint_struct'] < STRUCTURE_VISIBLE)}")
    if res.get("vector") and res.get("vced"):
        print(f"  vector: mixed-tint grain below vced's ({res['vector']['mix_grain']:.5f} vs "
              f"{res['vced']['mix_grain']:.5f}): {verdict(res['vector']['mix_grain'] < res['vced']['mix_grain'])}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=("wideprint", "peers"))
    ap.add_argument("--keep", metavar="DIR", help="work in DIR and keep the peers' files")
    ap.add_argument("--quick", action="store_true", help="one photo, no enlargement (a smoke run)")
    ap.add_argument("--methods", help="only these of wideprint's methods and references (comma-separated)")
    ap.add_argument("--json", metavar="PATH", help="also write the scores as JSON (bench/results/)")
    args = ap.parse_args(argv)
    work = args.keep or tempfile.mkdtemp(prefix="quality_bench_", dir="/tmp")
    os.makedirs(work, exist_ok=True)
    try:
        t = time.perf_counter()
        pics, source = photos()
        if args.quick:
            pics = pics[:1]
        inputs = {"photos": [separate(rgb) for _, rgb in pics],
                  "photos2": [] if args.quick else [separate(enlarge(rgb)) for _, rgb in pics],
                  "tints": tint_sheet(), "mixed": mixed_sheet(), "ramp": ramp(),
                  "zone": zone_plate(), "text": text()}
        if args.quick:
            inputs["photos2"] = inputs["photos"]
        print(f"quality_bench {time.strftime('%Y-%m-%d %H:%M')}: photos: {source} "
              f"({', '.join(f'{n} {a.shape[1]}x{a.shape[0]}' for n, a in pics)}), x2 by lanczos3; "
              f"{len(TINTS)} tints; {len(CM_TINTS)} C=M and {len(MIXED)} mixed tints; ramp, zone plate, "
              f"text; inputs made in {time.perf_counter() - t:.1f} s")
        print(f"HVS: Gaussian sigma {hvs.FINE} px (fine) and {hvs.COARSE} px (coarse) across, x "
              f"{hvs.ASPECT:.4f} along the feed; RMSE against the blurred contone (bench/hvs.py)")
        print()
        methods = {}
        if args.only != "peers":
            methods.update(wideprint_methods())
        if args.methods:
            keep = args.methods.split(",")
            methods = {k: v for k, v in methods.items() if k in keep}
        if args.only != "wideprint":
            methods.update(peer_methods(work))
        results = {}
        for name, run in methods.items():
            results[name] = None if run is None else score(run, inputs)
            print(f"  scored {name} in {results[name]['seconds'] if results[name] else 0:.1f} s",
                  file=sys.stderr, flush=True)
        print_table(results)
        print()
        print("screen masks over every ink level 1..254 (RMS of the blurred error of each flat tint, "
              "rip.bluenoise.level_noise / nested_bound)")
        print(f"  {'mask':28s} {'coarse':>9s} {'fine':>9s}")
        for name, c, f in mask_levels():
            print(f"  {name:28s} {c:9.5f} {f:9.5f}")
        print_targets(results)
        if args.json:
            import json
            with open(args.json, "w") as f:
                json.dump({"date": time.strftime("%Y-%m-%d %H:%M"), "photos": source,
                           "hvs": {"fine": hvs.FINE, "coarse": hvs.COARSE, "aspect": hvs.ASPECT},
                           "results": {k: None if v is None else {n: float(x) for n, x in v.items()}
                                       for k, v in results.items()}}, f, indent=1)
                f.write("\n")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
