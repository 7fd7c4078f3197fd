"""A noisy serial line (docs/driver.md, "A noisy serial line"): the seed's rule stays (3
tries of a frame, then a link error and a reconnect), but the host measures the line's bit
error rate, sizes the head-configuration frames to it, resumes the configuration where the
printer acknowledged it, and reconnects as long as the link makes progress.  At a bit error
rate of 1e-3 in both directions every job prints bit-exact; where the protocol cannot work
the job fails saying so, with the measured rate; never a wrong dot."""

import random
import subprocess
import sys

import numpy as np
import pytest

from support.images import PX, random_planes, write_cmyk_tiff
from wideprint.app.devices import close_device, open_device
from wideprint.device_sim.faults import Faults
from wideprint.driver import protocol as P
from wideprint.driver.device import config_chunk_digits
from wideprint.driver.job import JobError, PrintJob
from wideprint.driver.link import LineQuality
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes


def test_the_estimator_recovers_the_bit_error_rate():
    rng = random.Random(5)
    for p in (1e-4, 1e-3, 5e-3):
        q = LineQuality()
        for _ in range(LineQuality.WINDOW):
            bits = rng.choice((140, 580, 460, 200))          # the protocol's frame mix
            q.record(bits, rng.random() < (1 - p) ** bits)
        assert 0.6 * p < q.bit_error_rate() < 1.6 * p, (p, q.bit_error_rate())
    clean = LineQuality()
    for _ in range(50):
        clean.record(500, True)
    assert clean.bit_error_rate() == 0 and clean.frame_success(64) == 1


def test_configuration_frames_shrink_with_the_noise():
    sizes = [config_chunk_digits(p) for p in (0, 1e-5, 1e-4, 5e-4, 1e-3, 1e-2)]
    assert sizes[0] == sizes[1] == 400                    # a clean line: the largest frames
    assert sizes == sorted(sizes, reverse=True) and sizes[-1] == 8
    for p, n in zip((5e-4, 1e-3), sizes[3:5]):            # a try succeeds 3 times in 4
        frame_bits = 10 * (2 * P.FRAME_OVERHEAD + 2 + 3 + n // 2)
        assert (1 - p) ** frame_bits >= 0.75


def test_a_configuration_chunk_resent_is_harmless(profile):
    dev = open_device("emulator", profile)
    try:
        link = dev.link
        dev.connect()
        assert link.call(P.Op.HEAD_CONFIG_DATA, first=0, digits=(1, 2, 3, 4)).held == 4
        assert link.call(P.Op.HEAD_CONFIG_DATA, first=4, digits=(5, 6)).held == 6
        # the answer was lost: the host sends the chunk again
        assert link.call(P.Op.HEAD_CONFIG_DATA, first=4, digits=(5, 6)).held == 6
        assert link.call(P.Op.HEAD_CONFIG_DATA, first=2, digits=(9, 8)).held == 4  # rewrites
        assert dev.emulator.dsp.config_digits == [1, 2, 9, 8]
        from wideprint.driver.link import DeviceError
        with pytest.raises(DeviceError, match="BAD_ARGUMENT"):                    # a gap
            link.call(P.Op.HEAD_CONFIG_DATA, first=5, digits=(1, 2))
    finally:
        close_device(dev)


def _print(tmp_path, profile, faults, planes):
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    dev = open_device("emulator", profile, faults, media_path=str(tmp_path / "m.tif"))
    try:
        job = PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, passes=2, bidir=True), profile))
        return job, job.run(), dev
    finally:
        close_device(dev)


@pytest.mark.parametrize("seed", [3, 7, 11, 19])
def test_bit_error_rate_1e3_both_ways_prints_bit_exact(tmp_path, profile, seed):
    planes = random_planes(700, 900, seed=seed)
    job, rep, dev = _print(tmp_path, profile, Faults(serial_ber=1e-3, seed=seed), planes)
    assert rep.state == "done" and rep.retries > 0
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)
    assert dev.emulator.jobs_done[1]["stray"] == 0
    assert 3e-4 < dev.link.quality.bit_error_rate() < 3e-3      # it measured the line
    lines = [e["stroke"] for e in dev.emulator.events if e["event"] == "line"]
    assert len(lines) == len(set(lines))                       # no stroke printed twice


def test_a_line_that_cannot_work_is_named_with_its_rate(tmp_path, profile):
    planes = random_planes(200, 200, seed=1)
    with pytest.raises(JobError, match=r"too noisy: measured bit error rate \d\.\de-0[23]"):
        _print(tmp_path, profile, Faults(serial_ber=1e-2, seed=2), planes)
    assert not (tmp_path / "m.tif").exists() or not read_planes(tmp_path / "m.tif").any()


def test_an_open_but_silent_port_is_exit_3(tmp_path):
    """A pseudo-terminal nobody answers on, and a data port that accepts but never
    answers: the printer cannot be reached (exit 3), said in one line, no traceback."""
    import os
    import socket
    master, slave = os.openpty()
    data = socket.socket()
    data.bind(("127.0.0.1", 0))
    data.listen(1)
    try:
        src = write_cmyk_tiff(tmp_path / "in.tif", random_planes(20, 20))
        spec = f"serial={os.ttyname(slave)},data=tcp://127.0.0.1:{data.getsockname()[1]}"
        r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "print", str(src),
                            "--device", spec], capture_output=True, text=True, timeout=60)
    finally:
        os.close(master)
        os.close(slave)
        data.close()
    assert r.returncode == 3, r.stdout + r.stderr
    assert "no printer answered" in r.stderr and "Traceback" not in r.stderr
