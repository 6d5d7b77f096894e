"""The escape corpus: every expression and document in tests/security/ is refused.

An expression is refused when the model loads (an X301-X305 diagnostic) or, for
those marked ``run``, with a clear error when evaluated. A document is refused
at load, or runs into a ``refused`` final state via ``error.execution``, or is
stopped (wall-clock deadline, livelock bound, or nothing left to do) without
ever reaching its ``escaped`` final state.
"""

from __future__ import annotations

import re
import shutil
import time
from pathlib import Path
from typing import Any

import pytest

from statectl.kernel.errors import Location, StatectlError
from statectl.kernel.expr import MAX_DEPTH, MAX_SOURCE, ExpressionRefused, compile_expression
from statectl.out.scxml import RealClock, Scheduler, Session, SessionTimeout, read_scxml

CORPUS = Path(__file__).parent / "security"
HERE = Location("corpus", 1)
#: What ``run`` expressions see: each value is harmless, combined they are not.
ENV: dict[str, Any] = {
    "x": "abc",
    "n": 100_000_000,
    "m": 6_000,
    "lst": [0],
    "d": {"k": "v"},
    "big": "a" * 999_999,
    "b": 2**10_000 - 1,
    "obj": type("Obj", (), {"method": lambda self: 1})(),
    "In": {"s"}.__contains__,
}
DEADLINE = 0.5  # wall seconds a "stopped" document may run


def _expressions() -> list[tuple[str, str]]:
    cases = []
    for line in (CORPUS / "expressions.txt").read_text(encoding="utf-8").splitlines():
        if line.strip() and not line.startswith("#"):
            kind, source = line.split(maxsplit=1)
            cases.append((kind, source))
    generated = [
        "-" * 1000 + "1",
        "+" * 5000 + "1",
        "not " * 500 + "x",
        "[" * 2000 + "]" * 2000,
        "(" * 1000 + "1" + ")" * 1000,
        "{'a': " * 300 + "1" + "}" * 300,
        "1 + " * 200 + "1",
        "x" * (MAX_SOURCE + 1),
        "len(" * (MAX_DEPTH + 1) + "x" + ")" * (MAX_DEPTH + 1),
        "-" * 100_000 + "1",
        "9" * 3500,
        "9" * 3500 + " * 2",
        "9" * 5000,
    ]
    return cases + [("load", source) for source in generated]


EXPRESSIONS = _expressions()
DOCUMENTS = sorted(CORPUS.glob("documents/*.scxml"))


def test_corpus_is_large_enough() -> None:
    """The corpus holds at least 80 cases, and each class has some."""
    kinds = [kind for kind, _ in EXPRESSIONS]
    expects = [_expect(p) for p in DOCUMENTS]
    assert len(EXPRESSIONS) + len(DOCUMENTS) >= 80
    assert {"load", "run"} <= set(kinds)
    assert {"load", "refused", "stopped"} <= set(expects)


@pytest.mark.parametrize(("kind", "source"), EXPRESSIONS, ids=lambda v: str(v)[:40])
def test_expression_is_refused(kind: str, source: str) -> None:
    """A ``load`` case gives a diagnostic; a ``run`` case loads, then fails to evaluate."""
    expression, diagnostics = compile_expression(source, HERE)
    if kind == "load":
        assert expression is None
        assert diagnostics and {d.code for d in diagnostics} <= {
            "X301",
            "X302",
            "X304",
            "X305",
        }
        return
    assert expression is not None, [str(d) for d in diagnostics]
    with pytest.raises((ExpressionRefused, NameError)):
        expression.evaluate(ENV)


def _expect(path: Path) -> str:
    match = re.search(r"<!-- expect: (\w+) -->", path.read_text(encoding="utf-8"))
    assert match is not None, path
    return match.group(1)


@pytest.mark.parametrize("path", DOCUMENTS, ids=lambda p: p.stem)
def test_document_is_refused(path: Path, tmp_path: Path) -> None:
    """A document is refused at load, ends in ``refused``, or is stopped; never ``escaped``."""
    folder = tmp_path / "doc"
    shutil.copytree(path.parent, folder)
    text = (folder / path.name).read_text(encoding="utf-8")
    expect = _expect(path)
    chart, diagnostics = read_scxml(text, str(folder / path.name), str(folder))
    if expect == "load":
        assert chart is None
        assert any(d.code.startswith(("X30", "S6")) for d in diagnostics)
        return
    assert chart is not None, [str(d) for d in diagnostics]
    scheduler = Scheduler(RealClock())
    scheduler.wall_deadline = time.monotonic() + DEADLINE
    session = Session(chart, scheduler, base=folder)
    started = time.monotonic()
    try:
        final = scheduler.run(session, RealClock().now() + DEADLINE)
    except (SessionTimeout, StatectlError):
        final = None
    assert time.monotonic() - started < DEADLINE + 5.0  # bounded, not a speed target
    assert final != "escaped"
    assert not Path("/tmp/statectl-corpus-escaped").exists()
    if expect == "refused":
        assert final == "refused"
    else:
        assert final is None
