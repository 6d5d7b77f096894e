"""Names printed for people are escaped: one record is one line, and a newline, an ANSI
escape or a bidi control in a name shows as its escape (kernel/text.py's ``shown``).

Issue 28: a newline in an event name forged a line of ``journal show``; U+202E
reordered what followed it. The text trace, ``journal show`` and the dashboard print
names through the one display escape.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

from hostile_names import device_file
from statectl.channels.cli.journal import journal_show
from statectl.front.builder.build import load_chart
from statectl.run.journal import Journal
from statectl.run.runtime import SimClock, Subject
from statectl.run.runtime.trace import TraceWriter, format_record

#: Names that would break a line or reorder it, and how each must show.
NAMES = {
    "Go\nt=  0.00  Motor  event    Forged": "Go\\nt=  0.00  Motor  event    Forged",
    "Go\u202eevil\u2066": "Go\\u202eevil\\u2066",
    "Go\x1b[2J\x00": "Go\\x1b[2J\\x00",
}
DEVICE = "Dev\r\n\u202e"


def _chart(tmp_path: Path) -> object:
    return load_chart(device_file(tmp_path / "d.yaml", list(NAMES), device=DEVICE))


def _assert_lines(text: str, expected_lines: int) -> None:
    lines = text.split("\n")
    assert lines[-1] == "" and len(lines) - 1 == expected_lines, lines
    assert all(line.isprintable() for line in lines), [x for x in lines if not x.isprintable()]
    for shown in NAMES.values():
        assert shown in text
    assert "Dev\\r\\n\\u202e" in text


def test_the_text_trace_shows_names_escaped(tmp_path: Path) -> None:
    """A run's trace, by steps and by records: a line per line kind, names as escapes."""
    for mode in ("steps", "records"):
        subject = Subject(_chart(tmp_path), clock=SimClock())  # type: ignore[arg-type]
        out = io.StringIO()
        if mode == "steps":
            subject.listen_steps(TraceWriter(out).step)
        else:
            subject.listen(lambda r, out=out: out.write(format_record(r) + "\n"))
        subject.start()
        for name in NAMES:
            subject.post(name)
            subject.run_until_idle()
            subject.post("back")
            subject.run_until_idle()
        # started + enter A, then per name: event, exit, state, enter, invoke (twice)
        lines = out.getvalue().count("\n")
        _assert_lines(out.getvalue(), lines)
        assert lines >= 2 + 2 * 4 * len(NAMES), out.getvalue()


def test_journal_show_shows_names_escaped(tmp_path: Path) -> None:
    """An accepted event whose device, event and data hold newlines is one line."""
    journal = Journal(tmp_path / "j.db")
    for name in NAMES:
        journal.accept(DEVICE, name, {"note": "a\nb\u202e"}).wait(5.0)
    journal.close()
    out = io.StringIO()
    assert journal_show(str(tmp_path / "j.db"), out=out, err=io.StringIO()) == 0
    _assert_lines(out.getvalue(), len(NAMES))


def test_the_dashboard_state_carries_names_as_shown(tmp_path: Path) -> None:
    """The page prints the ``shown`` names; the raw ones stay for posting events back."""
    from statectl.channels.web.server import _Device

    subject = Subject(_chart(tmp_path), clock=SimClock())  # type: ignore[arg-type]
    subject.start()
    first = next(iter(NAMES))
    subject.post(first)
    subject.run_until_idle()
    state = _Device(subject).state()
    assert state["shown"] == {"name": "Dev\\r\\n\\u202e", "active": [NAMES[first]]}
    pairs = dict(zip(state["events"], state["events_shown"], strict=True))
    assert {name: pairs[name] for name in NAMES} == NAMES
    assert all(i["name"].isprintable() and i["method"].isprintable() for i in state["invokes"])
    json.dumps(state)


#: Names whose escape differed by where they were printed: ``repr`` doubled a backslash
#: and switched to double quotes around a quote; the one display escape does neither.
WIRE_NAMES = [*NAMES, "C:\\motor\n", "it's\u202e", 'say "hi"\x00']


def test_the_wire_and_the_commands_policy_escape_as_the_kernel_does() -> None:
    """A Zenoh name (trust.shown) and a principal in a refusal (run/commands.py) are
    escaped by kernel/text.py's ``shown``: each keeps only its quotes and its cut."""
    from statectl.channels.distributed.trust import shown as wire_shown
    from statectl.kernel.text import shown
    from statectl.run.commands import Commands, Origin

    for name in WIRE_NAMES:
        assert wire_shown(name) == f"'{shown(name)}'"
        refusal = str(Commands().refusal(Origin("opcua", name), "Motor", "Error"))
        assert f"opcua '{shown(name)}' may not send it" in refusal, refusal
    long = "\u202e" * 100
    assert wire_shown(long) == f"'{shown(long[:80])}'... (100 characters)"
