"""The one settings schema (rip/settings.py): its checks, and that the command line, the
server's validation and the GUI all take their options and choices from it."""

from __future__ import annotations

import argparse
import dataclasses
import re

import pytest

from wideprint.rip import settings as S
from wideprint.rip.place import Placement
from wideprint.rip.profile import load_profile


def _options(help_text: str) -> set[str]:
    return set(re.findall(r"(--[a-z][a-z0-9-]+)", help_text))


def _subparser_help(name: str) -> str:
    from wideprint.app.cli import build_parser
    ap = build_parser()
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name].format_help()


def test_submit_lists_every_print_option():
    schema_flags = {s.flag for s in S.SETTINGS} | {"--no-" + s.flag[2:] for s in S.SETTINGS
                                                   if s.kind is bool}
    for cmd in ("print", "rip", "submit"):
        missing = schema_flags - _options(_subparser_help(cmd))
        assert not missing, f"`wideprint {cmd} --help` lacks {sorted(missing)}"
    # and nothing print offers for the RIP is missing from submit
    rip_group = lambda text: _options(text.split("RIP settings")[1])   # noqa: E731
    assert rip_group(_subparser_help("print")) == rip_group(_subparser_help("submit"))


def test_dataclasses_follow_the_declarations():
    rs = S.RipSettings()
    for s in S.SETTINGS:
        obj = rs.placement if s.group == "placement" else rs
        assert getattr(obj, s.name) == s.default, s.name
    assert {f.name for f in dataclasses.fields(Placement)} == set(S.PLACEMENT_KEYS)


def test_command_line_gives_only_what_was_typed():
    ap = argparse.ArgumentParser()
    S.add_arguments(ap)
    assert S.mapping_from_args(ap.parse_args([])) == {}
    args = ap.parse_args(["--dpi", "150", "--passes", "4", "--no-bidir", "--x-mm", "-12.5",
                          "--align", "center", "--ink-limit", "280"])
    m = S.mapping_from_args(args)
    assert m == {"dpi": 150, "passes": 4, "bidir": False, "ink_limit": 280.0,
                 "placement": {"x_mm": -12.5, "align": "center"}}
    rs = S.from_mapping(m, load_profile())
    assert (rs.dpi, rs.passes, rs.bidir, rs.ink_limit) == (150, 4, False, 280.0)
    assert rs.placement.align == "center" and rs.placement.x_mm == -12.5
    assert rs.dither == "vced" and rs.placement.size == "physical"       # schema defaults


@pytest.mark.parametrize("mapping, phrase", [
    ({"speed": 3}, "unknown setting 'speed'"),
    ({"x_mm": 3}, "put it in \"placement\""),
    ({"passes": 5}, "passes must be one of 1, 2, 3, 4, 6, 8, not 5"),
    ({"passes": 2.0}, "passes must be one of"),
    ({"passes": True}, "passes must be one of"),
    ({"bidir": 1}, "bidir must be true or false"),
    ({"ink_limit": 0.5}, "ink_limit 0.5 is out of range (1..400)"),
    ({"ink_limit": float("nan")}, "ink_limit must be a finite number"),
    ({"dither": "magic"}, "dither must be one of vced, vector, dbs, fs, jarvis"),
    ({"intent": 3}, "intent must be a string"),
    ({"input_icc": 7}, "input_icc must be a string"),
    ({"placement": {"rotate": 45}}, "placement rotate must be one of 0, 90, 180, 270"),
    ({"placement": {"top_mm": -1}}, "placement top_mm must not be negative"),
    ({"placement": {"width_mm": 0}}, "placement width_mm must be a positive number"),
    ({"placement": {"size": "pixels", "scale": 2}}, "cannot be combined"),
    ({"placement": {"dpi": 300}}, "unknown placement field 'dpi'"),
    ({"placement": []}, "placement must be a JSON object"),
    ([], "settings must be a JSON object"),
])
def test_bad_settings_name_the_setting(mapping, phrase):
    with pytest.raises(S.SettingsError) as e:
        S.validate(mapping, load_profile())
    assert phrase in str(e.value)


def test_dpi_choices_come_from_the_printer_profile(tmp_path):
    from wideprint.rip.profile import DEFAULT_PROFILE
    text = DEFAULT_PROFILE.read_text()
    for a, b in (("dpi_modes = [150, 300, 600]", "dpi_modes = [150, 300]"),
                 ("{ 150 = 0, 300 = 0, 600 = 0 }", "{ 150 = 0, 300 = 0 }"),
                 ("{ 150 = 660.0, 300 = 660.0, 600 = 330.0 }", "{ 150 = 660.0, 300 = 660.0 }"),
                 ("{ 150 = 1.0, 300 = 1.0, 600 = 1.0 }", "{ 150 = 1.0, 300 = 1.0 }")):
        assert a in text
        text = text.replace(a, b)
    path = tmp_path / "two-modes.toml"
    path.write_text(text)
    prof = load_profile(path)
    assert S.setting("dpi").choices_for(prof) == (150, 300)
    S.validate({"dpi": 300}, prof)
    with pytest.raises(S.SettingsError, match=r"dpi must be one of 150, 300 \(the printer profile's modes\), not 600"):
        S.validate({"dpi": 600}, prof)
    with pytest.raises(S.SettingsError, match="dpi must be one of 150, 300"):
        S.RipSettings(dpi=600).check(prof)


def test_merge_overlays_placement_field_by_field():
    preset = {"passes": 4, "placement": {"margin_mm": 10.0, "align": "center"}}
    request = {"passes": 2, "placement": {"align": "right"}}
    assert S.merge(preset, request) == {"passes": 2, "placement": {"margin_mm": 10.0, "align": "right"}}


def test_server_validation_is_the_schema(tmp_path):
    from wideprint.app.server import Invalid, validate_settings
    prof = load_profile()
    assert validate_settings({"dpi": 150, "placement": {"x_mm": 5}}, prof) == \
        {"dpi": 150, "placement": {"x_mm": 5.0}}
    with pytest.raises(Invalid, match="pass_mask must be one of checker, random, feather"):
        validate_settings({"pass_mask": "stripes"}, prof)
    with pytest.raises(Invalid, match="is a path"):
        validate_settings({"input_icc": "../../etc/passwd"}, prof, tmp_path)


def test_help_does_not_import_the_rip_kernels():
    """`wideprint --help` and the options' choices need no numba or libvips (numpy still
    comes with the server module's imports)."""
    import subprocess
    import sys
    code = ("import sys; from wideprint.app.cli import build_parser; build_parser(); "
            "print(','.join(m for m in ('numba', 'pyvips') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
