"""The RIP's threads (rip/parallel.py, docs/rip.md "Threads"): whole `wideprint rip` commands
with 1 worker and with every core this process may use, per halftone method, wall and CPU
seconds and peak RSS (bench/rip_bench.py's launcher: the command's own rusage), the planes
compared byte for byte between the counts.  Results to bench/results/threads.json.

    .venv/bin/python bench/threads_bench.py                  # ~2 min on 2 cores
    .venv/bin/python bench/threads_bench.py --threads 1,2,4,8 --repeat 7

Counts above the cores are run when asked but say nothing about scaling: a 2-core machine
cannot measure 4 or 8 workers (the JSON records the cores each figure had).  What the JSON
gives for more cores than the machine has is extrapolated, and says so: Amdahl's law from
the parallel share that 1 against N workers measured (`extrapolated`).

On a machine shared with other work, `--nice 10` runs the commands at a higher priority
(needs root or CAP_SYS_NICE) so that they get the cores they ask for; each figure also
records how many cores the command kept busy (CPU over wall seconds)."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from rip_bench import TestImage, cli_env, cpu_model, run_measured, wideprint_cmd, write_tiff  # noqa: E402

METHODS = ("fs", "vced", "bayer", "bluenoise")


def cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def raise_priority(n: int) -> None:
    """Run this bench and its commands `n` steps of niceness ahead of other work.  Where the
    kernel groups processes by session (autogroup, /proc/sys/kernel/sched_autogroup_enabled),
    a process's niceness only ranks it within its session's group, and the groups share the
    cores equally: so the bench starts a session of its own and raises that group too."""
    auto = Path("/proc/self/autogroup")
    if auto.exists():
        try:
            os.setsid()
        except OSError:
            pass                                # already a session leader
        auto.write_text(f"{-n}\n")
    os.nice(-n)                                 # inherited by every command run below


def extrapolate(results: list[dict], machine_cores: int, to=(4, 8, 16)) -> dict:
    """Per method, Amdahl's law from the measured 1-worker and the most-workers (at most the
    machine's cores) medians: the parallel share p = (1 - T_N / T_1) / (1 - 1 / N) and the
    speed-up it predicts for `to` workers, 1 / ((1 - p) + p / n).  An estimate, not a
    measurement: more cores also bring more memory bandwidth contention, and the stages that
    run one band after another (error diffusion) stay on one core."""
    out = {}
    for method in sorted({r["method"] for r in results}):
        rows = {r["threads"]: r for r in results if r["method"] == method}
        n = max((t for t in rows if 1 < t <= machine_cores), default=None)
        if 1 not in rows or n is None:
            continue
        t1, tn = rows[1]["wall_s_median"], rows[n]["wall_s_median"]
        p = max(0.0, min(1.0, (1 - tn / t1) / (1 - 1 / n)))
        out[method] = dict(measured_workers=n, measured_speedup=round(t1 / tn, 3),
                           parallel_share=round(p, 3),
                           speedup={str(k): round(1 / ((1 - p) + p / k), 2) for k in to})
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width", type=int, default=6000)
    ap.add_argument("--height", type=int, default=3000)
    ap.add_argument("--threads", default=f"1,{cores()}", help="counts to run (default: 1 and the cores)")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--repeat", type=int, default=5, help="runs per count and method, interleaved")
    ap.add_argument("--out", default=str(HERE / "results" / "threads.json"))
    ap.add_argument("--nice", type=int, default=0,
                    help="raise the commands' priority by N (os.nice(-N)) on a shared machine")
    args = ap.parse_args()
    if args.nice:
        try:
            raise_priority(args.nice)
        except PermissionError:
            print(f"--nice {args.nice}: not permitted (root or CAP_SYS_NICE)", file=sys.stderr)
            return 2
    counts = [int(n) for n in args.threads.split(",")]
    methods = args.methods.split(",")
    env = cli_env()
    env.pop("WIDEPRINT_THREADS", None)
    results = []
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="wideprint-threads-") as d:
        tif = os.path.join(d, "photo.tif")
        write_tiff(tif, TestImage(args.width, args.height, seed=3))
        mpx = args.width * args.height / 1e6
        for method in methods:
            runs: dict[int, list] = {n: [] for n in counts}
            digests: dict[int, str] = {}
            for rep in range(args.repeat):
                for n in (counts if rep % 2 == 0 else counts[::-1]):   # interleaved, alternating
                    out = os.path.join(d, f"planes-{n}.tif")
                    r = run_measured(wideprint_cmd("rip", tif, "-o", out, "--dither", method,
                                                   "--size", "pixels", "--planes-format", "packed",
                                                   "--threads", str(n)), env=env)
                    if not r.ok:
                        print(r.err, file=sys.stderr)
                        return 1
                    runs[n].append(r)
                    if rep == 0:
                        with open(out, "rb") as f:
                            import tifffile
                            digests[n] = hashlib.sha256(tifffile.imread(f).tobytes()).hexdigest()
            same = len(set(digests.values())) == 1
            base = statistics.median(r.wall for r in runs[counts[0]])
            for n in counts:
                walls = [r.wall for r in runs[n]]
                row = dict(method=method, threads=n, cores=cores(), over_cores=n > cores(),
                           wall_s_median=round(statistics.median(walls), 3),
                           wall_s_min=round(min(walls), 3),
                           walls_s=[round(w, 3) for w in walls],
                           cpu_s_median=round(statistics.median(r.cpu for r in runs[n]), 3),
                           cores_busy_median=round(statistics.median(r.cpu / r.wall
                                                                     for r in runs[n]), 2),
                           rss_mb_max=round(max(r.rss_mb for r in runs[n]), 1),
                           mpx_per_s=round(mpx / statistics.median(walls), 1),
                           speedup_vs_first=round(base / statistics.median(walls), 3),
                           planes_identical=same)
                results.append(row)
                print(f"{method:10} threads {n:2}  wall {row['wall_s_median']:6.2f} s (min "
                      f"{row['wall_s_min']:.2f})  cpu {row['cpu_s_median']:6.2f} s  "
                      f"{row['mpx_per_s']:6.1f} Mpx/s  x{row['speedup_vs_first']:.2f}  "
                      f"cores busy {row['cores_busy_median']:.2f}  "
                      f"RSS {row['rss_mb_max']:.0f} MB  planes {'identical' if same else 'DIFFER'}",
                      flush=True)
            if not same:
                print(f"{method}: the planes differ between thread counts", file=sys.stderr)
    doc = dict(bench="threads_bench.py", date=time.strftime("%Y-%m-%d %H:%M"),
               nice=-args.nice, extrapolated=extrapolate(results, cores()),
               machine=dict(cpu=cpu_model(), cores=cores(), cpu_count=os.cpu_count(),
                            python=platform.python_version()),
               image=dict(width=args.width, height=args.height, kind="RGB TIFF, --size pixels",
                          planes_format="packed"),
               command="wideprint rip IMG -o PLANES --dither M --size pixels --planes-format packed --threads N",
               repeat=args.repeat, note=("medians of interleaved runs; counts above `cores` "
                                          "cannot show scaling on this machine; a load average "
                                          "above 0 means other work shared the cores"),
               loadavg_before=[round(v, 2) for v in load_before],
               loadavg_after=[round(v, 2) for v in os.getloadavg()],
               results=results)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"-> {args.out}")
    return 0 if all(r["planes_identical"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
