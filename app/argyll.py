"""ArgyllCMS as separate programs (docs/media.md "ArgyllCMS").

ArgyllCMS is AGPL: wideprint never imports or copies its code.  It runs Debian's `argyll`
programs (targen, colprof, profcheck, xicclu) as processes and exchanges CGATS files
with them (.ti1 device values, .ti3 device values with their measurements).  This module
finds the programs, runs them with a clear error when they are missing or fail, and
reads the CGATS tables they write.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REF_DIR = Path("/usr/share/color/argyll/ref")      # Debian's argyll-ref
INSTALL_HINT = ("ArgyllCMS is needed for this (Debian: `apt-get install argyll argyll-ref`; "
                "the project's list: resources/debian-packages.txt)")


class ArgyllError(RuntimeError):
    """An Argyll program is missing or failed (the message says which and why)."""


def tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise ArgyllError(f"ArgyllCMS's `{name}` was not found on PATH. {INSTALL_HINT}")
    return path


def run(name: str, *args: str, cwd: str | Path | None = None, timeout: float = 1800) -> str:
    """Run an Argyll program; its standard output, or ArgyllError with its message."""
    cmd = [tool(name), *map(str, args)]
    try:
        done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise ArgyllError(f"{name} took more than {timeout:g} s") from None
    if done.returncode != 0:
        msg = (done.stderr or done.stdout).strip().splitlines()
        raise ArgyllError(f"{name} failed (exit {done.returncode}): "
                          f"{' / '.join(msg[-3:]) or 'no message'}")
    return done.stdout


@dataclass
class Cgats:
    """One CGATS table: its keywords and its data as columns of strings."""
    kind: str
    keywords: dict[str, str]
    fields: list[str]
    rows: list[list[str]]

    def column(self, name: str) -> np.ndarray:
        i = self.fields.index(name)
        return np.array([float(r[i]) for r in self.rows])

    def columns(self, *names: str) -> np.ndarray:
        return np.stack([self.column(n) for n in names], axis=-1)

    @property
    def cmyk(self) -> np.ndarray:
        """Device values (n, 4) in percent."""
        return self.columns("CMYK_C", "CMYK_M", "CMYK_Y", "CMYK_K")


def read_cgats(path: str | Path) -> Cgats:
    """The first table of a CGATS file (.ti1, .ti2, .ti3)."""
    lines = Path(path).read_text(errors="replace").splitlines()
    kind = lines[0].split()[0] if lines and lines[0].split() else ""
    keywords: dict[str, str] = {}
    fields: list[str] = []
    rows: list[list[str]] = []
    state = "head"
    for line in lines[1:]:
        s = line.strip()
        if state == "head":
            if s == "BEGIN_DATA_FORMAT":
                state = "format"
            elif s and not s.startswith("#"):
                m = re.match(r'(\S+)\s+"?(.*?)"?$', s)
                if m:
                    keywords[m.group(1)] = m.group(2)
        elif state == "format":
            if s == "END_DATA_FORMAT":
                state = "between"
            else:
                fields += s.split()
        elif state == "between":
            if s == "BEGIN_DATA":
                state = "data"
        elif state == "data":
            if s == "END_DATA":
                break
            if s:
                rows.append(s.split())
    if not fields:
        raise ArgyllError(f"{path}: not a CGATS table (no data format)")
    return Cgats(kind, keywords, fields, rows)


def targen(out_stem: Path, patches: int, ink_limit: float) -> Cgats:
    """A CMYK print chart of about `patches` patches within the total ink limit
    (targen -d4: a printer; optimised farthest point sampling spread)."""
    args = ["-d4", f"-l{ink_limit:g}", f"-f{patches}"]
    run("targen", *args, out_stem.name, cwd=out_stem.parent)
    return read_cgats(out_stem.with_suffix(".ti1"))


def colprof(stem: Path, ink_limit: float, quality: str = "m", description: str = "") -> Path:
    """An output profile from STEM.ti3 -> STEM.icc (relative colorimetric A2B and B2A)."""
    args = ["-v", f"-q{quality}", f"-l{ink_limit:g}"]
    if description:
        args += ["-D", description]
    run("colprof", *args, stem.name, cwd=stem.parent)
    return stem.with_suffix(".icc")


def profcheck(ti3: Path, icc: Path) -> dict:
    """How well the profile predicts measurements: ΔE2000 mean, RMS and max
    (profcheck -k: CIEDE2000), as profcheck reports them."""
    out = run("profcheck", "-k", str(ti3), str(icc))
    m = re.search(r"max\.\s*=\s*([\d.]+),\s*avg\.\s*=\s*([\d.]+)(?:,\s*RMS\s*=\s*([\d.]+))?", out)
    if not m:
        raise ArgyllError(f"profcheck: cannot read its result: {out.strip()[-200:]}")
    return {"max": float(m.group(1)), "mean": float(m.group(2)),
            "rms": float(m.group(3) or "nan")}
