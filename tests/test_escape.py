"""Hostile names through every generator: each output is valid in its language and says
the name, never runs it (issue 28; src/statectl/out/escape/).

The corpus is tests/hostile_names.py: quotes of every kind, triple quotes, a backslash at
the end, ``*/``, ``??/``, newlines, NUL, bidi controls, and a 1 MB name on its own.
"""

from __future__ import annotations

import ast
import io
import json
import os
import shutil
import subprocess
import sys
import tokenize
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from codegen_support import CLANG, FLAGS, GXX
from hostile_names import HOSTILE, HOSTILE_DEVICE, LONG, device_file
from statectl.channels.cli import main
from statectl.kernel.errors import StatectlError
from statectl.kernel.text import shown
from statectl.out.escape import cpp, diagram, python, xml

NAMES = [*HOSTILE.values(), HOSTILE_DEVICE, LONG]
IDS = [*HOSTILE, "hostile device", "1 MB"]
COMPILERS = [c for c in (GXX, CLANG) if c is not None]


def _run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), out=out, err=err)
    return code, out.getvalue(), err.getvalue()


# -- each function, on each name -----------------------------------------------------------


@pytest.mark.parametrize("name", NAMES, ids=IDS)
def test_python_literal_and_docstring_give_back_the_name(name: str) -> None:
    """A string literal, and text in a triple-quoted string, evaluate to the very name."""
    assert ast.literal_eval(python.string(name)) == name
    assert ast.literal_eval('"""' + python.docstring(name) + '"""') == name
    assert ast.literal_eval('"""x ' + python.docstring(name) + ' y"""') == f"x {name} y"


@pytest.mark.parametrize("name", NAMES, ids=IDS)
def test_python_comment_stays_one_comment(name: str) -> None:
    """``x = 1  # NAME`` tokenizes as one assignment and one comment, on one line."""
    source = f"x = 1  # {python.comment(name)}\n"
    tokens = list(tokenize.generate_tokens(io.StringIO(source).readline))
    kinds = [t.type for t in tokens if t.type not in (tokenize.NEWLINE, tokenize.ENDMARKER)]
    assert kinds == [tokenize.NAME, tokenize.OP, tokenize.NUMBER, tokenize.COMMENT]
    assert source.count("\n") == 1 and source.isprintable() is False  # only the final \n


@pytest.mark.parametrize("name", NAMES, ids=IDS)
def test_python_identifier_is_an_ascii_identifier(name: str) -> None:
    """A name part makes a valid, bounded ASCII identifier; a class name too."""
    part = python.identifier(name, limit=python.NAME_LIMIT)
    assert f"test_{part}".isidentifier() and part.isascii() and len(part) <= python.NAME_LIMIT
    cls = python.class_name(name, "Machine")
    assert cls.isidentifier() and cls.isascii() and cls[0].isupper()


@pytest.mark.parametrize("name", NAMES, ids=IDS)
def test_xml_attribute_and_text_read_back_or_refuse(name: str) -> None:
    """Any name XML 1.0 can hold reads back exactly; one with NUL, ESC or another C0 control
    is refused, the character named, and nothing is written."""
    illegal = [c for c in name if ord(c) < 0x20 and c not in "\t\n\r"]
    try:
        doc = f"<a v={xml.attribute(name)}>{xml.text(name)}</a>"
    except StatectlError as exc:
        assert illegal and shown(illegal[0]) in str(exc) and "XML 1.0" in str(exc)
        return
    assert not illegal
    root = ET.fromstring(doc)
    assert root.get("v") == name and (root.text or "") == name.replace("\r", "\n")


@pytest.mark.parametrize("name", NAMES, ids=IDS)
def test_diagram_labels_are_one_printable_line(name: str) -> None:
    """Mermaid, PlantUML and Markdown labels are one printable line; DOT one quoted string."""
    for label in (diagram.mermaid(name), diagram.plantuml(name), diagram.markdown_cell(name)):
        assert label.isprintable(), label[:80]
    assert '"' not in diagram.mermaid(name) and '"' not in diagram.plantuml(name)
    assert "|" not in diagram.markdown_cell(name).replace("\\|", "")
    quoted = diagram.dot(name)
    assert quoted.isprintable() and quoted.startswith('"') and quoted.endswith('"')
    assert '"' not in quoted[1:-1].replace('\\"', "")


def test_display_escape_shows_controls_and_keeps_letters() -> None:
    """kernel.text.shown: newline, NUL, ESC and bidi controls as escapes; letters kept."""
    cases = {
        "Moving": "Moving",
        "Bewegung läuft": "Bewegung läuft",
        "a\nb": "a\\nb",
        "a\x00b\x1b[31m": "a\\x00b\\x1b[31m",
        "x\u202ey\u2066z": "x\\u202ey\\u2066z",
        "\U000e0001": "\\U000e0001",
    }
    assert {k: shown(k) for k in cases} == cases


def _cpp_program(names: list[str]) -> str:
    """Every name as a string literal and in both comment forms, between statements that
    a spliced or closed comment would swallow; main prints each literal's bytes in hex."""
    lines = ["#include <cstdio>", "static const char* const kNames[] = {"]
    lines += [f"    {cpp.string(n)},  // {cpp.comment(n)}" for n in names]
    lines += ["};", f"static int kept = {len(names)};  /* {cpp.comment(names[0])} */"]
    for i, n in enumerate(names):
        lines += [f"// {cpp.comment(n)}", f"static int a{i} = (kept += 1);"]
        lines += [f"/* {cpp.comment(n)} */ static int b{i} = (kept += 1);"]
    lines += [
        "int main() {",
        "  for (const char* s : kNames) {",
        '    for (const char* c = s; *c; ++c) std::printf("%02x", (unsigned char)*c);',
        '    std::printf("\\n");',
        "  }",
        '  std::printf("%d\\n", kept);',
        "}",
    ]
    return "\n".join(lines) + "\n"


@pytest.mark.skipif(not COMPILERS, reason="no C++ compiler on this machine")
@pytest.mark.parametrize("compiler", COMPILERS)
def test_cpp_literals_and_comments_compile_and_hold_the_name(compiler: str, tmp_path: Path) -> None:
    """With the suite's strict flags, every literal holds the name's bytes (a C string ends
    at NUL) and no comment swallows the statement after it."""
    names = [*HOSTILE.values(), HOSTILE_DEVICE]
    (tmp_path / "n.cpp").write_text(_cpp_program(names), encoding="utf-8")
    done = subprocess.run(
        [
            compiler,
            *FLAGS,
            "-Wno-unused-variable",
            str(tmp_path / "n.cpp"),
            "-o",
            str(tmp_path / "n"),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr[:3000]
    run = subprocess.run([str(tmp_path / "n")], capture_output=True, text=True, check=True)
    got = run.stdout.split("\n")
    want = [n.encode("utf-8").split(b"\x00")[0].hex() for n in names]
    assert got[: len(names)] == want
    assert got[len(names)] == str(3 * len(names))


# -- every generator, on a device whose every name is hostile -------------------------------

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _pytest(where: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """Run pytest on generated modules in a new process, in ``where`` (where the injected
    ``os.system("touch PWNED")`` would leave its file)."""
    env = {**os.environ, "PYTHONPATH": SRC}
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "-p",
            "no:randomly",
            *args,
        ],
        cwd=where,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


@pytest.fixture(scope="module")
def hostile_suite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The hostile device's modules for every criterion and --hypothesis, and its exports."""
    where = tmp_path_factory.mktemp("hostile")
    device_file(where / "h.yaml", list(HOSTILE.values()))
    for criterion in ("rows", "transitions", "states", "pairs"):
        assert (
            _run("testgen", str(where / "h.yaml"), "--criterion", criterion, "--out", str(where))[0]
            == 0
        )
    for flag in ("--hypothesis", "--graphwalker", "--xstate"):
        assert _run("testgen", str(where / "h.yaml"), flag, "--out", str(where))[0] == 0
    return where


def test_testgen_modules_parse_and_import_without_running_a_name(hostile_suite: Path) -> None:
    """Every generated module is valid Python; importing them all (pytest collects) runs no
    name as code: no PWNED file, no SystemExit, and every test is found."""
    modules = sorted(hostile_suite.glob("test_*.py"))
    assert len(modules) == 5
    for m in modules:
        compile(m.read_text(encoding="utf-8"), str(m), "exec")
    done = _pytest(hostile_suite, "--collect-only")
    assert done.returncode == 0, done.stdout[-3000:]
    assert not (hostile_suite / "PWNED").exists()


def test_testgen_rows_and_hypothesis_pass_on_the_twin(hostile_suite: Path) -> None:
    """The literals say the very names: the rows suite and the Hypothesis machine pass."""
    modules = [str(p) for p in hostile_suite.glob("test_*_rows.py")]
    modules += [str(p) for p in hostile_suite.glob("test_*_hypothesis.py")]
    done = _pytest(hostile_suite, *modules)
    assert done.returncode == 0, done.stdout[-3000:]
    assert not (hostile_suite / "PWNED").exists()


def test_graphwalker_and_xstate_exports_hold_the_names(hostile_suite: Path) -> None:
    """The JSON exports parse and carry every state name exactly."""
    for pattern in ("*.graphwalker.json", "*.xstate.json"):
        (path,) = hostile_suite.glob(pattern)
        found: set[str] = set()
        _strings(json.loads(path.read_text(encoding="utf-8")), found)
        assert set(HOSTILE.values()) <= found, pattern


def _strings(value: object, found: set[str]) -> None:
    """Every key and string anywhere in a JSON value."""
    if isinstance(value, str):
        found.add(value)
    elif isinstance(value, dict):
        for k, v in value.items():
            found.add(k)
            _strings(v, found)
    elif isinstance(value, list):
        for v in value:
            _strings(v, found)


def test_testgen_cell_modules_parse_and_pass(tmp_path: Path) -> None:
    """A hostile cell name, device and link events: the links module, the device module
    and the cell's Hypothesis module are valid, run no name, and pass."""
    names = list(HOSTILE.values())[:6]
    device_file(tmp_path / "d.yaml", names)
    device_file(tmp_path / "e.yaml", names, device="E\\")
    cell = {
        "cell": 'Cell"""\nimport os; os.system("touch PWNED")\u202e',
        "devices": {"dev": "d.yaml", "other": "e.yaml"},
        "environment": [{"send": n, "to": "dev"} for n in names] + [{"send": "back", "to": "dev"}],
        "links": [{"from": "dev", "enters": n, "to": "other", "send": n} for n in names[:3]],
    }
    (tmp_path / "cell.yaml").write_text(json.dumps(cell), encoding="utf-8")
    out = tmp_path / "out"
    assert _run("testgen", str(tmp_path / "cell.yaml"), "--out", str(out))[0] == 0
    assert _run("testgen", str(tmp_path / "cell.yaml"), "--hypothesis", "--out", str(out))[0] == 0
    modules = sorted(out.glob("test_*.py"))
    assert len(modules) == 4
    links = next(m for m in modules if m.name.endswith("_links.py")).read_text(encoding="utf-8")
    assert "def test_link_" in links
    done = _pytest(out)
    assert done.returncode == 0, done.stdout[-3000:]
    assert not (out / "PWNED").exists() and not (tmp_path / "PWNED").exists()


def test_a_one_megabyte_name_is_generated_bounded(tmp_path: Path) -> None:
    """A 1 MB device, state and event name: file names stay short, the module runs."""
    device_file(tmp_path / "l.yaml", [LONG + '\u202e"""'], device=LONG)
    assert _run("testgen", str(tmp_path / "l.yaml"), "--out", str(tmp_path))[0] == 0
    (module,) = tmp_path.glob("test_*_rows.py")
    assert len(module.name) < 100
    done = _pytest(tmp_path, str(module))
    assert done.returncode == 0, done.stdout[-3000:]


_NAMES_MAIN = """#include "@BASE@.hpp"
#include <cstdio>
int main() {
  namespace d = @NS@::detail;
  for (const char* s : d::kStateNames) {
    for (const char* c = s; *c; ++c) std::printf("%02x", (unsigned char)*c);
    std::printf("\\n");
  }
  for (const char* s : d::kEventNames) {
    for (const char* c = s; *c; ++c) std::printf("%02x", (unsigned char)*c);
    std::printf("\\n");
  }
}
"""


@pytest.mark.skipif(not COMPILERS, reason="no C++ compiler on this machine")
@pytest.mark.parametrize("compiler", COMPILERS)
def test_codegen_header_compiles_and_names_every_state(compiler: str, tmp_path: Path) -> None:
    """The hostile device's header and check program compile with the suite's strict flags
    (a name ending in a backslash used to splice the next line into a // comment), and
    its name tables hold each state and event name (up to a NUL, as C strings do)."""
    from statectl.front.builder.build import load_chart

    path = device_file(tmp_path / "h.yaml", list(HOSTILE.values()))
    assert _run("codegen", str(path), "--out", str(tmp_path / "cg"))[0] == 0
    (check,) = (tmp_path / "cg").glob("*_check.cpp")
    base = check.name.removesuffix("_check.cpp")
    (tmp_path / "cg" / "names.cpp").write_text(
        _NAMES_MAIN.replace("@BASE@", base).replace("@NS@", base), encoding="utf-8"
    )
    for source in (check, tmp_path / "cg" / "names.cpp"):
        done = subprocess.run(
            [compiler, *FLAGS, "-I", str(tmp_path / "cg"), str(source), "-o", str(tmp_path / "x")],
            capture_output=True,
            text=True,
            check=False,
        )
        assert done.returncode == 0, done.stderr[:3000]
    run = subprocess.run([str(tmp_path / "x")], capture_output=True, text=True, check=True)
    chart = load_chart(path)
    names = [s.name for s in chart.states] + [e.name for e in chart.events]
    want = [n.encode("utf-8").split(b"\x00")[0].hex() for n in names]
    assert run.stdout.split("\n")[: len(want)] == want


def test_scxml_export_round_trips_names_or_refuses(tmp_path: Path) -> None:
    """Names XML can hold read back exactly from the exported document; a name with NUL
    or ESC is refused with exit 1, the character named, no file and no traceback."""
    from statectl.front.builder.build import load_chart
    from statectl.out.scxml import read_scxml

    legal = [
        n
        for n in HOSTILE.values()
        if not any(c.isspace() for c in n) and all(ord(c) >= 0x20 for c in n)
    ]
    path = device_file(tmp_path / "ok.yaml", legal, device='D"<&>\u202e')
    assert _run("scxml", "export", str(path), "--out", str(tmp_path / "ok.scxml"))[0] == 0
    text = (tmp_path / "ok.scxml").read_text(encoding="utf-8")
    chart, diags = read_scxml(text, str(tmp_path / "ok.scxml"), str(tmp_path))
    assert chart is not None, diags
    assert [s.name for s in chart.states] == [s.name for s in load_chart(path).states]
    for bad in ("G\x00H", "\x1b[31mred"):
        path = device_file(tmp_path / "bad.yaml", [bad], device="D")
        code, _, err = _run("scxml", "export", str(path), "--out", str(tmp_path / "bad.scxml"))
        assert code == 1 and "XML 1.0" in err and shown(bad[0]) in err and "Traceback" not in err
        assert not (tmp_path / "bad.scxml").exists()


@pytest.mark.parametrize("fmt", ["mermaid", "dot", "plantuml", "md", "svg"])
def test_render_keeps_every_name_inside_its_label(fmt: str, tmp_path: Path) -> None:
    """Each diagram format draws the hostile device: every line is printable (no name
    breaks a line or hides a bidi control) and the SVG is well-formed XML."""
    if fmt == "svg" and shutil.which("dot") is None:
        pytest.skip("no Graphviz dot")
    path = device_file(tmp_path / "h.yaml", [*HOSTILE.values(), LONG])
    out = tmp_path / f"h.{fmt}"
    code, _, err = _run("render", str(path), "--format", fmt, "--out", str(out))
    assert code == 0, err[-2000:]
    text = out.read_text(encoding="utf-8")
    if fmt == "svg":
        ET.fromstring(text.encode("utf-8"))
        return
    bad = [line[:80] for line in text.split("\n") if not line.isprintable()]
    assert bad == []
    if fmt == "dot":
        svg = subprocess.run(["dot", "-Tsvg"], input=text, capture_output=True, text=True)
        assert svg.returncode == 0 or shutil.which("dot") is None, svg.stderr[:2000]
