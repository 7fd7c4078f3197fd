"""The dot coder (rip/dotdeflate.py, docs/formats.md "The dot coder"): every inflate reads
its streams back to the samples, and the planes/media files made with it open in the
common readers."""

import zlib

import imagecodecs
import numpy as np
import pytest
import tifffile
from isal import isal_zlib

from wideprint.rip import dotdeflate
from wideprint.rip.dotdeflate import deflate_dot_tile
from wideprint.rip.planes import TILE, PlanesWriter

INFLATES = {
    "zlib": zlib.decompress,
    "isal": isal_zlib.decompress,
    "libdeflate": imagecodecs.deflate_decode,
    "imagecodecs-zlib": imagecodecs.zlib_decode,
}


@pytest.mark.parametrize("density", [0.0, 0.002, 0.05, 0.25, 0.5, 0.93, 1.0])
@pytest.mark.parametrize("shape", [(64, 512), (1, 1), (3, 7), (64, 4096)])
def test_every_inflate_reads_the_samples_back(density, shape):
    rng = np.random.default_rng(int(density * 1000) + shape[1])
    samples = (rng.random((shape[0], shape[1] * 8)) < density).astype(np.uint8)
    stream = deflate_dot_tile(np.packbits(samples, axis=1))
    assert stream[:2] == b"\x78\x01"
    for name, inflate in INFLATES.items():
        assert inflate(stream) == samples.tobytes(), name


@pytest.mark.parametrize("byte", [0x00, 0x5A, 0xFF])
def test_runs_of_every_length_split_into_valid_matches(byte):
    # repeats of the byte before become matches of 8 k samples in pieces <= 258, none < 3:
    # k up to 130 crosses every split case (1,040 samples = 4 x 258 + 8)
    for k in range(1, 131):
        packed = np.concatenate([np.full(k, byte, np.uint8), [0x81, byte, byte, 0x7E]]).astype(np.uint8)
        assert zlib.decompress(deflate_dot_tile(packed)) == np.unpackbits(packed).tobytes(), k


def test_runs_are_matches_and_cost_few_bits():
    blank = deflate_dot_tile(np.zeros((64, 512), np.uint8))
    dense = deflate_dot_tile(np.packbits(np.random.default_rng(0).integers(0, 2, (64, 4096), np.uint8),
                                         axis=1))
    assert len(blank) < 1100                 # 262,144 zero samples: ~1,016 matches of 8 bits
    assert 0.14 < len(dense) / 262144 < 0.2  # half 1s: 1.5 bits a sample, no gain from runs


def test_the_block_header_declares_the_documented_code():
    lit, dist = dotdeflate._code_lengths()
    assert lit[0] == 1 and lit[1] == 2 and not any(lit[2:256])
    assert [lit[s] for s in (256, 266, 285)] == [7, 6, 6]
    assert sum(2.0 ** -n for n in lit if n) == 1.0           # complete
    assert dist == [0, 0, 0, 0, 1, 1]
    # the header's first bits: BFINAL 1, BTYPE 10, HLIT 29, HDIST 5
    assert dotdeflate._START[2] & 0b111 == 0b101
    bits = int.from_bytes(dotdeflate._START[2:].tobytes(), "little")
    assert (bits >> 3) & 31 == 29 and (bits >> 8) & 31 == 5


def _media_rows(height, width, rng, doubled=False):
    dots = (rng.random((height, width, 4)) < 0.3).astype(np.uint8)
    dots[:, : width // 3] = 0                          # blank paper tiles
    if doubled:
        dots[50, width // 2, 1] = 2                    # a doubled dot: its band through ISA-L
    return dots


@pytest.mark.parametrize("doubled", [False, True])
def test_planes_files_open_in_every_reader(tmp_path, doubled):
    height, width = 150, 2 * TILE[1] + 37              # partial tiles in both directions
    dots = _media_rows(height, width, np.random.default_rng(3), doubled)
    path = tmp_path / "m.tif"
    with PlanesWriter(path, width, height, 300, 370.5) as w:
        for y in range(0, height, 40):
            w.write(dots[y:y + 40])
    assert np.array_equal(tifffile.imread(path), dots)
    assert w.dots.tolist() == dots.reshape(-1, 4).sum(axis=0).tolist()
    from PIL import Image
    with Image.open(path) as im:
        assert im.mode == "CMYK"
        assert np.array_equal(np.asarray(im), dots)
    import pyvips
    v = pyvips.Image.new_from_file(str(path), access="sequential")
    assert np.array_equal(np.ndarray(buffer=v.write_to_memory(), dtype=np.uint8,
                                     shape=(v.height, v.width, v.bands)), dots)
    # which coder made a tile: the dot coder's header 78 01, ISA-L level 1's 78 5E; the band
    # holding the doubled dot (rows 0..63: written with rows 40..79) goes through ISA-L
    with tifffile.TiffFile(path) as tf:
        page = tf.pages[0]
        across = -(-width // TILE[1])

        def header(band, col):
            tf.filehandle.seek(page.dataoffsets[band * across + col])
            return tf.filehandle.read(2)
        assert header(0, 1) == (b"\x78\x5e" if doubled else b"\x78\x01")
        assert header(2, 1) == b"\x78\x01"


def test_read_planes_inflates_tiles_and_names_a_bad_one(tmp_path):
    from wideprint.rip.planes import read_planes
    height, width = 130, TILE[1] + 5
    dots = _media_rows(height, width, np.random.default_rng(4))
    path = tmp_path / "m.tif"
    with PlanesWriter(path, width, height, 300, 370.5) as w:
        w.write(dots)
    assert np.array_equal(read_planes(path), dots)
    with tifffile.TiffFile(path) as tf:
        off = tf.pages[0].dataoffsets[1]
    raw = bytearray(path.read_bytes())
    raw[off + 10:off + 30] = bytes(20)                 # tile 1's stream damaged
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"m\.tif: tile 1 "):
        read_planes(path)
