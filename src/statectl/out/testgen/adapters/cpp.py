"""The generated C++ as the implementation under test (``cpp:PROGRAM``).

``PROGRAM`` is the harness ``statectl codegen FILE --harness`` writes, compiled with
``-DSTATECTL_TRACE=1`` (:mod:`statectl.out.codegen.harness` gives its line protocol).
One process per test; each command's answer ends with ``done``.

What the C++ shows: the states, the invokes issued, each API call (the generated API's
methods take no arguments: a call's data is the event's, as the application passes it
along) and why an event changed nothing. Behind the API the harness has a small twin
on a simulated clock: ``advance`` lets its completions come, its monitors poll and
the device's timeouts fire; ``inject_fault`` gives the twin a fault. What it cannot
do is restart (the C++ keeps no journal): the recovery tests are skipped, saying so.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart
from statectl.out.testgen.adapters import Call, Observed, Unsupported

__all__ = ["CppImpl"]

#: Seconds the harness may take to answer one command.
ANSWER_TIMEOUT = 10.0


class CppImpl:
    """The :class:`~statectl.out.testgen.adapters.Implementation` of a C++ harness program."""

    def __init__(self, program: str, chart: Chart) -> None:
        path = Path(program)
        if not path.is_file() or not os.access(path, os.X_OK):
            raise StatectlError(
                f"{program}: no such executable; build the harness of `statectl codegen FILE "
                "--harness` (g++ -std=c++17 -DSTATECTL_TRACE=1 ...) and give its path"
            )
        self.chart = chart
        self.order = {s.name: i for i, s in enumerate(chart.states)}
        self.proc = subprocess.Popen(
            [str(path.resolve())],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
        self._answer()  # the start's

    def _ask(self, command: str) -> list[str]:
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write(command + "\n")
            self.proc.stdin.flush()
        except OSError as exc:
            raise StatectlError(f"the C++ harness stopped ({exc})") from None
        return self._answer()

    def _answer(self) -> list[str]:
        assert self.proc.stdout is not None
        lines: list[str] = []
        while True:
            line = self.proc.stdout.readline()
            if not line:
                raise StatectlError(
                    f"the C++ harness ended (exit {self.proc.poll()}) before answering"
                )
            line = line.rstrip("\n")
            if line == "done":
                return lines
            lines.append(line)

    def states(self) -> tuple[str, ...]:
        found = [x.removeprefix("state ") for x in self._ask("states") if x.startswith("state ")]
        return tuple(sorted(found, key=lambda s: self.order.get(s, len(self.order))))

    def send(self, event: str, data: Any = None) -> Observed:
        return self._observed(self._ask(f"send {event}"), event, data)

    def _observed(self, answer: list[str], sent: str | None, data: Any) -> Observed:
        invokes: list[tuple[int, str]] = []
        calls: list[Call] = []
        unhandled: list[tuple[str, str]] = []
        events: list[str] = []
        for line in answer:
            kind, _, rest = line.partition(" ")
            if kind == "event":
                if rest == sent and sent is not None:
                    sent = None  # the event sent: not one the device took by itself
                else:
                    events.append(rest)
            elif kind == "invoke":
                n, _, method = rest.partition(" ")
                invokes.append((int(n), method))
            elif kind == "api":
                calls.append(Call(rest, data if not events else None))
            elif kind == "ignored":
                name, _, reason = rest.rpartition(" (")
                unhandled.append((name, reason.rstrip(")")))
            elif kind == "unknown":
                unhandled.append((rest, "no transition"))
        return Observed(
            unhandled=unhandled[0][1] if unhandled else None,
            invokes=tuple(invokes),
            calls=tuple(calls),
            events=tuple(events),
            unhandled_all=tuple(unhandled),
        )

    def advance(self, seconds: float) -> Observed:
        return self._observed(self._ask(f"advance {seconds!r}"), None, None)

    def inject_fault(self, detail: str) -> None:
        self._ask(f"fault {detail}")

    def monitoring(self) -> Mapping[str, int]:
        found = {}
        for line in self._ask("monitors"):
            state, _, polls = line.removeprefix("monitor ").rpartition(" ")
            found[state] = int(polls)
        return found

    def restart(self) -> Observed:
        raise Unsupported("the C++ harness keeps no journal to resume from")

    def stall(self) -> None:
        self._ask("stall")

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=ANSWER_TIMEOUT)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
