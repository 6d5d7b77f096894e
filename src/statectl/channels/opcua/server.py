"""An OPC UA server for a running :class:`~statectl.run.system.System` (asyncua, its own thread).

Rules:
1. The server runs on its own asyncio loop on its own thread. It never makes a
   device wait: the owner only appends to a list while a step runs, and after the
   step hands the list over with one ``call_soon_threadsafe``; the loop writes
   the variables and fires the events (an update it cannot write is logged on
   ``statectl.opcua``; the later ones are still written). A step comes as one step record
   (``listen_steps``): only its transitions and notifications become records.
2. Address space (namespace ``urn:statectl``): ``Objects/<device>`` per device,
   holding its machines (:mod:`statectl.channels.opcua.space`), each an instance of
   ``StatectlStateMachineType`` (a subtype of ``FiniteStateMachineType``), with
   ``CurrentState`` (``Id``, ``Number``), ``LastTransition`` (``Id``, ``Number``,
   ``TransitionTime``), its states as ``StateType`` objects (``InitialStateType``
   for the initial one) and transitions as ``TransitionType`` objects with their
   numbers and ``FromState`` / ``ToState`` / ``HasCause`` references. Every
   transition a step takes fires a ``TransitionEventType`` event from the device
   object. ``Invokes`` lists the device's invoke numbers, ``LastInvoke`` is the
   last one issued (-1: none yet). A machine whose states are all inactive shows
   an empty ``CurrentState``. ``AvailableTransitions`` / ``AvailableStates`` list
   the transitions leaving the current state and the states they lead to, written
   with it. Every variable holds a value of its type from the start (a generic
   client reads the whole space cleanly): ``LastTransition`` is an empty text with
   a null ``Id`` and the null DateTime until the first transition.
3. Each command event is a method of the device object with one optional input,
   ``Data`` (the event's data as JSON), or, when the event declares its data
   fields, one typed input per field (``Movement(amount: Double)``), and two
   outputs: ``Handled`` and ``Reason`` (empty when handled, else why the event
   changed nothing, or why it was not accepted). Every call is checked (its
   object, its inputs, the session's user against the System's commands policy)
   and sent through the System's door
   (:mod:`statectl.channels.opcua.methods`). A device whose file declares
   ``profile: packml`` gets the PackML companion's names too
   (:mod:`statectl.channels.opcua.packml`), and its PackTags
   (:mod:`statectl.channels.opcua.packtags`).
4. Security: anonymous sessions may browse, read and subscribe; calling a method
   needs the configured user (a session with wrong credentials is refused). The
   endpoints offer only the configured policies (Basic256Sha256 SignAndEncrypt
   by default) with the server's certificate (:mod:`statectl.channels.opcua.certs`),
   and only those open a session: a None channel the config does not list serves
   discovery only (:mod:`statectl.channels.opcua.access`).
5. A device's data items are read-only variables in a ``Data`` folder, written
   after each step that changed them; the type comes from the initial value
   (Boolean, Int64, Double, String; anything else JSON text), and a value that
   fits it in no way keeps the last one, marked ``UncertainLastUsableValue``.
6. A fault a monitored state raises is an OPC UA alarm (``AlarmConditionType``) of
   the device, raised by the fault's step and cleared when the device leaves the
   state it entered; clients acknowledge it and refresh the retained ones
   (:mod:`statectl.channels.opcua.alarms`).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

from statectl.channels.opcua.access import Users as _Users
from statectl.channels.opcua.access import discovery_only
from statectl.channels.opcua.access import rules as _Rules
from statectl.channels.opcua.access import ua_module as _ua
from statectl.channels.opcua.alarms import AlarmSpace, alarm_events
from statectl.channels.opcua.certs import APP_URI, default_directory, ensure_certificate
from statectl.channels.opcua.config import endpoint_problem
from statectl.channels.opcua.methods import Calls
from statectl.channels.opcua.nodes import (
    browse,
    data_argument,
    data_kind,
    data_variant,
    node_ids,
    nothing_yet,
    optional,
    typed_argument,
    write_data,
)
from statectl.channels.opcua.packml import PackmlNaming, PackmlSpace, naming, packml_call
from statectl.channels.opcua.packtags import PackTags
from statectl.channels.opcua.space import Change, Layout, changes, layout
from statectl.kernel.errors import StatectlError
from statectl.kernel.semantics import Outcome
from statectl.run.runtime import InvokeIssued, MicrostepTaken, Started, StepRecord
from statectl.run.system import System

__all__ = ["NAMESPACE", "OpcuaServer", "OpcuaSettings"]

NAMESPACE = "urn:statectl"
_LOG = logging.getLogger("statectl.opcua")
#: A DateTime's null (OPC 10000-6: 1601-01-01, encoded 0): ``TransitionTime`` before any.
_NEVER = datetime(1601, 1, 1, tzinfo=UTC)
_START_TIMEOUT = 30.0


@contextlib.contextmanager
def _quiet_start() -> Iterator[None]:
    """asyncua logs a failed start (a port in use) with a traceback before it raises; the
    failure is reported once, by :meth:`OpcuaServer.start`, as one line."""
    log = logging.getLogger("asyncua.server.server")
    was = log.disabled
    log.disabled = True
    try:
        yield
    finally:
        log.disabled = was


@dataclass(frozen=True, slots=True)
class OpcuaSettings:
    """Everything the server needs; the CLI resolves flags, config and environment."""

    endpoint: str = "opc.tcp://127.0.0.1:4840"
    user: str | None = None
    password: str | None = None
    security: tuple[str, ...] = ("Basic256Sha256",)
    certificates: Path | None = None

    def __repr__(self) -> str:  # rule: a password is never echoed
        return (
            f"OpcuaSettings(endpoint={self.endpoint!r}, user={self.user!r}, "
            f"password={'***' if self.password else None}, security={self.security!r})"
        )


@dataclass(slots=True)
class _Machine:
    current: Any
    current_id: Any
    current_number: Any
    last: Any
    last_id: Any
    last_number: Any
    last_time: Any
    states: frozenset[str]
    available_states: Any = None
    available_transitions: Any = None
    shown: str | None = None


@dataclass(slots=True)
class _Device:
    name: str
    layout: Layout
    node: Any = None
    machines: list[_Machine] | None = None
    state_nodes: dict[str, Any] | None = None
    transition_nodes: dict[int, Any] | None = None
    last_invoke: Any = None
    events: Any = None  # the TransitionEventType generator
    pending: list[Change] | None = None
    #: data item -> its variable, its kind (rule 5) and the variant it shows
    data: dict[str, list[Any]] | None = None
    packtags: PackTags | None = None  # a PackML device's Status and Admin (packtags.py)


#: What a step shows: the device, its active states, its changes, its data, a fault.
_Update = tuple[
    _Device, frozenset[str], list[Change], dict[str, Any] | None, tuple[str, Any] | None
]


class OpcuaServer:
    """Serve ``system``'s devices over OPC UA; :meth:`start` returns once it listens."""

    def __init__(self, system: System, settings: OpcuaSettings) -> None:
        self.system = system
        self.settings = settings
        self.url = settings.endpoint
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._failure: BaseException | None = None
        self._stop: asyncio.Event | None = None
        self._devices = {
            name: _Device(name, layout(s.chart), pending=[]) for name, s in system.subjects.items()
        }
        self._offs: list[Callable[[], None]] = []
        self._server: Any = None
        self._updates: deque[_Update] = deque()
        self._alarms: AlarmSpace | None = None  # rule 6 (alarms.py)
        self._faults = {n: frozenset(alarm_events(s.chart)) for n, s in system.subjects.items()}
        self._kick: Any = None  # an asyncio.Event of the server's loop
        self._loop_thread: int | None = None
        self._packml_space: PackmlSpace | None = None  # when a device declares PackML
        self._calls = Calls(system)  # the methods' handlers (rule 3, methods.py)

    # -- hooks on the owner (rule 1) ------------------------------------------------------

    def _hook(self) -> None:
        for name, subject in self.system.subjects.items():
            device = self._devices[name]

            def keep(step: StepRecord, device: _Device = device) -> None:
                buffer = device.pending
                assert buffer is not None
                decided = step.step
                if decided is not None:  # an event's step: what it took, no typed records
                    buffer.extend(changes(step.device, step.time, decided))
                    return
                for record in step.records:  # one made outside an event (start, a monitor)
                    if type(record) is Started:
                        buffer.clear()
                    elif type(record) is MicrostepTaken:
                        buffer.extend(record.transitions)
                    elif type(record) is InvokeIssued:
                        buffer.append(record)

            def stepped(
                event: str, data: Any, outcome: str, device: _Device = device, s: Any = subject
            ) -> None:
                records = device.pending
                assert records is not None
                device.pending = []
                loop = self._loop
                fault = None  # a fault that raises an alarm (rule 6): its event and data
                if event in self._faults[device.name] and outcome == Outcome.HANDLED:
                    fault = (event, data)
                now: _Update = (device, s.configuration, records, dict(s.data), fault)
                if threading.get_ident() == self._loop_thread:
                    self._publish(now)
                elif loop is not None:
                    with contextlib.suppress(RuntimeError):  # the loop closed: stopping
                        loop.call_soon_threadsafe(self._publish, now)

            self._offs.append(subject.listen_steps(keep))
            self._offs.append(subject.on_step(stepped))

    # -- life ------------------------------------------------------------------------------

    def start(self) -> str:
        """Build the address space, listen, and hook the devices; returns the endpoint URL."""
        self._thread = threading.Thread(target=self._main, name="statectl-opcua", daemon=True)
        self._thread.start()
        if not self._ready.wait(_START_TIMEOUT):
            raise StatectlError("opcua: the server did not start within 30 s")
        if self._failure is not None:
            self._thread.join()
            failure = self._failure
            if isinstance(failure, StatectlError):
                raise failure
            raise StatectlError(f"opcua: cannot serve {self.url}: {failure}") from None
        self._hook()  # on the caller's thread, before the System starts (refresh() after)
        return self.url

    def refresh(self) -> None:
        """Show every device's current states (after the System started or resumed)."""
        loop = self._loop
        if loop is None:
            return
        for name, s in self.system.subjects.items():
            now: _Update = (self._devices[name], s.configuration, [], dict(s.data), None)
            loop.call_soon_threadsafe(self._publish, now)

    def stop(self) -> None:
        """Unhook the devices, stop the server and its thread."""
        for off in self._offs:
            off()
        self._offs.clear()
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(stop.set)
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()

    def _main(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # reported by start(); the thread ends quietly
            self._failure = exc
            self._ready.set()

    async def _serve(self) -> None:
        from asyncua.server.server import Server

        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        users: Any = _Users(self.settings.user, self.settings.password)  # asyncua's protocol
        server = Server(user_manager=users)
        await server.init()
        await self._secure(server)
        idx = await server.register_namespace(NAMESPACE)
        await self._build(server, idx)
        self._server = server
        self._kick = asyncio.Event()
        self._loop_thread = threading.get_ident()
        writer = asyncio.create_task(self._writer())
        try:
            with _quiet_start():
                await server.start()
        except BaseException:
            writer.cancel()
            raise
        try:
            self._ready.set()
            await self._stop.wait()
        finally:
            writer.cancel()
            await server.stop()

    async def _secure(self, server: Any) -> None:
        ua = _ua()

        settings = self.settings
        problem = endpoint_problem(settings.endpoint)
        if problem is not None:
            raise StatectlError(f"opcua: {problem}")
        host = urlparse(settings.endpoint).hostname
        try:  # asyncua would log a traceback of its own for a host it cannot bind
            await asyncio.get_running_loop().getaddrinfo(host, None)
        except OSError as exc:
            raise StatectlError(
                f"opcua: cannot serve {settings.endpoint}: host {host!r} is unknown ({exc})"
            ) from None
        server.set_endpoint(settings.endpoint)
        server.set_server_name("statectl")
        await server.set_application_uri(APP_URI)
        policies = []
        if "Basic256Sha256" in settings.security:
            cert, key = await ensure_certificate(settings.certificates or default_directory())
            await server.load_certificate(str(cert))
            await server.load_private_key(str(key))
            policies.append(ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt)
        if "None" in settings.security:
            policies.append(ua.SecurityPolicyType.NoSecurity)
        server.set_security_policy(policies, permission_ruleset=_Rules())
        if "None" not in settings.security:  # a None channel only discovers (access.py rule 2)
            factories = getattr(server, "_policies", None)  # asyncua's, shared with each channel
            if not isinstance(factories, list):  # never serve what could not be refused
                raise StatectlError(
                    "opcua: this asyncua has no policy factories statectl can add to, so it "
                    "could not refuse the None policy; install asyncua 1.1.5 to 2.x"
                )
            factories.append(discovery_only())
        server.set_identity_tokens([ua.AnonymousIdentityToken, ua.UserNameIdentityToken])

    # -- the address space (rule 2) --------------------------------------------------------

    async def _build(self, server: Any, idx: int) -> None:
        ua = _ua()

        fsm = server.get_node(ua.NodeId(ua.ObjectIds.FiniteStateMachineType))
        kind = await fsm.add_object_type(idx, "StatectlStateMachineType")
        objects = server.nodes.objects
        charts = {n: s.chart for n, s in self.system.subjects.items()}
        names = {n: naming(charts[n], d.layout) for n, d in self._devices.items()}
        packml = await PackmlSpace.create(server, kind, idx) if any(names.values()) else None
        self._alarms = alarms = await AlarmSpace.create(server, self.system)
        self._packml_space = packml
        for name, device in self._devices.items():
            chart = charts[name]
            node = await objects.add_object(idx, name)
            await node.set_event_notifier([ua.EventNotifier.SubscribeToEvents])
            device.node = node
            device.events = await server.get_event_generator(
                ua.ObjectIds.TransitionEventType, emitting_node=node
            )
            methods = {}
            declared = {e.name: e.fields for e in chart.events}
            for event in device.layout.commands:
                fields = declared.get(event, ())
                methods[event] = await node.add_method(
                    idx,
                    browse(event),
                    self._calls.event(name, event, node.nodeid, fields),
                    [typed_argument(f, kind) for f, kind in fields] or [data_argument()],
                    [ua.VariantType.Boolean, ua.VariantType.String],
                )
            invokes = [f"{i.number} {i.name} {i.method}" for i in chart.invokes]
            await node.add_variable(
                idx, "Invokes", ua.Variant(invokes, ua.VariantType.String, is_array=True)
            )
            await self._data(node, idx, device, self.system.subjects[name].data)
            device.last_invoke = await node.add_variable(
                idx, "LastInvoke", ua.Variant(-1, ua.VariantType.Int32)
            )
            await alarms.add_device(idx, name, node, chart)
            pack = names[name]
            made = await self._machines(node, kind, idx, device, methods, chart.initial, pack)
            if packml is not None and pack is not None:
                await packml.finish(node, made, pack, functools.partial(self._packml, name))
                data = dict(self.system.subjects[name].data)
                device.packtags = await PackTags.create(node, chart, idx, packml.index, data)

    def _packml(self, device: str, event: str, holder: Any) -> Callable[..., Any]:
        """A PackML command method of ``holder``: the same call, answered with a status."""
        return self._calls.checked(
            holder,
            False,
            packml_call(lambda data, origin: self._calls.outcome(device, event, data, origin)),
        )

    async def _machines(
        self, node: Any, kind: Any, idx: int, device: _Device, methods: dict[str, Any],
        initial: Sequence[str], pack: PackmlNaming | None = None,
    ) -> list[Any]:  # fmt: skip
        ua = _ua()

        lay = device.layout
        made: list[Any] = []
        device.machines, device.state_nodes, device.transition_nodes = [], {}, {}
        chart_initial = set(initial)
        packml = self._packml_space
        for at, spec in enumerate(lay.machines):
            holder = node if spec.holder is None else device.state_nodes[spec.holder]
            where, bname, otype = (packml and packml.machine(pack, at)) or (
                idx,
                spec.name,
                kind.nodeid,
            )
            machine = await holder.add_object(where, bname, objecttype=otype)
            made.append(machine)
            if spec.holder is not None:
                await holder.add_reference(machine.nodeid, ua.ObjectIds.HasSubStateMachine)
            first = _initial(self.system.subjects[device.name].chart, spec, chart_initial)
            for state in spec.states:
                stype = ua.ObjectIds.InitialStateType if state == first else ua.ObjectIds.StateType
                snode = await machine.add_object(idx, browse(state), objecttype=stype)
                number = await snode.get_child("0:StateNumber")
                await number.write_value(
                    ua.Variant(lay.state_numbers[state], ua.VariantType.UInt32)
                )
                device.state_nodes[state] = snode
            current = await machine.get_child("0:CurrentState")
            last = await machine.get_child("0:LastTransition")
            await nothing_yet(last)
            device.machines.append(
                _Machine(
                    current,
                    await current.get_child("0:Id"),
                    await optional(current, idx, "Number", ua.VariantType.UInt32, 0),
                    last,
                    await last.get_child("0:Id"),
                    await optional(last, idx, "Number", ua.VariantType.UInt32, 0),
                    await optional(last, idx, "TransitionTime", ua.VariantType.DateTime, _NEVER),
                    frozenset(spec.states),
                    await node_ids(machine, idx, "AvailableStates"),
                    await node_ids(machine, idx, "AvailableTransitions"),
                )
            )
        for at, spec in enumerate(lay.machines):
            for number in spec.transitions:
                tnode = await made[at].add_object(
                    idx,
                    browse(lay.transition_names[number]),
                    objecttype=ua.ObjectIds.TransitionType,
                )
                prop = await tnode.get_child("0:TransitionNumber")
                await prop.write_value(ua.Variant(number, ua.VariantType.UInt32))
                source, target = lay.ends[number]
                await tnode.add_reference(device.state_nodes[source].nodeid, ua.ObjectIds.FromState)
                if target is not None:
                    await tnode.add_reference(
                        device.state_nodes[target].nodeid, ua.ObjectIds.ToState
                    )
                t = self.system.subjects[device.name].chart.transitions[number - 1]
                for event in t.events:
                    if event in methods:
                        await tnode.add_reference(methods[event].nodeid, ua.ObjectIds.HasCause)
                device.transition_nodes[number] = tnode
        return made

    # -- updates on the loop (rule 1) ------------------------------------------------------

    async def _data(self, node: Any, idx: int, device: _Device, data: Any) -> None:
        """Rule 5: a ``Data`` folder with one read-only variable per data item."""
        device.data = {}
        if not data:
            return
        folder = await node.add_folder(idx, "Data")
        for item, value in data.items():
            kind = data_kind(value)
            variant = data_variant(value, kind) or data_variant(None, "Json")
            variable = await folder.add_variable(idx, browse(item), variant)
            device.data[item] = [variable, kind, variant]

    def _publish(self, update: _Update) -> None:
        self._updates.append(update)
        self._kick.set()

    async def _writer(self) -> None:
        """One task writes every update, in the order the steps happened."""
        updates, kick = self._updates, self._kick
        while True:
            await kick.wait()
            kick.clear()
            while updates:
                update = updates.popleft()
                try:
                    await self._write(update)
                except Exception:  # one bad update must not stop every later one
                    _LOG.exception("cannot show a step of %s; later ones still", update[0].name)

    async def _write(self, update: _Update) -> None:
        ua = _ua()
        device, active, records, data, fault = update

        if device.machines is None or device.state_nodes is None:
            return
        lay = device.layout
        now = datetime.now(UTC)
        server = self._server

        async def put(node: Any, value: Any, kind: Any) -> None:
            data = ua.DataValue(ua.Variant(value, kind), SourceTimestamp=now, ServerTimestamp=now)
            await server.write_attribute_value(node.nodeid, data)

        text, node_id, uint = (
            ua.VariantType.LocalizedText,
            ua.VariantType.NodeId,
            ua.VariantType.UInt32,
        )
        for m in device.machines:  # first what clients wait for
            inside = m.states & active
            shown = next(iter(inside)) if inside else ""
            if shown == m.shown:
                continue
            m.shown = shown
            await put(m.current, ua.LocalizedText(shown), text)
            sid = device.state_nodes[shown].nodeid if shown else ua.NodeId()
            await put(m.current_id, sid, node_id)
            if m.current_number is not None:
                await put(m.current_number, lay.state_numbers[shown] if shown else 0, uint)
            states, moves = _available(device, shown)
            await put(m.available_states, states, node_id)
            await put(m.available_transitions, moves, node_id)
        if data and device.data:
            await write_data(server, device.data, data, now)
        if device.packtags is not None:
            await device.packtags.write(server, active, data, now)
        if records:
            await asyncio.sleep(0)  # let the publisher send the new states before the rest
        for record in records:
            if isinstance(record, InvokeIssued):
                await put(device.last_invoke, record.invoke, ua.VariantType.Int32)
                continue
            number = lay.by_record.get((record.source, record.targets, record.label))
            if number is None or device.transition_nodes is None:
                continue
            source, target = lay.ends[number]
            name = lay.transition_names[number]
            tid = device.transition_nodes[number].nodeid
            for m in device.machines:
                if source in m.states:
                    await put(m.last, ua.LocalizedText(name), text)
                    await put(m.last_id, tid, node_id)
                    if m.last_number is not None:
                        await put(m.last_number, number, uint)
                    if m.last_time is not None:
                        await put(m.last_time, now, ua.VariantType.DateTime)
            ev = device.events
            ev.event.Transition = ua.LocalizedText(name)
            setattr(ev.event, "Transition/Id", ua.Variant(tid, node_id))
            ev.event.FromState = ua.LocalizedText(source)
            setattr(
                ev.event, "FromState/Id", ua.Variant(device.state_nodes[source].nodeid, node_id)
            )
            to = target or ""
            ev.event.ToState = ua.LocalizedText(to)
            to_id = device.state_nodes[to].nodeid if to else ua.NodeId()
            setattr(ev.event, "ToState/Id", ua.Variant(to_id, node_id))
            await ev.trigger(message=f"{device.name}: {name}")
        if self._alarms is not None:  # rule 6
            await self._alarms.stepped(device.name, active, records, fault)


def _initial(chart: Any, spec: Any, chart_initial: set[str]) -> str | None:
    """The state a machine starts in: the holder's initial child, else the chart's."""
    if spec.holder is not None:
        first = chart.state(spec.holder).initial
        picks = [s for s in first if s in spec.states]
        if picks:
            return str(picks[0])
    picks = [s for s in spec.states if s in chart_initial]
    return str(picks[0]) if picks else (str(spec.states[0]) if spec.states else None)


def _available(device: _Device, shown: str) -> tuple[list[Any], list[Any]]:
    """What a machine in ``shown`` offers (rule 2): the node ids of the transitions leaving
    it and of the states they lead to in the machine, in chart order; none when empty."""
    lay, states, moves = device.layout, device.state_nodes, device.transition_nodes
    if not shown or states is None or moves is None:
        return [], []
    numbers = [n for n, (source, _) in lay.ends.items() if source == shown and n in moves]
    targets = dict.fromkeys(t for n in numbers if (t := lay.ends[n][1]) is not None)
    return [states[t].nodeid for t in targets], [moves[n].nodeid for n in numbers]
