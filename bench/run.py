"""Runs every benchmark in bench/ in turn (make bench).  Each prints its own figures and,
where there is a peer or a target, the ratio."""

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCRIPTS = ["halftone_bench.py", "rip_bench.py", "quality_bench.py", "emulator_bench.py", "print_bench.py", "flow_bench.py",
           "pdf_bench.py", "layout_bench.py"]

if __name__ == "__main__":
    failed = 0
    for name in SCRIPTS:
        script = HERE / name
        if not script.exists():
            continue
        print(f"\n=== {name} ===", flush=True)
        failed |= subprocess.call([sys.executable, str(script)])
    sys.exit(1 if failed else 0)
