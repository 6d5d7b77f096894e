"""The registry of diagnostic codes, the source that raises them and the docs that explain
them agree with one another."""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator, Mapping
from pathlib import Path

import pytest

import statectl
from statectl.kernel import codes
from statectl.kernel.codes import ALL, REGISTRY, UnknownCodeError, explain, family, lookup
from statectl.kernel.errors import Severity, StatectlError

SRC = Path(statectl.__file__).parent
ROOT = SRC.parents[1]
CODE = re.compile(r"[A-Z][0-9]{3}")

#: Helpers that create a Diagnostic at a fixed severity from a code given first.
FIXED: dict[str, Severity] = {
    "diag": Severity.ERROR,  # tables.rows (re-exported by tables.schema)
    "_d": Severity.ERROR,  # cell (build's _d takes the severity: read from its arguments)
    "error": Severity.ERROR,  # devices.config
    "_info": Severity.INFO,  # build
    "_report": Severity.ERROR,  # codegen.flatten
    "YamlRefused": Severity.ERROR,  # tables.safeyaml, reported as errors
    "_Refused": Severity.ERROR,  # scxml.reader, reported as errors
}


def _sources() -> Iterator[tuple[str, ast.AST]]:
    for path in sorted(SRC.rglob("*.py")):
        if path.name == "codes.py" and path.parent == SRC:
            continue  # the registry itself
        yield str(path.relative_to(SRC)), ast.parse(path.read_text(encoding="utf-8"))


def code_literals() -> list[tuple[str, str]]:
    """Every string literal in the source that is a code, as ``(file:line, code)``."""
    found = []
    for name, tree in _sources():
        for node in ast.walk(tree):
            is_text = isinstance(node, ast.Constant) and isinstance(node.value, str)
            if is_text and CODE.fullmatch(node.value):
                found.append((f"{name}:{node.lineno}", node.value))
    return found


def _severity_of(call: ast.Call) -> Severity | None:
    """The severity a call creating a diagnostic gives it, when the source says it."""
    for arg in (*call.args, *(k.value for k in call.keywords)):
        if (
            isinstance(arg, ast.Attribute)
            and isinstance(arg.value, ast.Name)
            and arg.value.id == "Severity"
        ):
            return Severity[arg.attr]
    func = call.func
    name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
    if name == "problem":  # scxml.reader: warn=True makes a warning
        warn = any(
            k.arg == "warn" and isinstance(k.value, ast.Constant) and k.value.value is True
            for k in call.keywords
        )
        return Severity.WARNING if warn else Severity.ERROR
    return FIXED.get(name)


def raised_severities() -> list[tuple[str, str, Severity]]:
    """``(file:line, code, severity)`` of every call that creates a code at a static
    severity: ``Diagnostic("C401", Severity.ERROR, ...)``, ``diag("T101", ...)``, ..."""
    found = []
    for name, tree in _sources():
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call) or not node.args:
                continue
            first = node.args[0]
            if not (isinstance(first, ast.Constant) and isinstance(first.value, str)):
                continue
            if not CODE.fullmatch(first.value):
                continue
            severity = _severity_of(node)
            if severity is not None:
                found.append((f"{name}:{node.lineno}", first.value, severity))
    return found


def test_every_code_in_the_source_is_registered() -> None:
    """A code literal anywhere in src/statectl is a registered code."""
    literals = code_literals()
    assert len({c for _, c in literals}) > 50, "the scan no longer finds the codes"
    assert [(at, c) for at, c in literals if c not in REGISTRY] == []


def test_every_registered_code_is_raised_somewhere() -> None:
    """The registry lists no code the source never uses (a stale entry)."""
    used = {c for _, c in code_literals()}
    assert sorted(set(REGISTRY) - used) == []


def test_no_code_is_registered_twice() -> None:
    """Each code has one record: ALL holds no duplicate and REGISTRY has them all."""
    names = [c.code for c in ALL]
    assert sorted(n for n in set(names) if names.count(n) > 1) == []
    assert len(REGISTRY) == len(ALL)


def test_codes_are_well_formed() -> None:
    """A code is a capital letter and three digits, with a summary of one line."""
    bad = [c.code for c in ALL if not CODE.fullmatch(c.code) or not c.summary or "\n" in c.summary]
    assert bad == []


def test_severities_match_how_codes_are_raised() -> None:
    """Where a call gives a code a static severity, the registry allows that severity."""
    raised = raised_severities()
    assert len(raised) > 100, "the scan no longer finds the Diagnostic calls"
    wrong = [
        f"{at}: {code} raised as {sev.value}, registered {REGISTRY[code].severity.value}"
        for at, code, sev in raised
        if code in REGISTRY and sev not in REGISTRY[code].severities
    ]
    assert wrong == []


def test_default_severity_is_raised() -> None:
    """A code that the source raises at static severities uses its default among them."""
    seen: dict[str, set[Severity]] = {}
    for _, code, sev in raised_severities():
        seen.setdefault(code, set()).add(sev)
    assert sorted(c for c, sevs in seen.items() if REGISTRY[c].severity not in sevs) == []


# -- docs ---------------------------------------------------------------------------------


def slug(heading: str) -> str:
    """GitHub's anchor for a markdown heading's text."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def section(page: Path, anchor: str) -> str | None:
    """The text under the heading whose anchor is ``anchor``, up to the next heading of
    the same or a higher level; None when no heading has that anchor."""
    lines = page.read_text(encoding="utf-8").splitlines()
    fenced = False
    for i, line in enumerate(lines):
        fenced ^= line.startswith("```")
        m = re.match(r"(#+) (.*)", line)
        if fenced or not m or slug(m.group(2)) != anchor:
            continue
        level = len(m.group(1))
        body, inner = [], False
        for rest in lines[i + 1 :]:
            inner ^= rest.startswith("```")
            n = re.match(r"(#+) ", rest)
            if not inner and n and len(n.group(1)) <= level:
                break
            body.append(rest)
        return line + "\n" + "\n".join(body)
    return None


@pytest.mark.parametrize("code", ALL, ids=lambda c: c.code)
def test_docs_explain_every_code_at_its_anchor(code: codes.Code) -> None:
    """The registered page has a heading with the registered anchor whose section names
    the code."""
    page = ROOT / code.page
    assert page.is_file(), code.page
    text = section(page, code.anchor)
    assert text is not None, f"{code.page} has no heading with anchor #{code.anchor}"
    assert re.search(rf"\b{code.code}\b", text), f"{code.doc} does not mention {code.code}"


def test_docs_name_only_registered_codes() -> None:
    """A code the docs or README mention is a registered one (no stale or invented code)."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    named = {
        (page.name, code)
        for page in pages
        for code in re.findall(r"\b[A-Z][0-9]{3}\b", page.read_text(encoding="utf-8"))
    }
    assert len(named) > 50, "the scan no longer finds the codes in the docs"
    assert sorted((page, code) for page, code in named if code not in REGISTRY) == []


SLUGS = [
    ("C401 — unreachable state (error)", "c401--unreachable-state-error"),
    ("Builder codes reported through `check`", "builder-codes-reported-through-check"),
    ("Recovery table codes (J603\u2013J608)", "recovery-table-codes-j603j608"),
    ("Diagnostics", "diagnostics"),
]


@pytest.mark.parametrize(("heading", "anchor"), SLUGS)
def test_slug_is_githubs_anchor(heading: str, anchor: str) -> None:
    """The test's anchor rule drops punctuation and turns spaces into hyphens."""
    assert slug(heading) == anchor


# -- the modules' CODES views ---------------------------------------------------------------

VIEWS = [
    ("statectl.front.tables", "T1"),
    ("statectl.front.builder.build", "B2"),
    ("statectl.front.rules", "C4"),
    ("statectl.front.recovery", "J6"),
    ("statectl.out.codegen", "G7"),
    ("statectl.out.codegen.flatten", "G7"),
    ("statectl.cell.model", "V8"),
]


@pytest.mark.parametrize(("module", "prefix"), VIEWS)
def test_module_codes_are_views_of_the_registry(module: str, prefix: str) -> None:
    """A module's CODES maps each code of its family to the registry's summary, read-only."""
    import importlib

    table: Mapping[str, str] = importlib.import_module(module).CODES
    expected = {c.code: c.summary for c in ALL if c.code.startswith(prefix)}
    assert dict(table) == expected
    assert expected, prefix
    with pytest.raises(TypeError):
        table[prefix + "99"] = "added"  # type: ignore[index]


def test_family_takes_several_prefixes() -> None:
    """family("C4", "J6") is the check's codes and the Recovery table's together."""
    both = family("C4", "J6")
    assert set(both) == set(family("C4")) | set(family("J6"))


# -- explain and lookup ---------------------------------------------------------------------

EXPLAINED = [
    ("C401", "C401 error: unreachable state\nsee docs/check.md#c401--unreachable-state-error\n"),
    ("c401", "C401 error: unreachable state\nsee docs/check.md#c401--unreachable-state-error\n"),
    (" t115 ", "T115 error: a YAML alias (*name): refused, so an alias bomb cannot expand\n"),
    ("C403", "C403 error (or warning): two rows for the same state and event may both fire\n"),
    ("J606", "J606 info (or warning): a monitored state has no recovery rule\n"),
    ("G708", "G708 warning: a Log action the generated code skips\nsee docs/codegen.md#"),
]


@pytest.mark.parametrize(("code", "start"), EXPLAINED)
def test_explain(code: str, start: str) -> None:
    """explain() gives the code, its severity, its summary and where the docs explain it."""
    assert explain(code).startswith(start)


UNKNOWN = [
    ("Z999", "unknown diagnostic code 'Z999'"),
    ("C490", "did you mean C409"),  # no C409: the closest registered ones are named
    ("", "unknown diagnostic code ''"),
]


@pytest.mark.parametrize(("code", "message"), UNKNOWN)
def test_unknown_code(code: str, message: str) -> None:
    """An unregistered code is a StatectlError (and a KeyError) that says so."""
    with pytest.raises(UnknownCodeError) as info:
        explain(code)
    assert isinstance(info.value, StatectlError) and isinstance(info.value, KeyError)
    if "did you mean" in message:
        assert "did you mean C4" in str(info.value)
    else:
        assert str(info.value).startswith(message)


def test_lookup_returns_the_record() -> None:
    """lookup() gives the frozen record, whose doc joins page and anchor."""
    record = lookup("b218")
    assert record is REGISTRY["B218"]
    assert record.doc == "docs/tables.md#diagnostics"
    with pytest.raises(AttributeError):
        record.summary = "changed"  # type: ignore[misc]


@pytest.mark.parametrize(
    ("argv", "status", "stream", "text"),
    [
        (["check", "--explain", "C403"], 0, "out", "C403 error (or warning)"),
        (["check", "--explain", "t110"], 0, "out", "see docs/tables.md#"),
        (["check", "--explain", "C999"], 2, "err", "unknown diagnostic code 'C999'"),
        (["check"], 2, "err", "name at least one FILE"),
    ],
)
def test_check_explain_on_the_command_line(
    argv: list[str], status: int, stream: str, text: str
) -> None:
    """`statectl check --explain CODE` prints the registry's entry; unknown is a usage error."""
    import io

    from statectl.channels.cli import main

    out, err = io.StringIO(), io.StringIO()
    assert main(argv, out, err) == status
    assert text in (out if stream == "out" else err).getvalue()
