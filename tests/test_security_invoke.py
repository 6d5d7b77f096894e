"""Trust is never gained: a safe or null document cannot start a python child."""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import pytest

from statectl.out.scxml import Scheduler, Session, SimulatedClock, read_scxml
from statectl.out.scxml.xmltree import SCXML_NS


def _child(marker: Path) -> str:
    """A python-datamodel child whose script would leave ``marker`` behind."""
    return (
        f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="python">'
        f'<script>open({str(marker)!r}, "w").write("ran")</script>'
        '<final id="end"/></scxml>'
    )


def _run(parent_datamodel: str, invoke: str) -> tuple[str | None, list[str]]:
    text = (
        f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="{parent_datamodel}" '
        'initial="wait">'
        f'<state id="wait">{invoke}'
        '<transition event="error.execution" target="refused"/>'
        '<transition event="done.invoke" target="ran"/></state>'
        '<final id="refused"/><final id="ran"/></scxml>'
    )
    chart, diagnostics = read_scxml(text)
    assert chart is not None, diagnostics
    scheduler = Scheduler(SimulatedClock(), trace=(trace := []).append)
    return scheduler.run(Session(chart, scheduler), 10.0), trace


@pytest.mark.parametrize("parent", ["safe", "null"])
def test_inline_python_child_of_untrusted_parent_is_refused(tmp_path: Path, parent: str) -> None:
    """An inline ``<content>`` child declaring python never runs its script."""
    marker = tmp_path / "pwned"
    final, trace = _run(parent, f"<invoke><content>{_child(marker)}</content></invoke>")
    assert final == "refused"
    assert not marker.exists()
    assert any("trust is never gained" in line for line in trace)


def test_python_child_built_from_a_string_is_refused(tmp_path: Path) -> None:
    """A child assembled at run time (``<content expr>``) gets the same check."""
    marker = tmp_path / "pwned"
    expr = quoteattr(repr(_child(marker)))
    final, _ = _run("safe", f"<invoke><content expr={expr}/></invoke>")
    assert final == "refused"
    assert not marker.exists()


def test_python_child_from_src_is_refused(tmp_path: Path) -> None:
    """A ``src`` child is read and checked before anything in it runs."""
    marker = tmp_path / "pwned"
    (tmp_path / "child.scxml").write_text(_child(marker), encoding="utf-8")
    text = (
        f'<scxml xmlns="{SCXML_NS}" version="1.0" datamodel="safe" initial="wait">'
        '<state id="wait"><invoke src="child.scxml"/>'
        '<transition event="error.execution" target="refused"/>'
        '<transition event="done.invoke" target="ran"/></state>'
        '<final id="refused"/><final id="ran"/></scxml>'
    )
    chart, diagnostics = read_scxml(text)
    assert chart is not None, diagnostics
    scheduler = Scheduler(SimulatedClock())
    final = scheduler.run(Session(chart, scheduler, base=tmp_path), 10.0)
    assert final == "refused"
    assert not marker.exists()


def test_trusted_parent_may_start_a_python_child(tmp_path: Path) -> None:
    """A python document was trusted by whoever ran it, and so are its own children."""
    marker = tmp_path / "ran"
    final, _ = _run("python", f"<invoke><content>{_child(marker)}</content></invoke>")
    assert final == "ran"
    assert marker.read_text() == "ran"
