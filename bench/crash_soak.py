#!/usr/bin/env python3
"""The crash soak (issue 31, docs/server.md "Crash recovery"): a print server with two
printers (standalone emulators that outlive it), several clients submitting at once, the
server killed with SIGKILL at random moments and, now and then, a printer switched off
and on while the server is down; an operator releases the jobs held because a printer
could not confirm its sheet.  At the end every job must be done exactly once, its media
equal to its planes, each copy accounted done once.

    python bench/crash_soak.py [--seconds 120] [--clients 3] [--jobs N] [--seed 1]
                               [--json OUT.json] [--keep DIR]

Exit 0 when every check held.  Results kept as data: bench/results/crash_soak.json.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

PY = sys.executable


def _line(proc, timeout):
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    if not ready:
        proc.kill()
        raise RuntimeError("no output from " + " ".join(proc.args) + "\n" + proc.stderr.read())
    return proc.stdout.readline()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Emulator:
    """A standalone emulator on fixed ports: switched off and on under the same spec."""

    def __init__(self, folder: Path):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.ports = (_free_port(), _free_port())
        self.proc = None
        self.boots = 0

    def start(self) -> str:
        self.boots += 1
        self.proc = subprocess.Popen(
            [PY, "-m", "wideprint.app.cli", "emulator", "--serial-port", str(self.ports[0]),
             "--data-port", str(self.ports[1]), "--media-out", str(self.folder / "media-{job}.tif"),
             "--event-log", str(self.folder / f"events-{self.boots}.jsonl")],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        line = _line(self.proc, 60)
        if not line.startswith("device: "):
            raise RuntimeError(f"emulator did not start: {line}")
        return line.split(" ", 1)[1].strip()

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(30)


class Soak:
    def __init__(self, work: Path, seconds: float, clients: int, jobs: int, seed: int):
        self.work, self.seconds, self.n_clients, self.n_jobs = work, seconds, clients, jobs
        self.rng = random.Random(seed)
        self.seed = seed
        self.state = work / "state"
        self.emus = {"left": Emulator(work / "left"), "right": Emulator(work / "right")}
        self.specs = {name: e.start() for name, e in self.emus.items()}
        self.server = None
        self.lock = threading.Lock()
        self.submitted: dict[str, dict] = {}          # key -> {planes, copies, job}
        self.stats = dict(kills=0, power_cycles=0, releases=0, submit_retries=0)
        self.stop = threading.Event()
        self.killing_done = threading.Event()

    # -- the server ----------------------------------------------------------------------
    def start_server(self):
        args = [PY, "-m", "wideprint.app.cli", "serve", "--state-dir", str(self.state),
                "--port", "0"]
        for name, spec in self.specs.items():
            args += ["--printer", f"{name}={spec}"]
        self.n_starts = getattr(self, "n_starts", 0) + 1
        log = open(self.work / f"server-{self.n_starts}.log", "w")
        self.server = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=log, text=True)
        line = _line(self.server, 60)
        if not line.startswith("wideprint serve: http"):
            raise RuntimeError(line)
        # drain its output so a chatty server never blocks on a full pipe
        threading.Thread(target=self.server.communicate, daemon=True).start()

    def kill_server(self):
        self.server.send_signal(signal.SIGKILL)
        self.server.wait(30)
        self.stats["kills"] += 1

    def client(self):
        from wideprint.app.client import Client
        return Client(self.state)

    # -- clients, operator, killer ---------------------------------------------------------
    def submit_jobs(self, index: int):
        from wideprint.app.client import ApiError
        sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
        from support.images import random_planes, write_cmyk_tiff
        rng = random.Random(self.seed * 1000 + index)
        folder = self.work / f"client-{index}"
        folder.mkdir()
        for k in range(self.n_jobs):
            if self.stop.is_set() or self.killing_done.is_set():
                return                            # submissions go on while the kills do
            planes = random_planes(rng.randrange(200, 700), rng.randrange(80, 260),
                                   seed=rng.randrange(1 << 30))
            src = write_cmyk_tiff(folder / f"job-{k}.tif", planes)
            key = f"soak-{index}-{k}"
            copies = rng.choice((1, 1, 2))
            settings = {"passes": rng.choice((1, 2, 4)), "bidir": rng.random() < 0.5}
            with self.lock:
                self.submitted[key] = dict(planes=planes, copies=copies, job=None)
            while not self.stop.is_set():
                try:
                    job = self.client().submit(src, copies=copies, settings=settings, key=key)["job"]
                    with self.lock:
                        self.submitted[key]["job"] = job["id"]
                    break
                except (ApiError, OSError):
                    self.stats["submit_retries"] += 1      # the server is down: the same key again
                    time.sleep(0.3)
            time.sleep(rng.uniform(0.2, 1.5))

    def operator(self):
        """Releases jobs held because a printer could not confirm its sheet (in a shop: the
        operator looked at the sheet, cut it off)."""
        from wideprint.app.client import ApiError
        while not self.stop.is_set():
            try:
                c = self.client()
                for j in c.jobs("held"):
                    if "strokes are on the sheet" in j["message"]:
                        c.action(j["id"], "release")
                        self.stats["releases"] += 1
            except (ApiError, OSError):
                pass
            time.sleep(0.5)

    def printing(self) -> list[str]:
        """The printers printing now (a power cycle there leaves a sheet half printed)."""
        try:
            return sorted(p["name"] for p in self.client().printers() if p["state"] == "printing")
        except Exception:  # noqa: BLE001 - the server may be starting
            return []

    def killer(self, until: float):
        while time.monotonic() < until:
            time.sleep(self.rng.uniform(2.0, 5.0))
            busy = self.printing()
            self.kill_server()
            if self.rng.random() < 0.25:                  # a printer switched off and on
                name = self.rng.choice(busy or sorted(self.emus))
                self.emus[name].kill()
                self.emus[name].start()
                self.stats["power_cycles"] += 1
            self.start_server()

    # -- the run ---------------------------------------------------------------------------
    def run(self) -> dict:
        from wideprint.app.client import ApiError
        from wideprint.rip.planes import read_planes
        t0 = time.monotonic()
        self.start_server()
        crashed: list[str] = []          # a client that died submits nothing: never "ok"

        def client(i: int) -> None:
            try:
                self.submit_jobs(i)
            except BaseException as exc:  # noqa: BLE001 - reported as a problem
                crashed.append(f"client {i} died: {type(exc).__name__}: {exc}")
                raise
        threads = [threading.Thread(target=client, args=(i,)) for i in range(self.n_clients)]
        threads.append(threading.Thread(target=self.operator, daemon=True))
        for t in threads:
            t.start()
        self.killer(t0 + self.seconds)
        self.killing_done.set()
        for t in threads[:-1]:
            t.join()
        # the end: no more kills; every job must finish
        deadline = time.monotonic() + 300
        jobs = []
        while time.monotonic() < deadline:
            try:
                jobs = self.client().request("GET", "/v1/jobs")["jobs"]
            except (ApiError, OSError):
                time.sleep(0.5)
                continue
            if jobs and all(j["state"] in ("done", "failed", "cancelled") for j in jobs):
                break
            time.sleep(0.5)
        self.stop.set()
        report = self.client().report()
        self.server.send_signal(signal.SIGTERM)
        self.server.wait(60)
        for e in self.emus.values():
            e.kill()
        # the checks
        problems = []
        by_id = {j["id"]: j for j in jobs}
        keys = {v["job"]: k for k, v in self.submitted.items() if v["job"] is not None}
        if len(by_id) != len(keys) or set(by_id) != set(keys):
            problems.append(f"jobs {sorted(by_id)} but submitted {sorted(keys)}")
        for jid, j in by_id.items():
            sub = self.submitted.get(keys.get(jid), {})
            if j["state"] != "done":
                problems.append(f"job {jid} {j['state']}: {j['message']}")
                continue
            media = self.work / j["printed_on"] / f"media-{jid}.tif"
            if not media.exists() or not np.array_equal(read_planes(media), sub["planes"]):
                problems.append(f"job {jid} done but its media differs from its planes")
            done_rows = sorted(r["copy"] for r in report if r["job_id"] == jid and r["outcome"] == "done")
            if done_rows != list(range(1, sub["copies"] + 1)):
                problems.append(f"job {jid}: done rows for copies {done_rows}, {sub['copies']} copies")
        problems.extend(crashed)
        if not by_id:
            problems.append("no job was submitted")
        outcomes: dict[str, int] = {}
        for r in report:
            outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
        return dict(seconds=round(time.monotonic() - t0, 1), seed=self.seed, clients=self.n_clients,
                    jobs=len(by_id), done=sum(j["state"] == "done" for j in jobs),
                    resumed_copies=sum(1 for r in report if r["resumed"] and r["outcome"] == "done"),
                    accounting=outcomes, **self.stats, problems=problems, ok=not problems)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=120)
    ap.add_argument("--clients", type=int, default=3)
    ap.add_argument("--jobs", type=int, default=1000,
                    help="at most this many jobs per client (each submits until the kills end)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", metavar="OUT.json")
    ap.add_argument("--keep", metavar="DIR", help="work in DIR and keep it (logs, media)")
    args = ap.parse_args(argv)
    if args.keep:
        Path(args.keep).mkdir(parents=True, exist_ok=False)
        res = Soak(Path(args.keep), args.seconds, args.clients, args.jobs, args.seed).run()
    else:
        with tempfile.TemporaryDirectory(prefix="wideprint-soak-") as work:
            res = Soak(Path(work), args.seconds, args.clients, args.jobs, args.seed).run()
    res["when"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    text = json.dumps(res, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return 0 if res["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
