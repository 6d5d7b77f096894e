"""A corpus of hostile names and a device file that uses each as a state and an event name.

Names are the user's: the table loaders accept all of these, so every generator must
write them escaped (src/statectl/out/escape/). The device's own name is hostile too.
"""

from __future__ import annotations

import json
from pathlib import Path

#: label -> name. No commas (a list cell splits on them, T111), nothing that strips to "".
HOSTILE: dict[str, str] = {
    "triple double quotes": 'M"""\nimport os; os.system("touch PWNED")\n"""',
    "triple single quotes": "M'''\nraise SystemExit(3)\n'''",
    "every quote": "a\"b'c`d\u201ce\u2019",
    "ends in a double quote": 'q"',
    "backslash at the end": "B\\",
    "backslash newline": "b\\\nint pwned = 1;",
    "block comment end": "C */ int pwned; /*",
    "trigraph": "D??/",
    "trigraph at the end": "T ??/",
    "newline": "E\nint pwned = 1;",
    "carriage return": "F\r#define X 1",
    "nul": "G\x00H",
    "bidi override": "H\u202eI\u2066J\u2069K",
    "ansi escape": "\x1b[31mred",
    "line separator": "L\u2028M",
    "xml markup": "<x a='1'>&amp;</x>",
    "markdown and html": "|m|<script>alert(1)</script>",
    "diagram syntax": 'N" as X {\n} --> [*] : %% ;',
    "unicode letters": "Bewegung läuft ²",
}

#: The 1 MB name, kept apart: it goes through the same generators on a smaller device.
LONG = "O" * (1 << 20)

HOSTILE_DEVICE = 'Dev"""\nimport os  # \\\x00\u202e'


def device_file(path: Path, names: list[str], device: str = HOSTILE_DEVICE) -> Path:
    """A device file: ``A`` default; per name a state reached from A by the name as an
    event (a command with an API) and left by ``back``, the first also by a timeout
    (testgen writes a timing test); JSON is YAML, so any text fits."""
    states = [{"state": "A", "control": "default"}]
    events = []
    for i, name in enumerate(names):
        states.append({"state": name, "control": "event trigger required"})
        events.append({"event": name, "old": "A", "new": name, "kind": "command", "api": f"Go{i}"})
        events.append({"event": "back", "old": name, "new": "A", "kind": "command", "api": "Back"})
    states[1] |= {"timeout": "2s -> back"}  # the first state times out: timing tests too
    doc = {"device": device, "states": states, "events": events}
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path
