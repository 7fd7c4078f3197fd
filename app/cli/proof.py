"""`--preview PNG --proof` of `print` and `rip`: the soft proof (app/softproof.py)."""

from __future__ import annotations

import sys

from .common import NAME_LIMIT, shown


def _proof(f: str, png: str, settings, profile, rep: dict, say) -> bool:
    """`--preview PNG --proof`: the soft proof of file `f` through its media profile with
    the gamut warning (app/softproof.py), and its out-of-gamut share in the report."""
    from ...rip.load import ImageError
    from ..jobpreview import proof_job
    from ..softproof import GAMUT_DE2000, write_proof
    try:
        proof = proof_job(f, settings, profile)
        write_proof(proof, png)
    except (ImageError, ValueError, OSError) as exc:
        why = f"{exc.strerror} ({png})" if isinstance(exc, OSError) and exc.strerror \
            else str(exc)
        rep["preview_error"] = why
        print(f"{shown(f, NAME_LIMIT)}: proof not written: {shown(why)}", file=sys.stderr)
        return False
    rep.update(preview=png, proof_icc=proof.media_icc, out_of_gamut=proof.share)
    gamut = "not checked (device colours)" if proof.share is None else \
        f"{100 * proof.share:.1f} % of the image out of gamut (ΔE2000 > {GAMUT_DE2000:g})"
    print(f"{shown(f, NAME_LIMIT)}: proof {shown(png)} through {shown(proof.media_icc)}: {gamut}",
          file=say)
    return True
