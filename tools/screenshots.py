"""Screenshots of the operator GUI for docs/gui.md, taken on a real X display.

    .venv/bin/python tools/screenshots.py [--out docs/screenshots] [--offscreen]

Starts Xvfb (unless --offscreen, or a DISPLAY is set and --use-display is given), runs
the real MainWindow with QT_QPA_PLATFORM=xcb on the in-process emulator, and saves:

    empty.png        the window as it opens
    queue.png        a queue of images, the selected one previewed with its estimate
    printing.png     a job printing, the live media view partly filled
    calibration.png  the bidirectional alignment print on a misaligned machine, suggested block
    error.png        a damaged file: its row, the preview's message and the device panel

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
    from PySide6.QtWidgets import QApplication
    app = QApplication.instance() or QApplication(["wideprint-screenshots"])
    print(f"Qt platform: {app.platformName()}, display {os.environ.get('DISPLAY', '-')}")
    from wideprint.app.gui import queue as Q
    from wideprint.app.gui.main_window import MainWindow

    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="wideprint-shots-"))
    files = make_images(tmp / "jobs")

    def spin(cond, timeout=60.0, what=""):
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            app.processEvents()
            if cond():
                return True
            time.sleep(0.02)
        print(f"  timed out waiting for {what}")
        return False

    def settle(seconds=0.4):
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            app.processEvents()
            time.sleep(0.02)

    def shot(widget, name):
        settle()
        path = out / f"{name}.png"
        widget.grab().save(str(path))
        print(f"  {path}")

    win = MainWindow(config_dir=tmp / "config")
    win.ask_before_closing = False
    win.resize(1600, 1000)
    win.show()
    win.device.media_dir.setText(str(tmp / "media"))
    win.device.configChanged.emit()
    settle(1.0)
    shot(win, "empty")

    # -- a queue with previews ------------------------------------------------------------------
    items = win.add_files([str(files[k]) for k in ("banner", "chart", "photo", "bmp", "poster")])
    banner = items[0]
    spin(lambda: all(i.state != Q.LOADING for i in items), 120, "previews")
    win.select_item(banner.id)
    spin(lambda: win.preview.has_image, 30, "the banner's preview")
    win.preview.fit_image()
    shot(win, "queue")

    # -- printing, live view part filled ----------------------------------------------------------
    sp = win.settings_panel
    win.select_item(banner.id)
    sp.passes.setCurrentIndex(sp.passes.findData(4))
    sp.direction.setCurrentIndex(sp.direction.findData(True))
    settle(0.5)
    win.device.speed.setCurrentIndex(win.device.speed.findData(0.0))
    win.connect_device()                      # home and measure the paper at full speed
    spin(lambda: win.connected, 60, "connection")
    win.device.set_speed(5.0)                 # then print at 5 x real time
    win.print_queue()                         # the banner first, the others wait
    spin(lambda: banner.progress >= 0.45, 300, "half the banner")
    shot(win, "printing")
    win.cancel_job()
    spin(lambda: win.current is None, 30, "the cancel")
    win.device.set_speed(0.0)

    # -- calibration --------------------------------------------------------------------------
    win.device.faults.setText("bidir-error=2")
    win.device.configChanged.emit()
    dlg = win.open_calibration()
    dlg.pattern.setCurrentIndex(dlg.pattern.findData("bidir-align"))
    dlg.dpi.setCurrentIndex(dlg.dpi.findData(150))
    dlg.resize(900, 660)
    dlg.print_pattern()
    spin(lambda: dlg.media is not None, 120, "the alignment print")
    shot(dlg, "calibration")
    dlg.close()
    settle(0.3)
    win.device.faults.setText("")
    win.device.configChanged.emit()

    # -- an error: a damaged file; the queue prints the rest ---------------------------------------
    win.select_item(banner.id)
    win.remove_selected()                     # the operator drops the cancelled banner
    (bad,) = win.add_files([str(files["damaged"])])
    spin(lambda: bad.state != Q.LOADING, 30, "the damaged file")
    win.print_queue()
    spin(lambda: win.current is None and not win.running, 300, "the queue")
    win.select_item(bad.id)
    win.tabs.setCurrentWidget(win.preview)
    shot(win, "error")

    win.close()
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
