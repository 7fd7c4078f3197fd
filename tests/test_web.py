"""The shop's web page (docs/web.md; issue 34 part 6), in a real browser and by raw HTTP.

- Debian's chromium, headless, driven through chromium-driver by Selenium: the page signs
  in with the operator's token, shows both printers, sees a job submitted behind its back
  appear live (the event stream, no reload), holds it and releases it with its buttons,
  resumes the queue and sees the job print (the printer's card) and land in the history
  and the accounting.  A wrong token gets the login form again, no cookie and no data.
  Screenshots at 1366 x 768 (`WIDEPRINT_WEB_SCREENSHOTS=DIR` keeps them: docs/screenshots/).
- The session's rules by raw HTTP: the cookie's flags, CSRF, another origin, a token
  removed ending its sessions at once, the throttle, and static files only from the table.

A missing chromium or chromium-driver fails the browser tests, naming the package."""

from __future__ import annotations

import http.client
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from support.web import chromium



# -- the server ---------------------------------------------------------------------------------
@pytest.fixture
def shop(tmp_path):
    """A server in the test's process with two emulated printers, its queue paused (jobs
    wait until the page resumes it)."""
    from wideprint.app.server import PrintServer, ServerConfig
    from wideprint.app.server.config import PrinterConfig
    srv = PrintServer(ServerConfig(
        device="emulator", state_dir=tmp_path / "state", media_dir=tmp_path / "media", port=0,
        printers=[PrinterConfig("left", "emulator"), PrinterConfig("right", "emulator")],
        start_paused=True))
    srv.start()
    yield srv
    srv.stop(timeout=5)


def banner(path: Path, w: int = 600, h: int = 150) -> Path:
    """An RGB banner (a colour ramp with a dark band), 150 dpi: 102 x 25 mm."""
    import tifffile
    x = np.linspace(0, 1, w)[None, :]
    y = np.linspace(0, 1, h)[:, None]
    img = np.stack([255 * x * np.ones_like(y), 255 * y * np.ones_like(x),
                    255 * (1 - x) * np.ones_like(y)], axis=-1).astype(np.uint8)
    img[h // 3: h // 2, w // 8: w // 2] = (20, 30, 90)
    tifffile.imwrite(path, img, photometric="rgb", resolution=(150, 150), resolutionunit="INCH")
    return path


def request(srv, method, path, body=None, headers=None):
    """(status, headers, JSON or bytes) of one raw request (no bearer token)."""
    conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=30)
    hdrs = dict(headers or {})
    data = None
    if body is not None:
        data = json.dumps(body).encode()
        hdrs.setdefault("Content-Type", "application/json")
    conn.request(method, path, body=data, headers=hdrs)
    r = conn.getresponse()
    raw = r.read()
    conn.close()
    return r.status, r.headers, json.loads(raw) if raw.startswith(b"{") else raw


def login(srv, token, name=None, headers=None):
    status, hdrs, body = request(srv, "POST", "/login", {"token": token, "name": name}, headers)
    cookie = hdrs.get("Set-Cookie")
    return status, cookie, body


# -- the session's rules (raw HTTP) ------------------------------------------------------------
def test_the_page_and_its_files_are_served_from_the_package_and_nothing_else(shop):
    from importlib import resources
    status, hdrs, body = request(shop, "GET", "/")
    assert status == 200 and hdrs["Content-Type"].startswith("text/html")
    assert body == (resources.files("wideprint.app") / "web" / "index.html").read_bytes()
    assert "script-src 'self'" in hdrs["Content-Security-Policy"]
    assert hdrs["X-Frame-Options"] == "DENY" and hdrs["X-Content-Type-Options"] == "nosniff"
    for path, ctype in (("/web/app.js", "text/javascript"), ("/web/app.css", "text/css"),
                        ("/web/favicon.svg", "image/svg+xml")):
        status, hdrs, _ = request(shop, "GET", path)
        assert status == 200 and hdrs["Content-Type"].startswith(ctype), path
    # any other path is the API's: it needs a login, and nothing is read from the disk
    for path in ("/web/../token", "/web/%2e%2e/token", "/web/index.html", "/token",
                 "/web/app.js/../../server/auth.py", "/web/"):
        status, _, _ = request(shop, "GET", path)
        assert status == 401, path
    assert request(shop, "POST", "/")[0] == 405


def test_a_login_gives_an_httponly_strict_cookie_and_a_wrong_token_nothing(shop):
    status, cookie, body = login(shop, "x" * 43)
    assert status == 401 and cookie is None and body == {"error": "wrong token"}
    status, cookie, body = login(shop, "")
    assert status == 401 and cookie is None
    status, cookie, body = login(shop, shop.token, "Ann")
    assert status == 200 and body["role"] == "operator" and body["name"] == "Ann"
    sid = cookie.split(";")[0]
    flags = {f.strip() for f in cookie.split(";")[1:]}
    assert {"HttpOnly", "SameSite=Strict", "Path=/"} <= flags, cookie
    assert shop.token not in cookie and shop.token not in json.dumps(body)
    assert "Secure" not in flags                     # plain HTTP: a Secure cookie would not come back
    _, behind_tls, _ = login(shop, shop.token, headers={"X-Forwarded-Proto": "https"})
    assert "Secure" in {f.strip() for f in behind_tls.split(";")}
    # the cookie reads the API; a change needs the session's CSRF value too
    assert request(shop, "GET", "/v1/status", headers={"Cookie": sid})[0] == 200
    s, _, _ = request(shop, "POST", "/v1/queue", {"paused": False}, {"Cookie": sid})
    assert s == 401
    s, _, _ = request(shop, "POST", "/v1/queue", {"paused": False},
                      {"Cookie": sid, "X-Wideprint-CSRF": "not-the-value"})
    assert s == 401
    csrf = {"Cookie": sid, "X-Wideprint-CSRF": body["csrf"]}
    s, _, _ = request(shop, "POST", "/v1/queue", {"paused": False},
                      dict(csrf, Origin="http://evil.example"))
    assert s == 401
    s, _, st = request(shop, "POST", "/v1/queue", {"paused": True}, csrf)
    assert s == 200 and st["queue"]["paused"] is True
    s, _, who = request(shop, "GET", "/session", headers={"Cookie": sid})
    assert s == 200 and who["csrf"] == body["csrf"] and who["role"] == "operator"
    # logging out ends the session
    s, hdrs, _ = request(shop, "POST", "/logout", {}, csrf)
    assert s == 200 and "Max-Age=0" in hdrs["Set-Cookie"]
    assert request(shop, "GET", "/v1/status", headers={"Cookie": sid})[0] == 401


def test_a_login_from_another_site_or_not_json_is_refused(shop):
    s, cookie, _ = login(shop, shop.token, headers={"Origin": "http://evil.example"})
    assert s == 403 and cookie is None
    s, cookie, _ = login(shop, shop.token, headers={"Sec-Fetch-Site": "cross-site"})
    assert s == 403 and cookie is None
    s, hdrs, _ = request(shop, "POST", "/login", None,
                         {"Content-Type": "application/x-www-form-urlencoded"})
    assert s == 415 and "Set-Cookie" not in hdrs
    s, cookie, _ = login(shop, shop.token, headers={"Origin": f"http://127.0.0.1:{shop.port}"})
    assert s == 200 and cookie


def test_a_user_session_has_the_users_role_and_ends_when_the_user_is_removed(shop):
    from wideprint.app.server.auth import add_user, remove_user
    _, token = add_user(shop.state_dir, "bob")
    s, cookie, body = login(shop, token, "someone else")
    assert s == 200 and body["role"] == "user" and body["name"] == "bob"
    sid = cookie.split(";")[0]
    csrf = {"Cookie": sid, "X-Wideprint-CSRF": body["csrf"]}
    s, _, err = request(shop, "POST", "/v1/queue", {"paused": False}, csrf)
    assert s == 403 and "operator" in err["error"]
    assert request(shop, "GET", "/v1/jobs", headers={"Cookie": sid})[0] == 200
    remove_user(shop.state_dir, "bob")
    deadline = time.monotonic() + 5                  # users/ is looked at again when it changes
    while request(shop, "GET", "/v1/jobs", headers={"Cookie": sid})[0] != 401:
        assert time.monotonic() < deadline, "the removed user's session still reads the queue"
        time.sleep(0.05)
    assert request(shop, "GET", "/session", headers={"Cookie": sid})[0] == 401


def test_wrong_logins_from_one_address_are_throttled(shop):
    from wideprint.app.server import web
    for _ in range(web.LOGIN_FAILS):
        assert login(shop, "y" * 43)[0] == 401
    s, cookie, body = login(shop, shop.token)      # even the right token, for a while
    assert s == 429 and cookie is None and "wait" in body["error"]


# -- a real browser ---------------------------------------------------------------------------
def shot(driver, tmp_path, name):
    path = tmp_path / f"{name}.png"
    driver.save_screenshot(str(path))
    keep = os.environ.get("WIDEPRINT_WEB_SCREENSHOTS")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(keep) / f"{name}.png")
    from PIL import Image
    with Image.open(path) as im:
        assert im.size == (1366, 768), im.size
    return path


def attr(driver, css: str, name: str):
    """An attribute of the first element matching `css` (None: none), read in the page: the
    page redraws its tables on every event, so a Selenium element may go stale."""
    return driver.execute_script("const e = document.querySelector(arguments[0]); "
                                 "return e ? e.getAttribute(arguments[1]) : null", css, name)


def click(driver, css: str, timeout: float = 10) -> None:
    """Click the element matching `css` as a person would (Selenium's click), again if the
    page redrew it between finding and clicking."""
    from selenium.common.exceptions import (ElementClickInterceptedException,
                                            NoSuchElementException,
                                            StaleElementReferenceException)
    from selenium.webdriver.common.by import By
    deadline = time.monotonic() + timeout
    while True:
        try:
            return driver.find_element(By.CSS_SELECTOR, css).click()
        except (StaleElementReferenceException, NoSuchElementException,
                ElementClickInterceptedException):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def test_the_page_in_chromium_signs_in_follows_live_holds_releases_and_prints(shop, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait
    from wideprint.app.client import Client
    url = f"http://127.0.0.1:{shop.port}/"
    client = Client(shop.state_dir, url=url.rstrip("/"))
    # the operator's shop: a price list, a 50 m roll on the left printer (docs/server.md)
    client.prices({"currency": "EUR", "ink_per_ml": {c: 0.12 for c in "cmyk"},
                   "media_per_m2": {"default": 8.0}, "machine_per_hour": 30.0})
    client.roll("left", {"media": "vinyl-300", "length_m": 50})
    first = client.submit(banner(tmp_path / "shop-banner.tif"), name="shop-banner.tif")["job"]
    driver = chromium()
    try:
        from selenium.common.exceptions import StaleElementReferenceException
        wait = WebDriverWait(driver, 30, poll_frequency=0.05,
                             ignored_exceptions=(StaleElementReferenceException,))
        driver.get(url)
        wait.until(lambda d: d.find_element(By.ID, "login").is_displayed())
        assert not driver.find_element(By.ID, "app").is_displayed()
        # a wrong token: told so, no cookie, no data
        driver.find_element(By.ID, "login-name").send_keys("Ann")
        driver.find_element(By.ID, "login-token").send_keys("z" * 43)
        driver.find_element(By.ID, "login-submit").click()
        wait.until(lambda d: d.find_element(By.ID, "login-error").text == "Wrong token.")
        assert not driver.find_element(By.ID, "app").is_displayed()
        assert driver.get_cookies() == []
        assert driver.execute_async_script(
            "const done = arguments[0]; fetch('/v1/jobs').then(r => done(r.status))") == 401
        assert "shop-banner" not in driver.page_source
        shot(driver, tmp_path, "web-login-1366x768")
        # the operator's token
        driver.find_element(By.ID, "login-token").clear()
        driver.find_element(By.ID, "login-token").send_keys(shop.token)
        driver.find_element(By.ID, "login-submit").click()
        wait.until(lambda d: d.find_element(By.ID, "app").is_displayed())
        cookies = driver.get_cookies()
        assert [c["name"] for c in cookies] == ["wideprint_session"]
        assert cookies[0]["httpOnly"] and cookies[0]["sameSite"] == "Strict"
        assert driver.execute_script("return document.cookie") == ""     # no script sees it
        assert "Ann (operator)" in driver.find_element(By.ID, "who").text
        wait.until(lambda d: d.find_element(By.ID, "live").text == "live")
        cards = wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#printers .card")
                           if len(d.find_elements(By.CSS_SELECTOR, "#printers .card")) == 2 else None)
        assert [c.get_attribute("data-printer") for c in cards] == ["left", "right"]
        assert "paused" in cards[0].text
        assert "vinyl-300" in cards[0].text and "50.0 m left" in cards[0].text, cards[0].text
        assert "vinyl-300" not in cards[1].text              # no roll known on the right one
        # the row's text and state read at once: every `jobs` event draws the queue's rows
        # anew, so an element found before it may be gone when read (stale)
        text, state = wait.until(lambda d: d.execute_script(
            "const r = document.querySelector(arguments[0]); return r && [r.innerText, r.dataset.state]",
            f"#queue tr[data-job='{first['id']}']"))
        assert "shop-banner.tif" in text and state == "queued"
        # a job submitted behind the page's back appears live (the event stream, no reload)
        second = client.submit(banner(tmp_path / "second.tif", 450, 150),
                               name="<i>second.tif")["job"]
        sel = f"#queue tr[data-job='{second['id']}']"
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, sel))
        # its name is text, never HTML
        assert "<i>second.tif" in driver.execute_script(
            "return document.querySelector(arguments[0]).innerText", sel)
        assert not driver.find_elements(By.CSS_SELECTOR, "#queue td.name i")
        # its thumbnail: the server's halftone preview (numba's first compile on a busy
        # machine can take a minute; the compiled kernels of `make` take a second)
        WebDriverWait(driver, 180, poll_frequency=0.1).until(lambda d: d.execute_script(
            "const i = document.querySelector(arguments[0] + ' img'); "
            "return i && i.complete && i.naturalWidth > 0", sel))
        # hold it with its button, then release it
        click(driver, f"{sel} button[data-action='hold']")
        wait.until(lambda d: attr(d, sel, "data-state") == "held")
        assert client.job(second["id"])["state"] == "held"
        shot(driver, tmp_path, "web-queue-1366x768")
        click(driver, f"{sel} button[data-action='release']")
        wait.until(lambda d: attr(d, sel, "data-state") == "queued")
        assert client.job(second["id"])["state"] == "queued"
        # resume the queue: the printers print, their cards follow, the history fills
        click(driver, "#queue-toggle")
        seen_printing = WebDriverWait(driver, 120, poll_frequency=0.05).until(
            lambda d: d.execute_script(
                "return [...document.querySelectorAll('#printers .card')]"
                ".map(c => c.innerText).filter(t => t.includes('.tif'))"))
        assert any("shop-banner.tif" in t or "second.tif" in t for t in seen_printing)
        # the screenshot once a progress bar moves, if the jobs are not done before that
        end = time.monotonic() + 10
        while time.monotonic() < end and not driver.execute_script(
                "return [...document.querySelectorAll('#printers .bar')]"
                ".some(b => +b.getAttribute('aria-valuenow') > 0)"):
            time.sleep(0.02)
        shot(driver, tmp_path, "web-printing-1366x768")
        for job in (first, second):
            WebDriverWait(driver, 180, poll_frequency=0.2,
                          ignored_exceptions=(StaleElementReferenceException,)).until(
                lambda d, j=job: d.find_elements(
                    By.CSS_SELECTOR, f"#history tr[data-job='{j['id']}'][data-state='done']"))
        assert client.job(first["id"])["state"] == client.job(second["id"])["state"] == "done"
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#per-day tbody tr"))
        day = driver.find_element(By.CSS_SELECTOR, "#per-day tbody tr").text.split()
        assert day[1] == "2", day                     # two copies printed today
        assert driver.find_element(By.CSS_SELECTOR, "#per-day th.cost").text == "Cost (EUR)"
        cost = sum(r["cost"]["total"] for r in client.report_costs()["prints"])
        # the price list's cost, to the cent (the page's JavaScript and Python may round a
        # half cent differently: 0.045 shows as 0.05 there, 0.04 here)
        assert cost > 0 and abs(float(day[-1]) - cost) <= 0.005 + 1e-9, (day, cost)
        assert not driver.find_elements(By.CSS_SELECTOR, "#queue tbody tr")
        driver.execute_script("window.scrollTo(0, 0)")
        shot(driver, tmp_path, "web-history-1366x768")
        # a done job printed again from its archived file (docs/server.md "Archive and reprint")
        click(driver, f"#history tr[data-job='{first['id']}'] button[data-action='reprint']")
        again = WebDriverWait(driver, 30, poll_frequency=0.1).until(
            lambda d: [j for j in client.jobs("queued,held,printing,done")
                       if j.get("reprint_of") == first["id"]])
        assert again[0]["name"] == "shop-banner.tif" and again[0]["sha256"] == first["sha256"]
        assert not driver.find_element(By.ID, "message").is_displayed()    # no error said
        # sign out: the page is the login form again and the cookie reads nothing
        click(driver, "#logout")
        wait.until(lambda d: d.find_element(By.ID, "login").is_displayed())
        assert driver.execute_async_script(
            "const done = arguments[0]; fetch('/v1/status').then(r => done(r.status))") == 401
    finally:
        driver.quit()
        client.close()
