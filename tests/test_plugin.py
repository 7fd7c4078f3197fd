"""The pytest plugin and the stable API used the way an outside project uses them: a
throw-away project outside the repository, one acceptance test file, pytest in a
subprocess (the plugin comes in through the package's pytest11 entry point)."""

import subprocess
import sys
import textwrap

import numpy as np
import tifffile

TEST_FILE = '''
import numpy as np
import tifffile
import pytest
from wideprint.app import api
from wideprint.app.pytest_plugin import assert_media_equals_planes, assert_fault

@pytest.fixture
def image(tmp_path):
    rng = np.random.default_rng(7)
    path = tmp_path / "in.tif"
    tifffile.imwrite(path, (rng.random((150, 300, 4)) < 0.25).astype(np.uint8) * 255,
                     photometric="separated")
    return path

def test_prints_what_the_rip_means(print_job, wideprint_rip, image):
    result = print_job(image, passes=2, bidir=True, size="pixels")
    assert result.ok and api.API_VERSION.startswith("1.")
    assert_media_equals_planes(result, wideprint_rip(image, passes=2, bidir=True, size="pixels"))

def test_wrong_expectation(print_job, wideprint_rip, image):
    result = print_job(image, size="pixels")
    planes = wideprint_rip(image, size="pixels")
    planes[10, 20, 1] = 1 - planes[10, 20, 1]          # one magenta dot the print cannot match
    assert_media_equals_planes(result, planes)

def test_fault_is_reported(print_job, image):
    assert_fault(print_job(image, faults=["paper-length-mm=1"], size="pixels", passes=2), "paper out")
'''


def test_plugin_from_an_outside_project(tmp_path):
    project = tmp_path / "shop-acceptance"
    project.mkdir()
    (project / "test_shop.py").write_text(textwrap.dedent(TEST_FILE))
    artifacts = tmp_path / "artifacts"
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        f"--wideprint-artifacts={artifacts}", f"--junit-xml={tmp_path / 'j.xml'}"],
                       cwd=project, capture_output=True, text=True, timeout=300)
    out = r.stdout + r.stderr
    assert r.returncode == 1, out                               # one test fails, on purpose
    assert "2 passed, 1 failed" in out or "1 failed, 2 passed" in out, out
    assert "1 dots differ between media and planes" in out, out
    assert "M: media" in out and "(10, 20, M:" in out, out          # the first differing dot
    diff = list(artifacts.rglob("diff.png"))
    assert len(diff) == 1 and "test_wrong_expectation" in str(diff[0]), out
    img = __import__("cv2").imread(str(diff[0]))
    assert img is not None and (img == (0, 0, 255)).all(axis=-1).any()     # the missing dot, red
    assert 'tests="3"' in (tmp_path / "j.xml").read_text()


def test_the_sample_suite_passes(tmp_path):
    r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "acceptance",
                        "--junit-xml", str(tmp_path / "acceptance.xml")],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    xml = (tmp_path / "acceptance.xml").read_text()
    assert 'failures="0"' in xml and 'errors="0"' in xml


def test_api_compare_explains(tmp_path):
    from wideprint.app import api
    a = np.zeros((4, 5, 4), np.uint8)
    b = a.copy()
    b[1, 2, 3] = 1
    cmp = api.compare(a, b)
    assert not cmp.equal and cmp.missing == [0, 0, 0, 1] and cmp.first == [(1, 2, "K", 0, 1)]
    assert "1 missing" in cmp.explain()
    path = tmp_path / "x.tif"
    tifffile.imwrite(path, b, photometric="separated")
    assert api.compare(path, b).equal
