"""Diagrams show a state's timeout and the events it defers, in every format."""

from __future__ import annotations

import html
import re
import shutil
from pathlib import Path

import pytest

from statectl.front.builder.build import load_chart
from statectl.front.tables.timeouts import format_timeout
from statectl.kernel.model import Chart, State, Timeout
from statectl.out.render import FORMATS, from_chart, render
from statectl.out.render.diagram import state_details

CLAMP = Path(__file__).resolve().parent.parent / "examples" / "clamp" / "clamp.yaml"
NEEDS_DOT = pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz 'dot' is absent")


def _visible(fmt: str, text: str) -> str:
    """The text as a reader of the format sees it (entities decoded, DOT line breaks)."""
    if fmt in ("mermaid", "md"):
        return re.sub(r"#(\d+);", lambda m: chr(int(m.group(1))), text)
    if fmt == "svg":
        return html.unescape(text)
    return text.replace("\\n", "\n")


@pytest.fixture(scope="module")
def clamp() -> Chart:
    return load_chart(CLAMP)


FORMAT_PARAMS = [pytest.param(f, marks=NEEDS_DOT) if f == "svg" else f for f in FORMATS]


@pytest.mark.parametrize("fmt", FORMAT_PARAMS)
@pytest.mark.parametrize("line", ["after 2s / Close timeout", "defer: Release"])
def test_every_format_shows_timeout_and_defer(clamp: Chart, fmt: str, line: str) -> None:
    """Each format prints the Clamp's Closing timeout and its deferred Release."""
    assert line in _visible(fmt, render(clamp, fmt))


def test_only_the_timed_state_has_details(clamp: Chart) -> None:
    """The diagram model gives details to Closing alone, timeout first."""
    details = {n.name: n.details for n in from_chart(clamp).nodes if n.details}
    assert details == {"Closing": ("after 2s / Close timeout", "defer: Release")}


DURATIONS = [(2.0, "2s"), (0.25, "250ms"), (1.5, "1500ms"), (120.0, "2min")]


@pytest.mark.parametrize(("seconds", "text"), DURATIONS)
def test_duration_is_written_as_the_tables_write_it(seconds: float, text: str) -> None:
    """A timeout's seconds are shown in the largest whole unit, by diagrams and tables alike."""
    assert Timeout(seconds, "Ev").duration == text
    assert format_timeout(seconds, "Ev") == f"{text} -> Ev"


def test_state_without_timing_has_no_details() -> None:
    """A plain state gets no detail lines; one with a timeout gets exactly one."""
    assert state_details(State("Idle")) == ()
    assert state_details(State("Wait", timeout=Timeout(5.0, "Late"))) == ("after 5s / Late",)


def test_markdown_page_has_timeout_and_defer_columns(clamp: Chart) -> None:
    """The page's State Definition table gains timeout and defer columns for the Clamp."""
    page = render(clamp, "md")
    assert "| ignores | timeout | defer |" in page
    assert "| 2s -> Close timeout | Release |" in page


def test_markdown_page_of_untimed_device_keeps_five_columns(motor: Chart) -> None:
    """The Motor, with no timeout or defer, keeps the paper's five state columns."""
    assert "| ignores |\n" in render(motor, "md")
