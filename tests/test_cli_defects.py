"""`wideprint print` as a user sees it (issue 32, item 7): the progress line's stroke count,
an empty folder, and faults injected into every emulated device."""

import io
import re
import subprocess
import sys

import numpy as np
import pytest
import tifffile

from wideprint.app.cli import EXIT_OK, EXIT_USAGE, main

PY = sys.executable


def cli(*args, timeout=300):
    return subprocess.run([PY, "-m", "wideprint.app.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


class _Terminal(io.StringIO):
    """stderr as a 100-column terminal (app/cli/common.progress draws only on a tty; with no
    file number to ask, it takes 100 columns)."""

    def isatty(self):
        return True

    def fileno(self):
        raise OSError("no file number")


def test_the_progress_line_shows_the_whole_stroke_count(tmp_path, monkeypatch):
    """"stroke 4 of 1" was "stroke 4 of 14" cut at the terminal's width: the count came after
    a file name of up to 60 characters.  Every drawn line now holds the whole count."""
    name = "poster-for-the-spring-exhibition-final-v3.tif"              # 45 characters
    img = np.tile(np.linspace(0, 255, 300, dtype=np.uint8)[None, :, None], (400, 1, 3))
    tifffile.imwrite(tmp_path / name, img, photometric="rgb", resolution=(300, 300))
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    assert main(["print", "--passes", "4", str(tmp_path / name)]) == EXIT_OK
    lines = [ln for ln in term.getvalue().replace("\n", "\r").split("\r") if "stroke" in ln]
    assert lines
    totals = set()
    for ln in lines:
        m = re.search(r"stroke (\d+) of (\d+)\b", ln)
        assert m, ln
        totals.add(int(m.group(2)))
        assert int(m.group(1)) <= int(m.group(2)), ln
    assert len(totals) == 1 and totals.pop() > 9, lines         # the same, whole, total


@pytest.mark.parametrize("content", ["nothing", "hidden", "subfolder"])
def test_a_folder_with_nothing_to_print_is_an_error_naming_it(tmp_path, content):
    """`print EMPTY_DIR/` said "0 of 0 printed" and exited 0."""
    d = tmp_path / "incoming"
    d.mkdir()
    if content == "hidden":
        (d / ".DS_Store").write_bytes(b"x")
    elif content == "subfolder":
        (d / "old").mkdir()
    r = cli("print", "--device", "emulator", d)
    assert r.returncode == EXIT_USAGE, (r.returncode, r.stdout, r.stderr)
    assert str(d) in r.stderr and "no files" in r.stderr, r.stderr
    assert "0 of 0 printed" not in r.stdout


def test_an_empty_folder_beside_a_file_prints_the_file_and_fails(tmp_path):
    """The file is printed; the folder with nothing in it is a failed entry, named."""
    img = np.full((20, 30, 3), 128, np.uint8)
    tifffile.imwrite(tmp_path / "a.tif", img, photometric="rgb", resolution=(300, 300))
    (tmp_path / "empty").mkdir()
    report = tmp_path / "r.json"
    r = cli("print", "--report", report, tmp_path / "a.tif", tmp_path / "empty")
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "1 of 2 printed" in r.stdout and str(tmp_path / "empty") in r.stderr
    import json
    states = {e["file"]: e["state"] for e in json.loads(report.read_text())}
    assert states == {str(tmp_path / "a.tif"): "done", str(tmp_path / "empty"): "failed"}


@pytest.mark.parametrize("device", ["emulator-pci", "emulator-usb"])
def test_inject_is_taken_by_every_emulated_device(tmp_path, device):
    """docs/pci.md: the card's faults are injected with --inject; every emulated device
    (app/devices.is_emulator_spec) takes them, not only `--device emulator`."""
    img = np.full((40, 60, 3), 100, np.uint8)
    tifffile.imwrite(tmp_path / "a.tif", img, photometric="rgb", resolution=(300, 300))
    fault = "pci-dma-abort=1" if device == "emulator-pci" else "data-stall=0.001"
    r = cli("print", "--device", device, "--inject", fault, "--log-json", tmp_path / "log.jsonl",
            tmp_path / "a.tif")
    assert "--inject needs" not in r.stderr, r.stderr
    assert r.returncode == EXIT_OK, (r.stdout, r.stderr)
    if device == "emulator-pci":            # the abort happened on the card, and was recovered
        assert "DMA aborted" in (tmp_path / "log.jsonl").read_text()


def test_inject_with_a_real_device_is_still_refused(tmp_path):
    img = np.full((20, 30, 3), 100, np.uint8)
    tifffile.imwrite(tmp_path / "a.tif", img, photometric="rgb", resolution=(300, 300))
    r = cli("print", "--device", "serial=socket://127.0.0.1:9,data=tcp://127.0.0.1:9",
            "--inject", "pci-dma-abort=1", tmp_path / "a.tif")
    assert r.returncode == EXIT_USAGE and "emulated" in r.stderr, r.stderr
