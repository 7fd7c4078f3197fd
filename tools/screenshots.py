"""Screenshots of the operator GUI for README and docs/gui.md, taken on a real X display.

    .venv/bin/python tools/screenshots.py [--out docs/screenshots] [--offscreen]

Starts Xvfb (unless --offscreen, or a DISPLAY is set and --use-display is given), a print
server process with two emulated printers in a temporary state directory, and the real
MainWindow (QT_QPA_PLATFORM=xcb) as its client; then: a job printed (history), a damaged
file failed, a long banner printing on one printer, three jobs waiting, two of them
selected (the settings form shows their mixed values).  Saves, at the two screen sizes the
GUI is checked at:

    gui-1366x768.png     gui-1920x1080.png     calibration.png

Settings go to a temporary config dir, so the operator's own settings are not touched.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def start_xvfb(size: str = "1680x1060x24") -> subprocess.Popen:
    """Xvfb on the first free display; sets DISPLAY and QT_QPA_PLATFORM=xcb."""
    if not shutil.which("Xvfb"):
        sys.exit("tools/screenshots.py: Xvfb is not installed (apt-get install xvfb), "
                 "or run with --offscreen")
    for n in range(90, 140):
        if Path(f"/tmp/.X{n}-lock").exists() or Path(f"/tmp/.X11-unix/X{n}").exists():
            continue
        proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", size, "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(100):
            if Path(f"/tmp/.X11-unix/X{n}").exists():
                os.environ["DISPLAY"] = f":{n}"
                os.environ["QT_QPA_PLATFORM"] = "xcb"
                return proc
            if proc.poll() is not None:
                break
            time.sleep(0.05)
        proc.kill()
    sys.exit("tools/screenshots.py: cannot start Xvfb")


def make_images(folder: Path) -> dict[str, Path]:
    """Demo files: a banner (RGB TIFF), the bundled chart, a photo-like JPEG, a BMP, a
    CMYK poster and a damaged TIFF."""
    import cv2
    import numpy as np
    import tifffile
    folder.mkdir(parents=True, exist_ok=True)
    chart = tifffile.imread(ROOT / "resources" / "samples" / "sample.tif")[:, :, :3]
    out = {}
    # banner: 1.2 m x 0.2 m at 300 ppi
    W, H = 14000, 2300
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    hsv = np.dstack([(xx / W * 179).astype(np.uint8),
                     np.clip(80 + 175 * yy / H, 0, 255).astype(np.uint8),
                     np.full((H, W), 235, np.uint8)])
    banner = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    tile = cv2.resize(chart, (int(chart.shape[1] * 1600 / chart.shape[0]), 1600), interpolation=cv2.INTER_AREA)
    banner[350:350 + tile.shape[0], 250:250 + tile.shape[1]] = tile
    cv2.putText(banner, "WIDEPRINT", (4300, 1500), cv2.FONT_HERSHEY_DUPLEX, 40, (20, 20, 20), 90, cv2.LINE_AA)
    cv2.putText(banner, "3.4 m  CMYK  8 x XJ128", (4400, 2050), cv2.FONT_HERSHEY_DUPLEX, 12, (255, 255, 255),
                30, cv2.LINE_AA)
    out["banner"] = folder / "banner-1200mm.tif"
    tifffile.imwrite(out["banner"], banner, photometric="rgb", compression="zlib",
                     resolution=(300, 300), resolutionunit="INCH", rowsperstrip=64)
    out["chart"] = folder / "test-chart.tif"
    shutil.copyfile(ROOT / "resources" / "samples" / "sample.tif", out["chart"])
    # a photo-like JPEG: soft blobs
    rng = np.random.default_rng(3)
    ph = np.zeros((900, 1400, 3), np.float32)
    gy, gx = np.mgrid[0:900, 0:1400].astype(np.float32)
    for _ in range(40):
        c = rng.random(3) * 255
        cx, cy, r = rng.random() * 1400, rng.random() * 900, 60 + rng.random() * 220
        d = np.exp(-((gx - cx) ** 2 + (gy - cy) ** 2) / (2 * r * r))
        ph += d[:, :, None] * c
    ph = np.clip(255 - ph * 0.6, 0, 255).astype(np.uint8)
    out["photo"] = folder / "photo.jpg"
    cv2.imwrite(str(out["photo"]), ph[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 92])
    out["bmp"] = folder / "label.bmp"
    lab = np.full((300, 900, 3), 255, np.uint8)
    cv2.putText(lab, "SALE -30%", (40, 220), cv2.FONT_HERSHEY_DUPLEX, 5, (200, 0, 40), 14, cv2.LINE_AA)
    cv2.imwrite(str(out["bmp"]), lab)
    cmyk = np.zeros((1000, 1600, 4), np.uint8)
    cmyk[:, :, 0] = np.linspace(0, 255, 1600)[None, :]
    cmyk[:, :, 1] = np.linspace(255, 0, 1000)[:, None]
    cmyk[300:700, 500:1100, 3] = 200
    out["poster"] = folder / "poster-cmyk.tif"
    tifffile.imwrite(out["poster"], cmyk, photometric="separated", resolution=(300, 300), resolutionunit="INCH")
    out["damaged"] = folder / "damaged.tif"
    good = folder / "whole.tif"
    tifffile.imwrite(good, cmyk[:400, :600], photometric="separated")
    out["damaged"].write_bytes(good.read_bytes()[:3000])
    good.unlink()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "screenshots"))
    ap.add_argument("--offscreen", action="store_true", help="no X server: Qt's offscreen platform")
    ap.add_argument("--use-display", action="store_true", help="use $DISPLAY instead of starting Xvfb")
    args = ap.parse_args(argv)
    xvfb = None
    if args.offscreen:
        os.environ["QT_QPA_PLATFORM"] = "offscreen"
    elif not (args.use_display and os.environ.get("DISPLAY")):
        xvfb = start_xvfb()
    try:
        return run(Path(args.out))
    finally:
        if xvfb is not None:
            xvfb.terminate()
            xvfb.wait(5)


def run(out: Path) -> int:
    import subprocess as sp
    from PySide6.QtWidgets import QApplication
    app = QApplication.instance() or QApplication(["wideprint-screenshots"])
    from wideprint.app.gui.main_window import MainWindow
    from wideprint.app.gui.server_link import ServerLink, find_or_start
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="wideprint-shots-"))
    files = make_images(tmp / "files")
    state = tmp / "state"
    server = sp.Popen([sys.executable, "-m", "wideprint.app.cli", "serve", "--state-dir", str(state),
                       "--media-dir", str(tmp / "media"), "--port", "0", "--paused",
                       "--printer", "left=emulator", "--printer", "right=emulator"],
                      stdout=sp.DEVNULL, stderr=sp.DEVNULL)

    def spin(cond, timeout=120.0, what=""):
        t = time.monotonic() + timeout
        while not cond():
            app.processEvents()
            time.sleep(0.02)
            if time.monotonic() > t:
                raise SystemExit(f"tools/screenshots.py: timed out waiting for {what}")

    def settle(seconds=0.5):
        t = time.monotonic() + seconds
        while time.monotonic() < t:
            app.processEvents()
            time.sleep(0.02)

    try:
        from wideprint.app.client import ApiError, Client
        t = time.monotonic() + 60
        while True:                          # our server up, before the GUI looks for one
            try:
                Client(state).status()
                break
            except ApiError:
                if time.monotonic() > t or server.poll() is not None:
                    raise SystemExit("tools/screenshots.py: the print server did not start")
                time.sleep(0.2)
        client, _ = find_or_start(state)
        win = MainWindow(ServerLink(state, client), config_dir=tmp / "cfg")
        win.ask_before_closing = False
        win.resize(1366, 768)
        win.show()
        spin(lambda: len(win.printers) == 2, what="the printers")
        c = win.link.client()
        # history: a photo printed, a damaged file failed
        done = c.submit(files["photo"], settings={"dpi": 150})["job"]["id"]
        bad = c.submit(files["damaged"])["job"]["id"]
        c.pause_queue(False)
        spin(lambda: {j["id"]: j["state"] for j in c.jobs()}.get(done) == "done"
             and {j["id"]: j["state"] for j in c.jobs()}.get(bad) == "failed", what="the history")
        c.printer_action("right", "pause")
        # a banner printing on the left, jobs waiting
        banner = c.submit(files["banner"], printer="left",
                          settings={"passes": 4, "bidir": True})["job"]["id"]
        waiting = [c.submit(files[k], copies=n, settings=s)["job"]["id"] for k, n, s in (
            ("chart", 2, {"dpi": 300, "passes": 2}), ("poster", 1, {"dpi": 600, "passes": 4}),
            ("bmp", 3, {"dpi": 150}))]
        spin(lambda: any(j["id"] == banner and j["strokes_done"] >= 1 for j in c.jobs()),
             what="the banner printing")
        c.pause_queue(True)
        spin(lambda: len(win.queue_model.jobs) == 4, what="the queue in the GUI")
        spin(lambda: all(j in win.queue_model.thumbs for j in waiting), what="thumbnails")
        win.queue_view.select_ids(waiting[:2])
        win._show_selection()
        spin(lambda: win.estimate.all["time"].text() != "–", what="the estimate")
        for w, h in ((1366, 768), (1920, 1080)):
            win.resize(w, h)
            settle(1.0)
            win.grab().save(str(out / f"gui-{w}x{h}.png"))
            print(out / f"gui-{w}x{h}.png")
        c.action(banner, "cancel")
        spin(lambda: not any(p.get("current") for p in win.printers), what="the printers idle")
        dlg = win.open_calibration("right")
        dlg.pattern.setCurrentIndex(dlg.pattern.findData("bidir-align"))
        dlg.print_pattern()
        spin(lambda: dlg.media is not None, what="the test print")
        settle(0.5)
        dlg.grab().save(str(out / "calibration.png"))
        print(out / "calibration.png")
        dlg.close()
        win.link.stop()
        win.close()
    finally:
        server.terminate()
        server.wait(20)
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
