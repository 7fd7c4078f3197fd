"""Soft proof: the job as its media will print it, with a gamut warning (docs/color.md
"Soft proof").

The proof chains the RIP's own separation with the media profile, both through LittleCMS
(libvips' icc_transform, the transform the RIP prints with):

    source (its profile) --Separator: job's intent, ink limit--> media CMYK
    media CMYK --media ICC, relative colorimetric--> Lab --> sRGB (the display)

which is what LittleCMS's proofing transform (cmsCreateProofingTransform: input -> proof
profile -> display) does, except that the proof also sees the ink limit, which clips
deep colours after the profile and is not in it.  Relative colorimetric to the display:
the paper's white is the screen's white (as Photoshop's proof without "simulate paper").

Out of gamut: a pixel whose source colour (relative colorimetric Lab from its own
profile) and its relative-colorimetric print (through the media profile and the ink limit)
differ by more than GAMUT_DE2000 ΔE2000.  Measured per pixel of the reduced image, so the
share is of the image's area.  The relative intent is used for the check whatever the
job's intent: under perceptual every colour moves a little, and only a colour the media
cannot reach is "out of gamut".  CMYK files printed as they are (no output profile) and
grey printed with K alone are device colours: nothing to be out of; documents come out of
Ghostscript already in the printer's CMYK (rip/ghostscript.py), so their gamut is not
checked either (`share` None) and the proof shows that CMYK through the media profile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rip.color import Separator, default_output_icc

#: a colour further than this (ΔE2000) from its print is out of the media's gamut; 2 is
#: about what a trained eye notices side by side, and the verify tolerance's mean (docs/media.md)
GAMUT_DE2000 = 2.0
#: the gamut warning: out-of-gamut pixels striped with this grey every other 4 pixels,
#: so the proof's colour stays visible beside the alarm (LittleCMS's alarm is a flat grey)
ALARM_RGB = (128, 128, 128)
ALARM_STRIPE = 4


@dataclass
class Proof:
    rgb: np.ndarray                    # (h, w, 3) uint8 sRGB: the job as the media prints it
    out_of_gamut: np.ndarray | None    # (h, w) bool, None when not checked
    share: float | None                # fraction of the image out of gamut, None when not checked
    media_icc: str                     # the profile the proof went through
    max_de: float | None = None        # the largest ΔE2000 source -> print

    def with_warning(self) -> np.ndarray:
        """The proof with the gamut warning painted over the out-of-gamut pixels."""
        if self.out_of_gamut is None or not self.out_of_gamut.any():
            return self.rgb
        h, w = self.out_of_gamut.shape
        yy, xx = np.mgrid[0:h, 0:w]
        stripe = ((xx + yy) // ALARM_STRIPE) % 2 == 0
        out = self.rgb.copy()
        out[self.out_of_gamut & stripe] = ALARM_RGB
        return out


def _vips_image(arr: np.ndarray, interpretation: str):
    import pyvips
    return pyvips.Image.new_from_array(np.ascontiguousarray(arr)).copy(interpretation=interpretation)


def cmyk_to_lab(ink: np.ndarray, icc: str, intent: str = "relative") -> np.ndarray:
    """(h, w, 4) uint8 ink -> (h, w, 3) float Lab (D50) through the profile (relative: the
    paper is L* 100; absolute: as an instrument measures it)."""
    img = _vips_image(ink, "cmyk").icc_import(input_profile=icc, intent=intent,
                                              embedded=False)
    return img.numpy().astype(np.float64)


def lab_to_srgb(lab: np.ndarray) -> np.ndarray:
    img = _vips_image(lab.astype(np.float32), "lab")
    return np.ascontiguousarray(img.icc_export(output_profile="srgb", intent="relative",
                                               depth=8).numpy()[..., :3]).astype(np.uint8)


def _source_lab(small: np.ndarray, sep: Separator) -> np.ndarray:
    """The source pixels' own colours as relative colorimetric Lab (their profile)."""
    prof = sep.input_profile
    assert prof is not None
    interp = {1: "b-w", 3: "srgb", 4: "cmyk"}[small.shape[2]]
    if sep.depth == 16:
        interp = {"b-w": "grey16", "srgb": "rgb16", "cmyk": "cmyk"}[interp]
    img = _vips_image(small, interp)
    if prof.data is not None:
        import pyvips
        img.set_type(pyvips.GValue.blob_type, "icc-profile-data", prof.data)
        lab = img.icc_import(intent="relative", embedded=True)
    else:
        lab = img.icc_import(input_profile=prof.path or prof.name, intent="relative",
                             embedded=False)
    return lab.numpy().astype(np.float64)


def proof_image(small: np.ndarray, colorspace: str, depth: int, *, embedded_icc=None,
                input_icc=None, output_icc=None, intent="relative", ink_limit=None) -> Proof:
    """The soft proof of a reduced, placed image (as the RIP reads it: `small` (h, w, c))."""
    from ..device_sim.spectral import delta_e2000
    media_icc = output_icc or default_output_icc("rgb")
    if media_icc is None:
        raise ValueError("soft proof: no media profile (the default media's is not installed)")
    # the RIP's own choice (rip/pipeline.py): RGB and grey without a profile named go to the
    # default media's; CMYK without one prints as it is
    kw = dict(embedded_icc=embedded_icc, input_icc=input_icc, ink_limit=ink_limit,
              output_icc=output_icc or default_output_icc(colorspace))
    sep = Separator(colorspace, depth, intent=intent, **kw)
    ink = sep.convert(np.ascontiguousarray(small))
    rgb = lab_to_srgb(cmyk_to_lab(ink, media_icc))
    if sep.input_profile is None or (colorspace == "cmyk" and output_icc is None):
        return Proof(rgb, None, None, media_icc)          # device colours: nothing to check
    rel = ink if intent == "relative" else \
        Separator(colorspace, depth, intent="relative", **kw).convert(np.ascontiguousarray(small))
    de = delta_e2000(_source_lab(small, sep), cmyk_to_lab(rel, media_icc))
    mask = de > GAMUT_DE2000
    return Proof(rgb, mask, float(mask.mean()), media_icc, float(de.max()))


def proof_cmyk(ink: np.ndarray, media_icc: str | None = None) -> Proof:
    """The proof of CMYK ink already on the device grid (a document Ghostscript rendered)."""
    media_icc = media_icc or default_output_icc("rgb")
    if media_icc is None:
        raise ValueError("soft proof: no media profile (the default media's is not installed)")
    return Proof(lab_to_srgb(cmyk_to_lab(ink, media_icc)), None, None, media_icc)


def write_proof(proof: Proof, png: str) -> None:
    """The proof with its gamut warning as a PNG (libvips)."""
    _vips_image(proof.with_warning(), "srgb").pngsave(png)


def png_bytes(proof: Proof) -> bytes:
    """The proof with its gamut warning as PNG bytes (for the server's clients)."""
    return _vips_image(proof.with_warning(), "srgb").pngsave_buffer()
