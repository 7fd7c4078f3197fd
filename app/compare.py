"""Compare two planes/media TIFFs dot for dot (`wideprint compare A B`, also
`python -m wideprint.app.compare`).  Exit 0 when equal."""

from __future__ import annotations

import sys

import numpy as np

from ..rip.planes import read_planes

COLORS = "CMYK"


def compare(a_path: str, b_path: str) -> tuple[bool, str]:
    a, b = read_planes(a_path), read_planes(b_path)
    if a.shape != b.shape:
        return False, f"sizes differ: {a_path} {a.shape[1]}x{a.shape[0]}, {b_path} {b.shape[1]}x{b.shape[0]}"
    diff = a != b
    n = int(diff.sum())
    if n == 0:
        drops = a.reshape(-1, 4).sum(axis=0, dtype=np.int64)
        return True, (f"identical: {a.shape[1]} x {a.shape[0]} dots, drops "
                      + " ".join(f"{c} {d}" for c, d in zip(COLORS, drops)))
    r, c, ch = np.nonzero(diff)
    doubled = int((a > 1).sum() + (b > 1).sum())
    return False, (f"{n} dots differ (first at row {r[0]}, column {c[0]}, {COLORS[ch[0]]}); "
                   f"rows {r.min()}..{r.max()}; doubled dots {doubled}")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: compare A.tif B.tif", file=sys.stderr)
        return 2
    same, text = compare(*argv)
    print(text)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
