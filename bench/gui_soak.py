"""GUI soak (issue 34, "a GUI that runs all day"): the real main window against a real
`wideprint serve` with two emulated printers printing continuously for N minutes, while the
window is used as an operator would, and its references to True/False/None and its RSS are
watched.

    .venv/bin/python bench/gui_soak.py [--minutes 30] [--replay-hz 50] [--out bench/results/gui_soak.json]

- The parent starts the server (`--printer left=emulator --printer right=emulator`), keeps
  each printer fed (two jobs waiting per printer, small CMYK TIFFs of four sizes, one to
  three copies), and runs the GUI in a child process, so that a GUI that dies (a Python
  fatal error, a segfault) is recorded as a crash with its output rather than taking the
  measurement with it.
- The child is the real MainWindow (offscreen unless a DISPLAY is set) found by
  find_or_start, as `wideprint gui` does.  Every 3 s an operator action through the
  window's own actions (hold, release, priority up, the history and a job's accounting,
  pause and resume a printer, a wheel turn over the settings form, head care spit);
  **accelerated**: on top of the server's live events, the last printers and jobs are
  re-emitted on the window's ServerLink signals `--replay-hz` times a second (the path on
  which PySide6 6.12.0 on Python 3.11 lost a reference to True/None per emission and
  aborted after ~8 min of a busy shop).
- Every 5 s the child samples sys.getrefcount(True/False/None), its RSS, the live Python
  objects, the signals delivered; the parent adds the server's RSS and the jobs done.

The result: bench/results/gui_soak.json (the samples and a summary: drift of each
refcount from the first sample, the RSS at start, end and its growth over the second half,
the jobs printed, how the GUI ended).  Nothing is asserted here; tests/test_gui_soak.py runs
a 36 s version and asserts on the summary.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "wideprint.app.cli"]
SAMPLE_S = 5.0
ACTION_S = 3.0


def rss_mb(pid: int | str = "self") -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


# ------------------------------------------------------------------------------------------
# the child: the real window
def child(state: Path, cfg: Path, samples: Path, seconds: float, replay_hz: float) -> int:
    import gc

    from PySide6.QtCore import QPoint, QPointF, Qt, QTimer
    from PySide6.QtGui import QWheelEvent
    from PySide6.QtWidgets import QApplication

    from wideprint.app.gui.main_window import MainWindow
    from wideprint.app.gui.server_link import ServerLink, find_or_start

    app = QApplication.instance() or QApplication(["wideprint-soak"])
    client, proc = find_or_start(state)
    assert proc is None, "the soak's server, not a new one"
    w = MainWindow(ServerLink(state, client), config_dir=cfg)
    w.ask_before_closing = False
    w.resize(1366, 768)
    w.show()
    n = dict(printers=0, jobs=0, replayed=0, actions=0)
    w.link.printersChanged.connect(lambda _v: n.__setitem__("printers", n["printers"] + 1))
    w.link.jobsChanged.connect(lambda _v: n.__setitem__("jobs", n["jobs"] + 1))
    out = open(samples, "a", buffering=1)
    t0 = time.monotonic()
    kinds0: list = []

    def kinds():
        from collections import Counter
        return Counter(type(o).__name__ for o in gc.get_objects())

    def sample():
        gc.collect()
        if not kinds0:
            kinds0.append(kinds())
            kinds0.append({id(o) for o in gc.get_objects() if type(o) is dict})
        out.write(json.dumps(dict(
            t=round(time.monotonic() - t0, 1), true=sys.getrefcount(True),
            false=sys.getrefcount(False), none=sys.getrefcount(None), rss_mb=rss_mb(),
            objects=len(gc.get_objects()), printer_events=n["printers"], job_events=n["jobs"],
            replayed=n["replayed"], actions=n["actions"], queue=len(w.active),
            history=len(w.history))) + "\n")

    def replay():
        if w.printers:
            w.link.printersChanged.emit(list(w.printers))
            n["replayed"] += 1
        if w.active:
            w.link.jobsChanged.emit(list(w.active))
            n["replayed"] += 1

    rng = random.Random(34)
    step = [0]

    def wheel_over(widget):
        pos = QPointF(widget.width() / 2, widget.height() / 2)
        ev = QWheelEvent(pos, QPointF(widget.mapToGlobal(pos.toPoint())), QPoint(0, 0),
                         QPoint(0, -120), Qt.NoButton, Qt.NoModifier, Qt.NoScrollPhase, False)
        QApplication.sendEvent(widget, ev)

    def act():
        """One operator action, in turn; nothing destructive (no box to answer)."""
        k = step[0] % 8
        step[0] += 1
        n["actions"] += 1
        w.tabs.setCurrentIndex(0)
        waiting = [j for j in w.active if j["state"] in ("queued", "held")]
        if k == 0 and waiting:
            w.queue_view.select_ids([rng.choice(waiting)["id"]])
            w._update_actions()
            w.actions_["hold"].trigger()
        elif k == 1:
            held = [j["id"] for j in w.active if j["state"] == "held" and not j.get("fault")]
            if held:
                w.queue_view.select_ids(held)
                w._update_actions()
                w.actions_["release"].trigger()
        elif k == 2 and waiting:
            w.queue_view.select_ids([rng.choice(waiting)["id"]])
            w._update_actions()
            w.actions_["up"].trigger()
        elif k == 3 and w.history:
            w.tabs.setCurrentIndex(1)
            w.history_view.select_ids([w.history[0]["id"]])
            w._show_selection()
        elif k == 4:
            w.printer_action("left", "pause", None)
        elif k == 5:
            w.printer_action("left", "resume", None)
        elif k == 6:
            wheel_over(w.form.fields["placement.size"].w)
            wheel_over(w.form.fields["dpi"].w)
        elif k == 7:
            w.queue_view.clearSelection()
            card = w.printers_panel.cards.get("right")
            if card is not None and card.care.isEnabled():
                w.printer_action("right", "head-care", {"action": "spit"})
        # the held/paused ones are released/resumed a few steps on: the printers keep printing

    timers = []
    for interval, fn in ((SAMPLE_S, sample), (ACTION_S, act),
                         (1.0 / replay_hz if replay_hz > 0 else 0, replay)):
        if interval <= 0:
            continue
        t = QTimer()
        t.setInterval(int(interval * 1000))
        t.timeout.connect(fn)
        t.start()
        timers.append(t)
    QTimer.singleShot(1500, sample)           # the first sample once the window is up
    QTimer.singleShot(int(seconds * 1000), app.quit)
    app.exec()
    for t in timers:
        t.stop()
    sample()
    grown = kinds()
    grown.subtract(kinds0[0] if kinds0 else {})
    from collections import Counter
    old = kinds0[1] if len(kinds0) > 1 else set()
    new_dicts = Counter(",".join(sorted(map(str, o))[:8]) for o in gc.get_objects()
                        if type(o) is dict and id(o) not in old)
    out.write(json.dumps(dict(objects_grown_by_type=dict(grown.most_common(12)),
                              new_dicts_by_keys=dict(new_dicts.most_common(8)))) + "\n")
    w.printer_action("left", "resume", None)
    w.close()
    out.close()
    return 0


# ------------------------------------------------------------------------------------------
# the parent: server, jobs, the child, the summary
def make_images(folder: Path) -> list[Path]:
    import numpy as np
    import tifffile
    rng = np.random.default_rng(34)
    out = []
    for i, (rows, cols) in enumerate(((240, 400), (400, 600), (160, 900), (600, 300))):
        planes = ((rng.random((rows, cols, 4)) < 0.25) * 255).astype(np.uint8)
        p = folder / f"soak-{i}-{cols}x{rows}.tif"
        tifffile.imwrite(p, planes, photometric="separated", resolution=(300.0, 25400 / 68.55),
                         resolutionunit="INCH")
        out.append(p)
    return out


def feed(feeder, images: list[Path], rng: random.Random) -> list[dict]:
    """Keep three jobs waiting on each of the two printers, as a busy shop does: each new one
    a random image, 1-3 copies, 1, 2 or 4 passes.  The server's answers to the submits."""
    jobs = feeder.jobs()
    answers = []
    for printer in ("left", "right"):
        waiting = [j for j in jobs if j.get("printer") == printer
                   and j["state"] in ("queued", "held", "printing")]
        if len(waiting) < 3:
            answers.append(feeder.submit(rng.choice(images), printer=printer,
                                         copies=rng.randint(1, 3),
                                         settings={"passes": rng.choice([1, 2, 4])}))
    return answers


def start_server(root: Path):
    from wideprint.app.client import Client
    state = root / "state"
    log = open(root / "server.out", "ab")
    proc = subprocess.Popen(CLI + ["serve", "--state-dir", str(state), "--media-dir", str(root / "media"),
                                   "--hot-folder-root", str(root / "hot"), "--port", "0",
                                   "--keep-failed", "0",
                                   "--printer", "left=emulator", "--printer", "right=emulator"],
                            stdout=log, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            c = Client(state)
            c.status()
            return proc, c, state
        except Exception:  # noqa: BLE001 - not up yet
            if proc.poll() is not None:
                raise SystemExit((root / "server.out").read_text()) from None
            time.sleep(0.2)
    raise SystemExit("the server did not start")


def summarize(samples: list[dict], server_rss: list[float], child_rc: int, child_err: str,
              jobs: dict, minutes: float, replay_hz: float) -> dict:
    s0, s1 = (samples[0], samples[-1]) if samples else ({}, {})
    half = [s for s in samples if s["t"] >= (s1.get("t", 0) / 2)] if samples else []

    def drift(k):
        if not samples:
            return None
        return dict(first=s0[k], last=s1[k], drift=s1[k] - s0[k],
                    max_abs=max(abs(s[k] - s0[k]) for s in samples))
    rss = [s["rss_mb"] for s in samples if s.get("rss_mb")]
    return dict(
        minutes=minutes, replay_hz=replay_hz, python=platform.python_version(),
        pyside6=_pyside_version(), gui_exit=child_rc, crashed=child_rc != 0,
        gui_stderr_tail=child_err[-1500:] if child_rc != 0 else "",
        seconds=s1.get("t"), samples=len(samples),
        refcount=dict(true=drift("true"), false=drift("false"), none=drift("none")),
        gui_rss_mb=dict(first=rss[0] if rss else None, last=rss[-1] if rss else None,
                        max=max(rss) if rss else None,
                        second_half_growth=(half[-1]["rss_mb"] - half[0]["rss_mb"]) if len(half) > 1 else None),
        objects=dict(first=s0.get("objects"), last=s1.get("objects")),
        server_rss_mb=dict(first=server_rss[0] if server_rss else None,
                           last=server_rss[-1] if server_rss else None,
                           max=max(server_rss) if server_rss else None),
        signals=dict(printer_events=s1.get("printer_events"), job_events=s1.get("job_events"),
                     replayed=s1.get("replayed")),
        operator_actions=s1.get("actions"), jobs=jobs)


def _pyside_version() -> str:
    try:
        import PySide6
        return PySide6.__version__
    except ImportError:
        return "none"


def run(minutes: float, replay_hz: float, out: Path | None, keep: Path | None = None) -> dict:
    from wideprint.app.client import Client
    root = Path(keep or tempfile.mkdtemp(prefix="gui-soak-"))
    root.mkdir(parents=True, exist_ok=True)
    images = make_images(root)
    proc, client, state = start_server(root)
    samples_file = root / "samples.jsonl"
    samples_file.write_text("")
    env = dict(os.environ)
    if not env.get("DISPLAY"):
        env["QT_QPA_PLATFORM"] = "offscreen"
    seconds = minutes * 60
    child_proc = subprocess.Popen(
        [sys.executable, __file__, "--child", "--state", str(state), "--cfg", str(root / "cfg"),
         "--samples", str(samples_file), "--seconds", str(seconds), "--replay-hz", str(replay_hz)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    submitted, server_rss, rng = 0, [], random.Random(7)
    feeder = Client(state)
    next_rss = 0.0
    try:
        while child_proc.poll() is None:
            try:
                submitted += len(feed(feeder, images, rng))
            except Exception as exc:  # noqa: BLE001 - keep feeding; note it
                print(f"feeder: {exc}", file=sys.stderr)
            if time.monotonic() >= next_rss:
                r = rss_mb(proc.pid)
                if r:
                    server_rss.append(r)
                next_rss = time.monotonic() + SAMPLE_S
            time.sleep(0.5)
        _, err = child_proc.communicate(timeout=60)
        rc = child_proc.returncode
        states: dict[str, int] = {}
        for j in feeder.request("GET", "/v1/jobs?state=done,failed,cancelled&limit=100000")["jobs"]:
            states[j["state"]] = states.get(j["state"], 0) + 1
        jobs = dict(submitted=submitted, **states)
    finally:
        if child_proc.poll() is None:
            child_proc.kill()
        feeder.close()
        client.close()
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    samples = [json.loads(line) for line in samples_file.read_text().splitlines() if line.strip()]
    samples_all = samples
    grown = next((s["objects_grown_by_type"] for s in samples if "objects_grown_by_type" in s), None)
    samples = [s for s in samples if "t" in s]
    res = summarize(samples, server_rss, rc, err, jobs, minutes, replay_hz)
    res["objects"]["grown_by_type"] = grown
    res["objects"]["new_dicts_by_keys"] = next((s["new_dicts_by_keys"] for s in samples_all
                                               if "new_dicts_by_keys" in s), None)
    res["samples_data"] = samples
    res["server_rss_samples_mb"] = [round(r, 1) for r in server_rss]   # every SAMPLE_S: its curve
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(res, indent=1) + "\n")
    return res


def report(res: dict) -> None:
    rc = res["refcount"]
    print(f"GUI soak: {res['seconds']} s, Python {res['python']}, PySide6 {res['pyside6']}, "
          f"GUI {'CRASHED (exit %s)' % res['gui_exit'] if res['crashed'] else 'alive'}")
    for k in ("true", "false", "none"):
        d = rc[k]
        if d:
            print(f"  getrefcount({k.capitalize()}): {d['first']} -> {d['last']} "
                  f"(drift {d['drift']:+d}, max |drift| {d['max_abs']})")
    g = res["gui_rss_mb"]
    if g["first"] is not None:
        print(f"  GUI RSS: {g['first']:.0f} -> {g['last']:.0f} MB (max {g['max']:.0f}, "
              f"second half {g['second_half_growth'] or 0:+.1f} MB)")
    s = res["server_rss_mb"]
    if s["first"] is not None:
        print(f"  server RSS: {s['first']:.0f} -> {s['last']:.0f} MB (max {s['max']:.0f})")
    print(f"  signals: {res['signals']}, operator actions {res['operator_actions']}, jobs {res['jobs']}")
    if res["crashed"]:
        print(res["gui_stderr_tail"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--replay-hz", type=float, default=50.0,
                    help="extra emissions a second of the last printers and jobs (0: none)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "gui_soak.json")
    ap.add_argument("--keep", type=Path, help="work in this folder (kept)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--state", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--cfg", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--samples", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--seconds", type=float, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        return child(a.state, a.cfg, a.samples, a.seconds, a.replay_hz)
    res = run(a.minutes, a.replay_hz, a.out, a.keep)
    report(res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
