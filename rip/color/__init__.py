"""Colour separation: image bands -> CMYK ink amounts (docs/color.md), in four modules:

* separator.py: `Separator`, which turns a file's bands into C, M, Y, K ink;
* kernels.py: the numba kernels it runs (the 3-D LUT, the grey table, ink limit, curves);
* icc.py: ICC profiles through LittleCMS (libvips), checked and tried when named;
* lutcache.py: the 3-D LUTs kept between processes.
"""

from __future__ import annotations

from .icc import DEFAULT_OUTPUT_ICC, default_output_icc
from .kernels import apply_ink_limit, ink_limit_level
from .separator import INTENTS, Separator

__all__ = ["Separator", "INTENTS", "ink_limit_level", "apply_ink_limit", "DEFAULT_OUTPUT_ICC",
           "default_output_icc"]
