"""Partial-order reduction (explore/ample.py) gives the full search's verdicts.

Random cells, a few hundred of them, with links, guards over ``In()`` of other
devices, data, timeouts, deferral and completions, are searched reduced and in full;
the verdicts, the failing properties and the device states reached must agree, and
every counterexample the reduced search gives must replay on the simulated twins.
"""

from __future__ import annotations

import random
from pathlib import Path

from statectl.cell.explore import Report, explore
from statectl.cell.explore.replay import ReplayStep, run_cell
from statectl.cell.model import Cell, load_cell

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
        full = explore(cell, por=False)
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
