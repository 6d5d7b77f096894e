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

from statectl.channels.cli.demo import motor_chart
from statectl.channels.web.server import Dashboard
from statectl.run.devices import SimMotor
from statectl.run.runner import DeviceSetup, System
from statectl.run.runtime import SimClock

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


def test_an_event_the_chart_does_not_know_is_refused_on_the_page(page: object) -> None:
    """An unknown event is refused (422) with the events the Motor knows; it stays Blocked."""
    expect = sync_api.expect
    expect(page.locator("#state-Motor")).to_have_text("Blocked")
    page.fill("#post-event", "Bogus")
    page.fill("#token", TOKEN)
    page.click("#post-send")
    expect(page.locator("#post-status")).to_contain_text("refused (422): Motor has no event")
    expect(page.locator("#state-Motor")).to_have_text("Blocked")


def test_the_event_log_wraps_long_lines_instead_of_cutting_them_off(page: object) -> None:
    """Every log line fits the log's width (it wraps): nothing is cut off at the column edge."""
    expect = sync_api.expect
    send(page, TOKEN)
    expect(page.locator("#log")).to_contain_text("SimMotor.move_to(10.0)")
    widths = page.evaluate(
        "() => [...document.querySelectorAll('#log li')]"
        ".map(li => [li.scrollWidth, li.clientWidth])"
    )
    assert widths and all(scroll <= client for scroll, client in widths), widths


GANTRY = Path(__file__).resolve().parents[1] / "examples" / "gantry" / "gantry.yaml"

#: The smallest scale the page draws a diagram at (style.css, ``.diagram svg``).
MIN_SCALE = 0.6


def diagram_sizes(chart_path: Path | None, width: int) -> tuple[float, float, float, float]:
    """Drawn width, natural width, card width, and drawn width after a click, in CSS px."""
    from statectl.front.builder.build import load_chart

    chart = motor_chart() if chart_path is None else load_chart(chart_path)
    system = System((DeviceSetup(chart.name, chart),), SimClock())
    dash = Dashboard(system.subjects.values(), post=system.post, token=TOKEN)
    address = dash.start("127.0.0.1", 0)
    system.start()
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True)
            try:
                page = browser.new_page(viewport={"width": width, "height": 900})
                page.goto(address)
                page.wait_for_function("() => document.querySelector('.diagram svg g.node')")
                size = (
                    "() => { const s = document.querySelector('.diagram svg'); return "
                    "[s.getBoundingClientRect().width, s.width.baseVal.value, "
                    "s.parentElement.clientWidth]; }"
                )
                drawn, natural, card = page.evaluate(size)
                page.click(".diagram")
                fitted = page.evaluate(size)[0]
                return drawn, natural, card, fitted
            finally:
                browser.close()
    finally:
        dash.stop()
        system.close()


@pytest.mark.parametrize(
    ("chart", "viewport"),
    [(None, 1280), (None, 700), (GANTRY, 1280), (GANTRY, 2400)],
    ids=["motor-1280", "motor-700", "gantry-1280", "gantry-2400"],
)
def test_the_diagram_is_drawn_at_the_card_width_but_never_too_small_to_read(
    chart: Path | None, viewport: int
) -> None:
    """The diagram fills its card, never above its natural size nor below 0.6 of it (then it
    scrolls in the card); a click shows the whole chart at the card's width."""
    drawn, natural, card, fitted = diagram_sizes(chart, viewport)
    expected = min(natural, max(card, MIN_SCALE * natural))
    assert drawn == pytest.approx(expected, abs=1.5), (drawn, natural, card)
    assert fitted == pytest.approx(min(card, natural), abs=1.5), (fitted, natural, card)
