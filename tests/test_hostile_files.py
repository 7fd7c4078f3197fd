"""Hostile files and names on the command line (issue "Hardening", class 4): `wideprint
print` and `rip` fail each bad file with its own clear message and exit code - never a
traceback, a hang, a partial output or raw control characters on the terminal - and the
good files of the batch still print.  The loader's side of each case is in
tests/support/corpus.py (tests/test_load.py's hostile corpus)."""

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest
import pyvips
import tifffile

from support.corpus import bmp_indexed, bmp_rgb24, bmp_rle, gradient_rgb, set_jpeg_size
from support.images import random_planes, write_cmyk_tiff
from wideprint.rip.planes import read_planes

PY = sys.executable


def cli(*args, timeout=120):
    t0 = time.monotonic()
    r = subprocess.run([PY, "-m", "wideprint.app.cli", *map(str, args)], capture_output=True,
                       timeout=timeout)
    r.seconds = time.monotonic() - t0
    r.out = r.stdout.decode("utf-8", "replace")
    r.err = r.stderr.decode("utf-8", "replace")
    assert b"Traceback" not in r.stderr, r.err
    # nothing of a file name reaches the terminal raw: no control character but newlines
    for stream in (r.stdout, r.stderr):
        assert not any(b < 0x20 and b != 0x0A for b in stream), stream
    return r


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    d = tmp_path_factory.mktemp("good")
    img = gradient_rgb(40, 60, seed=3)
    tifffile.imwrite(d / "good.tif", img, photometric="rgb")
    return d / "good.tif"


def planes_of(src, out, *opts):
    """`wideprint rip` of one file (its main(), in this process: no interpreter start-up)."""
    from wideprint.app.cli import main
    assert main(["rip", str(src), "-o", str(out), "--size", "pixels", *map(str, opts)]) == 0
    return read_planes(out)


# -- names ------------------------------------------------------------------------------------
def test_path_longer_than_path_max_fails_its_job(tmp_path, good):
    deep = "/".join(["d" * 200] * 25) + "/x.tif"              # > PATH_MAX (4096)
    long_name = tmp_path / ("n" * 300 + ".bmp")                # > NAME_MAX (255)
    r = cli("print", deep, long_name, good, "--size", "pixels", "--report", tmp_path / "r.json")
    assert r.returncode == 1
    assert r.err.count("cannot read file: File name too long") == 2
    assert "characters)..." in r.err                            # the name is shortened
    reps = json.loads((tmp_path / "r.json").read_text())
    assert [x["state"] for x in reps] == ["failed", "failed", "done"]
    assert reps[0]["file"] == deep                              # the report keeps it whole
    r = cli("rip", deep, "-o", tmp_path / "p.tif")
    assert r.returncode == 1 and "File name too long" in r.err
    assert not (tmp_path / "p.tif").exists()


def test_non_utf8_names_print_their_images(tmp_path):
    """Each format under a plain name and under a name that is not UTF-8 (Latin-1 bytes):
    one batch, the same media; the names are shown with escapes."""
    img = gradient_rgb(30, 50, seed=4)
    fmts = ["tif", "jpg", "png", "bmp"]
    plain, odd = [], []
    for fmt in fmts:
        p = tmp_path / f"plain.{fmt}"
        if fmt == "tif":
            tifffile.imwrite(p, img, photometric="rgb")
        elif fmt == "bmp":
            p.write_bytes(bmp_rgb24(img))
        else:
            getattr(pyvips.Image.new_from_array(img).copy(interpretation="srgb"),
                    f"{'jpeg' if fmt == 'jpg' else fmt}save")(str(p))
        o = tmp_path / os.fsdecode(b"caf\xe9 \xff." + fmt.encode())
        o.write_bytes(p.read_bytes())
        plain.append(p)
        odd.append(o)
    r = cli("print", *plain, *odd, "--size", "pixels", "--media-out", tmp_path / "m.tif")
    assert r.returncode == 0, r.err
    n = len(fmts)
    for i, fmt in enumerate(fmts, 1):
        assert f"caf\\xe9 \\xff.{fmt}: printed" in r.out          # the bytes shown as escapes
        assert np.array_equal(read_planes(tmp_path / f"m-{i + n}.tif"),
                              read_planes(tmp_path / f"m-{i}.tif")), fmt
    want = read_planes(tmp_path / "m-1.tif")
    out = tmp_path / os.fsdecode(b"planes-\xe9.tif")            # an output name like it
    r = cli("rip", odd[0], "-o", out, "--size", "pixels")
    assert r.returncode == 0, r.err
    assert "planes-\\xe9.tif" in r.out
    assert np.array_equal(read_planes(out), want)
    utf8 = tmp_path / "caf\u00e9 \u6f22\u5b57.tif"                  # UTF-8 but not ASCII
    utf8.write_bytes(plain[0].read_bytes())
    assert np.array_equal(planes_of(utf8, tmp_path / "u.tif"), want)   # TIFF text: escaped


NASTY = [(b"\x1b[2J\x1b]0;owned\x07", "\\x1b[2J\\x1b]0;owned\\x07"),
         (b"new\nline\r", "new\\x0aline\\x0d"),
         ("\u202egnp".encode(), "\\u202egnp"),
         (b"tab\tdel\x7f\xc2\x9bcsi", "tab\\x09del\\x7f\\x9bcsi")]


def test_control_characters_in_names_are_escaped(tmp_path, good):
    """A file name is data: its escape sequences never reach the terminal (cli() checks
    every byte of the output); the report keeps the real names."""
    files = []
    for raw, _ in NASTY:
        bad = tmp_path / os.fsdecode(raw + b"-bad.tif")
        bad.write_bytes(b"II*\x00garbage")
        fine = tmp_path / os.fsdecode(raw + b"-good.tif")
        fine.write_bytes(good.read_bytes())
        files += [bad, fine]
    r = cli("print", *files, "--size", "pixels", "--media-out", tmp_path / "m.tif",
            "--report", tmp_path / "r.json")
    assert r.returncode == 1
    for _, escaped in NASTY:
        assert f"{escaped}-bad.tif: FAILED: " in r.err
        assert f"{escaped}-good.tif: printed " in r.out
    reps = json.loads((tmp_path / "r.json").read_text())
    assert [x["file"] for x in reps] == [str(f) for f in files]
    assert [x["state"] for x in reps] == ["failed", "done"] * len(NASTY)
    r = cli("rip", files[0], "-o", tmp_path / "p.tif")
    assert r.returncode == 1 and NASTY[0][1] + "-bad.tif: " in r.err and "TIFF" in r.err
    r = cli("rip", files[1], "-o", tmp_path / os.fsdecode(NASTY[0][0] + b".tif"), "--size", "pixels")
    assert r.returncode == 0 and NASTY[0][1] + ".tif: 60 x 40 dots" in r.out


# -- not regular files ------------------------------------------------------------------------
def test_fifo_and_devices_are_not_regular_files(tmp_path, good):
    fifo = tmp_path / "pipe.tif"
    os.mkfifo(fifo)
    r = cli("print", fifo, "/dev/zero", good, "--size", "pixels", timeout=60)
    assert r.returncode == 1
    assert "pipe.tif: not a regular file (a FIFO)" in r.err
    assert "/dev/zero: not a regular file (a character device)" in r.err
    assert "empty file" not in r.err
    assert "summary: 1 of 3 printed, 2 failed" in r.out
    r = cli("rip", fifo, "-o", tmp_path / "p.tif", timeout=60)
    assert r.returncode == 1 and "not a regular file (a FIFO)" in r.err
    d = tmp_path / "folder"
    d.mkdir()
    os.mkfifo(d / "in-a-folder.tif")
    (d / "ok.tif").write_bytes(good.read_bytes())
    r = cli("print", d, "--size", "pixels", timeout=60)        # a folder's FIFO is skipped
    assert r.returncode == 0 and "summary: 1 of 1 printed" in r.out


# -- contents ---------------------------------------------------------------------------------
def test_jpeg_claiming_a_huge_image_fails_fast_in_print_and_rip(tmp_path):
    """30000 x 20000 px (under the pixel cap) with 3 KB of data.  rip used to run until
    killed: the decoder failed at once, but the planes writer then padded the 'missing'
    24,000 x 24,700 dots with blank rows.  Now both fail on the first band."""
    small = tmp_path / "small.jpg"
    pyvips.Image.new_from_array(gradient_rgb(64, 64)).copy(interpretation="srgb").jpegsave(
        str(small), Q=90)
    huge = tmp_path / "huge.jpg"
    huge.write_bytes(set_jpeg_size(small.read_bytes(), 30000, 20000))
    out = tmp_path / "planes.tif"
    for args in (["rip", huge, "-o", out], ["rip", huge, "-o", out, "--dither", "bayer"],
                 ["print", huge, "--size", "pixels"]):
        r = cli(*args, timeout=60)
        assert r.returncode == 1, (args, r.err)
        assert r.seconds < 30, (args, r.seconds)
        assert "huge.jpg" in r.err
        assert "corrupt JPEG data" in r.err or "wide at 300 dpi but the paper" in r.err, r.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["huge.jpg", "small.jpg"]


def _bad_bmps(d):
    pal = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, 1)
    six = np.zeros((4, 6), np.uint8)
    files = {
        "overrun.bmp": (bmp_rle(six, pal, False, data=bytes([4, 1, 5, 2, 0, 0, 0, 1])),
                        "corrupt BMP: the RLE run of 5 pixels at byte 1080 overruns row 3"),
        "index.bmp": (bmp_rle(six, pal[:4], False, data=bytes([2, 1, 3, 9, 0, 1])),
                      "corrupt BMP: colour index 9 at byte 72 (row 3, column 2) is outside the "
                      "palette of 4 colours"),
        "index8.bmp": (bmp_indexed(np.full((3, 4), 7, np.uint8), pal[:2], 8),
                       "corrupt BMP: colour index 7 at byte 70 (row 0, column 0) is outside the palette of 2"),
    }
    for name, (data, _) in files.items():
        (d / name).write_bytes(data)
    return {name: phrase for name, (_, phrase) in files.items()}


def test_bad_rle_and_palette_bmps_fail_with_the_problem(tmp_path, good):
    phrases = _bad_bmps(tmp_path)
    names = sorted(phrases)
    r = cli("print", *(tmp_path / n for n in names), good, "--size", "pixels",
            "--report", tmp_path / "r.json")
    assert r.returncode == 1
    for n in names:
        assert f"{tmp_path / n}: FAILED: {tmp_path / n}: {phrases[n]}" in r.err, r.err
    reps = json.loads((tmp_path / "r.json").read_text())
    assert [x["state"] for x in reps] == ["failed"] * len(names) + ["done"]
    for n in names:
        r = cli("rip", tmp_path / n, "-o", tmp_path / "p.tif")
        assert r.returncode == 1 and phrases[n] in r.err
        assert not (tmp_path / "p.tif").exists()


# -- outputs ------------------------------------------------------------------------------------
def test_failed_rip_leaves_no_partial_output(tmp_path, good):
    """Planes are written under a temporary name and renamed when complete: a failure
    midway leaves the old file as it was and no temporary behind."""
    planes = random_planes(2000, 200, seed=17)
    late = tmp_path / "late.tif"
    tifffile.imwrite(late, planes * 255, photometric="separated", compression="deflate",
                     rowsperstrip=64)
    with tifffile.TiffFile(late) as t:               # a strip far down is garbage
        off = t.pages[0].tags["StripOffsets"].value[-5]
        cnt = t.pages[0].tags["StripByteCounts"].value[-5]
    raw = bytearray(late.read_bytes())
    raw[off:off + cnt] = np.random.default_rng(0).integers(0, 256, cnt, dtype=np.uint8).tobytes()
    late.write_bytes(bytes(raw))
    out = tmp_path / "out" / "planes.tif"
    out.parent.mkdir()
    r = cli("rip", late, "-o", out, "--size", "pixels")
    assert r.returncode == 1 and "corrupt TIFF data" in r.err
    assert list(out.parent.iterdir()) == []
    out.write_bytes(b"the previous planes")
    r = cli("rip", late, "-o", out, "--size", "pixels")
    assert r.returncode == 1
    assert out.read_bytes() == b"the previous planes"
    assert list(out.parent.iterdir()) == [out]
    planes_of(good, out)                              # a good rip replaces it
    assert list(out.parent.iterdir()) == [out]
    want = read_planes(out)
    # not a regular file: the finished TIFF is copied into it (a rename would replace it)
    r = cli("rip", good, "-o", "/dev/null", "--size", "pixels")
    assert r.returncode == 0 and not os.path.isfile("/dev/null")
    link = tmp_path / "link.tif"
    link.symlink_to(out)
    out.unlink()
    r = cli("rip", good, "-o", link, "--size", "pixels")
    assert r.returncode == 0 and link.is_symlink()
    assert np.array_equal(read_planes(out), want)
    with open(tmp_path / "stdout.tif", "wb") as f:   # -o /dev/stdout: the TIFF alone on stdout
        r = subprocess.run([PY, "-m", "wideprint.app.cli", "rip", str(good), "-o", "/dev/stdout",
                            "--size", "pixels"], stdout=f, stderr=subprocess.PIPE, timeout=120)
    assert r.returncode == 0 and b"/dev/stdout: 60 x 40 dots" in r.stderr
    assert np.array_equal(read_planes(tmp_path / "stdout.tif"), want)
    assert os.path.islink("/dev/stdout")
    assert not [p for p in tmp_path.rglob(".*.part")]


def test_output_folders_are_checked_before_anything_prints(tmp_path, good):
    for opt in ("--media-out", "--preview", "--report", "--log-json", "--event-log"):
        r = cli("print", good, opt, tmp_path / "no" / "such" / "f.x")
        assert r.returncode == 2, opt
        assert f"{opt} {tmp_path}/no/such/f.x: no folder {tmp_path}/no/such" in r.err
    r = cli("rip", good, "-o", tmp_path / "nope" / "p.tif")
    assert r.returncode == 2 and "no folder" in r.err
    r = cli("print", good, "--preview", tmp_path)
    assert r.returncode == 2 and f"--preview {tmp_path} is a folder, not a file" in r.err
    assert list(tmp_path.iterdir()) == []


def test_media_name_with_braces(tmp_path, good):
    r = cli("print", good, good, "--size", "pixels", "--media-out", tmp_path / "m{x}_{job}.tif")
    assert r.returncode == 0, r.err
    assert (tmp_path / "m{x}_1.tif").exists() and (tmp_path / "m{x}_2.tif").exists()


# -- ICC profiles -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cmyk_icc(tmp_path_factory):
    im = pyvips.Image.new_from_array(np.zeros((2, 2, 3), np.uint8)).copy(interpretation="srgb")
    p = tmp_path_factory.mktemp("icc") / "cmyk.icc"
    p.write_bytes(bytes(im.icc_transform("cmyk", input_profile="srgb").get("icc-profile-data")))
    return p


@pytest.mark.parametrize("option,kind", [("--input-icc", "missing"), ("--output-icc", "missing"),
                                         ("--input-icc", "garbage"), ("--output-icc", "truncated"),
                                         ("--input-icc", "directory")])
def test_bad_icc_is_refused_up_front_with_a_report(tmp_path, good, cmyk_icc, option, kind):
    icc = tmp_path / "profile.icc"
    if kind == "garbage":
        icc.write_bytes(b"not a profile at all, just text\n" * 8)
    elif kind == "truncated":
        icc.write_bytes(cmyk_icc.read_bytes()[:200])
    elif kind == "directory":
        icc.mkdir()
    r = cli("print", good, good, option, icc, "--report", tmp_path / "r.json")
    assert r.returncode == 2, r.err
    assert str(icc) in r.err
    reps = json.loads((tmp_path / "r.json").read_text())
    assert [x["state"] for x in reps] == ["failed", "failed"]
    assert all(x["message"].startswith("not printed: ") and str(icc) in x["message"]
               for x in reps)
    r = cli("rip", good, "-o", tmp_path / "p.tif", option, icc)
    assert r.returncode == 2 and str(icc) in r.err
    assert not (tmp_path / "p.tif").exists()


def test_icc_for_another_colour_space_fails_that_job_only(tmp_path, good, cmyk_icc):
    """A CMYK profile as --input-icc is fine for a CMYK file, wrong for an RGB one: the RGB
    job fails with the reason, the CMYK job prints, the report holds both."""
    planes = random_planes(30, 40, seed=12)
    cmyk = write_cmyk_tiff(tmp_path / "cmyk.tif", planes)
    r = cli("print", good, cmyk, "--input-icc", cmyk_icc, "--size", "pixels",
            "--media-out", tmp_path / "m.tif", "--report", tmp_path / "r.json")
    assert r.returncode == 1
    assert "input ICC profile is for CMYK, need RGB" in r.err
    reps = json.loads((tmp_path / "r.json").read_text())
    assert [x["state"] for x in reps] == ["failed", "done"]
    assert "need RGB" in reps[0]["message"]
    assert np.array_equal(read_planes(tmp_path / "m-2.tif"), planes)
