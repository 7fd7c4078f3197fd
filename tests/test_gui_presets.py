"""The GUI adds files with the server's presets (issue 34 part 3, "add as held (default per
preset)"; docs/gui.md "Presets"): the toolbar's preset list is the server's (GET
/v1/presets, a held preset marked), picking one makes its settings the settings for new
jobs and its "hold" default the "as held" box; a file added then is a job of that preset
- held or not as the box says - that carries only what the operator changed of the
preset's settings; the choice is remembered.  The real window against a real `wideprint
serve` (offscreen Qt, tests/support/gui.py)."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pytestqt")

from support.gui import Server, image, open_window  # noqa: E402
from wideprint.app.gui.config import GuiSettings  # noqa: E402
from wideprint.app.gui.settings_form import overrides  # noqa: E402

PRESETS = {"default": {},
           "photo": {"passes": 4, "bidir": False, "dither": "vced", "dpi": 300},
           "proof": {"passes": 1, "dpi": 150, "hold": True}}


@pytest.fixture
def server(tmp_path):
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "presets.json").write_text(json.dumps(PRESETS))
    s = Server(tmp_path, "--paused")
    yield s
    s.stop()


def test_overrides_are_what_differs_from_the_preset_placement_field_by_field():
    base = {"passes": 1, "dpi": 150, "placement": {"rotate": 90, "top_mm": 5}}
    assert overrides(base, dict(base, placement=dict(base["placement"]))) == {}
    assert overrides(base, {"passes": 2, "dpi": 150, "placement": {"rotate": 90, "top_mm": 8}}) \
        == {"passes": 2, "placement": {"top_mm": 8}}


def test_new_jobs_take_the_chosen_presets_settings_and_hold_default(qtbot, server, tmp_path):
    win = open_window(qtbot, server, tmp_path / "cfg")
    try:
        box = win.add_preset
        qtbot.waitUntil(lambda: box.count() == 4, timeout=20_000)
        assert [box.itemText(i) for i in range(box.count())] == \
            ["none", "default", "photo", "proof (held)"]
        assert box.currentData() is None and not win.add_held.isChecked()

        def added(name):
            qtbot.waitUntil(lambda: any(j["name"] == name for j in win.active), timeout=30_000)
            return next(j for j in win.active if j["name"] == name)

        # a held preset: its settings shown for new jobs, "as held" ticked
        win.choose_preset("proof")
        assert win.add_held.isChecked()
        assert (win.form.value("passes"), win.form.value("dpi")) == (1, 150)
        f1, _ = image(tmp_path, "proof-1.tif", seed=1, rows=60, cols=80)
        win.add_files([f1])
        j = added("proof-1.tif")
        assert (j["preset"], j["state"]) == ("proof", "held")
        assert (j["settings"]["passes"], j["settings"]["dpi"]) == (1, 150)
        # a setting the operator changes goes with the preset, the rest stays the preset's
        win.queue_view.clearSelection()
        win._show_selection()
        win.setting_edited("passes", 2)
        f2, _ = image(tmp_path, "proof-2.tif", seed=2, rows=60, cols=80)
        win.add_files([f2])
        j = added("proof-2.tif")
        assert (j["preset"], j["state"], j["settings"]["passes"], j["settings"]["dpi"]) == \
            ("proof", "held", 2, 150)
        # the box says otherwise: not held, though the preset holds
        win.add_held.setChecked(False)
        f3, _ = image(tmp_path, "proof-3.tif", seed=3, rows=60, cols=80)
        win.add_files([f3])
        assert added("proof-3.tif")["state"] == "queued"
        # a preset that does not hold: the box follows it
        win.choose_preset("proof")
        assert win.add_held.isChecked()
        win.choose_preset("photo")
        assert not win.add_held.isChecked()
        f4, _ = image(tmp_path, "photo-1.tif", seed=4, rows=60, cols=80)
        win.add_files([f4])
        j = added("photo-1.tif")
        assert (j["preset"], j["state"]) == ("photo", "queued")
        s = j["settings"]
        assert (s["passes"], s["bidir"], s["dither"], s["dpi"]) == (4, False, "vced", 300)
        # remembered for the next start
        qtbot.waitUntil(lambda: GuiSettings.load(win.settings_path).preset == "photo",
                        timeout=5_000)
    finally:
        win.link.stop()


def test_the_roll_warning_goes_into_the_log_once(qtbot, server, tmp_path, caplog):
    """(beside the presets: the window's other issue-34 addition) the printer card's warning
    is logged when it comes, not again as the metres go down."""
    import logging
    caplog.set_level(logging.INFO, logger="wideprint.gui")
    win = open_window(qtbot, server, tmp_path / "cfg")
    try:
        server.client.roll("main", {"media": "vinyl-300", "length_m": 0.5})
        card = win.printers_panel.cards["main"]
        qtbot.waitUntil(lambda: card.fault.text().startswith("Warning: roll low"), timeout=20_000)
        server.client.roll("main", {"remaining_m": 0.4})
        qtbot.waitUntil(lambda: "0.40 m" in card.fault.text(), timeout=20_000)
        said = [r.getMessage() for r in caplog.records if "roll low" in r.getMessage()]
        assert said == ["printer main: roll low: 0.50 m of vinyl-300 left (less than 1 m to "
                        "spare): have a new roll ready"], said
    finally:
        win.link.stop()
