"""A device served over OPC UA as the implementation under test (``opcua:URL``).

The address space ``statectl run --opcua`` serves (docs/opcua.md), or any server that
follows it: the device object ``Objects/<device>`` (namespace ``urn:statectl``) with a
method per command event (outputs ``Handled``, ``Reason``) and ``StateMachine`` whose
``CurrentState`` names the active state (a composite state's sub-state machines are
reached through ``HasSubStateMachine``).

Rules:
1. ``send`` calls the event's method (its data as the ``Data`` JSON input, or one typed
   input per declared field). A completion is no method: the device reports it, so
   ``send`` lets time run (at most :data:`WAIT` s) until the device took it; a fault,
   or a completion the device does not report then, cannot be sent, and the test is
   skipped saying so.
2. ``advance`` is a bounded wall wait: the device runs on its own clock. The events it
   took meanwhile are read from the state change (the chart's transition from the
   states before to the states after); where two transitions join the same states
   (the Motor's ``Initialization completion`` and ``Error completion``), the
   machines' ``LastTransition`` numbers say which one the server took.
3. Invoke numbers and API calls are the server's business, not shown. The address
   space has no method that injects a fault, shows a monitor, silences the device or
   restarts it (a fault event is no method; the driver is behind the server), so those
   tests are skipped, each saying why and where to run them instead.
4. A test that serves the device in its own process may give the driver behind the
   server (``behind``, a twin or a real driver with ``inject_fault``): the fault is
   then injected into it and silencing goes to it, and what follows is read over OPC
   UA as always (the fault's transition in ``CurrentState``), so the fault and timeout
   tests run.
5. ``opc.tcp://USER:PASSWORD@HOST:PORT`` gives the session's user; security policy None
   (a test server on the loopback); a server that refuses is a clear error.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator, Mapping
from typing import Any
from urllib.parse import unquote, urlparse

from statectl.kernel.errors import StatectlError
from statectl.kernel.model import Chart, EventKind, StateKind
from statectl.out.testgen.adapters import Observed, Unsupported
from statectl.run.devices.base import Driver

__all__ = ["OpcuaImpl"]

NAMESPACE = "urn:statectl"
#: Seconds ``send`` waits for the device to report a completion it was asked to take.
WAIT = 5.0
#: The steps it waits in.
STEP = 0.05
#: Reads of ``LastTransition`` before a state change's transition is guessed (rule 2).
WAIT_LAST = 10


def _silent(event: str, data: Any = None) -> None:
    """Where a silenced driver's reports go: nowhere."""


class OpcuaImpl:
    """The :class:`~statectl.out.testgen.adapters.Implementation` of a device over OPC UA."""

    def __init__(self, url: str, chart: Chart, behind: Any = None) -> None:
        try:
            from asyncua import ua as ua_module
            from asyncua.sync import Client
        except ImportError:
            raise StatectlError("opcua: needs asyncua (pip install 'statectl[opcua]')") from None
        ua: Any = ua_module  # asyncua's names are generated: typed loosely
        self.ua = ua
        self.chart = chart
        self.behind = behind  # rule 4: the served device's driver, when in this process
        self.order = {s.name: i for i, s in enumerate(chart.states)}
        self.leaves = {
            s.name for s in chart.states if s.kind in (StateKind.ATOMIC, StateKind.FINAL)
        }
        parts = urlparse(url)
        plain = url if parts.username is None else url.replace(parts.netloc, parts.hostname or "")
        if parts.port is not None and parts.username is not None:
            plain = plain.replace(parts.hostname or "", f"{parts.hostname}:{parts.port}", 1)
        self.client = Client(plain, timeout=10)
        if parts.username is not None:
            self.client.set_user(unquote(parts.username))
            self.client.set_password(unquote(parts.password or ""))
        try:
            self.client.connect()
        except Exception as exc:  # asyncua raises many kinds: each is "cannot connect"
            raise StatectlError(f"cannot connect to {plain}: {exc}") from None
        try:
            self.ns = self.client.get_namespace_index(NAMESPACE)
            self.device = self.client.nodes.objects.get_child([f"{self.ns}:{chart.name}"])
            self.methods = {
                m.read_browse_name().Name: m
                for m in self.device.get_children(refs=ua.ObjectIds.HasComponent)
                if m.read_node_class() == ua.NodeClass.Method
            }
            self.machine = self.device.get_child([f"{self.ns}:StateMachine"])
        except Exception as exc:
            self.client.disconnect()
            raise StatectlError(
                f"{plain}: no device {chart.name!r} in namespace {NAMESPACE} ({exc})"
            ) from None

    def _active(self, machine: Any) -> Iterator[tuple[Any, str]]:
        """``machine`` and its active sub-state machines, each with the state it shows."""
        ua = self.ua
        shown = machine.get_child("0:CurrentState").read_value().Text or ""
        yield machine, shown
        if not shown:
            return
        try:
            node = machine.get_child([f"{self.ns}:{shown}"])
            subs = node.get_referenced_nodes(ua.ObjectIds.HasSubStateMachine)
        except Exception:  # a server without sub-state machines there: the state is a leaf
            subs = []
        for sub in subs:
            yield from self._active(sub)

    def states(self) -> tuple[str, ...]:
        found = [s for _, s in self._active(self.machine) if s in self.leaves]
        return tuple(sorted(set(found), key=self.order.__getitem__))

    def _inputs(self, method: Any, data: Any) -> list[Any]:
        ua = self.ua
        try:
            args = method.get_child("0:InputArguments").read_value()
        except Exception:
            args = []
        if not args:
            return []
        if len(args) == 1 and args[0].Name == "Data":
            text = "" if data is None else json.dumps(data)
            return [ua.Variant(text, ua.VariantType.String)]
        given = data if isinstance(data, dict) else {}
        return [given.get(a.Name) for a in args]

    def send(self, event: str, data: Any = None) -> Observed:
        method = self.methods.get(event)
        if method is None and self._kind(event) is EventKind.COMPLETION:
            return self._await(event)
        if method is None:
            raise Unsupported(
                f"{event} is no method of the OPC UA device: only its command events can be "
                "sent; the device reports its completions and faults itself"
            )
        try:
            out = self.device.call_method(method, *self._inputs(method, data))
        except Exception as exc:
            raise AssertionError(f"{event}: the server refused the call ({exc})") from None
        handled, reason = (out[0], out[1]) if isinstance(out, list) else (bool(out), "")
        return Observed(
            unhandled=None if handled else (reason or "unhandled"),
            unhandled_all=() if handled else ((event, reason or "unhandled"),),
        )

    def _kind(self, event: str) -> EventKind | None:
        return next((e.kind for e in self.chart.events if e.name == event), None)

    def _await(self, event: str) -> Observed:
        """Rule 1: let the device report ``event`` itself, within :data:`WAIT` seconds."""
        waited, seen = 0.0, Observed()
        while waited < WAIT:
            seen = self.advance(STEP)
            waited += STEP
            if not seen.events:
                continue
            if seen.events[0] == event:
                return Observed()
            break
        raise Unsupported(
            f"{event} is no method of the OPC UA device: it is the device's to report, "
            f"and it did not within {WAIT:g} s (it took {list(seen.events) or 'nothing'})"
        )

    def advance(self, seconds: float) -> Observed:
        before = self.states()
        time.sleep(seconds)
        after = self.states()
        if after == before:
            return Observed()
        return Observed(events=self._events(before, after))

    def _events(self, before: tuple[str, ...], after: tuple[str, ...]) -> tuple[str, ...]:
        """The events of the chart's transitions from ``before`` into ``after`` (rule 2)."""
        ancestors: set[str] = set()
        for s in after:
            cur: str | None = s
            while cur is not None:
                ancestors.add(cur)
                parent = self.chart.state(cur).parent if cur in self.order else None
                cur = parent
        found = [
            number
            for number, t in enumerate(self.chart.transitions, 1)  # numbered as served
            if t.events and t.source in before and all(x in ancestors for x in t.targets)
        ]
        if len(found) > 1:  # rule 2: the server says which of them it took
            found = self._taken(found)
        return (self.chart.transitions[found[0] - 1].events[0],) if found else ("(a state change)",)

    def _taken(self, candidates: list[int]) -> list[int]:
        """Of the transition ``candidates``, those a machine's ``LastTransition`` shows.

        The server writes ``LastTransition`` just after ``CurrentState``, so it is read a
        few times before the first candidate is taken as the answer."""
        for _ in range(WAIT_LAST):
            shown = self._last_numbers()
            taken = [n for n in candidates if n in shown]
            if taken:
                return taken
            time.sleep(STEP / 5)
        return candidates

    def _last_numbers(self) -> set[int]:
        """The ``LastTransition`` numbers of the active machines (the main one and those
        of its active states)."""
        try:
            return {
                int(m.get_child(["0:LastTransition", "0:Number"]).read_value())
                for m, _ in self._active(self.machine)
            }
        except Exception:  # a server without the optional Number: nothing to go by
            return set()

    def inject_fault(self, detail: str) -> None:
        inject = getattr(self.behind, "inject_fault", None)
        if callable(inject):  # rule 4: the driver behind the server reports it
            inject(detail)
            return
        raise Unsupported(
            "a fault cannot be injected over OPC UA: the address space statectl serves "
            "(docs/opcua.md) has a method per command event only; a fault event is none, and "
            "no method reaches the driver behind the server. The device's monitors raise its "
            "faults from what the device reports (each shows as the alarm Alarms/<fault>); "
            "run the fault tests on the runtime with the device's driver (statectl_driver)"
        )

    def monitoring(self) -> Mapping[str, int]:
        raise Unsupported(
            "the OPC UA address space shows no monitors: whether one runs in a state and how "
            "often it polled stay in the server (an alarm shows only a fault once raised); "
            "run the monitor tests on the runtime with the device's driver (statectl_driver)"
        )

    def restart(self) -> Observed:
        raise Unsupported(
            "a client cannot stop and resume the OPC UA server's device: restart the server "
            "with its journal (statectl run --journal FILE --resume) and check it by hand"
        )

    def stall(self) -> None:
        if isinstance(self.behind, Driver) and self.behind._clock is not None:
            Driver.bind(self.behind, _silent, self.behind._clock)  # rule 4
            return
        raise Unsupported(
            "a client cannot silence the OPC UA device's own reports (its completions), so a "
            "state's timeout cannot be made to run out from a test"
        )

    def close(self) -> None:
        self.client.disconnect()
