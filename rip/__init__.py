"""The RIP.  Importing it installs one start-up saving (below); nothing else."""

import sys


class _NoScipyForNumbasBlasProbe:
    """numba's first compile or cache load imports `numba.np.arraymath`, which probes for
    BLAS by importing scipy.linalg (and through it numpy.f2py): ~0.25 s of every
    wideprint process's start-up, for `np.dot` inside kernels, which wideprint's kernels do
    not use.  This finder refuses scipy.linalg to that probe alone (the probe then records "no
    BLAS"); any other import of it, before or after, works as usual, and a kernel that
    does call `np.dot` still compiles (numba imports SciPy again when it does)."""

    def find_spec(self, name, path=None, target=None):
        if not name.startswith("scipy.linalg") or "scipy.linalg" in sys.modules:
            return None
        frame, depth = sys._getframe(1), 0
        while frame is not None and depth < 40:
            if frame.f_code.co_name == "_check_blas" and \
                    frame.f_globals.get("__name__") == "numba.np.arraymath":
                raise ImportError("scipy.linalg is not loaded for numba's BLAS probe (wideprint/rip/__init__.py)")
            frame, depth = frame.f_back, depth + 1
        return None


if not any(isinstance(f, _NoScipyForNumbasBlasProbe) for f in sys.meta_path):
    sys.meta_path.insert(0, _NoScipyForNumbasBlasProbe())
