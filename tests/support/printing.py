"""Printing in the test's process: a job on the in-process emulator, printer profiles that
differ from the default in one field (dead nozzles, head offsets, the bidirectional offset),
and the strokes' nozzle words mapped back to the image dots they land on."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wideprint.app.devices import open_device
from wideprint.driver import protocol as P
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipJob
from wideprint.rip.profile import DEFAULT_PROFILE, load_profile


def print_on_emulator(path, settings, profile, media, faults=None):
    """RIP and print `path` on the in-process emulator, its media written to `media`:
    (the job's report, the emulator)."""
    dev = open_device("emulator", profile, faults, media_path=str(media))
    try:
        rep = PrintJob(dev, RipJob(str(path), settings, profile)).run()
    finally:
        dev.emulator.close()
    return rep, dev.emulator


def variant_profile(tmp_dir: Path, dead=(), offsets=None, bidir=None, name="p"):
    """The default profile with `dead` nozzles ((head, nozzle) pairs), the heads' x offsets
    `offsets` (counts, in the heads' order) and `bidir` offsets, written to TMP/NAME.toml
    and loaded."""
    text = DEFAULT_PROFILE.read_text()
    lines = text.splitlines()
    out = []
    for line in lines:
        if line.startswith("dead_nozzles"):
            items = ", ".join(f'{{ head = "{h}", nozzle = {n} }}' for h, n in dead)
            line = f"dead_nozzles = [{items}]"
        if line.startswith("bidir_offset_columns") and bidir is not None:
            line = "bidir_offset_columns = { " + ", ".join(f'{k} = {v}' for k, v in bidir.items()) + " }"
        out.append(line)
    text = "\n".join(out) + "\n"
    if offsets is not None:
        new_heads = ",\n".join(
            f'  {{ name = "{h.name}", color = "{h.color}", x_counts = {off}, y_rows = {h.y_rows} }}'
            for h, off in zip(load_profile().heads, offsets))
        start = text.index("heads = [")
        end = text.index("]\n", start)
        text = text[:start] + "heads = [\n" + new_heads + ",\n" + text[end:]
    path = tmp_dir / f"{name}.toml"
    path.write_text(text)
    return load_profile(path)


def replay(profile, planner, strokes, height, width):
    """Map every fired nozzle back to the image dot it lands on."""
    got = np.zeros((height, width, 4), np.int32)
    k = planner.k
    hpc = profile.heads_per_color
    for sd in strokes:
        for h in profile.heads:
            bits = P.words_to_nozzles(sd.words[h.index])          # (fires, 128)
            assert not bits[:, 0].any() and not bits[:, 127].any()
            for n in range(profile.nozzles):
                if (h.index, n) in profile.dead_nozzles:
                    assert not bits[:, n].any(), f"dead nozzle {h.name}:{n} fired"
            fi, nz = np.nonzero(bits)
            if sd.direction == 0:
                t = sd.first_column + fi
            else:
                t = sd.first_column + sd.fires - 1 - fi - profile.bidir_offset_columns.get(planner.dpi, 0)
            x = t + h.x_counts // k
            r = sd.top_row + h.y_rows + hpc * nz
            assert (x >= 0).all() and (x < width).all() and (r >= 0).all() and (r < height).all()
            np.add.at(got, (r, x, h.channel), 1)
    return got
