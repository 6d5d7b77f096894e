"""Symmetry reduction (cell/explore/symmetry.py): which devices are interchangeable, and
that the reduced search gives the full search's verdicts with concrete, shortest,
replayable counterexamples."""

from __future__ import annotations

import io
import json
import random
import re
from pathlib import Path

import pytest

from statectl.cell.explore import Composed, Kind, Report, explore
from statectl.cell.explore.replay import ReplayStep, run_cell
from statectl.cell.explore.symmetry import find_symmetry
from statectl.cell.model import Cell, load_cell, load_cell_or_raise
from statectl.channels.cli import main

SUPERVISOR = """\
device: Supervisor
states:
  - {state: Idle, control: default, ignore: [Stop, Hold, Clear]}
  - {state: Run, control: event trigger required, ignore: [Start, Clear]}
  - {state: Halt, control: event trigger required, ignore: [Start, Stop, Hold]}
events:
  - {event: Start, old: Idle, new: Run, kind: command, api: Go}
  - {event: Stop, old: Run, new: Idle, kind: command, api: Go}
  - {event: Hold, old: Run, new: Halt, kind: command, api: Go}
  - {event: Clear, old: Halt, new: Idle, kind: command, api: Go}
"""

STATION = """\
device: Station
states:
  - {state: Idle, control: default, ignore: [Stop, Reset, Begin completion, Jam]}
  - {state: Busy, control: [event trigger required, monitoring required], ignore: [Begin, Reset]}
  - {state: Done, control: event trigger required, ignore: [Begin, Stop, Begin completion, Jam]}
  - {state: Faulted, control: event trigger required, ignore: [Begin, Stop, Begin completion, Jam]}
events:
  - {event: Begin, old: Idle, new: Busy, kind: command, api: Work}
  - {event: Begin completion, old: Busy, new: Done, kind: completion, api: Work}
  - {event: Reset, old: Done, new: Idle, kind: command, api: Clear}
  - {event: Reset, old: Faulted, new: Idle, kind: command, api: Clear}
  - {event: Jam, old: Busy, new: Faulted, kind: fault, api: Clear}
  - {event: Stop, old: Busy, new: Idle, kind: command, api: Clear}
"""


def _line(
    folder: Path,
    n: int,
    extra: str = "",
    links: str = "",
    invariants: str = "",
    broadcast: bool = True,
) -> Path:
    """A supervisor and ``n`` stations: Run sends Begin to each, a fault halts the line."""
    (folder / "sup.yaml").write_text(SUPERVISOR, encoding="utf-8")
    (folder / "station.yaml").write_text(STATION, encoding="utf-8")
    names = [f"s{i}" for i in range(n)]
    text = "cell: line\ndevices:\n  sup: sup.yaml\n"
    text += "".join(f"  {s}: station.yaml\n" for s in names)
    text += "links:\n" + links
    for s in names:
        if broadcast:
            text += f"  - {{from: sup, enters: Run, to: {s}, send: Begin}}\n"
        text += f"  - {{from: {s}, enters: Faulted, to: sup, send: Hold}}\n"
    text += "environment:\n  - {send: Start, to: sup}\n  - {send: Clear, to: sup}\n"
    for s in names:
        text += f"  - {{send: Reset, to: {s}}}\n  - {{fault: Jam, to: {s}}}\n"
    text += "invariants:\n" + invariants + extra
    path = folder / "line.cell.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def _groups(path: Path) -> list[tuple[str, ...]]:
    sym = find_symmetry(Composed(load_cell_or_raise(path)))
    return [] if sym is None else [g.names for g in sym.groups]


ALL_BUSY = "  - {name: nb, holds: \"not (In('s0.Busy') and In('s1.Busy') and In('s2.Busy'))\"}\n"


@pytest.mark.parametrize(
    ("extra", "links", "invariants", "groups"),
    [
        # symmetric: every station is every other's twin
        ("", "", ALL_BUSY, [("s0", "s1", "s2")]),
        # an invariant about s0 alone: s1 and s2 stay interchangeable
        ("", "", "  - {name: a, holds: \"not In('s0.Faulted')\"}\n", [("s1", "s2")]),
        # a chain s0 -> s1 -> s2: no two stations can be swapped
        (
            "",
            "  - {from: s0, enters: Done, to: s1, send: Stop}\n"
            "  - {from: s1, enters: Done, to: s2, send: Stop}\n",
            "",
            [],
        ),
        # a link to s2 alone from the supervisor: s0 and s1 remain
        ("", "  - {from: sup, enters: Halt, to: s2, send: Stop}\n", "", [("s0", "s1")]),
        # a link guard that tells s0 from s1: only s1 and s2 are still alike
        (
            "",
            "  - {from: sup, enters: Idle, to: s1, send: Stop, guard: \"In('s0.Busy')\"}\n"
            "  - {from: sup, enters: Idle, to: s2, send: Stop, guard: \"In('s0.Busy')\"}\n",
            "",
            [("s1", "s2")],
        ),
    ],
)
def test_detection(
    tmp_path: Path, extra: str, links: str, invariants: str, groups: list[tuple[str, ...]]
) -> None:
    """Groups are the devices whose swap maps links, environment and properties onto
    themselves; a cell that tells devices apart keeps them apart."""
    assert _groups(_line(tmp_path, 3, extra, links, invariants)) == groups


def test_a_device_read_by_a_guard_is_never_swapped(tmp_path: Path) -> None:
    """A chart reading In('s0.Busy') reads s0 from every device of its file: s0 stays fixed
    (with the supervisor's Begin links, whose order the reading could show, none is kept)."""
    plain = "{event: Reset, old: Done, new: Idle, kind: command, api: Clear}"
    reads = plain[:-1] + ", guard: \"not In('s0.Busy')\"}"
    for broadcast, groups in ((False, [("s1", "s2")]), (True, [])):
        path = _line(tmp_path, 3, broadcast=broadcast)
        text = (tmp_path / "station.yaml").read_text(encoding="utf-8")
        (tmp_path / "station.yaml").write_text(text.replace(plain, reads), encoding="utf-8")
        assert _groups(path) == groups


def test_an_order_that_shows_keeps_the_devices_apart(tmp_path: Path) -> None:
    """The supervisor sends Begin to s0 before s1; when a station's reaction to Begin
    fires a link, that order can show, so the stations are not reduced."""
    links = "".join(f"  - {{from: s{i}, enters: Busy, to: sup, send: Stop}}\n" for i in range(3))
    assert _groups(_line(tmp_path, 3, links=links)) == []


def test_cli_reports_the_reduction_and_no_symmetry_turns_it_off(tmp_path: Path) -> None:
    """verify prints the states stored, the full search's count and the reduction used
    (symmetry alone: the two reductions are not combined); --no-symmetry (with --no-por)
    stores them all, with the same verdict and exit code."""
    path = str(_line(tmp_path, 3, invariants=ALL_BUSY))
    out, err, out2 = io.StringIO(), io.StringIO(), io.StringIO()
    code = main(["verify", path], out=out, err=err)
    assert main(["verify", path, "--no-symmetry", "--no-por"], out=out2, err=err) == code == 1
    text, plain = out.getvalue(), out2.getvalue()
    full = re.search(r"explored ([\d,]+) global states", plain)
    reduced = re.search(
        r"symmetry: ([\d,]+) states stored, .* the full search stores ([\d,]+)", text
    )
    assert full is not None and reduced is not None, text
    assert reduced.group(2) == full.group(1)
    assert int(reduced.group(1).replace(",", "")) < int(full.group(1).replace(",", ""))
    assert "one per orbit of 3 interchangeable devices (s0, s1, s2)" in text
    assert "partial-order reduction" not in text
    assert "symmetry" not in plain
    assert text.splitlines()[-1] == plain.splitlines()[-1] == "verdict: fails"
    doc = io.StringIO()
    main(["verify", path, "--json"], out=doc, err=err)
    assert json.loads(doc.getvalue())["full_states"] == int(full.group(1).replace(",", ""))


def test_stations_no_link_touches_get_partial_order_reduction(tmp_path: Path) -> None:
    """Interchangeable devices that no link touches are left to partial-order reduction,
    which stores states linear in their number (symmetry would store a polynomial); the
    verdict is the full search's."""
    (tmp_path / "station.yaml").write_text(STATION, encoding="utf-8")
    stored = []
    for n in (4, 8):
        text = "cell: free\ndevices:\n" + "".join(f"  s{i}: station.yaml\n" for i in range(n))
        text += "environment:\n" + "".join(
            f"  - {{send: Begin, to: s{i}}}\n  - {{send: Reset, to: s{i}}}\n" for i in range(n)
        )
        path = tmp_path / f"free{n}.cell.yaml"
        path.write_text(text, encoding="utf-8")
        cell = load_cell_or_raise(path)
        assert find_symmetry(Composed(cell)) is not None  # interchangeable, yet not reduced so
        report = explore(cell)
        assert any("partial-order reduction" in line for line in report.reductions), report
        assert not any(line.startswith("symmetry") for line in report.reductions)
        full = explore(cell, por=False, symmetry=False)
        assert report.properties == full.properties and full.states > report.states
        stored.append(report.states)
    assert stored[1] < 3 * stored[0]  # 4 -> 8 stations: linear growth, not n^2 or 2^n


# -- random cells: the reduced search against the full one -----------------------------------


def _station(rng: random.Random) -> str:
    """A random station file: guards over In(), data, a timeout, a deferred event."""
    data = rng.random() < 0.4
    timeout = rng.random() < 0.4
    defer = rng.random() < 0.3
    cross = rng.random() < 0.3
    busy = "{state: Busy, control: [event trigger required, monitoring required]"
    if timeout:
        busy += ", timeout: 1s -> Tick"
    if defer:
        busy += ", defer: [Reset]"
    rows = [
        "{event: Begin, old: Idle, new: Busy, kind: command, api: Work"
        + (', guard: "n < 2", assign: {n: n + 1}' if data else "")
        + (", guard: \"In('sup.Run')\"" if cross and not data else "")
        + "}",
        "{event: Begin completion, old: Busy, new: Done, kind: completion, api: Work}",
        "{event: Reset, old: Done, new: Idle, kind: command, api: Clear"
        + (", assign: {n: 0}" if data and rng.random() < 0.5 else "")
        + "}",
        "{event: Reset, old: Faulted, new: "
        + rng.choice(["Idle", "Done"])
        + ", kind: command, api: Clear}",
        "{event: Jam, old: Busy, new: Faulted, kind: fault, api: Clear}",
        "{event: Stop, old: "
        + rng.choice(["Busy", "Done"])
        + ", new: Idle, kind: command, api: Clear}",
    ]
    if timeout:
        rows.append(
            "{event: Tick, old: Busy, new: "
            + rng.choice(["Faulted", "Idle"])
            + ", kind: command, api: Clear}"
        )
    if rng.random() < 0.5:
        rows.append("{event: Begin, old: Done, new: Busy, kind: command, api: Work}")
    ignores = ["[all others]", "[]"]
    states = [
        "{state: Idle, control: default, ignore: " + rng.choice(ignores) + "}",
        busy + ", ignore: " + rng.choice(ignores) + "}",
        "{state: Done, control: event trigger required, ignore: " + rng.choice(ignores) + "}",
        "{state: Faulted, control: event trigger required, ignore: [all others]}",
    ]
    head = "device: Station\n" + ("data: {n: 0}\n" if data else "")
    return (
        head
        + "states:\n"
        + "".join(f"  - {s}\n" for s in states)
        + "events:\n"
        + "".join(f"  - {r}\n" for r in rows)
    )


def _random_cell(folder: Path, rng: random.Random) -> Path:
    """A supervisor and 2-3 stations with symmetric links and properties, sometimes
    broken by one asymmetric link or invariant."""
    (folder / "sup.yaml").write_text(SUPERVISOR, encoding="utf-8")
    (folder / "station.yaml").write_text(_station(rng), encoding="utf-8")
    n = rng.choice([2, 3, 3])
    names = [f"s{i}" for i in range(n)]
    text = "cell: random\ndevices:\n  sup: sup.yaml\n" + "".join(
        f"  {s}: station.yaml\n" for s in names
    )
    links: list[str] = []
    kinds = rng.sample(["begin", "stop", "hold", "raise", "done"], rng.randint(1, 4))
    for s in names:
        if "begin" in kinds:
            links.append(f"{{from: sup, enters: Run, to: {s}, send: Begin}}")
        if "stop" in kinds:
            links.append(
                f"{{from: sup, enters: Halt, to: {s}, send: Stop, ignore_if_unhandled: true}}"
            )
        if "hold" in kinds:
            links.append(f"{{from: {s}, enters: Faulted, to: sup, send: Hold}}")
        if "raise" in kinds:
            links.append(
                f"{{from: {s}, raises: Jam, to: sup, send: Hold, guard: \"In('sup.Run')\"}}"
            )
        if "done" in kinds:
            links.append(
                f"{{from: {s}, enters: Done, to: sup, send: Stop, ignore_if_unhandled: true}}"
            )
    if rng.random() < 0.2:  # every station tells every other: symmetric, in file order
        links += [
            f"{{from: {a}, enters: Done, to: {b}, send: Stop, ignore_if_unhandled: true}}"
            for a in names
            for b in names
            if a != b
        ]
    if rng.random() < 0.2:
        links.append("{from: s0, enters: Done, to: s1, send: Stop, ignore_if_unhandled: true}")
    rng.shuffle(links)
    env = ["{send: Start, to: sup}", "{send: Clear, to: sup}"]
    when = " when: \"In('sup.Run')\"," if rng.random() < 0.3 else ""
    for s in names:
        env.append(f"{{send: Begin, to: {s},{when}}}".replace(",}", "}"))
        env.append(f"{{send: Reset, to: {s}}}")
        env.append(f"{{fault: Jam, to: {s}}}")
    state = rng.choice(["Busy", "Done", "Faulted"])
    pick = rng.random()
    if pick < 0.4:
        holds = "not (" + " and ".join(f"In('{s}.{state}')" for s in names) + ")"
    elif pick < 0.7:
        holds = (
            "not (In('sup.Idle') and (" + " or ".join(f"In('{s}.{state}')" for s in names) + "))"
        )
    elif pick < 0.85:
        holds = f"not In('s0.{state}')"
    else:
        holds = "True"
    text += "links:\n" + "".join(f"  - {k}\n" for k in links)
    text += "environment:\n" + "".join(f"  - {e}\n" for e in env)
    text += f'invariants:\n  - {{name: inv, holds: "{holds}"}}\n'
    if rng.random() < 0.4:
        text += (
            'recovery:\n  - {name: home, to: "'
            + " and ".join(["In('sup.Idle')", *(f"In('{s}.Idle')" for s in names)])
            + '"}\n'
        )
    path = folder / "random.cell.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def _replays(cell: Cell, report: Report) -> int:
    """Every reproducible counterexample of ``report`` replays on the twins as it says;
    how many did."""
    done = 0
    for f in report.failures:
        if f.trace is None or f.assumed:
            continue
        steps = [
            ReplayStep(s.kind, s.device, s.event, tuple(zip(f.trace.devices, s.state, strict=True)))
            for s in f.trace.steps
        ]
        result = run_cell(cell, replay=steps)
        assert result.divergences == (), (f.kind, f.name, result.divergences)
        if f.kind is Kind.INVARIANT:
            assert result.violations, f.name
        done += 1
    return done


ORBIT_WIDE = {Kind.DEADLOCK, Kind.INVARIANT, Kind.RECOVERY}


def test_random_cells_reduced_and_full_agree(tmp_path: Path) -> None:
    """On 300 random cells the reduced search gives every property the full search's
    verdict, counts the full search's states, keeps orbit-wide counterexamples as short,
    and each of its counterexamples replays on the twins."""
    rng = random.Random(29)
    reduced_cells = replayed = 0
    for k in range(300):
        folder = tmp_path / f"c{k}"
        folder.mkdir()
        path = _random_cell(folder, rng)
        cell, diags = load_cell(path)
        assert cell is not None, [str(d) for d in diags]
        model = Composed(cell)
        full = explore(cell, model=model, symmetry=False, por=False)
        reduced = explore(cell, model=model, por=False)
        assert (reduced.verdict, reduced.properties) == (full.verdict, full.properties), path
        if not reduced.reductions:
            assert reduced.states == full.states
            continue
        reduced_cells += 1
        assert reduced.full_states == full.states, path
        assert reduced.states <= full.states
        for kind in ORBIT_WIDE:
            mine = sorted((f.name, len(f.trace or ())) for f in reduced.failures if f.kind is kind)
            theirs = sorted((f.name, len(f.trace or ())) for f in full.failures if f.kind is kind)
            assert mine == theirs, (path, kind)
        unreached = {f.name for f in full.findings if f.kind is Kind.UNREACHED}
        assert {f.name for f in reduced.findings if f.kind is Kind.UNREACHED} == unreached
        if k % 3 == 0:
            replayed += _replays(cell, reduced)
    assert reduced_cells >= 100
    assert replayed >= 30


def test_a_bounded_reduced_search_says_at_least(tmp_path: Path) -> None:
    """Stopped by --max-states, the reduced search counts the orbits it stored: a lower
    bound on the full search's states, said as such."""
    cell = load_cell_or_raise(_line(tmp_path, 4))
    report = explore(cell, max_states=20)
    assert (report.states, report.complete, report.verdict) == (20, False, "incomplete")
    assert report.full_states is not None and report.full_states > 20
    assert f"the full search stores at least {report.full_states:,}" in report.to_text()
