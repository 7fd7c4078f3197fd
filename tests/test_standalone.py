"""The driver against `wideprint emulator` in its own process, over a real pseudo-terminal
(command channel) and TCP (data channel), and over socket:// for the command channel."""

import subprocess
import sys

import numpy as np
import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import start_emulator
from wideprint.rip.planes import read_planes


@pytest.mark.parametrize("serial,data", [("pty", "tcp"), ("socket", "tcp"), ("pty", "usb"),
                                         ("pty", "node")])
def test_print_through_standalone_emulator(tmp_path, serial, data):
    extra = ([] if serial == "pty" else ["--serial-port", "0"]) + \
        (["--data-pty"] if data == "node" else [])
    proc, spec = start_emulator(tmp_path, *extra)
    try:
        if data == "usb":
            usb_line = proc.stdout.readline()
            assert usb_line.startswith("device (USB): ")
            spec = usb_line.split(": ", 1)[1].strip()
            assert ",data=usb-emu://127.0.0.1:" in spec
        if serial == "pty":
            assert spec.startswith("serial=/dev/pts/")
        else:
            assert spec.startswith("serial=socket://127.0.0.1:")
        if data == "node":
            assert ",data=/dev/pts/" in spec
        planes = random_planes(400, 260, seed=11)
        src = write_cmyk_tiff(tmp_path / "in.tif", planes)
        r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "print", str(src),
                            "--device", spec, "--passes", "2", "--bidir", "--size", "pixels"],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr + "\n--- emulator ---\n" + (
            proc.terminate() or proc.communicate(timeout=10)[1])
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=10)
    assert "Traceback" not in err, err
    media = list(tmp_path.glob("media-*.tif"))          # {job}: this run's printer job id
    assert len(media) == 1, media
    assert np.array_equal(read_planes(media[0]), planes)


def test_one_stroke_jobs_in_a_row_take_no_earlier_lines_reports(tmp_path):
    """Each file a single stroke 0, one after another on one data link: the reports of
    the first line, left unread once its blocks were all sent, must not count as the next
    line's (docs/protocol.md 3.2; before, the second job overran the ring: fault 05)."""
    proc, spec = start_emulator(tmp_path)
    try:
        planes = [random_planes(113, 231, seed=s) for s in (3, 4, 5)]
        srcs = [str(write_cmyk_tiff(tmp_path / f"in{i}.tif", p)) for i, p in enumerate(planes)]
        r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "print", *srcs,
                            "--device", spec, "--passes", "1", "--bidir", "--size", "pixels"],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=10)
    assert "Traceback" not in err, err
    media = sorted(tmp_path.glob("media-*.tif"), key=lambda f: int(f.stem.split("-")[1]))
    assert len(media) == 3, media                    # the run's job ids, in order
    for m, p in zip(media, planes):
        assert np.array_equal(read_planes(m), p)
