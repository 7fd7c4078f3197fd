"""The crash soak in the suite (bench/crash_soak.py, issue 31): two printers that outlive
the server, three clients submitting at once, the server killed with SIGKILL every few
seconds and now and then a printer switched off and on while it is down; every job ends
done exactly once, its media equal to its planes, each copy accounted done once."""

import json
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "bench" / "crash_soak.py"


def test_crash_soak_two_printers_three_clients_random_kills(tmp_path):
    out = tmp_path / "soak.json"
    r = subprocess.run([sys.executable, str(BENCH), "--seconds", "25", "--clients", "3",
                        "--jobs", "3", "--seed", "7", "--json", str(out)],
                       capture_output=True, text=True, timeout=600)
    res = json.loads(out.read_text()) if out.exists() else {}
    assert r.returncode == 0 and res.get("ok"), r.stdout[-4000:] + r.stderr[-4000:]
    assert res["kills"] >= 3 and res["jobs"] == 9 and res["done"] == 9
