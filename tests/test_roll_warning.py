"""A warning before a job runs off the roll (issue 34 part 5; docs/server.md "Rolls: the
warning"): when the roll left is less than what the jobs waiting for the printer need plus
a metre to spare, the printer carries a `media-low` warning - not a fault, nothing stops -
naming the first job the roll cannot hold; it is in GET /v1/printers and the event stream,
the GUI's printer card, the web page and IPP's printer-state-reasons, and it comes before
the worker holds that job (never half printed); a new roll ends it."""

from __future__ import annotations

import http.client
import json
import time

import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import wait_for
from wideprint.app.client import ApiError, Client
from wideprint.app.server.rolls import paper_per_copy_mm, roll_warning


def test_the_warning_names_the_first_job_the_roll_cannot_hold():
    roll = dict(media="vinyl-300", remaining_mm=2500.0)
    a, b, c = (dict(id=i, name=f"j{i}.tif") for i in (1, 2, 3))
    assert roll_warning(roll, [(a, 1000.0)]) is None                     # 1.5 m to spare
    w = roll_warning(roll, [(a, 1000.0), (b, 1000.0), (c, 1000.0)])
    assert (w["kind"], w["job"], w["remaining_m"], w["need_m"]) == ("media-low", 3, 2.5, 3.0)
    assert w["message"] == ("roll low: 2.50 m of vinyl-300 left, the 3 jobs waiting need 3.00 m; "
                            "j3.tif (job 3) will not fit: load a new roll before it prints, or "
                            "it is held")
    w = roll_warning(roll, [(a, 1000.0), (b, 1000.0)])                   # fits, 0.5 m to spare
    assert w["job"] is None and "less than 1 m to spare" in w["message"]
    assert roll_warning(dict(media="x", remaining_mm=None), [(a, 9e9)]) is None   # unknown length
    assert roll_warning(None, [(a, 9e9)]) is None


def printers_event(srv) -> list[dict]:
    """The first `printers` event of GET /v1/events."""
    conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=30)
    conn.request("GET", "/v1/events?max_s=1", headers={"Authorization": f"Bearer {srv.token}"})
    body = conn.getresponse().read().decode()
    conn.close()
    for block in body.split("\n\n"):
        if block.startswith("event: printers\n"):
            return json.loads(block.split("data: ", 1)[1])
    raise AssertionError(body)


def test_the_warning_comes_before_the_job_that_would_run_off_is_held(print_server, tmp_path):
    s = print_server(start_paused=True)
    c = Client(s.state_dir)
    try:
        files = [write_cmyk_tiff(tmp_path / f"job{i}.tif", random_planes(300, 200, seed=50 + i))
                 for i in range(3)]
        need = paper_per_copy_mm(s.profile, 300 * s.profile.row_um / 1000.0)
        length_m = round(2.5 * need / 1000, 4)          # holds two of them and a half
        c.roll("main", {"media": "vinyl-300", "length_m": length_m})
        assert c.printers()[0]["warnings"][0]["job"] is None   # < 1 m to spare, nothing waiting
        ids = [c.submit(f)["job"]["id"] for f in files]        # each fits at submission
        time.sleep(1.1)                                        # worked out once a second
        [w] = c.printers()[0]["warnings"]
        assert w["kind"] == "media-low" and w["job"] == ids[2] and w["name"] == "job2.tif"
        assert f"job2.tif (job {ids[2]}) will not fit" in w["message"]
        assert c.printers()[0]["fault"] is None and c.printers()[0]["state"] == "idle"
        assert printers_event(s)[0]["warnings"] == [w]         # the event stream carries it
        assert c.job(ids[2])["state"] == "queued"              # before it is held
        # printing: the warning stays all along, and the third job is held, not started
        c.pause_queue(False)
        seen = []

        def held():
            p = c.printers()[0]
            seen.append([x["job"] for x in p["warnings"]])
            j = c.job(ids[2])
            return j if j["state"] == "held" else None
        third = wait_for(held, 90, what="the third job held")
        assert all(x == [ids[2]] for x in seen), seen
        assert third["strokes_done"] == 0 and c.report(ids[2]) == []
        assert [c.job(i)["state"] for i in ids[:2]] == ["done", "done"]
        time.sleep(1.1)
        assert [x["job"] for x in c.printers()[0]["warnings"]] == [ids[2]]   # still said
        # a new roll ends the warning
        c.roll("main", {"media": "vinyl-300", "length_m": 50})
        time.sleep(1.1)
        assert c.printers()[0]["warnings"] == []
    finally:
        c.close()


def test_the_printer_card_shows_the_warning_in_amber_and_a_fault_first(qtbot):
    pytest.importorskip("PySide6")
    from wideprint.app.gui.printers_panel import PrinterCard
    card = PrinterCard("main")
    qtbot.addWidget(card)
    msg = "roll low: 0.40 m of vinyl-300 left (less than 1 m to spare): have a new roll ready"
    p = dict(name="main", state="idle", paused=False, fault=None, current=None,
             roll=dict(media="vinyl-300", remaining_m=0.4), printable_mm=3190.0,
             warnings=[dict(kind="media-low", message=msg, job=None)])
    card.show_info(p)
    assert card.fault.text() == "Warning: " + msg
    assert "b26a00" in card.fault.styleSheet() and "roll low" in card.state.text()
    card.show_info(dict(p, fault="paper out", state="fault"))        # the fault comes first
    assert card.fault.text().startswith("paper out") and "c62828" in card.fault.styleSheet()
    assert msg in card.fault.toolTip()
    card.show_info(dict(p, warnings=[]))
    assert card.fault.text() == "" and "roll low" not in card.state.text()


@pytest.mark.timeout(300)
def test_ipp_says_media_low_as_a_warning_the_printer_goes_on(tmp_path):
    from support.private_cups import IppServe
    from support.ipp import BINARY, IPPTOOL_DIR, attrs, ipptool
    if BINARY is None:
        pytest.fail("the Printer Application is not built (make app/ipp/wideprint-ipp)")
    (tmp_path / "ipp").mkdir()
    ipp = IppServe(tmp_path / "ipp", ["left"])
    get = IPPTOOL_DIR / "get-printer-attributes.test"
    try:
        a = attrs(ipptool(ipp.auth_uri["left"], get)["Tests"][0])
        assert a["printer-state-reasons"] == "none"
        ipp.client.roll("left", {"media": "vinyl-300", "length_m": 0.5})
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            a = attrs(ipptool(ipp.auth_uri["left"], get)["Tests"][0])
            if "media-low" in str(a["printer-state-reasons"]):
                break
            time.sleep(0.3)
        assert a["printer-state-reasons"] == "media-low", a["printer-state-reasons"]
        assert a["printer-state"] == 3                                 # idle: not stopped
        assert "severity=warning" in str(a["printer-alert"])
        assert "code=inputMediaSupplyLow" in str(a["printer-alert"])
        assert str(a["printer-alert-description"]).startswith("roll low: 0.50 m of vinyl-300 left")
        ipp.client.roll("left", {"media": "vinyl-300", "length_m": 50})
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            a = attrs(ipptool(ipp.auth_uri["left"], get)["Tests"][0])
            if a["printer-state-reasons"] == "none":
                break
            time.sleep(0.3)
        assert a["printer-state-reasons"] == "none"
    finally:
        ipp.stop()


@pytest.mark.timeout(300)
def test_the_web_page_shows_the_warning_on_the_printers_card(tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait
    from support.web import chromium
    from wideprint.app.server import PrintServer, ServerConfig
    srv = PrintServer(ServerConfig(device="emulator", state_dir=tmp_path / "state", port=0,
                                   start_paused=True))
    srv.start()
    driver = None
    try:
        Client(srv.state_dir).roll("main", {"media": "vinyl-300", "length_m": 0.5})
        driver = chromium()
        driver.get(f"http://127.0.0.1:{srv.port}/")
        wait = WebDriverWait(driver, 30, poll_frequency=0.05)
        wait.until(lambda d: d.find_element(By.ID, "login").is_displayed())
        driver.find_element(By.ID, "login-name").send_keys("Ann")
        driver.find_element(By.ID, "login-token").send_keys(srv.token)
        driver.find_element(By.ID, "login-submit").click()
        text = wait.until(lambda d: d.execute_script(
            "const e = document.querySelector('#printers .card .warning-text'); "
            "return e ? e.innerText : null"))
        assert text.startswith("Warning: roll low: 0.50 m of vinyl-300 left"), text
        assert driver.execute_script("return getComputedStyle(document.querySelector("
                                     "'#printers .card .warning-text')).color") == "rgb(178, 106, 0)"
    finally:
        if driver is not None:
            driver.quit()
        srv.stop(timeout=5)


def test_the_cli_says_the_warning_under_the_roll_and_the_printer(print_server, capsys):
    s = print_server(start_paused=True)
    from wideprint.app.cli import main
    assert main(["printer", "roll", "load", "--media", "vinyl-300", "--length", "0.5",
                 "--state-dir", str(s.state_dir)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "printer main: vinyl-300, width not measured yet, 0.50 m left of 0.50 m"
    assert out[1] == ("WARNING: roll low: 0.50 m of vinyl-300 left (less than 1 m to spare): "
                      "have a new roll ready")
    assert main(["status", "--state-dir", str(s.state_dir)]) == 0
    out = capsys.readouterr().out
    assert "printer  main: idle  [paused: started paused]\n         WARNING: roll low: 0.50 m" in out


def test_each_roll_has_its_own_spare(print_server, capsys):
    """The 1 m spare is the default; a roll may say its own (POST roll `spare_m`, `printer
    roll load|set --spare M`), 0 .. 1,000 m, kept with the roll until another is loaded."""
    s = print_server(start_paused=True)
    c = Client(s.state_dir)
    try:
        r = c.roll("main", {"media": "vinyl-300", "length_m": 2, "spare_m": 0})
        assert r["roll"]["spare_m"] == 0 and c.printers()[0]["warnings"] == []
        r = c.roll("main", {"spare_m": "3m"})                 # set on the roll loaded
        assert r["roll"]["spare_m"] == 3.0 and r["roll"]["remaining_m"] == 2.0
        [w] = c.printers()[0]["warnings"]
        assert "(less than 3 m to spare)" in w["message"]
        for bad in (-1, 1001, "lots", True):
            with pytest.raises(ApiError) as e:
                c.roll("main", {"spare_m": bad})
            assert e.value.status == 400 and "spare" in str(e.value)
        c.roll("main", {"media": "vinyl-300", "length_m": 2})  # a new roll: the default again
        assert c.roll("main")["roll"]["spare_m"] == 1.0 and c.printers()[0]["warnings"] == []
        from wideprint.app.cli import main
        capsys.readouterr()
        assert main(["printer", "roll", "set", "--spare", "2.5", "--state-dir", str(s.state_dir)]) == 0
        assert "WARNING: roll low: 2.00 m of vinyl-300 left (less than 2.5 m to spare)" in \
            capsys.readouterr().out
    finally:
        c.close()
