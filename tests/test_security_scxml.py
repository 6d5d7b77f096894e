"""SCXML sessions under hostile documents: src files, invoke nesting and the timeout."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from statectl.channels.cli import main
from statectl.out.scxml import Scheduler, Session, SimulatedClock, read_scxml
from statectl.out.scxml.datamodel import EvaluationError, SafeDatamodel
from statectl.out.scxml.sending import MAX_INVOKE_DEPTH
from statectl.out.scxml.xmltree import MAX_SRC_BYTES, SCXML_NS

HEAD = f'<scxml xmlns="{SCXML_NS}" version="1.0"'
OUTCOME = (
    '<transition event="error.execution" target="refused"/>'
    '<transition event="go" target="read"/></state>'
    '<final id="refused"/><final id="read"/></scxml>'
)


def _data_src(datamodel: str, src: str) -> str:
    return (
        f'{HEAD} datamodel="{datamodel}" initial="s">'
        f'<datamodel><data id="v" src="{src}"/></datamodel>'
        '<state id="s"><onentry><raise event="go"/></onentry>' + OUTCOME
    )


def _run(text: str, folder: Path, *, allow_src: bool = False) -> tuple[str | None, list[str]]:
    chart, diagnostics = read_scxml(text, str(folder / "doc.scxml"), str(folder))
    assert chart is not None, [str(d) for d in diagnostics]
    trace: list[str] = []
    scheduler = Scheduler(SimulatedClock(), trace=trace.append)
    session = Session(chart, scheduler, base=folder, allow_src=allow_src)
    return scheduler.run(session, 10.0), trace


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A document directory with a sibling file and a secret outside it."""
    (tmp_path / "doc").mkdir()
    (tmp_path / "doc" / "value.json").write_text('{"speed": 3}', encoding="utf-8")
    (tmp_path / "secret.txt").write_text("secret", encoding="utf-8")
    (tmp_path / "doc" / "link.txt").symlink_to(tmp_path / "secret.txt")
    return tmp_path / "doc"


@pytest.mark.parametrize(
    ("datamodel", "src", "allow", "final", "why"),
    [
        ("safe", "value.json", False, "refused", "reads no files unless run with --allow-src"),
        ("safe", "value.json", True, "read", ""),
        ("safe", "link.txt", True, "refused", "through a link"),
        ("python", "value.json", False, "read", ""),
        ("python", "../secret.txt", False, "read", ""),
    ],
)
def test_data_src_is_confined_by_trust(
    folder: Path, datamodel: str, src: str, allow: bool, final: str, why: str
) -> None:
    """A safe document reads a src only when allowed, and only inside its directory."""
    result, trace = _run(_data_src(datamodel, src), folder, allow_src=allow)
    assert result == final
    assert why in " ".join(trace)


@pytest.mark.parametrize("src", ["../secret.txt", "/etc/passwd", "file:///etc/passwd"])
def test_safe_data_src_leaving_the_directory_is_refused_at_load(folder: Path, src: str) -> None:
    """A src that leaves the directory is X302 when a safe document loads."""
    chart, diagnostics = read_scxml(_data_src("safe", src), "doc.scxml", str(folder))
    assert chart is None
    assert any(d.code == "X302" and "outside its own directory" in d.message for d in diagnostics)


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_endless_src_is_refused_without_reading_it(folder: Path) -> None:
    """Even a trusted document cannot read an endless stream: src must be a regular file."""
    result, trace = _run(_data_src("python", "/dev/zero"), folder)
    assert result == "refused"
    assert "not a regular file" in " ".join(trace)


def test_oversized_src_is_refused(folder: Path) -> None:
    """A src file larger than MAX_SRC_BYTES gives error.execution, not a huge value."""
    (folder / "big.json").write_bytes(b" " * (MAX_SRC_BYTES + 1))
    result, trace = _run(_data_src("python", "big.json"), folder)
    assert result == "refused"
    assert "larger than" in " ".join(trace)


def test_self_invoking_document_stops_at_the_nesting_limit(folder: Path) -> None:
    """A document that invokes itself is refused at MAX_INVOKE_DEPTH with a clear trace."""
    text = (
        f'{HEAD} datamodel="python" initial="s"><state id="s"><invoke src="doc.scxml"/>'
        '<transition event="error.execution" target="refused"/>'
        '<transition event="done.invoke" target="refused"/></state>'
        '<final id="refused"/></scxml>'
    )
    (folder / "doc.scxml").write_text(text, encoding="utf-8")
    result, trace = _run(text, folder)
    assert result == "refused"
    assert any(f"deeper than {MAX_INVOKE_DEPTH}" in line for line in trace)


def _cli(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "statectl", "scxml", "run", str(path), "--timeout", "0.5"],
        capture_output=True,
        text=True,
        timeout=30,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )


LOOPS = {
    "cond-raises": ("safe", '<state id="s"><transition cond="1/0 == 1" target="f"/></state>'),
    "null-bogus": ("null", '<state id="s"><transition cond="Bogus(\'a\')" target="f"/></state>'),
    "foreach-data": (
        "safe",
        '<datamodel><data id="n" expr="500000"/></datamodel><state id="s"><onentry>'
        '<foreach array="[0] * n" item="i"><if cond="i &lt; 0"><raise event="x"/></if>'
        "</foreach></onentry></state>",
    ),
    "self-invoke": ("safe", '<state id="s"><invoke src="doc.scxml"/></state>'),
    "raise-loop": (
        "safe",
        '<state id="s"><onentry><raise event="again"/></onentry>'
        '<transition event="again" target="s"/></state>',
    ),
    "send-loop": (
        "safe",
        '<state id="s"><onentry><send event="again"/></onentry>'
        '<transition event="again" target="s"/></state>',
    ),
}


@pytest.mark.parametrize("case", sorted(LOOPS))
def test_scxml_run_timeout_bounds_wall_time(folder: Path, case: str) -> None:
    """`scxml run --timeout` stops any document with exit 1 and a clear message."""
    datamodel, body = LOOPS[case]
    path = folder / "doc.scxml"
    path.write_text(
        f'{HEAD} datamodel="{datamodel}" initial="s">{body}<final id="f"/></scxml>',
        encoding="utf-8",
    )
    done = _cli(path)  # a subprocess: without the bound this would hang, not fail
    assert done.returncode == 1
    assert any(
        why in done.stderr
        for why in ("--timeout 0.5 s passed", "no top-level final state", "without settling")
    ), done.stderr
    assert "final:" not in done.stdout
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("delay", ['delay="99999999999999999999999s"', "delayexpr=\"'600000h'\""])
def test_a_delay_no_clock_can_wait_for_is_error_execution(folder: Path, delay: str) -> None:
    """A send delayed past MAX_DELAY is error.execution on the wall clock, not a traceback."""
    path = folder / "doc.scxml"
    path.write_text(
        f'{HEAD} datamodel="safe" initial="s"><state id="s">'
        f'<onentry><send event="go" {delay}/></onentry>' + OUTCOME,
        encoding="utf-8",
    )
    done = _cli(path)
    assert "Traceback" not in done.stderr, done.stderr
    assert (done.returncode, done.stdout) == (0, "final: refused\n"), done.stderr


def test_scxml_run_watchdog_stops_trusted_code_no_check_reaches(folder: Path) -> None:
    """A python <script> looping forever is ended by the watchdog: message and exit 1."""
    path = folder / "doc.scxml"
    path.write_text(
        f'{HEAD} datamodel="python" initial="s"><script>while True: pass</script>'
        '<state id="s"/></scxml>',
        encoding="utf-8",
    )
    done = _cli(path)
    assert done.returncode == 1
    assert "still running" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(
    "cond", ["not " * 5000 + "In('s')", "x" * 20_000, "-" * 100_000 + "1", "In('s') +"]
)
def test_null_datamodel_refuses_hostile_conditions_without_a_traceback(
    folder: Path, cond: str
) -> None:
    """A null document's deep, long or broken condition is error.execution, not a crash."""
    text = (
        f'{HEAD} datamodel="null" initial="s"><state id="s">'
        f'<transition cond="{cond}" target="escaped"/>'
        '<transition event="error.execution" target="refused"/></state>'
        '<final id="refused"/><final id="escaped"/></scxml>'
    )
    result, _trace = _run(text, folder)
    assert result == "refused"


@pytest.mark.parametrize("timeout", ["0", "-1", "nan", "inf"])
def test_scxml_run_refuses_a_timeout_that_bounds_nothing(folder: Path, timeout: str) -> None:
    """A zero, negative, nan or infinite --timeout is a usage error (exit 2), not a hang."""
    path = folder / "doc.scxml"
    path.write_text(f'{HEAD} initial="f"><final id="f"/></scxml>', encoding="utf-8")
    out, err = io.StringIO(), io.StringIO()
    assert main(["scxml", "run", str(path), "--timeout", timeout], out, err) == 2
    assert "--timeout must be" in err.getvalue()


@pytest.mark.parametrize(
    ("action", "fragment"),
    [
        (lambda dm: dm.declare("len", [1]), "callable name"),
        (lambda dm: dm.declare("_x", 1), "callable name"),
        (lambda dm: dm.declare("f", "x".join), "is a function"),
        (lambda dm: dm.assign("s", "x".upper), "is a function"),
        (lambda dm: dm.declare("big", [0] * 1_000_001), "larger than"),
        (lambda dm: dm.evaluate("s.join"), "is a method"),
        (lambda dm: dm.evaluate("In"), "is a function"),
        (lambda dm: dm.evaluate("s * 1000000"), "repetition"),
    ],
)
def test_safe_datamodel_holds_data_only_at_run_time(
    action: Callable[[SafeDatamodel], object], fragment: str
) -> None:
    """Without the load check, the safe datamodel itself refuses callables and huge values."""
    dm = SafeDatamodel({"s"}.__contains__)
    dm.declare("s", "ab")
    with pytest.raises(EvaluationError, match=fragment):
        action(dm)
