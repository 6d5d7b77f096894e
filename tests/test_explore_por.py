"""Partial-order reduction (explore/ample.py) gives the full search's verdicts.

Random cells, a few hundred of them, with links, guards over ``In()`` of other
devices, data, timeouts, deferral and completions, are searched reduced and in full;
the verdicts, the failing properties and the device states reached must agree, and
every counterexample the reduced search gives must replay on the simulated twins.
"""

from __future__ import annotations

import io
import random
from pathlib import Path

from statectl.cell.explore import Report, explore
from statectl.cell.explore.ample import reducible
from statectl.cell.explore.replay import ReplayStep, run_cell
from statectl.cell.explore.verify import verify_cell
from statectl.cell.model import Cell, load_cell, load_cell_or_raise
from statectl.channels.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

STATION = """\
device: Station
states:
  - {state: Idle, control: default, ignore: [Reset, Jam]}
  - {state: Busy, control: [event trigger required, monitoring required], ignore: [Begin, Reset]}
  - {state: Done, control: event trigger required, ignore: [Begin, Jam]}
  - {state: Faulted, control: event trigger required, ignore: [Begin, Jam]}
events:
  - {event: Begin, old: Idle, new: Busy, kind: command, api: Work}
  - {event: Finish, old: Busy, new: Done, kind: command, api: Work}
  - {event: Reset, old: Done, new: Idle, kind: command, api: Clear}
  - {event: Reset, old: Faulted, new: Idle, kind: command, api: Clear}
  - {event: Jam, old: Busy, new: Faulted, kind: fault, api: Clear}
"""


def stations(
    folder: Path, n: int, invariant: str = "not (In('s0.Idle') and In('s0.Busy'))"
) -> Path:
    """``n`` stations that do not interact (each Idle, Busy, Done or Faulted) and one
    invariant; the cell's path."""
    (folder / "station.yaml").write_text(STATION, encoding="utf-8")
    lines = ["cell: stations", "devices:", *(f"  s{i}: station.yaml" for i in range(n))]
    lines.append("environment:")
    for i in range(n):
        lines += [f"  - {{send: {e}, to: s{i}}}" for e in ("Begin", "Finish", "Reset")]
        lines.append(f"  - {{fault: Jam, to: s{i}}}")
    lines += ["invariants:", "  - name: inv", f'    holds: "{invariant}"']
    path = folder / f"stations-{n}.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_stations_that_do_not_interact_grow_linearly(tmp_path: Path) -> None:
    """N stations that share nothing: the reduced search stores a number of states that
    grows by the same amount per station; the full search stores 4**N."""
    counts = [
        explore(load_cell_or_raise(stations(tmp_path, n)), symmetry=False).states for n in (4, 6, 8)
    ]
    assert counts[2] - counts[1] == counts[1] - counts[0] > 0
    assert (
        explore(load_cell_or_raise(stations(tmp_path, 6)), por=False, symmetry=False).states == 4**6
    )
    assert counts[1] < 4**6 // 20


def test_no_por_option(tmp_path: Path) -> None:
    """``verify --no-por`` stores every state and prints no reduction line; by default
    the report names the reduction, the states stored and the full search's bound
    (the stations are interchangeable: symmetry, which would take them, is off)."""
    path = str(stations(tmp_path, 6))
    for argv, stored, line in (
        (["verify", path, "--no-symmetry"], None, True),
        (["verify", path, "--no-por", "--no-symmetry"], "explored 4,096 global states", False),
    ):
        out = io.StringIO()
        assert main(argv, out, io.StringIO()) == 0
        text = out.getvalue()
        assert ("partial-order reduction:" in text) is line
        assert stored is None or stored in text
        if line:
            assert "the full search stores at most 4,096 states" in text
    full, _ = verify_cell(path, por=False, symmetry=False)
    reduced, _ = verify_cell(path, symmetry=False)
    assert full is not None and reduced is not None
    assert full.states == 4**6 > reduced.states and full.verdict == reduced.verdict == "holds"


def test_recovery_cells_are_searched_in_full() -> None:
    """A cell with recovery properties is searched in full: the reduction does not keep
    "can always reach"."""
    cell = load_cell_or_raise(EXAMPLES / "pick-and-place" / "cell.yaml")
    assert "recovery" in reducible(cell)
    report = explore(cell)
    assert (
        report.reductions == () and report.states == explore(cell, por=False, symmetry=False).states
    )


def test_a_failure_is_searched_again_in_full(tmp_path: Path) -> None:
    """When the reduced search fails, the report is the full search's: shortest traces,
    counts over every state, and a line saying so."""
    cell = load_cell_or_raise(stations(tmp_path, 6, "not (In('s4.Faulted') and In('s5.Faulted'))"))
    report, full = explore(cell, symmetry=False), explore(cell, por=False, symmetry=False)
    assert report.verdict == "fails" and report.shortest
    assert "searched again in full" in report.reductions[0]
    assert [(f.name, len(f.trace or ()), f.count) for f in report.failures] == [
        (f.name, len(f.trace or ()), f.count) for f in full.failures
    ]
    assert "shortest trace (4 steps)" in report.to_text()


def test_not_shortest_when_the_full_search_stops_first(tmp_path: Path) -> None:
    """If the full search reaches the bound before the failure the reduced one met, the
    reduced report stands and says its traces are not shortest."""
    path = stations(tmp_path, 8, "not (In('s6.Faulted') and In('s7.Faulted'))")
    report = explore(load_cell_or_raise(path), max_states=300, symmetry=False)
    assert report.verdict == "fails" and not report.shortest
    text = report.to_text()
    assert "steps; not shortest: partial-order reduction):" in text
    assert "shortest trace" not in text
    doc = report.to_json()
    assert doc["shortest_traces"] is False and doc["reductions"]


STATES = ("A", "B", "C", "D")
EVENTS = ("Go", "Back", "Poke", "Kick")


def _device(
    rng: random.Random, name: str, others: list[tuple[str, int]]
) -> tuple[str, int, list[tuple[str, str]]]:
    """A random device file: 2-4 states, rows over a few events, maybe data, a timeout,
    a deferred event, a completion, a guard over another device's state. Also its
    number of states and the inputs the environment may give it (kind, event)."""
    k = rng.randint(2, 4)
    states = STATES[:k]
    rows: list[str] = []
    handled: dict[str, set[str]] = {s: set() for s in states}
    kinds: dict[str, str] = {}
    data = rng.random() < 0.25
    ring = [(s, states[(i + 1) % k]) for i, s in enumerate(states) if rng.random() < 0.7]
    for i in range(len(ring) + rng.randint(1, 4)):
        event = rng.choice(EVENTS)
        old, new = ring[i] if i < len(ring) else (rng.choice(states), rng.choice(states))
        if event in handled[old] or old == new:
            continue
        handled[old].add(event)
        extra = ""
        if others and rng.random() < 0.25:
            dev, n = rng.choice(others)
            extra = f", guard: \"In('{dev}.{STATES[rng.randrange(n)]}')\""
        elif data and rng.random() < 0.4:
            extra = ", guard: n < 2, assign: n = n + 1"
        kind = kinds.setdefault(event, "fault" if rng.random() < 0.2 and old != "A" else "command")
        rows.append(
            f"  - {{event: {event}, old: {old}, new: {new}, kind: {kind}, api: M{event}}}"[:-1]
            + f"{extra}}}"
        )
    if not rows:
        rows.append("  - {event: Go, old: A, new: B, kind: command, api: MGo}")
        handled["A"].add("Go")
        kinds["Go"] = "command"
    commands = [e for e, kd in kinds.items() if kd == "command"]
    if commands and rng.random() < 0.3:
        old, new = rng.sample(states, 2)
        rows.append(
            f"  - {{event: Fin, old: {old}, new: {new}, kind: completion, api: M{commands[0]}}}"
        )
        handled[old].add("Fin")
        kinds["Fin"] = "completion"
    timeout = rng.random() < 0.2
    if timeout:
        rows.append(
            f"  - {{event: Tick, old: {states[-1]}, new: {states[0]}, kind: fault, api: MTick}}"
        )
        handled[states[-1]].add("Tick")
    known = [e for e in (*EVENTS, "Fin") if e in kinds]
    lines = [f"device: {name}"]
    if data:
        lines.append("data: {n: 0}")
    lines.append("states:")
    deferred = False
    for i, s in enumerate(states):
        control = "default" if i == 0 else "[event trigger required, monitoring required]"
        ignore = [e for e in known if e not in handled[s] and rng.random() < 0.6]
        keys = f"state: {s}, control: {control}"
        free = [e for e in known if e not in handled[s] and e not in ignore]
        if i > 0 and free and not deferred and rng.random() < 0.2:
            keys += f", defer: [{free[0]}]"
            deferred = True
        if ignore:
            keys += f", ignore: [{', '.join(ignore)}]"
        if timeout and i == k - 1:
            keys += ", timeout: 5s -> Tick"
        lines.append(f"  - {{{keys}}}")
    lines.append("events:")
    lines.extend(rows)
    inputs = [(kd, e) for e, kd in kinds.items() if kd in ("command", "fault")]
    return "\n".join(lines) + "\n", k, inputs


def random_cell(rng: random.Random, folder: Path) -> Path:
    """2-5 random devices, links between them, environment inputs (some with ``when``),
    one or two invariants over ``In()``."""
    n = rng.randint(2, 5)
    names = [f"d{i}" for i in range(n)]
    sizes: list[tuple[str, int]] = []
    inputs: dict[str, list[tuple[str, str]]] = {}
    for name in names:
        text, k, inputs[name] = _device(rng, name.upper(), list(sizes))
        sizes.append((name, k))
        (folder / f"{name}.yaml").write_text(text, encoding="utf-8")

    def atom(among: list[tuple[str, int]] = sizes) -> str:
        dev, k = rng.choice(among)
        return f"In('{dev}.{STATES[rng.randrange(k)]}')"

    lines = ["cell: random", "devices:", *(f"  {n}: {n}.yaml" for n in names)]
    if rng.random() < 0.3:
        lines.append("completions: auto")
    links = []
    for _ in range(rng.randint(0, 3)):
        src, dst = rng.sample(names, 2)
        state = STATES[rng.randrange(dict(sizes)[src])]
        guard = f', guard: "{atom()}"' if rng.random() < 0.3 else ""
        event = rng.choice([e for _, e in inputs[dst]] or ["Go"])
        links.append(f"  - {{from: {src}, enters: {state}, to: {dst}, send: {event}{guard}}}")
    if links:
        lines += ["links:", *links]
    lines.append("environment:")
    for name in names:
        mine = inputs[name]
        for kind, event in rng.sample(mine, min(len(mine), rng.randint(1, 3))):
            when = f', when: "{atom()}"' if rng.random() < 0.2 and kind == "command" else ""
            key = "send" if kind == "command" else "fault"
            lines.append(f"  - {{{key}: {event}, to: {name}{when}}}")
    lines.append("invariants:")
    for i in range(rng.randint(1, 2)):
        among = sizes if rng.random() < 0.5 else [rng.choice(sizes)]  # one device: often holds
        lines.append(f"  - name: inv{i}")
        lines.append(f'    holds: "not ({atom(among)} and {atom(among)})"')
    path = folder / "cell.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _replay_steps(report: Report) -> list[tuple[str, list[ReplayStep]]]:
    """Each counterexample of ``report`` that assumes nothing beyond the model, as steps."""
    out = []
    for f in report.failures:
        if f.trace is None or f.assumed:
            continue
        steps = [
            ReplayStep(
                s.kind,
                s.device,
                s.event,
                tuple(zip(f.trace.devices, s.state, strict=True)),
                tuple((d.via, d.fate) for d in s.deliveries if d.fate),
            )
            for s in f.trace.steps
        ]
        out.append((f"{f.kind.value} {f.name}", steps))
    return out


def _summary(report: Report) -> tuple[object, ...]:
    """What the reduced search must agree on with the full one."""
    return (
        report.verdict,
        report.properties,
        sorted((f.kind.value, f.name) for f in report.findings),
        sorted((u.device, u.state, u.event, u.source.value) for u in report.unanticipated),
    )


def _reduced(cell: Cell) -> Report:
    """The reduced search alone, without explore()'s full search again on failure."""
    from statectl.cell.explore.compose import Composed
    from statectl.cell.explore.search import _search

    return _search(cell, Composed(cell), None, None, True)


def test_random_cells_same_verdicts(tmp_path: Path) -> None:
    """On 300 random cells the reduced search gives the full search's verdicts,
    failures, unreached states and unanticipated inputs, never stores more states, and
    every counterexample it gives replays on the twins without a divergence."""
    reduced_somewhere = replayed = failing = 0
    for seed in range(300):
        folder = tmp_path / f"c{seed}"
        folder.mkdir()
        cell, diags = load_cell(random_cell(random.Random(seed), folder))
        assert cell is not None, (seed, [str(d) for d in diags])
        full = explore(cell, por=False, symmetry=False)
        red = _reduced(cell)
        assert _summary(red) == _summary(full), seed
        assert red.states <= full.states
        reduced_somewhere += red.states < full.states
        failing += bool(red.failures)
        shortest = dict(_replay_steps(full))
        for name, steps in _replay_steps(red):
            result = run_cell(cell, replay=steps)
            replayed += 1
            if result.divergences:
                # only where the full search's own trace diverges too (the runner
                # disagrees with the explorer there, with or without the reduction)
                again = run_cell(cell, replay=shortest[name])
                assert again.divergences, (seed, name, result.divergences)
    # the generator must keep making cells where the reduction bites, and failures
    assert reduced_somewhere > 50 and failing > 50 and replayed > 50, (
        reduced_somewhere,
        failing,
        replayed,
    )
