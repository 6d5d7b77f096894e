"""Seeded fuzzing: mutated example files and W3C documents never crash the loaders.

Every example file (device tables in YAML, CSV, XLSX; the Motor also as Markdown
and SCXML, written at test time; the cell files) and every document of the W3C
pack in ../shared (read in place, skipped when absent) is mutated by a seeded
mutator: byte flips, truncation, line duplication, deep nesting, alias and entity
bombs, encoding changes, huge numbers. Each mutant goes through what ``statectl
check`` (device files), ``verify``'s loader (cells) and ``scxml import`` (SCXML)
do. The only exceptions allowed are statectl's own (``StatectlError``); each case
must end within :data:`CASE_SECONDS` (a hang detector, not a speed test). Mutants
are only loaded, never run, so a python-datamodel document executes nothing.
``STATECTL_FUZZ_SEEDS=50`` runs more mutants per example file (default 8, about 20 s).
"""

from __future__ import annotations

import importlib
import importlib.util
import io
import os
import random
import shutil
import signal
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import openpyxl
import pytest

from statectl.cell.model import load_cell
from statectl.front.builder.build import chart_to_tables, load_and_build
from statectl.front.tables import load, save
from statectl.kernel.errors import StatectlError
from statectl.out.scxml import read_scxml, write_scxml
from support import W3C_PACK, W3C_SKIPPED

ROOT = Path(__file__).resolve().parents[1]

#: The checker's module: ``statectl.check``, named ``statectl.front.rules`` on branches where it was
#: renamed (the facade's ``check()`` function took the name).
RULES: Any = importlib.import_module(
    "statectl.front.rules" if importlib.util.find_spec("statectl.front.rules") else "statectl.check"
)
EXAMPLES = ROOT / "examples"
PACK = W3C_PACK  # $STATECTL_W3C_DIR, else ../shared/conformance/w3c-scxml
CASE_SECONDS = 10
SEEDS = int(os.environ.get("STATECTL_FUZZ_SEEDS", "8"))  # mutants per mutator and file
PACK_MUTANTS = 7  # mutants per W3C document (mutators drawn at random, each once)

BOMB = (
    "[&a [x,x,x,x,x,x,x,x,x]"
    + "".join(
        f", &{b} [{', '.join(['*' + a] * 9)}]" for a, b in zip("abcdef", "bcdefg", strict=True)
    )
    + "]"
)
LAUGHS = (
    '<!DOCTYPE scxml [<!ENTITY e0 "ha">'
    + "".join(f'<!ENTITY e{i} "{f"&e{i - 1};" * 10}">' for i in range(1, 10))
    + "]>"
)

Mutator = Callable[[bytes, random.Random, str], bytes]


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def flip_bytes(data: bytes, rng: random.Random, kind: str) -> bytes:
    out = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        if out:
            out[rng.randrange(len(out))] = rng.randrange(256)
    return bytes(out)


def truncate(data: bytes, rng: random.Random, kind: str) -> bytes:
    return data[: rng.randrange(len(data) + 1)]


def duplicate_line(data: bytes, rng: random.Random, kind: str) -> bytes:
    lines = _lines(data)
    at = rng.randrange(len(lines))
    return b"".join(lines[:at] + [lines[at]] * rng.choice((2, 50, 2000)) + lines[at:])


def deep_nesting(data: bytes, rng: random.Random, kind: str) -> bytes:
    depth = rng.choice((200, 5000))
    if kind == "scxml":
        deep = b'<if cond="true">' * depth + b"</if>" * depth
        at = data.rfind(b"</")
    else:
        deep = b"[" * depth + b"]" * depth
        at = data.find(b": ", rng.randrange(len(data) + 1)) + 2
    at = at if at > 1 else len(data)
    return data[:at] + deep + data[at:]


def alias_bomb(data: bytes, rng: random.Random, kind: str) -> bytes:
    if kind == "scxml":
        at = data.find(b"<scxml")
        at = at if at >= 0 else 0
        return data[:at] + LAUGHS.encode() + b"\n" + data[at:] + b"&e9;"
    bomb = BOMB.encode() if kind != "csv" else b'"' + BOMB.encode() + b'"'
    separator = b": " if kind == "yaml" else b","
    at = data.find(separator, rng.randrange(len(data) + 1))
    if at < 0:
        return data + bomb
    end = data.find(b"\n", at)
    end = end if end >= 0 else len(data)
    return data[: at + len(separator)] + bomb + data[end:]


def change_encoding(data: bytes, rng: random.Random, kind: str) -> bytes:
    text = data.decode("utf-8", "replace")
    choice = rng.randrange(4)
    if choice == 0:
        return text.encode("utf-16")
    if choice == 1:
        return text.encode("latin-1", "replace") + "\u00e9\u00ff".encode("latin-1")
    if choice == 2:
        return b"\xef\xbb\xbf" + data
    return b'<?xml version="1.0" encoding="x-no-such-codec"?>\n' + data


def huge_number(data: bytes, rng: random.Random, kind: str) -> bytes:
    digits = [i for i, b in enumerate(data) if 48 <= b <= 57]
    at = rng.choice(digits) if digits else len(data)
    return data[:at] + b"9" * rng.choice((5000, 100_000)) + data[at:]


MUTATORS: dict[str, Mutator] = {
    "flip": flip_bytes,
    "truncate": truncate,
    "duplicate": duplicate_line,
    "deep": deep_nesting,
    "alias": alias_bomb,
    "encoding": change_encoding,
    "huge-number": huge_number,
}


def mutate_xlsx(data: bytes, rng: random.Random, name: str) -> bytes:
    """A workbook with one random cell replaced (the byte mutators only damage the zip)."""
    if name in ("flip", "truncate"):
        return MUTATORS[name](data, rng, "xlsx")
    wb = openpyxl.load_workbook(io.BytesIO(data))
    ws = wb.worksheets[rng.randrange(len(wb.worksheets))]
    row = rng.randint(1, max(1, ws.max_row))
    column = rng.randint(1, max(1, ws.max_column))
    value = {
        "deep": "[" * 300 + "]" * 300,
        "alias": BOMB,
        "huge-number": "9" * 5000,
        "encoding": "\udcff bad",
        "duplicate": "state",
    }[name]
    try:
        ws.cell(row=row, column=column, value=value)
        out = io.BytesIO()
        wb.save(out)
    except Exception:  # a value the workbook cannot hold: damage the bytes instead
        return flip_bytes(data, rng, "xlsx")
    return out.getvalue()


class _Hang(Exception):
    """A case ran past CASE_SECONDS."""


def _alarm(signum: int, frame: object) -> None:
    raise _Hang(f"no result within {CASE_SECONDS} s")


def _bounded(work: Callable[[], object]) -> str | None:
    """Run one case; ``None`` if it ended well, else what went wrong."""
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_SECONDS)
    try:
        work()
    except StatectlError:
        return None
    except BaseException as exc:  # any other exception is the finding
        if isinstance(exc, KeyboardInterrupt):
            raise
        return "".join(traceback.format_exception(exc)[-3:])
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    return None


def _device(path: Path) -> None:
    RULES.check_paths([str(path)])
    chart, _ = load_and_build(path)
    if chart is not None:
        read_scxml(write_scxml(chart))


def _scxml(path: Path, base: Path | None = None) -> None:
    chart, _ = read_scxml(path.read_bytes(), str(path), str(base or path.parent))
    if chart is not None:
        chart_to_tables(chart)


def _cell(path: Path) -> None:
    load_cell(path)


def _kind(path: Path) -> str:
    name = path.name.lower()
    if name.endswith(".scxml"):
        return "scxml"
    return {".csv": "csv", ".md": "md", ".xlsx": "xlsx"}.get(path.suffix.lower(), "yaml")


def _seeds() -> Iterator[tuple[str, Path, Callable[[Path], None]]]:
    """Every example input with the loader a user's command would call on it."""
    for path in sorted(EXAMPLES.rglob("*")):
        if path.suffix.lower() not in (".yaml", ".csv", ".xlsx", ".md", ".scxml"):
            continue
        text = path.read_text(encoding="utf-8") if path.suffix == ".yaml" else ""
        if text.startswith("cell:") or "\ncell:" in text:
            yield str(path.relative_to(EXAMPLES)), path, _cell
        else:
            yield str(path.relative_to(EXAMPLES)), path, _device


SEED_FILES = list(_seeds())


def _fuzz(
    source: Path,
    loader: Callable[[Path], None],
    tmp_path: Path,
    names: list[str],
    seeds: range,
    siblings: bool = True,
) -> list[str]:
    """Mutate ``source`` (its siblings copied along) and load each mutant; the findings."""
    findings: list[str] = []
    kind = _kind(source)
    original = source.read_bytes()
    for name in names:
        for seed in seeds:
            rng = random.Random(f"{source.name}/{name}/{seed}")
            case = tmp_path / f"{name}-{seed}"
            if siblings:  # a CSV pair's other files, a cell's devices
                shutil.copytree(source.parent, case, ignore=shutil.ignore_patterns("cpp"))
            else:
                case.mkdir()
            target = case / source.name
            mutant = (
                mutate_xlsx(original, rng, name)
                if kind == "xlsx"
                else MUTATORS[name](original, rng, kind)
            )
            target.write_bytes(mutant)
            problem = _bounded(lambda target=target: loader(target))
            if problem is not None:
                findings.append(f"{source.name} {name} seed {seed}:\n{problem}")
            shutil.rmtree(case)
    return findings


@pytest.mark.parametrize(("source", "loader"), [pytest.param(p, f, id=i) for i, p, f in SEED_FILES])
def test_mutated_example_loads_or_is_refused(
    tmp_path: Path, source: Path, loader: Callable[[Path], None]
) -> None:
    """Every mutant of an example file ends in a result or statectl's diagnostics, in time."""
    assert _fuzz(source, loader, tmp_path, list(MUTATORS), range(SEEDS)) == []


@pytest.mark.parametrize("fmt", ["md", "scxml"])
def test_mutated_motor_in_other_formats(tmp_path: Path, fmt: str) -> None:
    """The Motor written as Markdown and as SCXML survives every mutator too."""
    home = tmp_path / "motor"
    home.mkdir()
    if fmt == "md":
        tables, _ = load(EXAMPLES / "motor" / "motor.yaml")
        assert tables is not None
        save(tables, home / "motor.md")
        source, loader = home / "motor.md", _device
    else:
        chart, _ = load_and_build(EXAMPLES / "motor" / "motor.yaml")
        assert chart is not None
        (home / "motor.scxml").write_text(write_scxml(chart), encoding="utf-8")
        source, loader = home / "motor.scxml", _scxml
    work = tmp_path / "work"
    work.mkdir()
    assert _fuzz(source, loader, work, list(MUTATORS), range(SEEDS)) == []


PACK_DOCS = sorted(PACK.glob("*/*.scxml")) if PACK.is_dir() else []


@pytest.mark.skipif(not PACK_DOCS, reason=W3C_SKIPPED)
def test_mutated_w3c_documents_load_or_are_refused(tmp_path: Path) -> None:
    """Mutants of every W3C document (read in place from ../shared) end well, in time."""
    findings: list[str] = []
    for i, doc in enumerate(PACK_DOCS):
        rng = random.Random(f"w3c/{doc.parent.name}/{doc.name}")
        names = rng.sample(sorted(MUTATORS), PACK_MUTANTS)
        work = tmp_path / str(i)
        work.mkdir()
        # only the mutant is written (to tmp); its src files are read from the pack
        findings += _fuzz(doc, lambda p, d=doc: _scxml(p, d.parent), work, names, range(1), False)
    assert findings == []
