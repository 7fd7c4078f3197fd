"""rip.profile.save_calibration(dead_nozzles=...): the nozzle check's write-back keeps the
file's comments and every other value, stays valid TOML and reloads to exactly the list."""

import re
import tomllib

import pytest

from wideprint.rip.profile import DEFAULT_PROFILE, ProfileError, load_profile, save_calibration


@pytest.fixture
def user(tmp_path):
    p = tmp_path / "user.toml"
    p.write_text(DEFAULT_PROFILE.read_text())
    return p


def names(prof) -> set[tuple[str, int]]:
    return {(prof.heads[h].name, z) for h, z in prof.dead_nozzles}


def without_dead(text: str) -> dict:
    doc = tomllib.loads(text)
    doc["layout"].pop("dead_nozzles", None)
    return doc


def comments(text: str) -> list[str]:
    return [ln.strip() for ln in text.splitlines() if ln.strip().startswith("#")]


def test_write_then_clear_keeps_comments_and_every_other_value(user):
    before = user.read_text()
    prof = save_calibration(user, dead_nozzles=[("K2", 3), ("M1", 57), {"head": "M1", "nozzle": 57}])
    assert names(prof) == names(load_profile(user)) == {("M1", 57), ("K2", 3)}
    text = user.read_text()
    # one line in the documented format, in head order; the example comment stays put
    line = next(ln for ln in text.splitlines() if ln.startswith("dead_nozzles"))
    assert line.startswith('dead_nozzles = [{ head = "M1", nozzle = 57 }, { head = "K2", nozzle = 3 }]')
    assert line.endswith('# e.g. [{ head = "M1", nozzle = 57 }]')
    assert comments(text) == comments(before)
    assert without_dead(text) == without_dead(before)
    assert len(text.splitlines()) == len(before.splitlines())
    # a replaced head: clear the list again
    prof = save_calibration(user, dead_nozzles=[])
    assert prof.dead_nozzles == frozenset()
    assert tomllib.loads(user.read_text())["layout"]["dead_nozzles"] == []
    assert without_dead(user.read_text()) == without_dead(before)
    assert comments(user.read_text()) == comments(before)


def test_long_lists_hand_edited_lists_and_a_missing_key(user, tmp_path):
    many = [("C1", z) for z in (5, 9, 11)] + [("Y2", 100), ("K1", 126)]
    save_calibration(user, dead_nozzles=many)
    text = user.read_text()
    assert "dead_nozzles = [\n" in text                 # one nozzle a line when there are many
    assert names(load_profile(user)) == set(many)
    # rewriting a multi-line list (ours, or one edited by hand with comments and brackets
    # inside strings and comments) replaces all of it
    text = text.replace('  { head = "C1", nozzle = 9 },\n',
                        '  { head = "C1", nozzle = 9 },   # weak since March ] [\n')
    user.write_text(text)
    save_calibration(user, dead_nozzles=[("M2", 7)])
    assert names(load_profile(user)) == {("M2", 7)}
    assert "weak since March" not in user.read_text()
    line = next(ln for ln in user.read_text().splitlines() if ln.startswith("dead_nozzles"))
    assert re.fullmatch(r'dead_nozzles = \[\{ head = "M2", nozzle = 7 \}\] +# e\.g\. \[\{.*', line)
    assert without_dead(user.read_text()) == without_dead(DEFAULT_PROFILE.read_text())
    # a profile without the key gets one in [layout]
    bare = tmp_path / "bare.toml"
    bare.write_text("".join(ln for ln in DEFAULT_PROFILE.read_text().splitlines(keepends=True)
                            if not ln.startswith("dead_nozzles")))
    assert load_profile(bare).dead_nozzles == frozenset()
    save_calibration(bare, dead_nozzles=[("M1", 57)])
    assert names(load_profile(bare)) == {("M1", 57)}
    assert without_dead(bare.read_text()) == without_dead(DEFAULT_PROFILE.read_text())


def test_together_with_the_alignment_values(user):
    prof = save_calibration(user, bidir_offset_columns={150: 2, 300: 1, 600: 0},
                            head_x_counts={"M1": 1212}, dead_nozzles=[("M1", 57)])
    assert prof.bidir_offset_columns == {150: 2, 300: 1, 600: 0}
    assert prof.heads[2].name == "M1" and prof.heads[2].x_counts == 1212
    assert names(prof) == {("M1", 57)}


@pytest.mark.parametrize("bad, match", [
    ([("Z9", 10)], "no head 'Z9'"),
    ([("M1", 0)], "M1:0: nozzles are 1..126"),
    ([("M1", 127)], "M1:127: nozzles are 1..126"),
])
def test_bad_entries_are_refused_and_the_file_is_untouched(user, bad, match):
    before = user.read_text()
    with pytest.raises(ProfileError, match=match):
        save_calibration(user, dead_nozzles=bad)
    assert user.read_text() == before
    assert not user.with_suffix(".toml.tmp").exists()
