"""rip.profile: the printer profile is read and checked once, at load, into one typed
section per [section]; a bad file is refused with a message naming the file, the section,
the key and the problem."""

import dataclasses
import re
import tomllib
from pathlib import Path

import pytest
import tomlkit

from wideprint.rip import profile as P
from wideprint.rip.profile import (DEFAULT_PROFILE, Head, ProfileError, load_profile,
                                   save_calibration, spec_markdown)

ROOT = Path(__file__).resolve().parent.parent


def edited(tmp_path, edit, name="bad.toml") -> Path:
    """The default profile with `edit(doc)` applied (tomlkit: everything else as it was)."""
    doc = tomlkit.parse(DEFAULT_PROFILE.read_text())
    edit(doc)
    path = tmp_path / name
    path.write_text(tomlkit.dumps(doc))
    return path


def refused(path: Path) -> str:
    with pytest.raises(ProfileError) as exc:
        load_profile(path)
    return str(exc.value)


def delete(*keys):
    def edit(doc):
        t = doc
        for k in keys[:-1]:
            t = t[k]
        del t[keys[-1]]
    return edit


def put(*keys_value):
    *keys, value = keys_value

    def edit(doc):
        t = doc
        for k in keys[:-1]:
            t = t[k]
        t[keys[-1]] = value
    return edit


def head(i, **kv):
    def edit(doc):
        for k, v in kv.items():
            doc["layout"]["heads"][i][k] = v
    return edit


# (edit, what the message says after "<file>: ")
BAD = {
    # missing section / key
    "missing section": (delete("feed"),
                        "[feed]: missing section (keys: steps_per_rev, gear_ratio, roller_radius_mm"),
    "missing key": (delete("feed", "steps_per_rev"),
                    "[feed] steps_per_rev: missing required key (an integer > 0)"),
    "missing heads": (delete("layout", "heads"), "[layout] heads: missing required key"),
    "missing head key": (lambda d: d["layout"]["heads"][3].remove("y_rows"),
                         "[layout] heads[3].y_rows: missing required key (an integer >= 0)"),
    "missing speed": (delete("carriage", "speed_mm_s", "600"),
                      "[carriage] speed_mm_s: no value for dpi 600 (every dpi mode needs one)"),
    # wrong type
    "string for a number": (put("carriage", "accel_mm_s2", "fast"),
                            '[carriage] accel_mm_s2: must be a number > 0, not "fast"'),
    "bool for an integer": (put("feed", "steps_per_rev", True),
                            "[feed] steps_per_rev: must be an integer > 0, not true"),
    "float for an integer": (put("feed", "steps_per_rev", 800.5),
                             "[feed] steps_per_rev: must be an integer > 0, not 800.5"),
    "number for a bool": (put("fpga", "starve_guard", 1),
                          "[fpga] starve_guard: must be true or false, not 1"),
    "number for a string": (put("printer", "name", 3400),
                            "[printer] name: must be a non-empty string, not 3400"),
    "table for a list": (put("encoder", "dpi_modes", {"a": 1}),
                         "[encoder] dpi_modes: must be a non-empty list of integers > 0, "
                         "not { a = 1 }"),
    "list item type": (put("encoder", "dpi_modes", [150, "300"]),
                       '[encoder] dpi_modes[1]: must be an integer > 0, not "300"'),
    "head not a table": (lambda d: d["layout"]["heads"].__setitem__(0, 5),
                            "[layout] heads[0]: must be a table { name, color, x_counts, y_rows }, "
                            "not 5"),
    # out of range
    "negative speed": (put("carriage", "speed_mm_s", "300", -660.0),
                       "[carriage] speed_mm_s.300: must be a number > 0, not -660.0"),
    "zero steps_per_rev": (put("feed", "steps_per_rev", 0),
                           "[feed] steps_per_rev: must be an integer > 0, not 0"),
    "negative margin": (put("paper", "margin_mm", -1),
                        "[paper] margin_mm: must be a number >= 0, not -1"),
    "zero timeout": (put("link", "response_timeout_s", 0.0),
                     "[link] response_timeout_s: must be a number > 0, not 0.0"),
    "infinite accel": (put("carriage", "accel_mm_s2", float("inf")),
                       "[carriage] accel_mm_s2: must be a number > 0, not inf"),
    "ink limit": (put("color", "ink_limit_percent", 500),
                  "[color] ink_limit_percent: must be a number > 0 and <= 400, not 500"),
    "quadrature": (put("encoder", "quadrature", 3), "[encoder] quadrature: must be one of 1, 2, 4, not 3"),
    "nozzles": (put("head", "nozzles", 256), "[head] nozzles: must be 128, not 256"),
    "fifo words": (put("fpga", "fifo_words", 100),
                   "[fpga] fifo_words: must be an integer > 0 and a multiple of 8, not 100"),
    "curve point": (put("curves", "C", [[0, 0], [128, 300], [255, 255]]),
                    "[curves] C[1]: must be a number in 0..255, not 300"),
    "curve order": (put("curves", "K", [[0, 0], [128, 100], [100, 255]]),
                    "[curves] K[2]: in must increase: [100, 255] follows [128, 100]"),
    "feed profile": (put("feed", "profile", "scurve"),
                     '[feed] profile: must be one of "trapezoid", "sigmoid", not "scurve"'),
    "intent": (put("color", "intent", "vivid"),
               '[color] intent: must be one of "perceptual", "relative", "saturation", '
               '"absolute", not "vivid"'),
    # consistency
    "dpi not dividing": (put("encoder", "dpi_modes", [150, 300, 400]),
                         "[encoder] dpi_modes[2]: 400 does not divide the 600 counts per inch "
                         "(lines_per_inch 150 x quadrature 4)"),
    "dpi twice": (put("encoder", "dpi_modes", [150, 300, 300]),
                  "[encoder] dpi_modes: 300 is listed twice"),
    "no dpi modes": (put("encoder", "dpi_modes", []),
                     "[encoder] dpi_modes: must be a non-empty list of integers > 0, not []"),
    "head colour unknown": (head(2, color="G"),
                            '[layout] heads[2].color: must be one of "C", "M", "Y", "K", not "G"'),
    "colours uneven": (head(1, color="M"), "[layout] heads: every colour needs the same number "
                                           "of heads, not C: 1, M: 3, Y: 2, K: 2"),
    "head name twice": (head(1, name="C1"), '[layout] heads[1].name: "C1" is used by two heads'),
    "x offset off the grid": (head(3, x_counts=1801),
                              "[layout] heads[3].x_counts: must be a multiple of 4 (whole columns "
                              "at 150 dpi), not 1801"),
    "rows overlap": (head(1, y_rows=0), "[layout] heads: heads C1 and C2 print the same row"),
    "no common row": (lambda d: [head(i, y_rows=600 + i % 2)(d) for i in (6, 7)],
                      "[layout] heads: no row that every colour can print"),
    "too many heads": (lambda d: d["layout"]["heads"].extend(
        [{"name": f"{c}3", "color": c, "x_counts": 4800, "y_rows": 2} for c in "CMYK"]),
                       "[layout] heads: the FPGA has 8 head channels, not 12"),
    "dead nozzle head": (put("layout", "dead_nozzles", [{"head": "Z9", "nozzle": 3}]),
                         '[layout] dead_nozzles[0].head: no head "Z9" (heads: C1, C2, M1'),
    "dead nozzle number": (put("layout", "dead_nozzles", [{"head": "M1", "nozzle": 127}]),
                           "[layout] dead_nozzles[0].nozzle: must be a nozzle that fires, 0..127 "
                           "but not 0, 127 (dead_end_nozzles), not 127"),
    "bidir mode": (put("layout", "bidir_offset_columns", "450", 1),
                   "[layout] bidir_offset_columns.450: not a dpi mode ([encoder] dpi_modes: "
                   "150, 300, 600)"),
    "speed mode": (put("carriage", "speed_mm_s", "1200", 100.0),
                   "[carriage] speed_mm_s.1200: not a dpi mode"),
    "dead-end nozzle": (put("head", "dead_end_nozzles", [0, 128]),
                        "[head] dead_end_nozzles[1]: must be a nozzle 0..127, not 128"),
    "config file": (put("head", "config_file", "heads/nope.hex"),
                    "[head] config_file: no such file"),
    "temperatures": (put("head", "nominal_temp_c", 60.0),
                     "[head] nominal_temp_c: must be below overtemp_c (55.0), not 60.0"),
    "park": (put("carriage", "park_counts", 92004),
             "[carriage] park_counts: must be <= rail_counts (92000), not 92004"),
    "coarse feed": (put("feed", "roller_radius_mm", 300.0),
                    "[feed] steps_per_rev, gear_ratio, roller_radius_mm: a feed step (235.6 um) "
                    "is coarser than half a row (34.3 um)"),
    "block": (put("fpga", "block_fires", 64),
              "[fpga] block_fires: a data block of 64 fires (512 words) must fit fifo_words + "
              "pass_buffer_words (256 words)"),
    "almost empty": (put("fpga", "almost_empty_words", 256),
                     "[fpga] almost_empty_words: must be below fifo_words (256), not 256"),
    "margins": (put("paper", "margin_mm", 1700.0),
                "[paper] margin_mm: two margins of 1700.0 mm leave nothing of the 3400.0 mm "
                "print width"),
    # typos
    "unknown key": (put("carriage", "acel_mm_s2", 2000.0),
                    "[carriage] acel_mm_s2: unknown key (known keys: rail_counts, home_counts, "
                    "park_counts, max_speed_mm_s, accel_mm_s2, speed_mm_s, motor_ke"),
    "unknown head key": (head(0, colour="C"),
                         "[layout] heads[0].colour: unknown key (known keys: name, color, "
                         "x_counts, y_rows); did you mean color?"),
    "unknown section": (put("carrige", {"speed": 1}),
                        "[carrige]: unknown section (known sections: printer, encoder, head, "
                        "layout, carriage, feed, fpga, link, paper, color, curves, maintenance, "
                        "physical); "
                        "did you mean [carriage]?"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_profile_is_refused_naming_file_section_and_key(tmp_path, case):
    edit, says = BAD[case]
    path = edited(tmp_path, edit)
    msg = refused(path)
    assert msg.startswith(f"{path}: {says}"), msg


def test_unknown_key_suggests_the_near_one(tmp_path):
    msg = refused(edited(tmp_path, put("carriage", "acel_mm_s2", 2000.0)))
    assert msg.endswith("; did you mean accel_mm_s2?"), msg


def test_a_section_that_is_not_a_table(tmp_path):
    path = tmp_path / "flat.toml"
    path.write_text("link = 5\n" + DEFAULT_PROFILE.read_text().replace("[link]", "[unused]"))
    assert refused(path) == f"{path}: [unused]: unknown section (known sections: printer, " \
        "encoder, head, layout, carriage, feed, fpga, link, paper, color, curves, maintenance, " \
        "physical)"
    path.write_text("link = 5\n" + re.sub(r"(?s)\[link\].*?(?=\[paper\])", "", DEFAULT_PROFILE.read_text()))
    assert refused(path) == f"{path}: [link]: must be a table of keys, not 5"


def test_unreadable_files(tmp_path):
    assert refused(tmp_path / "none.toml") == f"{tmp_path / 'none.toml'}: printer profile not found"
    broken = tmp_path / "broken.toml"
    broken.write_text("[printer\nname = 1\n")
    assert refused(broken).startswith(f"{broken}: not a valid TOML printer profile (")


# -- the default profile, typed ----------------------------------------------------------------
def test_every_value_of_the_default_profile_comes_through_typed():
    prof = load_profile()
    doc = tomllib.loads(DEFAULT_PROFILE.read_text())
    assert set(doc) == set(P.SECTIONS)
    assert not hasattr(prof, "raw")
    for name, table in doc.items():
        section = getattr(prof, name)
        assert isinstance(section, P.SECTIONS[name]) and dataclasses.is_dataclass(section)
        types = {f.name: f.type for f in dataclasses.fields(section)}
        for key, value in table.items():
            got = getattr(section, key)
            if key == "heads":
                assert got == tuple(Head(i, **h) for i, h in enumerate(value))
            elif key == "dead_nozzles":
                assert got == frozenset() and value == []
            elif isinstance(value, dict):           # dpi tables
                assert got == {int(k): v for k, v in value.items()}
                assert all(type(k) is int for k in got)
                assert all(type(v) is (float if "float" in types[key] else int) for v in got.values())
            elif isinstance(value, list):
                assert got == tuple(tuple(v) if isinstance(v, list) else v for v in value)
                assert isinstance(got, tuple)
            else:
                assert got == value, (name, key)
                assert type(got).__name__ in types[key], (name, key, types[key])
    # frozen
    with pytest.raises(dataclasses.FrozenInstanceError):
        prof.carriage.accel_mm_s2 = 1.0


def test_the_default_profile_by_name():
    p = load_profile()
    assert p.printer.name == "WP-3400 (thesis machine, 8 x XJ128-360)" == p.name
    assert p.printer.print_width_mm == 3400.0 == p.print_width_mm
    assert p.encoder.lines_per_inch == 150 and p.encoder.quadrature == 4
    assert p.encoder.counts_per_inch == 600 == p.counts_per_inch
    assert p.encoder.dpi_modes == (150, 300, 600) == p.dpi_modes
    assert p.head.nozzles == 128 and p.head.dead_end_nozzles == (0, 127)
    assert p.head.nozzle_pitch_um == 137.1 and p.head.max_fire_hz == 8300.0 and p.head.phases == 3
    assert p.head.config_path == P.RESOURCES / "heads" / "xj128_config.hex"
    assert (p.head.overtemp_c, p.head.nominal_temp_c) == (55.0, 35.0)
    assert [h.name for h in p.layout.heads] == ["C1", "C2", "M1", "M2", "Y1", "Y2", "K1", "K2"]
    assert p.layout.heads[7] == Head(7, "K2", "K", 4200, 1) and p.layout.heads_per_color == 2
    assert p.layout.dead_nozzles == frozenset() and p.layout.bidir_offset_columns == {150: 0, 300: 0, 600: 0}
    c = p.carriage
    assert c.speed_mm_s[300] == 660.0 and c.speed_mm_s[600] == 330.0
    assert (c.rail_counts, c.home_counts, c.park_counts) == (92000, 0, 600)
    assert (c.max_speed_mm_s, c.accel_mm_s2) == (660.0, 2000.0)
    assert (c.motor_ke, c.motor_kt, c.torque_constant, c.motor_r_ohm, c.motor_l_h) == (
        0.0287, None, 0.0287, 1.89, 0.00156)
    assert (c.supply_v, c.current_limit_a, c.inertia_kg_m2, c.friction_nm) == (19.1, 2.0, 1e-4, 0.0)
    assert (c.pulley_diameter_mm, c.servo_period_s, c.kp, c.ti_s) == (10.0, 0.001, 32.0, 1.32)
    f = p.feed
    assert (f.steps_per_rev, f.gear_ratio, f.roller_radius_mm) == (800, 10.0, 30.0)
    assert (f.max_steps_s, f.accel_steps_s2, f.profile) == (4000.0, 40000.0, "trapezoid")
    assert f.um_per_step == pytest.approx(23.562, abs=1e-3) == p.feed_um_per_step
    g = p.fpga
    assert (g.fifo_words, g.almost_empty_words, g.pass_buffer_words) == (256, 64, 0)
    assert (g.dma_ring_blocks, g.block_fires, g.starve_guard) == (2, 16, True)
    assert (p.fifo_words, p.ring_blocks, p.block_fires, p.pass_buffer_words) == (256, 2, 16, 0)
    assert (p.link.baud, p.link.retries, p.link.response_timeout_s) == (57600, 3, 0.25)
    assert (p.paper.default_width_mm, p.paper.margin_mm) == (3200.0, 5.0)
    assert (p.color.ink_limit_percent, p.color.intent) == (300.0, "relative")
    assert p.curves.C == ((0.0, 0.0), (255.0, 255.0)) == p.curves.K
    # the derived grid is unchanged
    assert p.row_um == pytest.approx(68.55) and p.swath_rows == 256 and p.usable_slots() == (2, 254)
    assert p.k(300) == 2 and p.speed_counts_s(300) == 15590 and p.accel_counts_s2() == 47244
    assert p.rail_counts == 92000 and len(p.head_config_digits()) == 1020


def test_defaults_are_the_default_profiles_values(tmp_path):
    """Every key that has a default can be left out; the defaults are what default.toml
    writes (except the ink limit, which is off unless given)."""
    def strip(doc):
        for name, cls in P.SECTIONS.items():
            for f in dataclasses.fields(cls):
                if f.metadata["default"] is not P._REQUIRED and name in doc:
                    doc[name].pop(f.name, None)
            if name in doc and not doc[name]:
                del doc[name]
    path = edited(tmp_path, strip, "lean.toml")
    doc = tomllib.loads(path.read_text())
    assert "color" not in doc and "curves" not in doc and "quadrature" not in doc["encoder"]
    lean, full = load_profile(path), load_profile()
    for name in P.SECTIONS:
        if name != "color":
            assert getattr(lean, name) == getattr(full, name), name
    assert lean.color.ink_limit_percent is None and lean.color.intent == "relative"


def test_ints_are_accepted_for_numbers(tmp_path):
    p = load_profile(edited(tmp_path, put("feed", "max_steps_s", 4000), "int.toml"))
    assert p.feed.max_steps_s == 4000.0 and type(p.feed.max_steps_s) is float


def test_optional_servo_keys(tmp_path):
    def edit(doc):
        doc["carriage"]["motor_kt"] = 0.03
        doc["carriage"]["friction_nm"] = 0.002
    p = load_profile(edited(tmp_path, edit, "servo.toml"))
    assert p.carriage.torque_constant == 0.03 and p.carriage.friction_nm == 0.002
    from wideprint.device_sim.servo import ServoParams
    s = ServoParams.from_profile(p)
    assert (s.kt, s.ke, s.friction_nm) == (0.03, 0.0287, 0.002)


# -- save_calibration checks through the same reader -------------------------------------------
def test_save_calibration_refuses_what_would_not_load(tmp_path):
    user = tmp_path / "user.toml"
    user.write_text(DEFAULT_PROFILE.read_text())
    before = user.read_text()
    with pytest.raises(ProfileError) as exc:
        save_calibration(user, head_x_counts={"M1": 1203})
    assert str(exc.value) == (f"{user}: [layout] heads[2].x_counts: must be a multiple of 4 "
                              f"(whole columns at 150 dpi), not 1203")
    with pytest.raises(ProfileError, match=r"\[layout\] bidir_offset_columns.450: not a dpi mode"):
        save_calibration(user, bidir_offset_columns={450: 1})
    assert user.read_text() == before and not list(tmp_path.glob("*.tmp"))


def test_save_calibration_adds_a_missing_bidir_table(tmp_path):
    user = edited(tmp_path, delete("layout", "bidir_offset_columns"), "user.toml")
    assert load_profile(user).bidir_offset_columns == {150: 0, 300: 0, 600: 0}
    assert save_calibration(user, bidir_offset_columns={300: 2}).bidir_offset_columns == {
        150: 0, 300: 2, 600: 0}


# -- one place ---------------------------------------------------------------------------------
def test_no_profile_raw_look_ups_outside_the_profile_module():
    pattern = re.compile(r"\.raw\b(?!\w)|\braw\[\"(printer|encoder|head|layout|carriage|feed|"
                         r"fpga|link|paper|color|curves)\"\]")
    hits = []
    for path in ROOT.rglob("*.py"):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith((".", "rip/profile.py", "tests/test_profile.py")) or "/." in rel:
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line) and "rotate.raw" not in line:
                hits.append(f"{rel}:{n}: {line.strip()}")
    assert not hits, hits


def test_the_spec_table_in_the_docs_is_current():
    """docs/geometry.md carries spec_markdown()'s table: regenerate it after changing a key."""
    assert spec_markdown() in (ROOT / "docs" / "geometry.md").read_text()
    for name, cls in P.SECTIONS.items():
        for f in dataclasses.fields(cls):
            assert f"`[{name}] {f.name}`" in spec_markdown()
