"""A job's media through every front end (docs/media.md "A job's media"): the `media`
setting of the one schema names an entry of the library, and the print server resolves it
from its own library exactly as `wideprint print --media` does on the command line."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from wideprint.app.client import ApiError, Client
from wideprint.rip.planes import read_planes

SHIPPED = Path(__file__).resolve().parent.parent / "resources" / "media" / "vinyl-300"


def dark_rgb(path: Path) -> Path:
    """Deep colours, where a 150 % total ink limit must cut ink the 260 % one leaves."""
    y, x = np.mgrid[0:48, 0:96]
    rgb = np.stack([(x * 2) % 90, (y * 3) % 80, ((x + y) * 2) % 70], axis=2).astype(np.uint8)
    Image.fromarray(rgb, "RGB").save(path)
    return path


def thin_media(library: Path) -> None:
    """A copy of the shipped entry with a 150 % total ink limit, in a user library."""
    dest = library / "thin-300"
    shutil.copytree(SHIPPED, dest)
    toml = dest / "media.toml"
    text = toml.read_text().replace('name = "vinyl-300"', 'name = "thin-300"')
    toml.write_text(text.replace("ink_limit_percent = 260.0", "ink_limit_percent = 150.0"))


def cli_print(src: Path, out: Path, env: dict, *extra: str) -> np.ndarray:
    subprocess.run([sys.executable, "-m", "wideprint.app.cli", "print", str(src), "--device", "emulator",
                    "--size", "pixels", "--media-out", str(out), *extra],
                   check=True, env=env, capture_output=True, timeout=120)
    return read_planes(out)


@pytest.fixture
def server(tmp_path):
    from wideprint.app.server import PrintServer, ServerConfig
    state = tmp_path / "state"
    thin_media(state / "media")
    srv = PrintServer(ServerConfig(state_dir=state, media_dir=tmp_path / "printed", port=0))
    srv.start()
    client = Client(srv.state_dir)
    yield srv, client, tmp_path
    client.close()
    srv.stop(timeout=5)


def test_a_server_job_prints_its_media_as_the_command_line_does(server):
    srv, client, tmp = server
    src = dark_rgb(tmp / "dark.png")
    job = client.submit(src, settings={"media": "thin-300", "placement": {"size": "pixels"}})["job"]
    done = client.wait(job["id"], 120)
    assert done["state"] == "done", done
    assert done["settings"]["media"] == "thin-300"
    served = read_planes(tmp / "printed" / f"job-{job['id']}.tif")

    env = {**os.environ, "WIDEPRINT_MEDIA_DIR": str(srv.state_dir / "media")}
    same = cli_print(src, tmp / "cli.tif", env, "--media", "thin-300")
    plain = cli_print(src, tmp / "plain.tif", env)
    assert np.array_equal(served, same)
    # the media's 150 % limit, not the default's 260 %: fewer drops where the colour is deep
    assert (served > 0).sum() < 0.8 * (plain > 0).sum()
    assert (served > 0).sum(axis=2).mean() <= 1.5 + 0.02    # 150 % of one channel, halftoned


def test_a_request_naming_a_media_the_server_lacks_is_refused(server):
    srv, client, tmp = server
    src = dark_rgb(tmp / "dark.png")
    with pytest.raises(ApiError) as err:
        client.submit(src, settings={"media": "no-such-paper"})
    assert err.value.status == 400
    assert "no media 'no-such-paper'" in str(err.value) and "thin-300" in str(err.value)
    with pytest.raises(ApiError) as err:
        client.submit(src, settings={"media": "../etc"})
    assert err.value.status == 400 and "media name" in str(err.value)


def test_the_python_api_applies_a_media_as_the_command_line_does(tmp_path, monkeypatch):
    from wideprint.app import api
    library = tmp_path / "library"
    thin_media(library)
    monkeypatch.setenv("WIDEPRINT_MEDIA_DIR", str(library))
    src = dark_rgb(tmp_path / "dark.png")
    planes = api.rip(src, {"media": "thin-300"}, size="pixels")
    env = {**os.environ, "WIDEPRINT_MEDIA_DIR": str(library)}
    r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "rip", str(src), "-o",
                        str(tmp_path / "cli.tif"), "--size", "pixels", "--media", "thin-300"],
                       env=env, capture_output=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert np.array_equal(planes, read_planes(tmp_path / "cli.tif"))
    assert not np.array_equal(planes, api.rip(src, size="pixels"))
