"""The dashboard in a real browser: Playwright driving Debian's headless Chromium.

Skipped when the ``playwright`` package or ``/usr/bin/chromium`` is missing
(``pip install playwright`` and ``apt-get install chromium``; never
``playwright install``: the system browser is used).
"""

from __future__ import annotations

import shutil
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from statectl.demo import motor_chart
from statectl.devices import SimMotor
from statectl.runner import DeviceSetup, System
from statectl.runtime import SimClock
from statectl.web import Dashboard

sync_api = pytest.importorskip("playwright.sync_api")
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
if not Path(CHROMIUM).exists():
    pytest.skip("no Chromium at /usr/bin/chromium", allow_module_level=True)

TOKEN = "browser-test-token"


@pytest.fixture
def url() -> Iterator[str]:
    """The Motor on a SimClock that follows the wall clock, behind a dashboard."""
    system = System((DeviceSetup("Motor", motor_chart(), driver=SimMotor(speed=2.0)),), SimClock())
    dash = Dashboard(system.subjects.values(), post=system.post, token=TOKEN)
    address = dash.start("127.0.0.1", 0)
    stop = threading.Event()
    system.start()
    owner = threading.Thread(target=system.serve, args=(stop,), daemon=True)
    owner.start()
    try:
        yield address
    finally:
        stop.set()
        owner.join(5)
        dash.stop()
        system.close()


@pytest.fixture
def page(url: str) -> Iterator[object]:
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True)
        try:
            page = browser.new_page()
            page.goto(url)
            yield page
        finally:
            browser.close()


def send(page: object, token: str) -> None:
    page.fill("#post-event", "Movement")
    page.fill("#post-data", '{"amount": 10}')
    page.fill("#token", token)
    page.click("#post-send")


def test_an_event_sent_with_the_token_changes_the_motor_on_the_page(page: object) -> None:
    """Blocked is highlighted; Movement with the token is accepted and the page shows Moving."""
    expect = sync_api.expect
    expect(page.locator("#state-Motor")).to_have_text("Blocked")
    expect(page.locator("g.node.active title")).to_have_text("Blocked")
    send(page, TOKEN)
    expect(page.locator("#post-status")).to_contain_text("accepted")
    expect(page.locator("#state-Motor")).to_have_text("Moving")
    expect(page.locator("g.node.active title")).to_have_text("Moving")
    expect(page.locator("#log")).to_contain_text("SimMotor.move_to(10.0)")


def test_an_event_without_the_token_is_refused_on_the_page(page: object) -> None:
    """Without the token the page says refused and the Motor stays Blocked."""
    expect = sync_api.expect
    expect(page.locator("#state-Motor")).to_have_text("Blocked")
    send(page, "")
    expect(page.locator("#post-status")).to_contain_text("refused (401)")
    expect(page.locator("#state-Motor")).to_have_text("Blocked")
