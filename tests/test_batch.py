"""Batches (issue "Hardening", class 5): every file of a `wideprint print` batch lands on
the media exactly as `wideprint rip` of that file alone says; media and preview outputs
that cannot work are refused up front; CLI job ids differ between runs.

The bug behind "2 of 2 printed while n-2.tif holds 0 drops": drops were lost, not the
media file.  PrintJob took the printer's pass registers (pass 0, N fires, line done), left
by the previous job's last line, for its own pass 0 "finished while we were away" and
skipped it - two one-pass images of the same width in one batch, or two copies of one."""

import json
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest
import pyvips
import tifffile

from support.images import PX, random_planes, write_cmyk_tiff
from support.corpus import bmp_rgb24, bmp_rle, gradient_rgb
from wideprint.app.devices import open_device
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes, preview_image

PY = sys.executable


def cli(*args, timeout=300, env=None):
    return subprocess.run([PY, "-m", "wideprint.app.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=env)


def rip_planes(src, out, *opts):
    """`wideprint rip` of one file (its main(), in this process: no interpreter start-up)."""
    from wideprint.app.cli import main
    assert main(["rip", str(src), "-o", str(out), *map(str, opts)]) == 0
    return read_planes(out)


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    """Files of every format; a.tif, b.bmp and c.png hold the same image (the same line
    length: the case that printed nothing), the others differ in size and colour space."""
    d = tmp_path_factory.mktemp("batch")
    img = gradient_rgb(50, 70, seed=1)
    tifffile.imwrite(d / "a.tif", img, photometric="rgb")
    (d / "b.bmp").write_bytes(bmp_rgb24(img))
    pyvips.Image.new_from_array(img).copy(interpretation="srgb").pngsave(str(d / "c.png"))
    pyvips.Image.new_from_array(gradient_rgb(90, 120, seed=2)).copy(
        interpretation="srgb").jpegsave(str(d / "d.jpg"), Q=92)
    pal = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, 1)
    idx = ((np.arange(64 * 40).reshape(40, 64) // 7) % 256).astype(np.uint8)
    (d / "e.bmp").write_bytes(bmp_rle(idx, pal, False))
    write_cmyk_tiff(d / "f.tif", random_planes(80, 70, seed=5))
    tifffile.imwrite(d / "g.tif", img, photometric="rgb", compression="lzw", rowsperstrip=7)
    return d, ["a.tif", "b.bmp", "c.png", "d.jpg", "e.bmp", "f.tif", "g.tif"]


@pytest.mark.parametrize("opts", [["--passes", "1"], ["--passes", "2", "--bidir"]],
                         ids=["1-pass", "2-pass-bidir"])
def test_batch_of_formats_prints_every_file_bit_exact(batch, tmp_path, opts):
    d, names = batch
    opts = ["--size", "pixels", *opts]
    files = [d / n for n in names]
    r = cli("print", *files, "--media-out", tmp_path / "n.tif", "--report", tmp_path / "r.json",
            *opts)
    assert r.returncode == 0, r.stderr
    assert f"summary: {len(files)} of {len(files)} printed, 0 failed" in r.stdout
    reports = json.loads((tmp_path / "r.json").read_text())
    for i, (f, rep) in enumerate(zip(files, reports), 1):
        media = read_planes(tmp_path / f"n-{i}.tif")
        planes = rip_planes(f, tmp_path / f"p-{i}.tif", *opts)
        assert media.shape == planes.shape, f.name
        assert np.array_equal(media, planes), f"{f.name}: the media differs from its planes"
        assert planes.any(), f.name
        assert rep["state"] == "done" and rep["stray_drops"] == 0
        assert rep["drops"] == planes.reshape(-1, 4).sum(axis=0).tolist()


def test_jobs_and_copies_of_equal_lines_all_print(tmp_path, profile):
    """Driver level: one printer, one-pass jobs of the same width one after another, with
    new job ids (a batch) and with the same id (the print server's copies)."""
    planes = random_planes(40, 90, seed=8)
    src = write_cmyk_tiff(tmp_path / "same.tif", planes)
    names = {}
    dev = open_device("emulator", profile, media_path=lambda job: names[job])
    try:
        for n, job_id in enumerate([7, 8, 8, 9]):
            names[job_id] = str(tmp_path / f"m{n}.tif")
            rep = PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, passes=1), profile),
                           job_id=job_id).run()
            assert rep.strokes_printed == 1
            dev.emulator.close()       # the media of the job so far is complete
            assert np.array_equal(read_planes(names[job_id]), planes), (n, job_id)
    finally:
        dev.emulator.close()


def test_preview_alone_is_drawn_from_a_temporary_media(batch, tmp_path):
    d, names = batch
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = dict(os.environ, TMPDIR=str(scratch))
    r = cli("print", d / "a.tif", d / "d.jpg", "--preview", tmp_path / "p.png", "--size", "pixels",
            "--report", tmp_path / "r.json", env=env)
    assert r.returncode == 0, r.stderr
    for i, name in enumerate(["a.tif", "d.jpg"], 1):
        rip_planes(d / name, tmp_path / f"planes-{i}.tif", "--size", "pixels")
        png = cv2.imread(str(tmp_path / f"p-{i}.png"))[:, :, ::-1]
        # the preview of what landed equals the preview of what the RIP meant
        assert np.array_equal(png, preview_image(tmp_path / f"planes-{i}.tif")), name
    reps = json.loads((tmp_path / "r.json").read_text())
    assert [r["media"] for r in reps] == [None, None]
    assert [r["preview"] for r in reps] == [str(tmp_path / "p-1.png"), str(tmp_path / "p-2.png")]
    assert list(scratch.iterdir()) == []            # the temporary media went away


def test_cli_job_ids_differ_between_runs(batch, tmp_path):
    d, _ = batch
    ids = []
    for run in range(2):
        r = cli("print", d / "a.tif", d / "b.bmp", "--size", "pixels", "--json")
        assert r.returncode == 0, r.stderr
        ids.append([rep["job_id"] for rep in json.loads(r.stdout)])
    for run_ids in ids:
        assert run_ids[1] == run_ids[0] + 1
        assert all(10 ** 9 <= i < 2 ** 32 for i in run_ids)
    assert not set(ids[0]) & set(ids[1])


# -- a standalone emulator ----------------------------------------------------------------
@pytest.fixture
def standalone(tmp_path):
    media = tmp_path / "emu"
    media.mkdir()
    proc = subprocess.Popen([PY, "-m", "wideprint.app.cli", "emulator",
                             "--media-out", str(media / "sa_{job}.tif")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith("device: "), proc.stderr.read()
    yield line.split(" ", 1)[1].strip(), media
    proc.terminate()
    _, err = proc.communicate(timeout=20)
    assert "Traceback" not in err, err


def test_emulator_outputs_are_refused_with_a_standalone_device(batch, standalone, tmp_path):
    d, _ = batch
    spec, emu_media = standalone
    for opt in (["--media-out", tmp_path / "m.tif"], ["--preview", tmp_path / "p.png"],
                ["--media-out", tmp_path / "m.tif", "--preview", tmp_path / "p.png"],
                ["--event-log", tmp_path / "e.jsonl"]):
        r = cli("print", d / "a.tif", "--device", spec, "--size", "pixels", *opt,
                "--report", tmp_path / "r.json")
        assert r.returncode == 2, r.stdout + r.stderr
        assert "need the in-process emulator (--device emulator)" in r.stderr or \
            "needs the in-process emulator (--device emulator)" in r.stderr
        assert "wideprint emulator --media-out" in r.stderr and "Traceback" not in r.stderr
        rep = json.loads((tmp_path / "r.json").read_text())
        assert rep[0]["state"] == "failed" and "not printed" in rep[0]["message"]
    assert list(emu_media.iterdir()) == []              # nothing was printed
    assert not (tmp_path / "m.tif").exists() and not (tmp_path / "p.png").exists()


def test_standalone_media_names_differ_between_runs(batch, standalone, tmp_path):
    """`wideprint emulator --media-out sa_{job}.tif`: {job} is the printer job id, unique
    per CLI run, so the next run does not overwrite this one's media."""
    d, _ = batch
    spec, emu_media = standalone
    seen = {}
    for n, name in enumerate(["a.tif", "d.jpg", "a.tif"]):
        r = cli("print", d / name, "--device", spec, "--size", "pixels", "--passes", "2",
                "--report", tmp_path / f"r{n}.json")
        assert r.returncode == 0, r.stderr
        job_id = json.loads((tmp_path / f"r{n}.json").read_text())[0]["job_id"]
        seen[job_id] = name
    assert len(seen) == 3
    assert sorted(p.name for p in emu_media.iterdir()) == sorted(f"sa_{j}.tif" for j in seen)
    for job_id, name in seen.items():
        planes = rip_planes(d / name, tmp_path / f"planes-{job_id}.tif", "--size", "pixels",
                            "--passes", "2")
        assert np.array_equal(read_planes(emu_media / f"sa_{job_id}.tif"), planes), name
